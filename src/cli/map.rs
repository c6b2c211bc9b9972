//! `bowloc map build`: index a set of images against a vocabulary;
//! `bowloc map add|remove|list|compact`: change a map file's images through
//! its change log, as the service's `/images` endpoints do; `bowloc map
//! orb-pass`: a map's ORB side, for the ORB pass.

use anyhow::Context;
use bowloc::dataset::image_list;
use bowloc::geometry::packed::PACKED_BYTES;
use bowloc::index::metadata::pose_row;
use bowloc::index::{MapRead, Places};
use bowloc::live::{Applied, Change, LiveMap, NewImage, now_ms};
use bowloc::orb_pass::OrbPassParams;
use bowloc::pipeline::Localizer;
use bowloc::pipeline::build_map;
use bowloc::server::images::{ImageItem, check_id};
use bowloc::vocabulary::Vocabulary;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum MapCommand {
    /// Build a tf-idf inverted index over map images.
    Build(BuildArgs),
    /// Add an image to a map (or replace the image of the same id), durably
    /// in the map's change log (MAP.changes).
    Add(AddArgs),
    /// Remove an image from a map, durably in its change log.
    Remove(ChangeArgs),
    /// List a map's images (changes included) as JSON lines.
    List(ListArgs),
    /// Fold a map's change log into a new map file.
    Compact(ListArgs),
    /// Build a map's ORB side (MAP.orbpass), for the ORB pass that answers
    /// easy queries before SIFT (`[orb_pass]` of `bowloc serve`).
    OrbPass(OrbPassArgs),
}

#[derive(Args)]
pub struct OrbPassArgs {
    /// Vocabulary file the map was built with.
    #[arg(long)]
    vocab: PathBuf,
    /// Map file.
    #[arg(long)]
    map: PathBuf,
    /// The image list or folder the map was built from (same order).
    #[arg(long)]
    images: PathBuf,
    /// Output file (default: MAP.orbpass beside the map, where the service
    /// looks for it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Binary words of the side's vocabulary.
    #[arg(long, default_value_t = OrbPassParams::default().words)]
    words: usize,
    /// ORB keypoints kept per map image (queries keep as many).
    #[arg(long, default_value_t = OrbPassParams::default().keypoints)]
    keypoints: usize,
    /// Where ORB's keypoints come from: `none` (ORB's own strongest
    /// corners) or `COLSxROWS` (spread over a grid of cells).
    #[arg(long, default_value_t = OrbPassParams::default().grid)]
    grid: String,
}

#[derive(Args)]
pub struct AddArgs {
    /// Vocabulary file the map was built with.
    #[arg(long)]
    vocab: PathBuf,
    /// Map file.
    #[arg(long)]
    map: PathBuf,
    /// The image's id (its name in the map); default: the file name.
    #[arg(long)]
    id: Option<String>,
    /// Place label.
    #[arg(long)]
    place: Option<String>,
    /// A pose value, FIELD=VALUE for one of the map's pose fields (repeat).
    #[arg(long = "pose", value_name = "FIELD=VALUE")]
    pose: Vec<String>,
    /// The image file.
    image: PathBuf,
}

#[derive(Args)]
pub struct ChangeArgs {
    /// Map file.
    #[arg(long)]
    map: PathBuf,
    /// The image's id (its name in the map).
    #[arg(long)]
    id: String,
}

#[derive(Args)]
pub struct ListArgs {
    /// Map file.
    #[arg(long)]
    map: PathBuf,
}

fn open_live(map: &std::path::Path) -> anyhow::Result<LiveMap> {
    let (live, opened) = LiveMap::open(map, None, true, usize::MAX)?;
    if opened.replayed > 0 {
        tracing::info!(replayed = opened.replayed, "change log replayed");
    }
    Ok(live)
}

/// The pose row of `--pose FIELD=VALUE` arguments.
fn pose_values(given: &[String], fields: &[String]) -> anyhow::Result<Vec<f64>> {
    let pairs = given
        .iter()
        .map(|g| {
            g.split_once('=')
                .ok_or_else(|| anyhow::anyhow!("--pose {g}: expected FIELD=VALUE"))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    pose_row(fields, pairs).map_err(|e| anyhow::anyhow!("--pose {}: {e}", e.field()))
}

fn print_change(
    id: &str,
    applied: Applied,
    generation: u64,
    features: Option<usize>,
) -> anyhow::Result<()> {
    let line = serde_json::json!({
        "id": id,
        "index": applied.id,
        "generation": generation,
        "replaced": applied.replaced,
        "features": features,
    });
    outln!("{line}")
}

#[derive(Args)]
pub struct BuildArgs {
    /// Vocabulary file.
    #[arg(long)]
    vocab: PathBuf,
    /// An image list (line order = map image id) or a folder.
    #[arg(long)]
    images: PathBuf,
    /// Output map file.
    #[arg(long)]
    out: PathBuf,
    /// CSV with header `image,place[,pose fields...]` labelling map images.
    #[arg(long)]
    places: Option<PathBuf>,
    /// Name of the map (default: the output file's stem).
    #[arg(long)]
    name: Option<String>,
    /// Fail on the first unreadable image instead of skipping it.
    #[arg(long)]
    strict: bool,
}

pub fn run(command: MapCommand) -> anyhow::Result<()> {
    match command {
        MapCommand::Build(a) => build(a),
        MapCommand::OrbPass(a) => orb_pass(a),
        MapCommand::Add(a) => {
            let id = match &a.id {
                Some(id) => id.clone(),
                None => a
                    .image
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .ok_or_else(|| anyhow::anyhow!("give --id"))?,
            };
            check_id(&id).map_err(|e| anyhow::anyhow!("--id {id}: {}", e.message))?;
            let (localizer, _) = Localizer::open_live(&a.vocab, &a.map, true, usize::MAX)?;
            let bytes = std::fs::read(&a.image)
                .with_context(|| format!("{}: cannot read", a.image.display()))?;
            let features = localizer
                .map_features(&bytes)
                .with_context(|| format!("{}", a.image.display()))?;
            let live = &localizer.map;
            let pose = pose_values(&a.pose, &live.snapshot().meta().pose_fields)?;
            let n = features.len();
            if n == 0 {
                tracing::warn!(id, "the image has no features: no query can find it");
            }
            let (applied, generation) = live.apply(Change::Add(NewImage {
                name: id.clone(),
                place: a.place.clone().unwrap_or_default(),
                pose,
                features,
                added_at_ms: now_ms(),
            }))?;
            print_change(&id, applied, generation, Some(n))?;
            Ok(())
        }
        MapCommand::Remove(a) => {
            let live = open_live(&a.map)?;
            let (applied, generation) = live.apply(Change::Remove { name: a.id.clone() })?;
            print_change(&a.id, applied, generation, None)?;
            Ok(())
        }
        MapCommand::List(a) => {
            let live = open_live(&a.map)?;
            let s = live.snapshot();
            for j in s.ids() {
                let item = ImageItem::of(&s, j);
                outln!("{}", serde_json::to_string(&item)?)?;
            }
            Ok(())
        }
        MapCommand::Compact(a) => {
            let live = open_live(&a.map)?;
            match live.compact()? {
                Some(c) => outln!("{}", serde_json::to_string(&c)?)?,
                None => tracing::info!("no changes to fold"),
            }
            Ok(())
        }
    }
}

fn build(a: BuildArgs) -> anyhow::Result<()> {
    let vocab = Vocabulary::open(&a.vocab, true)?;
    let images = image_list(&a.images)?;
    let places = a.places.as_deref().map(Places::from_csv).transpose()?;
    let name = a.name.clone().unwrap_or_else(|| {
        a.out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "map".into())
    });
    let map = build_map(&vocab, &images, places.as_ref(), &name, a.strict)?;
    map.save(&a.out)?;
    let m = map.meta();
    let bytes = std::fs::metadata(&a.out).map_or(0, |f| f.len());
    // the two geometry sections: packed features and per-image offsets
    let geometry_bytes = m.features as usize * PACKED_BYTES + (m.images + 1) * 8;
    tracing::info!(
        path = %a.out.display(),
        images = m.images,
        postings = m.postings,
        features = m.features,
        without_features = m.images_without_features,
        bytes,
        geometry_bytes,
        "map written"
    );
    Ok(())
}

fn orb_pass(a: OrbPassArgs) -> anyhow::Result<()> {
    let params = OrbPassParams {
        words: a.words,
        keypoints: a.keypoints,
        grid: a.grid.clone(),
        ..OrbPassParams::default()
    };
    params.validate().map_err(anyhow::Error::msg)?;
    let localizer = Localizer::open(&a.vocab, &a.map, true)?;
    let images = image_list(&a.images)?;
    let side = bowloc::pipeline::build_orb_side(&localizer, &images, &params)?;
    let out = a
        .out
        .unwrap_or_else(|| bowloc::orb_pass::file::path_beside(&a.map));
    side.save(&out)?;
    let features: usize = side.images.iter().map(|m| m.centres.len()).sum();
    tracing::info!(
        path = %out.display(),
        images = side.images.len(),
        features,
        words = side.vocabulary.len(),
        bytes = std::fs::metadata(&out).map_or(0, |f| f.len()),
        "ORB side written"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::pose_values;

    #[test]
    fn pose_arguments() {
        let fields = vec!["x".to_owned(), "y".to_owned()];
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let pose = pose_values(&args(&["y=2"]), &fields).unwrap();
        assert!(pose[0].is_nan());
        assert_eq!(pose[1], 2.0);
        assert!(pose_values(&[], &fields).unwrap().is_empty());
        for (bad, says) in [
            (&["x"][..], "FIELD=VALUE"),
            (&["z=1"], "its pose fields: x, y"),
            (&["x=1", "x=2"], "more than once"),
            (&["x=inf"], "finite"),
        ] {
            let e = pose_values(&args(bad), &fields).unwrap_err().to_string();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }
}

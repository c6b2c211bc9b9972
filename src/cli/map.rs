//! `bowloc map build`: index a set of images against a vocabulary.

use bowloc::dataset::image_list;
use bowloc::geometry::packed::PACKED_BYTES;
use bowloc::index::Places;
use bowloc::pipeline::build_map;
use bowloc::vocabulary::Vocabulary;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum MapCommand {
    /// Build a tf-idf inverted index over map images.
    Build(BuildArgs),
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
    let MapCommand::Build(a) = command;
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

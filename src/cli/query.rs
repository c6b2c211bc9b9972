//! `bowloc query`: localize image files and print the answers as JSON.

use super::args::{MapFiles, SearchArgs, SequenceArgs, VerifyArgs};
use bowloc::features::TileGrid;
use bowloc::index::MapRead;
use bowloc::pipeline::Localizer;
use bowloc::report::SequenceAnswer;
use bowloc::sequence::{Filter, Topology, TopologyKind};
use clap::Args;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(Args)]
pub struct QueryArgs {
    #[command(flatten)]
    files: MapFiles,
    /// Query images, or folders of them (a folder's images in name order,
    /// numbers by value, as `map build` takes a folder). One that cannot be
    /// read or decoded gets an answer holding its error (and a warning);
    /// the others are answered, and the command exits with an error at the
    /// end.
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Print each answer as one line of JSON as soon as it is answered,
    /// instead of a JSON array once every image is.
    #[arg(long)]
    jsonl: bool,
    #[command(flatten)]
    search: SearchArgs,
    /// Streaming extraction's tile grid, COLSxROWS[+MARGIN][,coarse] (1x1: the
    /// whole image at once; `,coarse`: a half-size pass first). Default:
    /// 2x2+24, or the whole image for the rule `none`, which cannot stop.
    #[arg(long)]
    tiles: Option<TileGrid>,
    #[command(flatten)]
    verify: VerifyArgs,
    /// Do not let the ORB pass look at each image first. By default it does,
    /// as the service's, when the map has its ORB side beside it
    /// (MAP.orbpass, from `bowloc map orb-pass`), with the service's default
    /// setting (`[orb_pass]`).
    #[arg(long)]
    no_orb_pass: bool,
    /// Run the images, in the order given, as the frames of one camera
    /// through the sequence filter (each answer's `sequence` has the filtered
    /// candidates); frames stop by the service's sequence rule unless
    /// `--rule` or a parameter is given.
    #[arg(long)]
    sequence: bool,
    #[command(flatten)]
    model: SequenceArgs,
}

pub fn run(a: QueryArgs) -> anyhow::Result<()> {
    a.files.check_defaults()?;
    let mut localizer = Localizer::open(&a.files.vocab, &a.files.map, true)?;
    localizer.tiles = TileGrid::DEFAULT;
    localizer.set_verify(a.verify.params()?);
    let model = a.model.model()?;
    let snapshot = localizer.map.snapshot();
    let side = bowloc::orb_pass::file::path_beside(&a.files.map);
    if !a.no_orb_pass && side.exists() {
        let params = bowloc::orb_pass::OrbPassParams::default();
        match bowloc::pipeline::OrbPass::open(&side, snapshot.base().meta(), &params) {
            Ok(pass) => localizer.orb_pass = Some(pass),
            Err(e) => tracing::warn!("{e:#}: the ORB pass is off"),
        }
    }
    let mut options = if a.sequence {
        // the frames stop by the sequence's rule, as the service's do
        let sequence = bowloc::server::config::SequenceConfig::default();
        let rule = sequence.rule().map_err(anyhow::Error::msg)?;
        let warmup = sequence.min_features.resolve(snapshot.auto_warmup());
        a.search.options_over(&rule, warmup)?
    } else {
        a.search.options()?
    };
    options.orb_pass = localizer.orb_pass.is_some();
    let topology = Topology::of(
        TopologyKind::Auto,
        snapshot.id_range(),
        snapshot.positions(),
    )
    .map_err(anyhow::Error::msg)?;
    let images = image_files(&a.images)?;
    let mut filter = Filter::new();
    let mut answers = Answers::new(a.jsonl);
    let mut failed = 0;
    for path in &images {
        let prediction = a.sequence.then(|| filter.predict(&model, &topology, None));
        let mut frame_options = options.clone();
        frame_options.prior = prediction.as_ref().map(|p| Arc::new(p.prior.clone()));
        let query = serde_json::Value::String(path.display().to_string());
        let mut answer = match localizer.localize_file(path, &frame_options, a.tiles) {
            Ok(answer) => answer,
            Err(e) => {
                // one bad file does not cost the others their answers
                tracing::warn!("not localized: {e:#}");
                failed += 1;
                answers.push(serde_json::json!({"query": query, "error": format!("{e:#}")}))?;
                continue;
            }
        };
        if let (Some(p), Some(post)) = (&prediction, answer.posterior.take()) {
            filter.update(post, p);
            answer.sequence = filter.belief().map(|b| {
                SequenceAnswer::new(&*snapshot, "cli", p, filter.frames(), b, options.top_n)
            });
        }
        let mut value = serde_json::to_value(&answer)?;
        value["query"] = query;
        answers.push(value)?;
    }
    answers.finish()?;
    if failed > 0 {
        anyhow::bail!(
            "{failed} of {} images could not be localized (their answers hold the error)",
            images.len()
        );
    }
    Ok(())
}

/// The image files `paths` name: a folder stands for its images.
fn image_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        if path.is_dir() {
            let images = bowloc::dataset::image_list(path)?;
            files.extend(images.into_iter().map(|image| image.path));
        } else {
            files.push(path.clone());
        }
    }
    Ok(files)
}

/// Where the answers go: a line each as it comes (`--jsonl`), or an
/// array at the end.
enum Answers {
    Lines,
    Array(Vec<serde_json::Value>),
}

impl Answers {
    fn new(lines: bool) -> Self {
        if lines {
            Answers::Lines
        } else {
            Answers::Array(Vec::new())
        }
    }

    fn push(&mut self, answer: serde_json::Value) -> anyhow::Result<()> {
        match self {
            Answers::Lines => outln!("{}", serde_json::to_string(&answer)?)?,
            Answers::Array(all) => all.push(answer),
        }
        Ok(())
    }

    fn finish(self) -> anyhow::Result<()> {
        if let Answers::Array(all) = self {
            outln!("{}", serde_json::to_string_pretty(&all)?)?;
        }
        Ok(())
    }
}

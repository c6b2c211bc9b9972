//! `bowloc query`: localize image files and print the answers as JSON.

use super::args::{SearchArgs, VerifyArgs};
use bowloc::features::TileGrid;
use bowloc::pipeline::Localizer;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct QueryArgs {
    /// Vocabulary file.
    #[arg(long)]
    vocab: PathBuf,
    /// Map file.
    #[arg(long)]
    map: PathBuf,
    /// Query images.
    #[arg(required = true)]
    images: Vec<PathBuf>,
    #[command(flatten)]
    search: SearchArgs,
    /// Streaming extraction's tile grid, COLSxROWS[+MARGIN][,coarse] (1x1: the
    /// whole image at once; `,coarse`: a half-size pass first).
    #[arg(long, default_value = "2x2+24")]
    tiles: TileGrid,
    #[command(flatten)]
    verify: VerifyArgs,
}

pub fn run(a: QueryArgs) -> anyhow::Result<()> {
    let mut localizer = Localizer::open(&a.vocab, &a.map, true)?;
    localizer.tiles = a.tiles;
    localizer.set_verify(a.verify.params()?);
    let options = a.search.options()?;
    let mut answers = Vec::with_capacity(a.images.len());
    for path in &a.images {
        let answer = localizer.localize_file(path, &options)?;
        let mut value = serde_json::to_value(&answer)?;
        value["query"] = serde_json::Value::String(path.display().to_string());
        answers.push(value);
    }
    println!("{}", serde_json::to_string_pretty(&answers)?);
    Ok(())
}

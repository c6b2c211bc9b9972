//! `bowloc vocab build`: train a vocabulary on the descriptors of an image set.

use super::args::ExtractArgs;
use bowloc::dataset::image_list;
use bowloc::pipeline::build_vocabulary;
use bowloc::vocabulary::kmeans::KmeansConfig;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum VocabCommand {
    /// Train a vocabulary with k-means (k-means++ seeding, Lloyd iterations).
    Build(BuildArgs),
}

#[derive(Args)]
pub struct BuildArgs {
    /// An image list (one path a line, relative to the list) or a folder.
    #[arg(long)]
    images: PathBuf,
    /// Number of visual words K.
    #[arg(long)]
    words: usize,
    /// k-means seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output vocabulary file.
    #[arg(long)]
    out: PathBuf,
    /// Maximum Lloyd iterations.
    #[arg(long, default_value_t = KmeansConfig::default().max_iter)]
    max_iter: usize,
    /// Stop when fewer than this fraction of descriptors change word.
    #[arg(long, default_value_t = KmeansConfig::default().tolerance)]
    tolerance: f64,
    /// Train on at most this many descriptors, drawn at random (0 = all).
    #[arg(long, default_value_t = KmeansConfig::default().train_sample)]
    train_sample: usize,
    /// Fail on the first unreadable image instead of skipping it.
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    extract: ExtractArgs,
}

pub fn run(command: VocabCommand) -> anyhow::Result<()> {
    let VocabCommand::Build(a) = command;
    let images = image_list(&a.images)?;
    let config = KmeansConfig {
        k: a.words,
        seed: a.seed,
        max_iter: a.max_iter,
        tolerance: a.tolerance,
        train_sample: a.train_sample,
        ..Default::default()
    };
    let vocab = build_vocabulary(&images, &a.extract.config(), &config, a.strict)?;
    vocab.save(&a.out)?;
    tracing::info!(
        path = %a.out.display(),
        words = vocab.words(),
        hash = %vocab.hash_hex(),
        "vocabulary written"
    );
    Ok(())
}

//! `bowloc shards`: the sharded search simulated on a dataset. Prints, for
//! each vocabulary seed, setting and shard count, whether the shards gave one
//! machine's answers and the messages per query; fails when any answer differs.

use super::args::{ExtractArgs, dataset_name, vocab_seeds};
use bowloc::eval::shards::{self, ShardsConfig};
use bowloc::features::TileGrid;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct ShardsArgs {
    /// Dataset folder (map.txt, queries.txt).
    #[arg(long)]
    dataset: PathBuf,
    /// Vocabulary size K (trained on the map images, cached).
    #[arg(long, default_value_t = 1000)]
    words: usize,
    /// Vocabularies: N (k-means seeds 1..=N) or a list of seeds `a,b,…`.
    #[arg(long, value_delimiter = ',', default_value = "3")]
    vocab_seeds: Vec<u64>,
    /// Shard counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [2usize, 4, 8])]
    shards: Vec<usize>,
    /// Random feature orders per query.
    #[arg(long, default_value_t = 3)]
    runs: u32,
    /// Candidates each search returns.
    #[arg(long, default_value_t = 5)]
    top_n: usize,
    /// Settings RULE[=VALUE][@WARMUP] (repeatable; default: every vote-only
    /// rule at its example value, and the recommended default).
    #[arg(long = "set", value_name = "RULE[=VALUE][@WARMUP]")]
    set: Vec<String>,
    /// The queries' tile grid, COLSxROWS[+MARGIN] (1x1: whole images).
    #[arg(long, default_value = "2x2+24")]
    tiles: TileGrid,
    /// Cache folder (default data/eval-cache/<dataset>, shared with `bowloc eval`).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Also write the rows as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    extract: ExtractArgs,
}

pub fn run(a: ShardsArgs) -> anyhow::Result<()> {
    let name = dataset_name(&a.dataset);
    let config = ShardsConfig {
        words: a.words,
        seeds: vocab_seeds(&a.vocab_seeds),
        shards: a.shards,
        runs: a.runs,
        top_n: a.top_n,
        settings: a.set,
        tiles: a.tiles,
        extract: a.extract.config(),
        cache: a
            .cache
            .unwrap_or_else(|| PathBuf::from("data/eval-cache").join(&name)),
        dataset: a.dataset,
    };
    let rows = shards::run(&config)?;
    out!("{}", shards::markdown(&rows))?;
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)?;
    }
    let differ: usize = rows.iter().map(|r| r.searches - r.identical).sum();
    let searches: usize = rows.iter().map(|r| r.searches).sum();
    outln!("{name}: {differ} of {searches} sharded searches differ from one machine's")?;
    anyhow::ensure!(
        differ == 0,
        "{differ} sharded answers differ from one machine's"
    );
    Ok(())
}

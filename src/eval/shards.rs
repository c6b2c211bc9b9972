//! The sharded search simulated on a dataset (`bowloc shards`): the map of
//! each vocabulary seed split into 2, 4, 8… in-process shards by image, every
//! query searched by one machine ([`Query::search`]) and by the shards
//! ([`crate::search::shard`]) under each setting and random order, the two
//! answers compared (candidates with their scores, stop point, stop reason)
//! and the messages per query counted. docs/scale.md quotes its output.

use super::cache;
use super::sweep::{self, Setting};
use super::tiles::Query;
use crate::dataset::Dataset;
use crate::features::{ExtractConfig, TileGrid};
use crate::index::MapIndex;
use crate::search::shard::{self, ShardedMap};
use crate::search::stop::RULES;
use crate::search::{RuleSpec, SearchOptions};
use crate::vocabulary::kmeans::KmeansConfig;
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;

/// What to simulate.
#[derive(Debug, Clone)]
pub struct ShardsConfig {
    pub dataset: PathBuf,
    /// Vocabulary size K.
    pub words: usize,
    /// k-means seeds: one vocabulary and map each.
    pub seeds: Vec<u64>,
    /// Shard counts.
    pub shards: Vec<usize>,
    /// Random feature orders per query.
    pub runs: u32,
    /// Candidates each search returns.
    pub top_n: usize,
    /// Settings `RULE[=VALUE][@WARMUP]`; empty: every rule of the registry
    /// that votes only (not `verified`) at its example value, and the
    /// recommended default.
    pub settings: Vec<String>,
    pub tiles: TileGrid,
    pub extract: ExtractConfig,
    pub cache: PathBuf,
}

/// One setting at one shard count on one vocabulary, over every query and run.
#[derive(Debug, Clone, Serialize)]
pub struct ShardRow {
    pub seed: u64,
    pub setting: String,
    pub shards: usize,
    pub searches: usize,
    /// Searches whose sharded answer equals one machine's: the same
    /// candidates with bit-equal scores, stop point and stop reason.
    pub identical: usize,
    /// Mean fraction of the query's features voted.
    pub fraction: f64,
    /// Per query, means: round trips, messages, bytes, and the messages a
    /// round trip per feature would have taken.
    pub rounds: f64,
    pub messages: f64,
    pub kib: f64,
    pub per_feature_messages: f64,
    /// Largest shard's share of the map's postings.
    pub largest_shard: f64,
}

/// The settings simulated by default: every rule of the registry a sharded
/// map runs ([`crate::search::stop::RuleInfo::shardable`]) at its example value (no warm-up), and
/// the recommended default's vote rule (without its verified stop).
pub fn default_settings() -> Vec<Setting> {
    let mut settings: Vec<Setting> = RULES
        .iter()
        .filter(|r| r.shardable())
        .map(|r| {
            let rule = RuleSpec::new(r.name, r.parameter.map(|p| p.example))
                .expect("the registry's example values are valid");
            Setting::new(rule, 0)
        })
        .collect();
    // the default's vote rule: its verified stop checks geometry, which
    // shards do not simulate
    let recommended = SearchOptions::recommended();
    let votes = recommended
        .rule
        .or_verified(Some(0.0))
        .expect("0 turns the check off");
    settings.push(Setting::new(votes, recommended.min_features));
    settings
}

/// Maps and quantized queries, one pair per vocabulary seed (from the
/// evaluation's cache, made on first use).
fn seed_maps(config: &ShardsConfig) -> anyhow::Result<Vec<(u64, MapIndex, Vec<Query>)>> {
    let dataset = Dataset::open(&config.dataset)?;
    let (map_desc, query_desc) =
        cache::dataset_descriptors(&config.cache, &dataset, &config.extract, config.tiles)?;
    config
        .seeds
        .iter()
        .map(|&seed| {
            let kmeans = KmeansConfig {
                k: config.words,
                seed,
                ..KmeansConfig::default()
            };
            let vocab = cache::vocabulary(&config.cache, &map_desc, &kmeans)?;
            let map = cache::map_index(&config.cache, &vocab, &map_desc, &dataset.name)?;
            let (queries, _) =
                super::quantize_queries(&query_desc, &vocab, &format!("quantizing (seed {seed})"));
            Ok((seed, map, queries))
        })
        .collect()
}

/// Run the simulation: one row per seed × setting × shard count.
pub fn run(config: &ShardsConfig) -> anyhow::Result<Vec<ShardRow>> {
    anyhow::ensure!(config.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(
        config.shards.iter().all(|&s| s >= 1),
        "shard counts are at least 1"
    );
    let settings = if config.settings.is_empty() {
        default_settings()
    } else {
        config
            .settings
            .iter()
            .map(|spec| sweep::parse_setting(spec, 0))
            .collect::<anyhow::Result<_>>()?
    };
    anyhow::ensure!(
        settings.iter().all(|s| s.rule.shardable()),
        "rules that verify geometry or read the whole histogram are not simulated on shards"
    );
    let mut rows = Vec::new();
    for (seed, map, queries) in seed_maps(config)? {
        for &count in &config.shards {
            let sharded = ShardedMap::split(&map, count);
            let postings = sharded.postings_per_shard();
            let largest = *postings.iter().max().unwrap_or(&0) as f64
                / postings.iter().sum::<usize>().max(1) as f64;
            for setting in &settings {
                rows.push(compare(
                    &map, &sharded, &queries, setting, config, seed, largest,
                ));
            }
        }
    }
    Ok(rows)
}

/// One sharded search: (identical to the single map's answer, fraction of
/// the features used, rounds, messages, bytes, messages per feature).
type SearchStats = (bool, f64, usize, usize, usize, usize);

/// Every query and run of one setting, on one machine and on the shards.
fn compare(
    map: &MapIndex,
    sharded: &ShardedMap<'_>,
    queries: &[Query],
    setting: &Setting,
    config: &ShardsConfig,
    seed: u64,
    largest_shard: f64,
) -> ShardRow {
    let jobs: Vec<(u32, usize)> = (0..config.runs)
        .flat_map(|run| (0..queries.len()).map(move |q| (run, q)))
        .collect();
    let per_search: Vec<SearchStats> = jobs
        .par_iter()
        .map(|&(run, q)| {
            let query = &queries[q];
            // the shards hold no signatures: both searches vote plain tf-idf
            let options = SearchOptions {
                hamming: None,
                ..setting.options(sweep::seed(run, q), sweep::Ranking::top(config.top_n))
            };
            let one = query.search(map, &options, false).outcome;
            let (_, spans) = query.tile_order(options.seed, options.tile_order);
            let s = shard::search_tiles(sharded, &query.batches(&spans), &options);
            let identical = s.outcome.candidates == one.candidates
                && s.outcome.features_used == one.features_used
                && s.outcome.features_total == one.features_total
                && s.outcome.stop == one.stop;
            let t = s.traffic;
            (
                identical,
                if query.words.is_empty() {
                    1.0
                } else {
                    one.features_used as f64 / query.words.len() as f64
                },
                t.rounds,
                t.messages,
                t.bytes,
                t.per_feature_messages,
            )
        })
        .collect();
    let n = per_search.len().max(1) as f64;
    let mean = |f: &dyn Fn(&SearchStats) -> f64| per_search.iter().map(f).sum::<f64>() / n;
    ShardRow {
        seed,
        setting: setting.label(),
        shards: sharded.shards(),
        searches: per_search.len(),
        identical: per_search.iter().filter(|r| r.0).count(),
        fraction: mean(&|r| r.1),
        rounds: mean(&|r| r.2 as f64),
        messages: mean(&|r| r.3 as f64),
        kib: mean(&|r| r.4 as f64 / 1024.0),
        per_feature_messages: mean(&|r| r.5 as f64),
        largest_shard,
    }
}

/// The rows as a Markdown table, one line per setting and shard count:
/// sums over the vocabulary seeds for the searches, means over the seeds
/// for the rest, with the messages' range over seeds.
pub fn markdown(rows: &[ShardRow]) -> String {
    let mut out = String::from(
        "| setting | shards | identical / searches | features used | round trips | messages (range over seeds) | KiB | messages, a round trip per feature | largest shard's postings |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    let mut keys: Vec<(&str, usize)> = Vec::new();
    for r in rows {
        if !keys.contains(&(r.setting.as_str(), r.shards)) {
            keys.push((r.setting.as_str(), r.shards));
        }
    }
    keys.sort_by_key(|k| k.1);
    for (setting, shards) in keys {
        let group: Vec<&ShardRow> = rows
            .iter()
            .filter(|r| r.setting == setting && r.shards == shards)
            .collect();
        let n = group.len() as f64;
        let mean = |f: fn(&ShardRow) -> f64| group.iter().map(|r| f(r)).sum::<f64>() / n;
        let lo = group
            .iter()
            .map(|r| r.messages)
            .fold(f64::INFINITY, f64::min);
        let hi = group.iter().map(|r| r.messages).fold(0.0, f64::max);
        out += &format!(
            "| {setting} | {shards} | {} / {} | {:.1} % | {:.1} | {:.1} ({lo:.1}–{hi:.1}) | {:.1} | {:.0} | {:.1} % |\n",
            group.iter().map(|r| r.identical).sum::<usize>(),
            group.iter().map(|r| r.searches).sum::<usize>(),
            100.0 * mean(|r| r.fraction),
            mean(|r| r.rounds),
            mean(|r| r.messages),
            mean(|r| r.kib),
            mean(|r| r.per_feature_messages),
            100.0 * mean(|r| r.largest_shard),
        );
    }
    out
}

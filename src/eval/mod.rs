//! The evaluation of the paper (Hajebi & Zhang, Tables I–IV, Figs. 5–7) on a
//! dataset in the shared layout: vocabularies on the map images, every query
//! searched under the full search and every stopping rule over a grid of
//! parameters, repeated over vocabulary seeds and random feature orders, then
//! tables, CSV, JSON and plots. This module runs the stages in order:
//!
//! 1. [`cache`]: descriptors of map and queries, and one vocabulary and map
//!    per k-means seed — made once, reused by later runs; [`machine`]
//!    records where they were made;
//! 2. [`timing`]: each query quantized once per vocabulary (timed);
//! 3. [`sweep`]: calibrate the grids (on the first vocabulary), then vote
//!    every setting × vocabulary × run × query; with a learned coarse pass,
//!    [`plan_orders`] (when asked) replays fresh and restarted plans over
//!    random query orders;
//! 4. [`summary`] (with the definitions in [`metrics`]): every figure as a
//!    mean over vocabulary seeds with its spread over seeds and, apart, over
//!    runs; [`recommend`] and [`equal_recall`] decide on the worst seed;
//! 5. [`verify`] (when asked): the full search and the explicit settings
//!    re-ranked by geometric verification, with and without side by side
//!    (on the first vocabulary);
//! 6. [`orb_pass`] (when asked): the full search and the settings asked
//!    for again with the service's ORB pass first, on every vocabulary;
//! 7. [`table`] and [`plots`]: the outputs, with every query's answers in
//!    `results.json` for re-scoring.
//!
//! [`sequence`] is the other evaluation (`bowloc eval --sequence`): the
//! queries replayed in order as one camera's frames, with and without the
//! sequence filter, on the same caches. [`shards`] replays the same queries
//! on a map split into shards (`bowloc shards`).

pub mod cache;
pub mod equal_recall;
pub mod machine;
pub mod metrics;
pub mod orb_pass;
pub mod plan_orders;
pub mod plots;
pub mod recommend;
pub mod sequence;
pub mod shards;
pub mod summary;
pub mod sweep;
pub mod table;
pub mod tiles;
pub mod timing;
pub mod verify;

use crate::calibrate::{Warmup, auto_warmup, median_features};
use crate::dataset::Dataset;
use crate::features::{ExtractConfig, TileGrid, TilePlan};
use crate::geometry::verify::VerifyParams;
use crate::index::MapIndex;
use crate::pipeline::progress_bar;
use crate::search::RuleSpec;
use crate::vocabulary::Vocabulary;
use crate::vocabulary::kmeans::KmeansConfig;
use anyhow::{Context, bail};
use equal_recall::EqualRecall;
use machine::{MachineInfo, OpenCvInfo};
use rayon::prelude::*;
use recommend::{Criterion, Recommendation};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use summary::{QueryCost, SeedOutcomes, SettingSummary};
use sweep::{BASELINE, Calibration, Outcome, RULE_GRIDS, RuleGrid};
use tiles::Query;

/// Quantization block, as the search uses by default.
const BLOCK: usize = 32;
/// Bins of the fraction-of-features histogram.
const HISTOGRAM_BINS: usize = 20;

/// Default calibration targets: mean fraction of features used.
pub const DEFAULT_TARGETS: &[f64] = &[0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95];

/// What to evaluate and where.
#[derive(Debug, Clone)]
pub struct EvalConfig {
    pub dataset: PathBuf,
    /// Vocabulary size K (ignored with `vocab`).
    pub words: usize,
    /// k-means seeds: one vocabulary each (ignored with `vocab`).
    pub seeds: Vec<u64>,
    /// Monte Carlo runs (random feature orders).
    pub runs: u32,
    /// Rules to sweep (empty: all of [`RULE_GRIDS`]); the full search is always in.
    pub rules: Vec<String>,
    /// Extra settings, `RULE=VALUE[@WARMUP]` (see [`sweep::parse_setting`]),
    /// run besides the grids and listed in a table of their own.
    pub explicit: Vec<String>,
    /// Warm-ups (`min_features`); the first is the main one.
    pub warmups: Vec<Warmup>,
    /// Calibration targets (mean fraction of features used).
    pub targets: Vec<f64>,
    /// Allowed recall loss for the recommended setting.
    pub tolerance: f64,
    /// Setting whose per-query fractions are histogrammed: `RULE` (its
    /// setting nearest half the features) or `RULE=VALUE`; default the
    /// recommended one.
    pub histogram: Option<String>,
    pub extract: ExtractConfig,
    /// Streaming extraction's tile grid for the queries (the map images are
    /// extracted whole). The full search is also run on the queries
    /// extracted whole, to show what tiling changes. A learned coarse pass
    /// (`,auto`) is replayed as the service learns it
    /// ([`sweep::run_learned`]).
    pub tiles: TilePlan,
    /// Use this vocabulary instead of training one (its extraction settings win).
    pub vocab: Option<PathBuf>,
    pub out: PathBuf,
    pub cache: PathBuf,
    /// Write the plots (PNG and SVG).
    pub plots: bool,
    /// The command line, recorded in the outputs.
    pub command: String,
    /// OpenCV as loaded (recorded in the outputs).
    pub opencv: OpenCvInfo,
    /// Also report precision and recall of the top answer kept when its
    /// distinctness is at least this.
    pub distinct_cut: Option<f32>,
    /// Also verify the full search and the explicit settings geometrically.
    pub verify: Option<crate::geometry::verify::VerifyParams>,
    /// Images on each side, along the map's order, that belong to an
    /// image's place: for distinctness and the rule `place-lead`.
    pub place_window: u32,
    /// The order the queries' tiles are replayed in.
    pub tile_order: crate::search::TileOrder,
    /// The order each tile's features are voted in.
    pub feature_order: tiles::FeatureOrder,
    /// With a learned coarse pass: fresh plans replayed over this many
    /// random query orders for every setting asked for ([`plan_orders`]).
    pub plan_orders: u32,
    /// Also run the full search and the settings asked for with the ORB
    /// pass first, with this setting of it ([`orb_pass`]).
    pub orb_pass: Option<crate::orb_pass::OrbPassParams>,
}

/// The dataset as evaluated.
#[derive(Debug, Clone, Serialize)]
pub struct DatasetInfo {
    pub name: String,
    pub root: PathBuf,
    pub map_images: usize,
    pub queries: usize,
    pub with_match: usize,
    pub ground_truth_pairs: usize,
    /// Mean descriptors per query.
    pub mean_features: f64,
    /// Median descriptors per query.
    pub median_features: usize,
    /// Recall@1 of a random guess (see [`recommend::chance_recall`]).
    pub chance_recall_at_1: f64,
}

/// The settings of the run, as recorded.
#[derive(Debug, Clone, Serialize)]
pub struct ConfigInfo {
    pub runs: u32,
    /// k-means seeds of the vocabularies.
    pub seeds: Vec<u64>,
    pub rules: Vec<String>,
    /// Warm-ups as run (`auto` resolved).
    pub warmups: Vec<usize>,
    /// What `auto` resolved to.
    pub auto_warmup: usize,
    pub targets: Vec<f64>,
    pub precision: f64,
    pub top_n: [usize; 3],
    /// Images on each side of a candidate that make its place.
    pub place_window: u32,
    pub tolerance: f64,
    pub extract: ExtractConfig,
    /// The queries' tile grid, `COLSxROWS+MARGIN`.
    pub tiles: String,
    /// The order their tiles were replayed in.
    pub tile_order: String,
    /// The order each tile's features were voted in.
    pub feature_order: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct VocabularyInfo {
    pub seed: u64,
    pub words: usize,
    pub hash: String,
}

/// Wall time of each stage, in seconds (summed over vocabularies).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Stages {
    pub extract_s: f64,
    pub vocabulary_s: f64,
    pub map_s: f64,
    pub quantize_s: f64,
    pub calibrate_s: f64,
    pub sweep_s: f64,
    /// The verification pass (0 without).
    pub verify_s: f64,
    /// The ORB pass's looks and rows (0 without).
    pub orb_pass_s: f64,
    pub total_s: f64,
}

/// The fraction of features each query used under one setting.
#[derive(Debug, Clone, Serialize)]
pub struct HistogramInfo {
    pub index: usize,
    pub label: String,
    /// Counts in equal bins over [0, 1].
    pub bins: Vec<usize>,
    /// Seeds × queries × runs counted.
    pub values: usize,
    pub mean: f64,
    pub median: f64,
    pub p95: f64,
}

/// Every search's outcome, for re-scoring: `outcomes[seed][setting][run][query]`
/// (seeds in the order of [`ConfigInfo::seeds`], settings of
/// [`Report::settings`], queries of `queries`).
#[derive(Debug, Clone, Serialize)]
pub struct PerQuery {
    /// Query names, in dataset order.
    pub queries: Vec<String>,
    /// Each query's ground-truth matches (map ids, ascending).
    pub truth: Vec<Vec<u32>>,
    pub outcomes: Vec<Vec<Vec<Vec<Outcome>>>>,
}

/// Everything an evaluation produced.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub command: String,
    pub dataset: DatasetInfo,
    pub config: ConfigInfo,
    pub machine: MachineInfo,
    /// One per seed.
    pub vocabularies: Vec<VocabularyInfo>,
    pub stages: Stages,
    pub calibrations: Vec<Calibration>,
    pub settings: Vec<SettingSummary>,
    /// Indices into `settings` of the settings asked for explicitly.
    pub explicit: Vec<usize>,
    pub recommendation: Option<Recommendation>,
    /// Why there is no recommendation, when there is none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub no_recommendation: Option<String>,
    /// Features each rule needs at equal recall (top-5 @90%P and recall@1).
    pub equal_recall: Option<EqualRecall>,
    /// The same on plain recall@1 and recall@5.
    pub equal_recall_plain: Option<EqualRecall>,
    pub histogram: Option<HistogramInfo>,
    /// The full search on the queries extracted whole (when they are tiled):
    /// its time share is against the tiled full search.
    pub whole_image: Option<SettingSummary>,
    pub per_query: PerQuery,
    /// The verification pass, when asked for.
    pub verification: Option<verify::VerificationReport>,
    /// The settings again with the ORB pass first, when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orb_pass: Option<orb_pass::OrbPassReport>,
    /// Fresh learned plans over random query orders, when asked for.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub plan_orders: Vec<plan_orders::PlanOrders>,
}

/// The grids of the rules asked for, the full search first.
fn resolve_rules(names: &[String]) -> anyhow::Result<Vec<&'static RuleGrid>> {
    let mut grids = vec![sweep::rule_grid(BASELINE).expect("baseline is in the table")];
    let all: Vec<String> = RULE_GRIDS.iter().map(|g| g.rule.to_owned()).collect();
    for name in if names.is_empty() { &all } else { names } {
        let Some(g) = sweep::rule_grid(name) else {
            bail!("no sweep grid for rule `{name}`; rules: {}", all.join(", "));
        };
        if !grids.iter().any(|x| x.rule == g.rule) {
            grids.push(g);
        }
    }
    Ok(grids)
}

/// A `--histogram` value: `RULE` or `RULE=VALUE`.
fn parse_histogram(spec: &str) -> anyhow::Result<(&str, Option<f64>)> {
    Ok(match spec.split_once('=') {
        Some((r, v)) => (
            r.trim(),
            Some(
                v.trim()
                    .parse::<f64>()
                    .with_context(|| format!("--histogram {spec}: value"))?,
            ),
        ),
        None => (spec.trim(), None),
    })
}

/// The setting `spec` names (`RULE` or `RULE=VALUE`) at warm-up `w`.
fn pick_setting(summaries: &[SettingSummary], spec: &str, w: usize) -> anyhow::Result<usize> {
    let (rule, value) = parse_histogram(spec)?;
    let distance = |s: &SettingSummary| match (value, s.setting.parameter()) {
        (Some(v), Some(p)) => (p - v).abs(),
        _ => (s.fraction.mean - 0.5).abs(),
    };
    summaries
        .iter()
        .enumerate()
        .filter(|(_, s)| s.setting.rule.name == rule && s.setting.min_features == w)
        .min_by(|(_, a), (_, b)| distance(a).total_cmp(&distance(b)))
        .map(|(i, _)| i)
        .with_context(|| format!("--histogram {spec}: no such setting in the sweep"))
}

/// Check every option before any extraction or training, so a typo fails
/// at once; returns the grids of the rules asked for.
fn validate(config: &EvalConfig) -> anyhow::Result<Vec<&'static RuleGrid>> {
    anyhow::ensure!(config.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(!config.warmups.is_empty(), "give at least one warm-up");
    anyhow::ensure!(
        config.vocab.is_some() || !config.seeds.is_empty(),
        "give at least one vocabulary seed"
    );
    anyhow::ensure!(
        config.targets.iter().all(|&t| t > 0.0 && t <= 1.0),
        "targets are fractions in (0, 1]"
    );
    anyhow::ensure!(
        (0.0..1.0).contains(&config.tolerance),
        "--tolerance must lie in [0, 1)"
    );
    anyhow::ensure!(
        config.plan_orders == 0 || config.tiles.learn_coarse,
        "--plan-orders replays a learned coarse pass: give --tiles …,auto"
    );
    let grids = resolve_rules(&config.rules)?;
    let mut rules: Vec<String> = grids.iter().map(|g| g.rule.to_owned()).collect();
    for spec in &config.explicit {
        let setting = sweep::parse_setting(spec, 0).with_context(|| format!("--set {spec}"))?;
        rules.push(setting.rule.name);
    }
    if let Some(spec) = &config.histogram {
        let (rule, value) = parse_histogram(spec)?;
        anyhow::ensure!(
            rules.iter().any(|r| r == rule),
            "--histogram {spec}: rule `{rule}` is not in the sweep (rules: {})",
            rules.join(", ")
        );
        if let Some(v) = value {
            RuleSpec::new(rule, Some(v)).map_err(|e| anyhow::anyhow!("--histogram {spec}: {e}"))?;
        }
    }
    Ok(grids)
}

/// Quantize every query once (timed), as the sweep replays it.
fn quantize_queries(
    set: &cache::DescriptorSet,
    vocab: &Vocabulary,
    what: &str,
) -> (Vec<Query>, Vec<QueryCost>) {
    let quantizer = vocab.exact_quantizer();
    let bar = progress_bar(set.len() as u64, what);
    let quantized: Vec<(Query, QueryCost)> = (0..set.len())
        .into_par_iter()
        .map(|q| {
            let w = match set.image(q) {
                Some(d) => timing::quantize_timed(quantizer, vocab.hamming(), d, BLOCK),
                None => timing::QueryWords {
                    words: Vec::new(),
                    signatures: Vec::new(),
                    quantize_ms_per_feature: 0.0,
                },
            };
            bar.inc(1);
            let cost = QueryCost {
                quantize_ms_per_feature: w.quantize_ms_per_feature,
                decode_ms: set.decode_ms(q),
            };
            (set.query(q, w.words, w.signatures), cost)
        })
        .collect();
    bar.finish_and_clear();
    quantized.into_iter().unzip()
}

/// The vocabularies of the evaluation: `given`, or one per k-means seed of
/// `words` words trained on the map's descriptors (cached).
fn vocabularies(
    cache_dir: &Path,
    words: usize,
    seeds: &[u64],
    given: Option<Vocabulary>,
    map_desc: &cache::DescriptorSet,
) -> anyhow::Result<Vec<Vocabulary>> {
    match given {
        Some(v) => Ok(vec![v]),
        None => seeds
            .iter()
            .map(|&seed| {
                cache::vocabulary(
                    cache_dir,
                    map_desc,
                    &KmeansConfig {
                        k: words,
                        seed,
                        ..KmeansConfig::default()
                    },
                )
            })
            .collect(),
    }
}

/// The map of each vocabulary (cached).
fn maps_of(
    cache_dir: &Path,
    vocabs: &[Vocabulary],
    map_desc: &cache::DescriptorSet,
    name: &str,
) -> anyhow::Result<Vec<MapIndex>> {
    vocabs
        .iter()
        .map(|v| cache::map_index(cache_dir, v, map_desc, name))
        .collect()
}

fn seconds_since(t: &mut Instant) -> f64 {
    let s = t.elapsed().as_secs_f64();
    *t = Instant::now();
    s
}

/// One vocabulary's queries and their quantization costs.
struct SeedWords {
    queries: Vec<Query>,
    costs: Vec<QueryCost>,
}

/// The queries' descriptors as the evaluation reads them.
struct QuerySets {
    /// Extracted in the plan's grid.
    plain: cache::DescriptorSet,
    /// The same grid with the coarse pass first, when the plan learns it.
    coarse: Option<cache::DescriptorSet>,
    /// Extracted whole, for the whole-image full search.
    whole: Option<cache::DescriptorSet>,
}

/// Stage 1, the queries: their descriptors in the plan's grid (and with the
/// coarse pass, and whole), from the cache or extracted now.
fn query_sets(
    config: &EvalConfig,
    dataset: &Dataset,
    extract: &ExtractConfig,
) -> anyhow::Result<QuerySets> {
    let (mut sets, whole) =
        cache::query_descriptors_with_whole(&config.cache, dataset, extract, config.tiles)?;
    // a learned coarse pass: the grid without it, then with it
    let coarse = if config.tiles.learn_coarse {
        sets.pop()
    } else {
        None
    };
    let plain = sets.pop().expect("the plan's grid");
    if let Some(with_coarse) = coarse
        .as_ref()
        .or_else(|| config.tiles.grid.coarse.then_some(&plain))
    {
        log_coarse_share(with_coarse);
    }
    Ok(QuerySets {
        plain,
        coarse,
        whole,
    })
}

/// Log the share of the queries' keypoints the coarse pass finds.
fn log_coarse_share(with_coarse: &cache::DescriptorSet) {
    let (coarse, all) = with_coarse
        .meta()
        .tiles
        .iter()
        .fold((0u64, 0u64), |(c, a), t| {
            // the tiles after the pass hold every scale: the whole image's
            let first = t.first().map_or(0, |t| t.features as u64);
            (
                c + first,
                a + t.iter().skip(1).map(|t| t.features as u64).sum::<u64>(),
            )
        });
    tracing::info!(
        "coarse pass: {:.3} of the queries' keypoints (the search assumes {} before counting)",
        coarse as f64 / all.max(1) as f64,
        TileGrid::COARSE_SHARE
    );
}

/// The warm-ups asked for, `auto` resolved, each once, in order.
fn resolve_warmups(asked: &[Warmup], auto: usize) -> Vec<usize> {
    let mut warmups: Vec<usize> = Vec::new();
    for w in asked {
        let w = w.resolve(auto);
        if !warmups.contains(&w) {
            warmups.push(w);
        }
    }
    warmups
}

/// Every query set quantized with each vocabulary.
struct Words {
    /// In the plan's grid, per seed.
    plain: Vec<SeedWords>,
    /// With the coarse pass first, per seed.
    coarse: Option<Vec<SeedWords>>,
    /// Extracted whole, per seed.
    whole: Option<Vec<SeedWords>>,
}

/// Stage 2: each query quantized once per vocabulary (timed). Streamed
/// queries carry the geometry the `verified` stop and re-ranking use,
/// shared across seeds.
fn quantize_sets(
    sets: &QuerySets,
    vocabs: &[Vocabulary],
    verify: &VerifyParams,
    order: tiles::FeatureOrder,
) -> Words {
    let geometry = tiles::Geometry::shared(verify);
    let quantize = |set: &cache::DescriptorSet, v: &Vocabulary, what: String| {
        let (mut queries, costs) = quantize_queries(set, v, &what);
        if order == tiles::FeatureOrder::Strongest {
            queries.iter_mut().for_each(Query::strongest_first);
        }
        SeedWords { queries, costs }
    };
    let streamed = |set: &cache::DescriptorSet, what: &str| -> Vec<SeedWords> {
        vocabs
            .iter()
            .map(|v| {
                let s = v.meta().seed;
                let mut words = quantize(set, v, format!("quantizing {what}(seed {s})"));
                for q in &mut words.queries {
                    q.geometry = Some(geometry.clone());
                }
                words
            })
            .collect()
    };
    Words {
        plain: streamed(&sets.plain, ""),
        coarse: sets
            .coarse
            .as_ref()
            .map(|set| streamed(set, "with the coarse pass ")),
        whole: sets.whole.as_ref().map(|d| {
            vocabs
                .iter()
                .map(|v| {
                    let s = v.meta().seed;
                    quantize(d, v, format!("quantizing whole queries (seed {s})"))
                })
                .collect()
        }),
    }
}

/// The settings to sweep and where the report finds them.
struct SweepPlan {
    settings: Vec<sweep::Setting>,
    calibrations: Vec<Calibration>,
    /// The index of each `--set` setting.
    explicit: Vec<usize>,
    /// Each setting re-ranked by verification: (without, with).
    verified_pairs: Vec<(usize, usize)>,
}

impl SweepPlan {
    /// Setting `i` re-ranked by verification, when verification is on
    /// (else `i` itself).
    fn verified(&self, i: usize) -> usize {
        self.verified_pairs
            .iter()
            .find(|p| p.0 == i)
            .map_or(i, |p| p.1)
    }
}

/// Stage 3a: the grids calibrated once, on the first vocabulary, so every
/// seed runs the same settings; the explicit settings added; with
/// verification, the full search and each explicit setting again,
/// re-ranked by geometric verification.
fn plan_sweep(
    config: &EvalConfig,
    grids: &[&'static RuleGrid],
    warmups: &[usize],
    map: &MapIndex,
    queries: &[Query],
    ranking: sweep::Ranking,
) -> anyhow::Result<SweepPlan> {
    let calibrated = grids
        .iter()
        .filter(|g| matches!(g.grid, sweep::Grid::Calibrated { .. }))
        .count();
    let bar = progress_bar(
        (calibrated * warmups.len() * config.targets.len()) as u64,
        "calibrating grids",
    );
    let (mut settings, calibrations) =
        sweep::plan(map, queries, grids, warmups, &config.targets, ranking, &bar)?;
    bar.finish_and_clear();
    let mut explicit = Vec::with_capacity(config.explicit.len());
    for spec in &config.explicit {
        let setting = sweep::parse_setting(spec, warmups[0])?;
        let index = settings
            .iter()
            .position(|s| s.rule == setting.rule && s.min_features == setting.min_features)
            .unwrap_or_else(|| {
                settings.push(setting);
                settings.len() - 1
            });
        explicit.push(index);
    }
    let mut verified_pairs = Vec::new();
    if config.verify.is_some() {
        let mut indices = vec![0];
        indices.extend(explicit.iter().copied().filter(|&i| i != 0));
        for i in indices {
            // a geometric rule's setting verifies already
            if settings[i].verify {
                verified_pairs.push((i, i));
                continue;
            }
            let mut s = settings[i].clone();
            s.verify = true;
            settings.push(s);
            verified_pairs.push((i, settings.len() - 1));
        }
    }
    Ok(SweepPlan {
        settings,
        calibrations,
        explicit,
        verified_pairs,
    })
}

/// Outcomes indexed by seed, setting, run and query.
type SeedSettingRuns = Vec<Vec<Vec<Vec<Outcome>>>>;
/// Request times (ms) indexed by seed, run and query.
type SeedRunTimes = Vec<Vec<Vec<f64>>>;

/// What the sweep gave.
struct Swept {
    outcomes: SeedSettingRuns,
    /// The full search's request times, per seed: what time shares are of.
    full_ms: SeedRunTimes,
    /// The full search on the queries extracted whole, per seed (runs ×
    /// queries), and its request times.
    whole: Option<(Vec<Vec<Vec<Outcome>>>, SeedRunTimes)>,
}

/// Stage 3b: every setting × vocabulary × run × query, replaying a learned
/// coarse pass when there is one; then the full search on the queries
/// extracted whole (what tiling changes, and what the service's
/// `rule=none` costs).
fn sweep_settings(
    maps: &[MapIndex],
    words: &Words,
    settings: &[sweep::Setting],
    runs: u32,
    ranking: sweep::Ranking,
) -> Swept {
    let queries = words.plain.first().map_or(0, |w| w.queries.len());
    // The tiles alone advance the bar once per query, a learned coarse pass
    // (replayed in order) once per setting and run.
    let bar = match &words.coarse {
        None => progress_bar((queries * maps.len()) as u64, "sweeping"),
        Some(_) => progress_bar(
            (settings.len() * runs as usize * maps.len()) as u64,
            "sweeping, the coarse pass learned",
        ),
    };
    let outcomes: SeedSettingRuns = maps
        .iter()
        .zip(&words.plain)
        .enumerate()
        .map(|(s, (map, plain))| match &words.coarse {
            None => sweep::run_all(map, &plain.queries, settings, runs, ranking, &bar),
            Some(coarse) => {
                let plan = sweep::LearnedPlan {
                    plain: (&plain.queries, &plain.costs),
                    coarse: (&coarse[s].queries, &coarse[s].costs),
                };
                sweep::run_learned(map, plan, settings, runs, ranking, &bar)
            }
        })
        .collect();
    bar.finish_and_clear();
    let full_ms = outcomes
        .iter()
        .zip(&words.plain)
        .map(|(o, q)| summary::request_ms(&o[0], &q.costs))
        .collect();
    let whole = words.whole.as_ref().map(|whole| {
        let bar = progress_bar((queries * maps.len()) as u64, "sweeping whole queries");
        let runs: Vec<Vec<Vec<Outcome>>> = maps
            .iter()
            .zip(whole)
            .map(|(map, q)| {
                let mut o = sweep::run_all(map, &q.queries, &settings[..1], runs, ranking, &bar);
                o.swap_remove(0)
            })
            .collect();
        bar.finish_and_clear();
        let ms = runs
            .iter()
            .zip(whole)
            .map(|(o, q)| summary::request_ms(o, &q.costs))
            .collect();
        (runs, ms)
    });
    Swept {
        outcomes,
        full_ms,
        whole,
    }
}

/// Stage 3c ([`plan_orders`]): with a learned coarse pass and
/// `plan_orders` asked for, every setting asked for that stops early (the
/// one re-ranked by verification, when verification is on) replayed as
/// fresh and restarted plans over random query orders, on every vocabulary.
#[allow(clippy::too_many_arguments)]
fn replay_plan_orders(
    config: &EvalConfig,
    maps: &[MapIndex],
    seeds: &[u64],
    words: &Words,
    plan: &SweepPlan,
    swept: &Swept,
    dataset: &Dataset,
    ranking: sweep::Ranking,
) -> Vec<plan_orders::PlanOrders> {
    let Some(coarse) = words.coarse.as_ref().filter(|_| config.plan_orders > 0) else {
        return Vec::new();
    };
    let replayed: Vec<usize> = plan
        .explicit
        .iter()
        .map(|&i| plan.verified(i))
        .filter(|&i| plan.settings[i].rule.info().stops_early)
        .collect();
    let bar = progress_bar(
        (replayed.len() * maps.len()) as u64,
        "replaying the learned plan over query orders",
    );
    // per seed, the whole-image full search's median request (the tiled
    // one's when the queries were not also extracted whole)
    let full_medians: Vec<f64> = (0..maps.len())
        .map(|s| {
            let full = swept
                .whole
                .as_ref()
                .map_or(&swept.full_ms[s], |(_, w)| &w[s]);
            timing::median(&full.iter().flatten().copied().collect::<Vec<_>>())
        })
        .collect();
    let mut rows = Vec::new();
    for &i in &replayed {
        let setting = &plan.settings[i];
        for (s, map) in maps.iter().enumerate() {
            let learned = sweep::LearnedPlan {
                plain: (&words.plain[s].queries, &words.plain[s].costs),
                coarse: (&coarse[s].queries, &coarse[s].costs),
            };
            let replayed = plan_orders::Replayed {
                map,
                plan: learned,
                setting,
                truth: &dataset.truth,
                ranking,
            };
            for start in plan_orders::Start::BOTH {
                rows.push(plan_orders::PlanOrders {
                    label: setting.label(),
                    start,
                    seed: seeds[s],
                    full_median_ms: full_medians[s],
                    passes: config.runs,
                    orders: plan_orders::replay(replayed, start, config.plan_orders, config.runs),
                });
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    rows
}

/// One setting's runs on every seed, with the costs and full-search times
/// its time shares need.
fn by_seed<'a>(
    runs: impl Iterator<Item = &'a Vec<Vec<Outcome>>>,
    words: &'a [SeedWords],
    swept: &'a Swept,
) -> Vec<SeedOutcomes<'a>> {
    runs.zip(words)
        .zip(&swept.full_ms)
        .enumerate()
        .map(|(k, ((o, q), full))| SeedOutcomes {
            runs: o,
            costs: &q.costs,
            full_ms: full,
            whole_ms: swept.whole.as_ref().map(|(_, w)| &w[k][..]),
        })
        .collect()
}

/// Each query's tiles in the grid, without the coarse pass (an outcome
/// adds it when it started with it).
fn grid_tiles(words: &Words) -> Vec<usize> {
    words.plain[0]
        .queries
        .iter()
        .map(|q| (q.tiles.len() - usize::from(q.coarse_first)).max(1))
        .collect()
}

/// Stage 4: every setting summarized over seeds and runs, and the whole-image
/// full search apart.
fn summarize_settings(
    config: &EvalConfig,
    dataset: &Dataset,
    settings: &[sweep::Setting],
    words: &Words,
    swept: &Swept,
) -> (Vec<SettingSummary>, Option<SettingSummary>) {
    let tiles_total = grid_tiles(words);
    let summaries = settings
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let seeds = by_seed(swept.outcomes.iter().map(|o| &o[i]), &words.plain, swept);
            let mut summary = summary::summarize(s, &seeds, &dataset.truth, &tiles_total);
            summary.at_distinct_cut = config
                .distinct_cut
                .map(|cut| summary::at_distinct_cut(&seeds, &dataset.truth, cut));
            summary
        })
        .collect();
    let whole_image = swept
        .whole
        .as_ref()
        .zip(words.whole.as_ref())
        .map(|((runs, _), whole)| {
            let seeds = by_seed(runs.iter(), whole, swept);
            let ones = vec![1; tiles_total.len()];
            let mut s = summary::summarize(&settings[0], &seeds, &dataset.truth, &ones);
            s.label = format!("{} (whole image)", s.label);
            s
        });
    (summaries, whole_image)
}

/// Stage 6 ([`orb_pass`]): each vocabulary's pass (its map's ORB side
/// cached beside the map) looks at every query; the full search and each
/// setting asked for (re-ranked by verification, when verification is on)
/// summarized again with the pass first.
#[allow(clippy::too_many_arguments)]
fn replay_orb_pass(
    config: &EvalConfig,
    params: &crate::orb_pass::OrbPassParams,
    dataset: &Dataset,
    extract: &ExtractConfig,
    vocabs: &[Vocabulary],
    map_desc: &cache::DescriptorSet,
    maps: &[MapIndex],
    words: &Words,
    plan: &SweepPlan,
    swept: &Swept,
) -> anyhow::Result<orb_pass::OrbPassReport> {
    let passes = vocabs
        .iter()
        .zip(maps)
        .map(|(v, m)| {
            let side =
                cache::orb_side(&config.cache, v, map_desc, m, &dataset.map, extract, params)?;
            Ok(crate::pipeline::OrbPass::new(side, params))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    // each look priced against the query's whole-image SIFT as the cache
    // timed it
    let whole = words.whole.as_ref().unwrap_or(&words.plain);
    let cached_sift: Vec<f32> = whole[0]
        .queries
        .iter()
        .map(|q| q.tiles.iter().map(|t| t.ms).sum())
        .collect();
    let mut looks = orb_pass::look_all(&dataset.queries, extract, &passes, config.place_window);
    for (look, &ms) in looks
        .iter_mut()
        .flat_map(|seed| seed.iter_mut().zip(&cached_sift))
    {
        look.price(ms);
    }
    let mut alone: Vec<usize> = vec![plan.verified(0)];
    for &i in &plan.explicit {
        if !alone.contains(&plan.verified(i)) {
            alone.push(plan.verified(i));
        }
    }
    let tiles_total = grid_tiles(words);
    let rows = alone
        .into_iter()
        .map(|i| {
            let runs: Vec<Vec<Vec<Outcome>>> = swept
                .outcomes
                .iter()
                .zip(&looks)
                .zip(&words.plain)
                .map(|((o, l), q)| orb_pass::first(&o[i], l, &q.costs))
                .collect();
            let seeds = by_seed(runs.iter(), &words.plain, swept);
            let setting = &plan.settings[i];
            let mut with = summary::summarize(setting, &seeds, &dataset.truth, &tiles_total);
            with.label = format!("{} +orb", with.label);
            orb_pass::OrbPassRow {
                alone: i,
                full: if setting.verify { plan.verified(0) } else { 0 },
                with,
            }
        })
        .collect();
    Ok(orb_pass::OrbPassReport::new(
        params.clone(),
        looks,
        &dataset.truth,
        rows,
    ))
}

/// The histogram of the fractions of features used under setting `index`,
/// over every seed, run and query.
fn histogram_of(outcomes: &SeedSettingRuns, index: usize, label: &str) -> HistogramInfo {
    let values: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| summary::fractions(&o[index]))
        .collect();
    let q = timing::quantiles(&values);
    HistogramInfo {
        index,
        label: label.to_owned(),
        bins: metrics::histogram(&values, HISTOGRAM_BINS),
        values: values.len(),
        mean: metrics::mean(&values),
        median: q.median,
        p95: q.p95,
    }
}

/// The dataset as the report describes it.
fn dataset_info(dataset: &Dataset, counts: &[usize], chance_at_1: f64) -> DatasetInfo {
    DatasetInfo {
        name: dataset.name.clone(),
        root: dataset.root.clone(),
        map_images: dataset.map.len(),
        queries: dataset.queries.len(),
        with_match: dataset.queries_with_match(),
        ground_truth_pairs: dataset.truth.iter().map(|t| t.len()).sum(),
        mean_features: metrics::mean(&counts.iter().map(|&n| n as f64).collect::<Vec<_>>()),
        median_features: median_features(counts),
        chance_recall_at_1: chance_at_1,
    }
}

/// Run the whole evaluation and write its outputs into `config.out`.
pub fn run(config: &EvalConfig) -> anyhow::Result<Report> {
    let started = Instant::now();
    let mut clock = Instant::now();
    let mut stages = Stages::default();
    let grids = validate(config)?;
    let dataset = Dataset::open(&config.dataset)?;
    let given_vocab = config
        .vocab
        .as_deref()
        .map(|p| Vocabulary::open(p, true))
        .transpose()?;
    let extract = given_vocab
        .as_ref()
        .map_or(config.extract.clone(), |v| v.meta().extract.clone());

    // 1. descriptors, vocabularies and maps
    let map_desc = cache::map_descriptors(&config.cache, &dataset, &extract)?;
    let sets = query_sets(config, &dataset, &extract)?;
    stages.extract_s = seconds_since(&mut clock);
    let machine = MachineInfo::here(config.opencv.clone(), map_desc.hash(), sets.plain.hash());
    let counts: Vec<usize> = (0..sets.plain.len())
        .map(|q| sets.plain.image(q).map_or(0, |d| d.nrows()))
        .collect();
    let auto = auto_warmup(&counts);
    let warmups = resolve_warmups(&config.warmups, auto);
    let vocabs = vocabularies(
        &config.cache,
        config.words,
        &config.seeds,
        given_vocab,
        &map_desc,
    )?;
    let seeds: Vec<u64> = vocabs.iter().map(|v| v.meta().seed).collect();
    stages.vocabulary_s = seconds_since(&mut clock);
    let maps = maps_of(&config.cache, &vocabs, &map_desc, &dataset.name)?;
    stages.map_s = seconds_since(&mut clock);

    // 2. the queries quantized; one OpenCV thread per query (the sweep runs
    // one query per core), geometric verification as the service does it:
    // for the `verified` stop always, for re-ranking in the `+verify` settings
    crate::features::set_opencv_threads(1);
    let words = quantize_sets(
        &sets,
        &vocabs,
        &config.verify.clone().unwrap_or_default(),
        config.feature_order,
    );
    stages.quantize_s = seconds_since(&mut clock);

    // 3. the settings planned, then swept
    let ranking = sweep::Ranking {
        top_n: summary::TOP_N.iter().copied().max().unwrap_or(10),
        place_window: config.place_window,
        tile_order: config.tile_order,
        given_order: config.feature_order != tiles::FeatureOrder::Random,
    };
    let plan = plan_sweep(
        config,
        &grids,
        &warmups,
        &maps[0],
        &words.plain[0].queries,
        ranking,
    )?;
    stages.calibrate_s = seconds_since(&mut clock);
    tracing::info!(
        settings = plan.settings.len(),
        seeds = seeds.len(),
        runs = config.runs,
        queries = counts.len(),
        "sweeping"
    );
    let swept = sweep_settings(&maps, &words, &plan.settings, config.runs, ranking);

    // 4. summaries, and the decisions taken on them
    let (summaries, whole_image) =
        summarize_settings(config, &dataset, &plan.settings, &words, &swept);
    stages.sweep_s = seconds_since(&mut clock);
    let chance_at_1 = recommend::chance_recall(&dataset.truth, dataset.map.len(), 1);
    let (recommendation, no_recommendation) =
        match recommend::recommend(&summaries, config.tolerance, chance_at_1) {
            Ok(r) => (Some(r), None),
            Err(why) => (None, Some(why)),
        };
    let rules: Vec<String> = grids.iter().map(|g| g.rule.to_owned()).collect();
    let equal_recall = equal_recall::equal_recall(
        &summaries,
        &rules,
        &equal_recall::tolerances(config.tolerance),
        Criterion::Precision90,
    );
    let equal_recall_plain = equal_recall::equal_recall(
        &summaries,
        &rules,
        &[equal_recall::PLAIN_TOLERANCE],
        Criterion::PlainRecall,
    );
    let histogram_index = match &config.histogram {
        Some(spec) => Some(pick_setting(&summaries, spec, warmups[0])?),
        None => recommendation.as_ref().map(|r| r.index),
    };
    let histogram = histogram_index.map(|i| histogram_of(&swept.outcomes, i, &summaries[i].label));
    let plan_orders = replay_plan_orders(
        config, &maps, &seeds, &words, &plan, &swept, &dataset, ranking,
    );

    // 5. with and without verification, side by side (first vocabulary)
    let verification = config
        .verify
        .as_ref()
        .map(|params| verify::VerificationReport {
            params: params.clone(),
            rows: plan
                .verified_pairs
                .iter()
                .map(|&(without, with)| {
                    verify::row(
                        &summaries[without].label,
                        without,
                        &swept.outcomes[0][without],
                        &swept.outcomes[0][with],
                        &dataset.truth,
                    )
                })
                .collect(),
        });
    stages.verify_s = seconds_since(&mut clock);

    // 6. the ORB pass first (every vocabulary)
    let orb_pass = match &config.orb_pass {
        None => None,
        Some(params) => Some(replay_orb_pass(
            config, params, &dataset, &extract, &vocabs, &map_desc, &maps, &words, &plan, &swept,
        )?),
    };
    stages.orb_pass_s = seconds_since(&mut clock);
    stages.total_s = started.elapsed().as_secs_f64();

    // 6. the report and its outputs
    let report = Report {
        command: config.command.clone(),
        dataset: dataset_info(&dataset, &counts, chance_at_1),
        config: ConfigInfo {
            runs: config.runs,
            seeds,
            rules,
            warmups,
            auto_warmup: auto,
            targets: config.targets.clone(),
            precision: summary::PRECISION,
            top_n: summary::TOP_N,
            place_window: config.place_window,
            tolerance: config.tolerance,
            extract,
            tiles: config.tiles.to_string(),
            tile_order: config.tile_order.to_string(),
            feature_order: config.feature_order.to_string(),
        },
        machine,
        vocabularies: vocabs
            .iter()
            .map(|v| VocabularyInfo {
                seed: v.meta().seed,
                words: v.words(),
                hash: v.hash_hex(),
            })
            .collect(),
        stages,
        calibrations: plan.calibrations,
        settings: summaries,
        explicit: plan.explicit,
        recommendation,
        no_recommendation,
        equal_recall,
        equal_recall_plain,
        histogram,
        whole_image,
        verification,
        orb_pass,
        plan_orders,
        per_query: PerQuery {
            queries: dataset.queries.iter().map(|q| q.name.clone()).collect(),
            truth: dataset
                .truth
                .iter()
                .map(|t| {
                    let mut ids: Vec<u32> = t.iter().copied().collect();
                    ids.sort_unstable();
                    ids
                })
                .collect(),
            outcomes: swept.outcomes,
        },
    };
    write_outputs(&report, &config.out, config.plots)?;
    Ok(report)
}

/// Write `results.md`, `results.csv`, `equal_recall.csv`, `results.json` and
/// (with `plots`) the figures into `out`.
pub fn write_outputs(report: &Report, out: &Path, plots: bool) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let markdown = table::markdown(report);
    crate::store::write_atomic(&out.join("results.md"), |w| {
        w.write_all(markdown.as_bytes())
    })?;
    table::write_csv(report, &out.join("results.csv"))?;
    table::write_equal_recall_csv(report, &out.join("equal_recall.csv"))?;
    table::write_json(report, &out.join("results.json"))?;
    if plots {
        plots::write_all(report, out)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warmups_resolve_auto_and_keep_each_once_in_order() {
        let asked = [
            Warmup::Features(50),
            Warmup::Auto,
            Warmup::Features(100),
            Warmup::Features(50),
        ];
        assert_eq!(resolve_warmups(&asked, 100), vec![50, 100]);
        assert_eq!(resolve_warmups(&asked, 30), vec![50, 30, 100]);
        assert!(resolve_warmups(&[], 30).is_empty());
    }
}

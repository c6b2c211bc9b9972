//! The evaluation of the paper (Hajebi & Zhang, Tables I–IV, Figs. 5–7) on a
//! dataset in the shared layout: vocabulary on the map images, every query
//! searched under the full search and every stopping rule over a grid of
//! parameters, repeated over random feature orders, then tables, CSV, JSON and
//! plots. This module runs the stages in order:
//!
//! 1. [`cache`]: descriptors of map and queries, vocabulary and map — made
//!    once, reused by later runs;
//! 2. [`timing`]: each query quantized once (timed);
//! 3. [`sweep`]: calibrate the grids, then vote every setting × run × query;
//! 4. [`summary`] (with the definitions in [`metrics`]), [`recommend`] and
//!    [`equal_recall`];
//! 5. [`verify`] (when asked): the full search and the explicit settings
//!    re-ranked by geometric verification, with and without side by side;
//! 6. [`table`] and [`plots`]: the outputs.

pub mod cache;
pub mod equal_recall;
pub mod metrics;
pub mod plots;
pub mod recommend;
pub mod summary;
pub mod sweep;
pub mod table;
pub mod tiles;
pub mod timing;
pub mod verify;

use crate::dataset::Dataset;
use crate::features::{ExtractConfig, TileGrid};
use crate::pipeline::progress_bar;
use crate::vocabulary::Vocabulary;
use crate::vocabulary::kmeans::KmeansConfig;
use anyhow::{Context, bail};
use equal_recall::EqualRecall;
use rayon::prelude::*;
use recommend::Recommendation;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use summary::{QueryCost, SettingSummary};
use sweep::{BASELINE, Calibration, RULE_GRIDS, RuleGrid};
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
    /// k-means seed.
    pub seed: u64,
    /// Monte Carlo runs (random feature orders).
    pub runs: u32,
    /// Rules to sweep (empty: all of [`RULE_GRIDS`]); the full search is always in.
    pub rules: Vec<String>,
    /// Extra settings, `RULE=VALUE[@WARMUP]` (see [`sweep::parse_setting`]),
    /// run besides the grids and listed in a table of their own.
    pub explicit: Vec<String>,
    /// Warm-ups (`min_features`); the first is the main one.
    pub warmups: Vec<usize>,
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
    /// extracted whole, to show what tiling changes.
    pub tiles: TileGrid,
    /// Use this vocabulary instead of training one (its extraction settings win).
    pub vocab: Option<PathBuf>,
    pub out: PathBuf,
    pub cache: PathBuf,
    /// Write the plots (PNG and SVG).
    pub plots: bool,
    /// The command line, recorded in the outputs.
    pub command: String,
    /// Also verify the full search and the explicit settings geometrically.
    pub verify: Option<crate::geometry::verify::VerifyParams>,
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
}

/// The settings of the run, as recorded.
#[derive(Debug, Clone, Serialize)]
pub struct ConfigInfo {
    pub runs: u32,
    pub seed: u64,
    pub rules: Vec<String>,
    pub warmups: Vec<usize>,
    pub targets: Vec<f64>,
    pub precision: f64,
    pub top_n: [usize; 3],
    pub tolerance: f64,
    pub extract: ExtractConfig,
    /// The queries' tile grid, `COLSxROWS+MARGIN`.
    pub tiles: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct VocabularyInfo {
    pub words: usize,
    pub hash: String,
}

/// Wall time of each stage, in seconds.
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
    pub total_s: f64,
}

/// The fraction of features each query used under one setting.
#[derive(Debug, Clone, Serialize)]
pub struct HistogramInfo {
    pub index: usize,
    pub label: String,
    /// Counts in equal bins over [0, 1].
    pub bins: Vec<usize>,
    /// Queries × runs counted.
    pub values: usize,
    pub mean: f64,
    pub median: f64,
    pub p95: f64,
}

/// Everything an evaluation produced.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub command: String,
    pub dataset: DatasetInfo,
    pub config: ConfigInfo,
    pub vocabulary: VocabularyInfo,
    pub stages: Stages,
    pub calibrations: Vec<Calibration>,
    pub settings: Vec<SettingSummary>,
    /// Indices into `settings` of the settings asked for explicitly.
    pub explicit: Vec<usize>,
    pub recommendation: Option<Recommendation>,
    /// Features each rule needs at equal recall.
    pub equal_recall: Option<EqualRecall>,
    pub histogram: Option<HistogramInfo>,
    /// The full search on the queries extracted whole (when they are tiled):
    /// its time share is against the tiled full search.
    pub whole_image: Option<SettingSummary>,
    /// The verification pass, when asked for.
    pub verification: Option<verify::VerificationReport>,
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

/// The setting `spec` names (`RULE` or `RULE=VALUE`) at warm-up `w`.
fn pick_setting(summaries: &[SettingSummary], spec: &str, w: usize) -> anyhow::Result<usize> {
    let (rule, value) = match spec.split_once('=') {
        Some((r, v)) => (r, Some(v.parse::<f64>().context("histogram value")?)),
        None => (spec, None),
    };
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

/// Quantize every query once (timed), as the sweep replays it.
fn quantize_queries(
    set: &cache::DescriptorSet,
    quantizer: &dyn crate::quantize::Quantizer,
    what: &str,
) -> (Vec<Query>, Vec<QueryCost>) {
    let bar = progress_bar(set.len() as u64, what);
    let quantized: Vec<(Query, QueryCost)> = (0..set.len())
        .into_par_iter()
        .map(|q| {
            let w = match set.image(q) {
                Some(d) => timing::quantize_timed(quantizer, d, BLOCK),
                None => timing::QueryWords {
                    words: Vec::new(),
                    quantize_ms_per_feature: 0.0,
                },
            };
            bar.inc(1);
            let cost = QueryCost {
                quantize_ms_per_feature: w.quantize_ms_per_feature,
            };
            (set.query(q, w.words), cost)
        })
        .collect();
    bar.finish_and_clear();
    quantized.into_iter().unzip()
}

fn seconds_since(t: &mut Instant) -> f64 {
    let s = t.elapsed().as_secs_f64();
    *t = Instant::now();
    s
}

/// Run the whole evaluation and write its outputs into `config.out`.
pub fn run(config: &EvalConfig) -> anyhow::Result<Report> {
    let started = Instant::now();
    let mut clock = Instant::now();
    let mut stages = Stages::default();
    anyhow::ensure!(config.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(!config.warmups.is_empty(), "give at least one warm-up");
    anyhow::ensure!(
        config.targets.iter().all(|&t| t > 0.0 && t <= 1.0),
        "targets are fractions in (0, 1]"
    );
    let grids = resolve_rules(&config.rules)?;
    let dataset = Dataset::open(&config.dataset)?;
    let given_vocab = config
        .vocab
        .as_deref()
        .map(|p| Vocabulary::open(p, true))
        .transpose()?;
    let extract = given_vocab
        .as_ref()
        .map_or(config.extract.clone(), |v| v.meta().extract.clone());

    let map_desc = cache::descriptors(
        &config.cache.join("map.bowdesc"),
        &dataset.map,
        &extract,
        TileGrid::WHOLE,
        "extracting map",
    )?;
    let query_desc = cache::descriptors(
        &config
            .cache
            .join(format!("queries-{}.bowdesc", config.tiles)),
        &dataset.queries,
        &extract,
        config.tiles,
        "extracting queries",
    )?;
    let whole_desc = (config.tiles != TileGrid::WHOLE)
        .then(|| {
            cache::descriptors(
                &config
                    .cache
                    .join(format!("queries-{}.bowdesc", TileGrid::WHOLE)),
                &dataset.queries,
                &extract,
                TileGrid::WHOLE,
                "extracting whole queries",
            )
        })
        .transpose()?;
    stages.extract_s = seconds_since(&mut clock);

    let vocab = match given_vocab {
        Some(v) => v,
        None => cache::vocabulary(
            &config.cache,
            &map_desc,
            &KmeansConfig {
                k: config.words,
                seed: config.seed,
                ..KmeansConfig::default()
            },
        )?,
    };
    stages.vocabulary_s = seconds_since(&mut clock);
    let map = cache::map_index(&config.cache, &vocab, &map_desc, &dataset.name)?;
    stages.map_s = seconds_since(&mut clock);

    // one OpenCV thread per query: the sweep already runs one query per core
    crate::features::set_opencv_threads(1);
    let quantizer = vocab.exact_quantizer();
    let (mut queries, costs) = quantize_queries(&query_desc, &quantizer, "quantizing queries");
    // Geometric verification as the service does it: for the `verified`
    // stop always, for re-ranking in the `+verify` settings.
    let verify_params = config.verify.clone().unwrap_or_default();
    let geometry = std::sync::Arc::new(tiles::Geometry {
        fit: Box::new(crate::features::fit::OpenCvFit::new(verify_params.fit())),
        params: verify_params.clone(),
    });
    for q in &mut queries {
        q.geometry = Some(geometry.clone());
    }
    let whole = whole_desc
        .as_ref()
        .map(|d| quantize_queries(d, &quantizer, "quantizing whole queries"));
    stages.quantize_s = seconds_since(&mut clock);

    let calibrated = grids
        .iter()
        .filter(|g| matches!(g.grid, sweep::Grid::Calibrated { .. }))
        .count();
    let bar = progress_bar(
        (calibrated * config.warmups.len() * config.targets.len()) as u64,
        "calibrating grids",
    );
    let (mut settings, calibrations) = sweep::plan(
        &map,
        &queries,
        &grids,
        &config.warmups,
        &config.targets,
        &bar,
    )?;
    bar.finish_and_clear();
    let mut explicit = Vec::with_capacity(config.explicit.len());
    for spec in &config.explicit {
        let setting = sweep::parse_setting(spec, config.warmups[0])?;
        let index = settings
            .iter()
            .position(|s| s.rule == setting.rule && s.min_features == setting.min_features)
            .unwrap_or_else(|| {
                settings.push(setting);
                settings.len() - 1
            });
        explicit.push(index);
    }
    // With verification: the full search and each explicit setting again,
    // re-ranked by geometric verification.
    let mut verified_pairs = Vec::new();
    if config.verify.is_some() {
        let mut indices = vec![0];
        indices.extend(explicit.iter().copied().filter(|&i| i != 0));
        for i in indices {
            let mut s = settings[i].clone();
            s.verify = true;
            settings.push(s);
            verified_pairs.push((i, settings.len() - 1));
        }
    }
    stages.calibrate_s = seconds_since(&mut clock);
    tracing::info!(
        settings = settings.len(),
        runs = config.runs,
        queries = queries.len(),
        "sweeping"
    );

    let top_n = summary::TOP_N.iter().copied().max().unwrap_or(10);
    let bar = progress_bar(queries.len() as u64, "sweeping");
    let outcomes = sweep::run_all(&map, &queries, &settings, config.runs, top_n, &bar);
    bar.finish_and_clear();
    let tiles_total: Vec<usize> = queries.iter().map(|q| q.tiles.len().max(1)).collect();
    let full_ms = summary::request_ms(&outcomes[0], &costs);
    let summaries: Vec<SettingSummary> = settings
        .par_iter()
        .zip(&outcomes)
        .map(|(s, o)| summary::summarize(s, o, &dataset.truth, &costs, &tiles_total, &full_ms))
        .collect();
    // The full search on the queries extracted whole: what tiling changes.
    let whole_image = whole.map(|(queries, costs)| {
        let bar = progress_bar(queries.len() as u64, "sweeping whole queries");
        let o = sweep::run_all(&map, &queries, &settings[..1], config.runs, top_n, &bar);
        bar.finish_and_clear();
        let ones = vec![1; queries.len()];
        let mut s =
            summary::summarize(&settings[0], &o[0], &dataset.truth, &costs, &ones, &full_ms);
        s.label = format!("{} (whole image)", s.label);
        s
    });
    stages.sweep_s = seconds_since(&mut clock);

    let recommendation = recommend::recommend(&summaries, config.tolerance);
    let rules: Vec<String> = grids.iter().map(|g| g.rule.to_owned()).collect();
    let equal_recall = equal_recall::equal_recall(
        &summaries,
        &rules,
        &equal_recall::tolerances(config.tolerance),
    );
    let main_warmup = config.warmups[0];
    let histogram_index = match &config.histogram {
        Some(spec) => Some(pick_setting(&summaries, spec, main_warmup)?),
        None => recommendation.as_ref().map(|r| r.index),
    };
    let histogram = histogram_index.map(|index| {
        let values = summary::fractions(&outcomes[index]);
        let q = timing::quantiles(&values);
        HistogramInfo {
            index,
            label: summaries[index].label.clone(),
            bins: metrics::histogram(&values, HISTOGRAM_BINS),
            values: values.len(),
            mean: metrics::mean(&values),
            median: q.median,
            p95: q.p95,
        }
    });

    let verification = config
        .verify
        .as_ref()
        .map(|params| verify::VerificationReport {
            params: params.clone(),
            rows: verified_pairs
                .iter()
                .map(|&(without, with)| {
                    verify::row(
                        &summaries[without].label,
                        without,
                        &outcomes[without],
                        &outcomes[with],
                        &dataset.truth,
                    )
                })
                .collect(),
        });
    stages.verify_s = seconds_since(&mut clock);

    let mean_features = metrics::mean(
        &queries
            .iter()
            .map(|q| q.words.len() as f64)
            .collect::<Vec<_>>(),
    );
    stages.total_s = started.elapsed().as_secs_f64();
    let report = Report {
        command: config.command.clone(),
        dataset: DatasetInfo {
            name: dataset.name.clone(),
            root: dataset.root.clone(),
            map_images: dataset.map.len(),
            queries: dataset.queries.len(),
            with_match: dataset.queries_with_match(),
            ground_truth_pairs: dataset.truth.iter().map(|t| t.len()).sum(),
            mean_features,
        },
        config: ConfigInfo {
            runs: config.runs,
            seed: config.seed,
            rules,
            warmups: config.warmups.clone(),
            targets: config.targets.clone(),
            precision: summary::PRECISION,
            top_n: summary::TOP_N,
            tolerance: config.tolerance,
            extract,
            tiles: config.tiles.to_string(),
        },
        vocabulary: VocabularyInfo {
            words: vocab.words(),
            hash: vocab.hash_hex(),
        },
        stages,
        calibrations,
        settings: summaries,
        explicit,
        recommendation,
        equal_recall,
        histogram,
        whole_image,
        verification,
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

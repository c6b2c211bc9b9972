//! `bowloc eval --sequence`: the queries, in list order, as the frames of one
//! camera moving along the map (both shared datasets were recorded along a
//! path), localized frame by frame and through the sequence filter
//! ([`crate::sequence`]), with a few unrelated images injected into the
//! sequence to measure how quickly the filter recovers.
//!
//! Four modes run on the same cached, pre-quantized tiles, for every
//! vocabulary seed and random feature order (run):
//!
//! - `frame, full`: each frame alone, every feature (rule `none`);
//! - `frame, STOP`: each frame alone with the stopping rule (its prior is
//!   uniform);
//! - `filter, full`: the filter, every feature;
//! - `filter, STOP`: the filter, its prediction the prior of the stop.
//!
//! A frame alone answers its vote ranking; the filter answers its
//! posterior's ranking. Recall@k counts the real frames with a match whose
//! top k hold one; features are the share of each real frame's features
//! voted, and tiles the share of its tiles extracted (the extraction the
//! service would do). Injected frames count in none of these; after each,
//! the recovery is the number of real frames until the filter's leader is
//! a match again (1: the first frame after it).

use super::cache;
use super::tiles::{Geometry, Query};
use super::{maps_of, quantize_queries, vocabularies};
use crate::calibrate::{Warmup, auto_warmup};
use crate::dataset::{Dataset, image_list};
use crate::features::{ExtractConfig, TileGrid};
use crate::geometry::verify::VerifyParams;
use crate::index::MapIndex;
use crate::search::{RuleSpec, SearchOptions};
use crate::sequence::{Filter, SequenceModel, Topology, TopologyKind};
use anyhow::Context;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;

/// What to evaluate.
#[derive(Debug, Clone)]
pub struct SequenceEvalConfig {
    pub dataset: PathBuf,
    pub words: usize,
    pub seeds: Vec<u64>,
    /// Random feature orders per seed.
    pub runs: u32,
    pub extract: ExtractConfig,
    pub tiles: TileGrid,
    pub cache: PathBuf,
    /// Where `sequence.json` and `sequence.md` go.
    pub out: PathBuf,
    pub model: SequenceModel,
    /// The stopping rule of the `STOP` modes.
    pub stop: RuleSpec,
    /// Its warm-up (`auto`: [`crate::calibrate::auto_warmup`] of the map
    /// images' feature counts, as the service resolves it).
    pub min_features: Warmup,
    /// How a rule with a geometric check (`or_verified`, `verified`)
    /// verifies, as the service does.
    pub verify: VerifyParams,
    /// Unrelated images (a list or a folder) to inject.
    pub inject: Option<PathBuf>,
    /// How many to inject, evenly spaced.
    pub injections: usize,
    pub command: String,
}

/// One mode's figures over one seed (means over runs).
#[derive(Debug, Clone, Serialize)]
pub struct ModeSeed {
    pub seed: u64,
    pub recall_at_1: f64,
    pub recall_at_5: f64,
    /// Mean share of a real frame's features voted.
    pub features: f64,
    /// Mean share of a real frame's tiles extracted.
    pub tiles: f64,
    /// Recovery after each injection (frames), every run; `None`: not
    /// within the rest of the sequence.
    pub recovery: Vec<Option<usize>>,
}

/// A mean over seeds with its spread and the worst seed.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Spread {
    pub mean: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    fn of(v: &[f64]) -> Self {
        let n = v.len().max(1) as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        Self {
            mean,
            std: var.sqrt(),
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// One mode over every seed.
#[derive(Debug, Clone, Serialize)]
pub struct ModeReport {
    pub mode: String,
    pub filter: bool,
    pub rule: String,
    pub recall_at_1: Spread,
    pub recall_at_5: Spread,
    pub features: Spread,
    pub tiles: Spread,
    /// Largest recovery over every injection, seed and run (`None`: some
    /// injection never recovered, or none was injected).
    pub recovery_max: Option<usize>,
    pub recovery_mean: Option<f64>,
    pub per_seed: Vec<ModeSeed>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SequenceReport {
    pub command: String,
    pub dataset: String,
    pub frames: usize,
    pub injected_at: Vec<usize>,
    pub injected_images: Vec<String>,
    pub runs: u32,
    pub seeds: Vec<u64>,
    pub words: usize,
    pub tiles: String,
    pub model: SequenceModel,
    pub min_features: usize,
    pub modes: Vec<ModeReport>,
}

/// A frame of the replayed sequence.
#[derive(Clone, Copy)]
enum Frame {
    /// The query with this index.
    Real(usize),
    /// The injected image with this index.
    Injected(usize),
}

/// What one pass over the sequence measured.
struct Pass {
    hits1: usize,
    hits5: usize,
    scored: usize,
    features: f64,
    tiles: f64,
    frames: usize,
    recovery: Vec<Option<usize>>,
}

struct Mode {
    filter: bool,
    rule: RuleSpec,
    min_features: usize,
}

#[allow(clippy::too_many_arguments)]
fn pass(
    map: &MapIndex,
    queries: &[Query],
    injected: &[Query],
    frames: &[Frame],
    truth: &[HashSet<u32>],
    mode: &Mode,
    model: &SequenceModel,
    seed: u64,
) -> Pass {
    let topology =
        Topology::of(TopologyKind::Order, map.meta().images, None).expect("order needs no poses");
    let mut filter = Filter::new();
    let mut p = Pass {
        hits1: 0,
        hits5: 0,
        scored: 0,
        features: 0.0,
        tiles: 0.0,
        frames: 0,
        recovery: Vec::new(),
    };
    // injections whose recovery is still open: frames since
    let mut open: Vec<usize> = Vec::new();
    for (f, frame) in frames.iter().enumerate() {
        let query = match *frame {
            Frame::Real(q) => &queries[q],
            Frame::Injected(i) if mode.filter => &injected[i],
            Frame::Injected(_) => continue,
        };
        let mut options = SearchOptions {
            rule: mode.rule.clone(),
            top_n: 5,
            seed: seed.wrapping_mul(1_000_003).wrapping_add(f as u64),
            min_features: mode.min_features,
            ..SearchOptions::default()
        };
        let prediction = mode.filter.then(|| filter.predict(model, &topology, None));
        // a frame alone: a uniform prior at the model's κ, so the rule
        // `posterior` weighs evidence as the filter does
        options.prior = Some(Arc::new(match &prediction {
            Some(pr) => pr.prior.clone(),
            None => model.uniform_prior(topology.images()),
        }));
        let replay = query.search(map, &options, false);
        let ranked: Vec<u32> = match (&prediction, replay.outcome.posterior.clone()) {
            (Some(pr), Some(post)) => {
                let ids = post.top.iter().map(|e| e.0).collect();
                filter.update(post, pr);
                ids
            }
            _ => replay.outcome.candidates.iter().map(|c| c.id).collect(),
        };
        let Frame::Real(q) = *frame else {
            open.push(0);
            continue;
        };
        let n = query.feature_count().max(1) as f64;
        p.features += replay.outcome.features_used as f64 / n;
        p.tiles += replay.tiles as f64 / query.tiles.len().max(1) as f64;
        p.frames += 1;
        let right = |k: usize| ranked.iter().take(k).any(|j| truth[q].contains(j));
        if !truth[q].is_empty() {
            p.scored += 1;
            p.hits1 += right(1) as usize;
            p.hits5 += right(5) as usize;
        }
        for since in &mut open {
            *since += 1;
        }
        if right(1) {
            p.recovery.extend(open.drain(..).map(Some));
        }
    }
    p.recovery.extend(open.drain(..).map(|_| None));
    p
}

/// The sequence: the `n` queries in order, `injections` injected images
/// evenly spaced among them (cycling through `inject_images`); and the
/// query before which each injection comes.
fn sequence_frames(n: usize, injections: usize, inject_images: usize) -> (Vec<Frame>, Vec<usize>) {
    let injected_at: Vec<usize> = (0..injections)
        .map(|k| (k + 1) * n / (injections + 1))
        .collect();
    let mut frames = Vec::with_capacity(n + injected_at.len());
    for q in 0..n {
        if let Some(k) = injected_at.iter().position(|&at| at == q) {
            frames.push(Frame::Injected(k % inject_images.max(1)));
        }
        frames.push(Frame::Real(q));
    }
    (frames, injected_at)
}

/// The four ways the sequence is replayed: each frame alone or through the
/// filter, by the full search or by `stop` after `min_features`.
fn modes(stop: &RuleSpec, min_features: usize) -> [Mode; 4] {
    let full = RuleSpec::new("none", None).expect("built-in rule");
    let mode = |filter, rule: &RuleSpec, min_features| Mode {
        filter,
        rule: rule.clone(),
        min_features,
    };
    [
        mode(false, &full, 0),
        mode(false, stop, min_features),
        mode(true, &full, 0),
        mode(true, stop, min_features),
    ]
}

/// One mode's passes (one per run) on one vocabulary, averaged.
fn mode_seed(seed: u64, passes: &[&Pass]) -> ModeSeed {
    let mean =
        |f: &dyn Fn(&Pass) -> f64| passes.iter().map(|p| f(p)).sum::<f64>() / passes.len() as f64;
    ModeSeed {
        seed,
        recall_at_1: mean(&|p| p.hits1 as f64 / p.scored.max(1) as f64),
        recall_at_5: mean(&|p| p.hits5 as f64 / p.scored.max(1) as f64),
        features: mean(&|p| p.features / p.frames.max(1) as f64),
        tiles: mean(&|p| p.tiles / p.frames.max(1) as f64),
        recovery: passes
            .iter()
            .flat_map(|p| p.recovery.iter().copied())
            .collect(),
    }
}

/// One mode over every vocabulary seed: means ± spread, and the frames it
/// took to recover after each injection (when it always recovered).
fn mode_report(mode: &Mode, seeds: Vec<ModeSeed>) -> ModeReport {
    let col = |f: fn(&ModeSeed) -> f64| Spread::of(&seeds.iter().map(f).collect::<Vec<_>>());
    let recoveries: Vec<Option<usize>> = seeds
        .iter()
        .flat_map(|s| s.recovery.iter().copied())
        .collect();
    let all: Option<Vec<usize>> = recoveries.iter().copied().collect();
    let all = all.filter(|a| !a.is_empty());
    let rule = if mode.rule.name == "none" {
        "full".to_owned()
    } else {
        format!("{} w={}", mode.rule, mode.min_features)
    };
    ModeReport {
        mode: format!("{}, {rule}", if mode.filter { "filter" } else { "frame" }),
        filter: mode.filter,
        rule,
        recall_at_1: col(|s| s.recall_at_1),
        recall_at_5: col(|s| s.recall_at_5),
        features: col(|s| s.features),
        tiles: col(|s| s.tiles),
        recovery_max: all.as_ref().and_then(|a| a.iter().copied().max()),
        recovery_mean: all
            .as_ref()
            .map(|a| a.iter().sum::<usize>() as f64 / a.len() as f64),
        per_seed: seeds,
    }
}

/// Run the sequence evaluation, write its outputs, and return it.
pub fn run(config: &SequenceEvalConfig) -> anyhow::Result<SequenceReport> {
    config.model.check().map_err(anyhow::Error::msg)?;
    anyhow::ensure!(config.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(
        !config.seeds.is_empty(),
        "give at least one vocabulary seed"
    );
    let dataset = Dataset::open(&config.dataset)?;
    let (map_desc, query_desc) =
        cache::dataset_descriptors(&config.cache, &dataset, &config.extract, config.tiles)?;
    let inject_images = match &config.inject {
        Some(p) if config.injections > 0 => {
            image_list(p).with_context(|| format!("--inject {}", p.display()))?
        }
        _ => Vec::new(),
    };
    anyhow::ensure!(
        config.injections == 0 || !inject_images.is_empty(),
        "--injections {} needs --inject with images",
        config.injections
    );
    let inject_desc = (!inject_images.is_empty())
        .then(|| {
            cache::descriptors(
                &config
                    .cache
                    .join(format!("injected-{}.bowdesc", config.tiles)),
                &inject_images,
                &config.extract,
                config.tiles,
                "extracting injected images",
            )
        })
        .transpose()?;
    let vocabs = vocabularies(&config.cache, config.words, &config.seeds, None, &map_desc)?;
    let maps = maps_of(&config.cache, &vocabs, &map_desc, &dataset.name)?;
    crate::features::set_opencv_threads(1);
    // every seed's map holds the same images with the same features
    let map_counts: Vec<usize> = (0..map_desc.len())
        .map(|j| map_desc.image(j).map_or(0, |d| d.nrows()))
        .collect();
    let min_features = config.min_features.resolve(auto_warmup(&map_counts));

    let n = dataset.queries.len();
    let (frames, injected_at) = sequence_frames(n, config.injections, inject_images.len());
    let truth: Vec<HashSet<u32>> = dataset.truth.clone();
    let modes = modes(&config.stop, min_features);
    let geometry = Geometry::shared(&config.verify);
    let mut per_mode: Vec<Vec<ModeSeed>> = vec![Vec::new(); modes.len()];
    for (v, map) in vocabs.iter().zip(&maps) {
        let seed = v.meta().seed;
        let (mut queries, _) =
            quantize_queries(&query_desc, v, &format!("quantizing (seed {seed})"));
        let mut injected: Vec<Query> = match &inject_desc {
            Some(d) => quantize_queries(d, v, "quantizing injected images").0,
            None => Vec::new(),
        };
        for q in queries.iter_mut().chain(injected.iter_mut()) {
            q.geometry = Some(geometry.clone());
        }
        let jobs: Vec<(usize, u32)> = (0..modes.len())
            .flat_map(|m| (0..config.runs).map(move |r| (m, r)))
            .collect();
        let passes: Vec<(usize, Pass)> = jobs
            .par_iter()
            .map(|&(m, r)| {
                let p = pass(
                    map,
                    &queries,
                    &injected,
                    &frames,
                    &truth,
                    &modes[m],
                    &config.model,
                    r as u64 + 1,
                );
                (m, p)
            })
            .collect();
        for (m, mode_seeds) in per_mode.iter_mut().enumerate() {
            let mine: Vec<&Pass> = passes.iter().filter(|e| e.0 == m).map(|e| &e.1).collect();
            mode_seeds.push(mode_seed(seed, &mine));
        }
    }
    let reports: Vec<ModeReport> = modes
        .iter()
        .zip(per_mode)
        .map(|(mode, seeds)| mode_report(mode, seeds))
        .collect();
    let report = SequenceReport {
        command: config.command.clone(),
        dataset: dataset.name.clone(),
        frames: n,
        injected_images: injected_at
            .iter()
            .enumerate()
            .map(|(k, _)| inject_images[k % inject_images.len()].name.clone())
            .collect(),
        injected_at,
        runs: config.runs,
        seeds: vocabs.iter().map(|v| v.meta().seed).collect(),
        words: config.words,
        tiles: config.tiles.to_string(),
        model: config.model,
        min_features,
        modes: reports,
    };
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("{}: cannot create", config.out.display()))?;
    std::fs::write(
        config.out.join("sequence.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    std::fs::write(config.out.join("sequence.md"), markdown(&report))?;
    Ok(report)
}

/// The report as a markdown table (means ± std over seeds, worst seed).
pub fn markdown(r: &SequenceReport) -> String {
    let pct = |s: &Spread| {
        format!(
            "{:.1} ± {:.1} (worst {:.1})",
            100.0 * s.mean,
            100.0 * s.std,
            100.0 * s.min
        )
    };
    let mut out = format!(
        "{}: {} frames in order, {} injected at {:?}; {} vocabulary seeds {:?} (K = {}), {} runs; tiles {}\n\n\
         | mode | recall@1 % | recall@5 % | features % | tiles % | recovery (max / mean frames) |\n\
         | --- | --- | --- | --- | --- | --- |\n",
        r.dataset,
        r.frames,
        r.injected_at.len(),
        r.injected_at,
        r.seeds.len(),
        r.seeds,
        r.words,
        r.runs,
        r.tiles
    );
    for m in &r.modes {
        let worst_features = format!(
            "{:.1} ± {:.1} (worst {:.1})",
            100.0 * m.features.mean,
            100.0 * m.features.std,
            100.0 * m.features.max
        );
        let recovery = match (m.filter, m.recovery_max, m.recovery_mean) {
            (false, _, _) => "–".to_owned(),
            (true, Some(max), Some(mean)) => format!("{max} / {mean:.2}"),
            (true, _, _) if r.injected_at.is_empty() => "–".to_owned(),
            (true, _, _) => "not always".to_owned(),
        };
        out += &format!(
            "| {} | {} | {} | {} | {:.1} | {} |\n",
            m.mode,
            pct(&m.recall_at_1),
            pct(&m.recall_at_5),
            worst_features,
            100.0 * m.tiles.mean,
            recovery
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn injections_are_spread_evenly_and_cycle_through_the_images() {
        let (frames, at) = sequence_frames(10, 3, 2);
        assert_eq!(at, vec![2, 5, 7]);
        assert_eq!(frames.len(), 13);
        let injected: Vec<(usize, usize)> = frames
            .iter()
            .enumerate()
            .filter_map(|(i, f)| match f {
                Frame::Injected(k) => Some((i, *k)),
                Frame::Real(_) => None,
            })
            .collect();
        // each injection comes just before the query it is placed at, the
        // images taken in turn
        assert_eq!(injected, vec![(2, 0), (6, 1), (9, 0)]);
        let real: Vec<usize> = frames
            .iter()
            .filter_map(|f| match f {
                Frame::Real(q) => Some(*q),
                Frame::Injected(_) => None,
            })
            .collect();
        assert_eq!(real, (0..10).collect::<Vec<_>>());
        let (plain, none) = sequence_frames(4, 0, 0);
        assert!(none.is_empty());
        assert_eq!(plain.len(), 4);
    }

    #[test]
    fn the_four_modes_are_each_filter_with_each_rule() {
        let stop = RuleSpec::new("place-z", Some(2.0)).expect("a rule");
        let m = modes(&stop, 20);
        let seen: Vec<(bool, String, usize)> = m
            .iter()
            .map(|m| (m.filter, m.rule.name.to_string(), m.min_features))
            .collect();
        assert_eq!(
            seen,
            vec![
                (false, "none".to_owned(), 0),
                (false, "place-z".to_owned(), 20),
                (true, "none".to_owned(), 0),
                (true, "place-z".to_owned(), 20),
            ]
        );
    }
}

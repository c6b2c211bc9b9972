//! The numbers of one setting: the metrics of each Monte Carlo run on each
//! vocabulary (recall at 90 % precision is computed per run, then averaged
//! over runs), their mean and the two spreads kept apart — over vocabulary
//! seeds (k-means draws) and over runs (random feature orders) — with each
//! seed's figure for decisions on the worst seed, the fraction of features
//! used and the per-stage time of a query. Tables, CSV, JSON and plots all
//! read these.

use super::metrics::{self, Answer};
use super::sweep::{Outcome, Setting};
use super::timing::{self, StageSample, StageTimes};
use serde::Serialize;
use std::collections::HashSet;

/// Candidate list lengths of the paper's tables (recall top-n at 90 % P).
pub const TOP_N: [usize; 3] = [3, 5, 10];
/// The precision the tables' recall is read at.
pub const PRECISION: f64 = 0.9;

/// One figure of a setting over vocabulary seeds and runs.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Stat {
    /// Mean over vocabulary seeds of each seed's mean over runs.
    pub mean: f64,
    /// Sample standard deviation over vocabulary seeds of those means (0 with
    /// one seed).
    pub std: f64,
    /// The Monte Carlo spread: sample standard deviation over runs (random
    /// feature orders), averaged over seeds.
    pub runs_std: f64,
    /// Each seed's mean over runs, in the order of the seeds.
    pub per_seed: Vec<f64>,
}

impl Stat {
    /// From `values[seed][run]`.
    pub fn of(values: &[Vec<f64>]) -> Self {
        let per_seed: Vec<f64> = values.iter().map(|v| metrics::mean(v)).collect();
        let spreads: Vec<f64> = values.iter().map(|v| metrics::std_dev(v)).collect();
        Self {
            mean: metrics::mean(&per_seed),
            std: metrics::std_dev(&per_seed),
            runs_std: metrics::mean(&spreads),
            per_seed,
        }
    }

    /// The lowest seed's figure (the worst, for a recall).
    pub fn lowest(&self) -> f64 {
        self.per_seed.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// The highest seed's figure (the worst, for a cost).
    pub fn highest(&self) -> f64 {
        self.per_seed
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// The metrics of one run.
#[derive(Debug, Clone, Serialize)]
pub struct RunMetrics {
    /// Recall at 90 % precision for each n of [`TOP_N`].
    pub recall90: [f64; 3],
    /// The score cut giving it.
    pub cut90: [Option<f32>; 3],
    pub recall_at_1: f64,
    pub recall_at_5: f64,
    /// Recall of the top candidate at 90 % precision when its
    /// distinctness, not its score, is cut ([`crate::search::Ranked::distinct`]).
    pub recall90_top1_distinct: f64,
    /// The distinctness cut giving it (`None`: no cut reaches the precision).
    pub cut90_top1_distinct: Option<f32>,
    /// Mean over queries of the fraction of features used.
    pub fraction: f64,
}

/// What the evaluation needs to know about each query besides its answers
/// (its extraction cost comes with each outcome: it depends on the tiles
/// extracted).
#[derive(Debug, Clone, Copy)]
pub struct QueryCost {
    /// Quantization time per feature, in milliseconds.
    pub quantize_ms_per_feature: f64,
    /// Decoding the image, in milliseconds: part of every outcome's
    /// extraction time, whatever the plan.
    pub decode_ms: f64,
}

/// A query's request time under one outcome: decoding and extracting the
/// tiles extracted, quantizing and voting the features used, in milliseconds.
pub fn stage_sample(o: &Outcome, c: &QueryCost) -> StageSample {
    StageSample {
        extract: o.extract_ms as f64,
        quantize: c.quantize_ms_per_feature * o.used as f64,
        vote: o.vote_ms as f64,
        verify: o.verify_ms as f64,
    }
}

/// The time the service measures for a search (every stage but decoding,
/// which it does before a plan is chosen), in milliseconds: what a learned
/// plan is told a search cost.
pub fn served_ms(o: &Outcome, c: &QueryCost) -> f64 {
    (stage_sample(o, c).total() - c.decode_ms).max(0.0)
}

/// Request time of every outcome `runs[run][query]`, in milliseconds.
pub fn request_ms(runs: &[Vec<Outcome>], costs: &[QueryCost]) -> Vec<Vec<f64>> {
    runs.iter()
        .map(|r| {
            r.iter()
                .zip(costs)
                .map(|(o, c)| stage_sample(o, c).total())
                .collect()
        })
        .collect()
}

/// A setting's request time as a fraction of the full search's, query by
/// query in the same run: mean and median over queries × runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct TimeShare {
    pub mean: f64,
    pub median: f64,
}

impl TimeShare {
    /// `ms[run][query]` against the full search's `full[run][query]`.
    pub fn of(ms: &[Vec<f64>], full: &[Vec<f64>]) -> Self {
        let ratios: Vec<f64> = ms
            .iter()
            .zip(full)
            .flat_map(|(a, b)| a.iter().zip(b))
            .filter(|(_, b)| **b > 0.0)
            .map(|(a, b)| a / b)
            .collect();
        Self {
            mean: metrics::mean(&ratios),
            median: timing::quantiles(&ratios).median,
        }
    }
}

/// Everything reported for one setting.
#[derive(Debug, Clone, Serialize)]
pub struct SettingSummary {
    pub setting: Setting,
    pub label: String,
    /// Recall at 90 % precision for each n of [`TOP_N`].
    pub recall90: [Stat; 3],
    pub recall_at_1: Stat,
    pub recall_at_5: Stat,
    /// Recall top-1 @90 % precision by distinctness.
    pub recall90_top1_distinct: Stat,
    /// The distinctness cut giving it: the least `distinct` of a kept top
    /// answer (NaN for a seed where a run has no such cut).
    pub cut90_top1_distinct: Stat,
    /// The top answer kept when its distinctness reaches a given cut
    /// (`bowloc eval --distinct-cut`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at_distinct_cut: Option<DistinctCut>,
    pub fraction: Stat,
    /// Per-query stage times over all seeds, queries and runs, in milliseconds.
    pub time_ms: StageTimes,
    /// Request time as a fraction of the full search's on the same query
    /// (and vocabulary).
    pub time_share: TimeShare,
    /// Request time as a fraction of the full search's on the same query
    /// extracted whole, as the service answers `rule=none` (when the
    /// evaluation ran it: queries streamed in tiles).
    pub time_share_whole: Option<TimeShare>,
    /// Mean fraction of the image's tiles extracted (the coarse pass counted
    /// as one).
    pub tiles: f64,
    /// Share of the searches that started with the coarse pass.
    pub coarse_first: f64,
    /// The metrics of every run: `runs[seed][run]`.
    pub runs: Vec<Vec<RunMetrics>>,
}

impl SettingSummary {
    /// Recall at 90 % precision with `n` candidates (n from [`TOP_N`]).
    pub fn recall90_at(&self, n: usize) -> &Stat {
        let i = TOP_N
            .iter()
            .position(|&t| t == n)
            .expect("n is one of TOP_N");
        &self.recall90[i]
    }
}

#[cfg(test)]
impl SettingSummary {
    /// A summary made by hand for tests: the means of recall top-n @90%P (all
    /// n), recall@1 (and @5) and the fraction of features; no spread, no runs.
    pub(crate) fn hand_made(
        rule: &str,
        parameter: Option<f64>,
        min_features: usize,
        recall90: f64,
        recall_at_1: f64,
        fraction: f64,
    ) -> Self {
        let setting = Setting::new(
            crate::search::RuleSpec::new(rule, parameter).expect("a valid rule"),
            min_features,
        );
        let stat = |mean| Stat {
            mean,
            per_seed: vec![mean],
            ..Stat::default()
        };
        Self {
            label: setting.label(),
            setting,
            recall90: std::array::from_fn(|_| stat(recall90)),
            recall_at_1: stat(recall_at_1),
            recall_at_5: stat(recall_at_1),
            recall90_top1_distinct: stat(recall90),
            cut90_top1_distinct: Stat::default(),
            at_distinct_cut: None,
            fraction: stat(fraction),
            time_ms: StageTimes::default(),
            time_share: TimeShare::default(),
            time_share_whole: None,
            tiles: 1.0,
            coarse_first: 0.0,
            runs: vec![],
        }
    }
}

/// One run's outcomes as the metrics take them, query by query with its truth.
pub fn answers<'a>(outcomes: &'a [Outcome], truth: &'a [HashSet<u32>]) -> Vec<Answer<'a>> {
    outcomes
        .iter()
        .zip(truth)
        .map(|(o, t)| Answer {
            candidates: &o.candidates,
            truth: t,
        })
        .collect()
}

/// The metrics of one run's answers.
pub fn run_metrics(outcomes: &[Outcome], truth: &[HashSet<u32>]) -> RunMetrics {
    let answers = answers(outcomes, truth);
    let at = TOP_N.map(|n| metrics::recall_at_precision(&answers, n, PRECISION));
    let fractions: Vec<f64> = outcomes.iter().map(Outcome::fraction).collect();
    let by_distinct = by_distinct(outcomes, truth, |answers| {
        metrics::recall_at_precision(answers, 1, PRECISION)
    });
    RunMetrics {
        recall90: at.map(|r| r.recall),
        cut90: at.map(|r| r.threshold),
        recall_at_1: metrics::recall_at(&answers, 1),
        recall_at_5: metrics::recall_at(&answers, 5),
        recall90_top1_distinct: by_distinct.recall,
        cut90_top1_distinct: by_distinct.threshold,
        fraction: metrics::mean(&fractions),
    }
}

/// Precision and recall of the top answer kept when its distinctness is at
/// least `cut`: a cut chosen on one map, checked on another.
#[derive(Debug, Clone, Serialize)]
pub struct DistinctCut {
    pub cut: f32,
    /// Of the answers kept, the share that are right (NaN for a run that
    /// keeps none).
    pub precision: Stat,
    /// Of the queries, the share answered right and kept.
    pub recall: Stat,
}

/// [`DistinctCut`] of a setting's outcomes on each vocabulary seed.
pub fn at_distinct_cut(
    seeds: &[SeedOutcomes<'_>],
    truth: &[HashSet<u32>],
    cut: f32,
) -> DistinctCut {
    let points: Vec<Vec<metrics::PrPoint>> = seeds
        .iter()
        .map(|s| {
            s.runs
                .iter()
                .map(|outcomes| {
                    by_distinct(outcomes, truth, |answers| {
                        metrics::at_threshold(answers, 1, cut)
                    })
                })
                .collect()
        })
        .collect();
    let over = |f: &dyn Fn(&metrics::PrPoint) -> f64| {
        Stat::of(
            &points
                .iter()
                .map(|runs| runs.iter().map(f).collect())
                .collect::<Vec<Vec<f64>>>(),
        )
    };
    DistinctCut {
        cut,
        precision: over(&|p| p.precision.unwrap_or(f64::NAN)),
        recall: over(&|p| p.recall),
    }
}

/// `metric` of one run's answers with each candidate's distinctness as its
/// score.
fn by_distinct<T>(
    outcomes: &[Outcome],
    truth: &[HashSet<u32>],
    metric: impl FnOnce(&[Answer<'_>]) -> T,
) -> T {
    let ranked: Vec<Vec<crate::search::Ranked>> = outcomes
        .iter()
        .map(|o| {
            o.candidates
                .iter()
                .map(|c| crate::search::Ranked {
                    score: c.distinct,
                    ..*c
                })
                .collect()
        })
        .collect();
    metric(&Answer::all(&ranked, truth))
}

/// One vocabulary's outcomes of a setting, `runs[run][query]`, and what
/// each query costs on that vocabulary.
#[derive(Debug, Clone, Copy)]
pub struct SeedOutcomes<'a> {
    pub runs: &'a [Vec<Outcome>],
    pub costs: &'a [QueryCost],
    /// The full search's request time on this vocabulary, `[run][query]`
    /// (see [`request_ms`]).
    pub full_ms: &'a [Vec<f64>],
    /// The same for the full search on the queries extracted whole, if run.
    pub whole_ms: Option<&'a [Vec<f64>]>,
}

/// Summarise a setting from its outcomes on each vocabulary seed;
/// `tiles_total` is each query's number of tiles, the coarse pass not
/// counted.
pub fn summarize(
    setting: &Setting,
    seeds: &[SeedOutcomes<'_>],
    truth: &[HashSet<u32>],
    tiles_total: &[usize],
) -> SettingSummary {
    let per_run: Vec<Vec<RunMetrics>> = seeds
        .iter()
        .map(|s| s.runs.iter().map(|r| run_metrics(r, truth)).collect())
        .collect();
    let over = |f: &dyn Fn(&RunMetrics) -> f64| {
        Stat::of(
            &per_run
                .iter()
                .map(|runs| runs.iter().map(f).collect())
                .collect::<Vec<Vec<f64>>>(),
        )
    };
    let samples: Vec<StageSample> = seeds
        .iter()
        .flat_map(|s| s.runs.iter().flat_map(|r| r.iter().zip(s.costs)))
        .map(|(o, c)| stage_sample(o, c))
        .collect();
    let tile_shares: Vec<f64> = seeds
        .iter()
        .flat_map(|s| s.runs.iter().flat_map(|r| r.iter().zip(tiles_total)))
        .map(|(o, &n)| o.tiles as f64 / (n + usize::from(o.coarse)).max(1) as f64)
        .collect();
    let coarse_first: Vec<f64> = seeds
        .iter()
        .flat_map(|s| s.runs.iter().flatten())
        .map(|o| f64::from(u8::from(o.coarse)))
        .collect();
    // request times of every seed's runs, against that seed's full search
    let ms: Vec<Vec<f64>> = seeds
        .iter()
        .flat_map(|s| request_ms(s.runs, s.costs))
        .collect();
    let full: Vec<Vec<f64>> = seeds.iter().flat_map(|s| s.full_ms.to_vec()).collect();
    let whole: Option<Vec<Vec<f64>>> = seeds
        .iter()
        .map(|s| s.whole_ms.map(<[Vec<f64>]>::to_vec))
        .collect::<Option<Vec<_>>>()
        .map(|w| w.into_iter().flatten().collect());
    SettingSummary {
        setting: setting.clone(),
        label: setting.label(),
        recall90: [0, 1, 2].map(|i| over(&|m| m.recall90[i])),
        recall_at_1: over(&|m| m.recall_at_1),
        recall_at_5: over(&|m| m.recall_at_5),
        recall90_top1_distinct: over(&|m| m.recall90_top1_distinct),
        cut90_top1_distinct: over(&|m| m.cut90_top1_distinct.map_or(f64::NAN, f64::from)),
        at_distinct_cut: None,
        fraction: over(&|m| m.fraction),
        time_ms: timing::summarize(&samples),
        time_share: TimeShare::of(&ms, &full),
        time_share_whole: whole.map(|w| TimeShare::of(&ms, &w)),
        tiles: metrics::mean(&tile_shares),
        coarse_first: metrics::mean(&coarse_first),
        runs: per_run,
    }
}

/// Fraction of features used by each query in each run, pooled.
pub fn fractions(runs: &[Vec<Outcome>]) -> Vec<f64> {
    runs.iter().flatten().map(Outcome::fraction).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::search::{Ranked, RuleSpec};

    fn outcome(list: &[(u32, f32)], used: u32) -> Outcome {
        Outcome {
            candidates: list
                .iter()
                .map(|&(id, score)| Ranked {
                    id,
                    score,
                    distinct: score,
                })
                .collect(),
            used,
            total: 100,
            stop: crate::search::StopKind::Rule,
            vote_ms: 1.0,
            extract_ms: 10.0,
            verify_ms: 0.0,
            tiles: 1,
            verified: false,
            coarse: false,
        }
    }

    #[test]
    fn a_learned_plan_is_told_the_request_without_decoding() {
        // 10 ms extraction (decoding included) + 50 × 0.1 quantization + 1 vote
        let o = outcome(&[(1, 0.9)], 50);
        let c = QueryCost {
            quantize_ms_per_feature: 0.1,
            decode_ms: 2.0,
        };
        assert_eq!(stage_sample(&o, &c).total(), 16.0);
        assert_eq!(served_ms(&o, &c), 14.0);
    }

    #[test]
    fn metrics_are_computed_per_run_then_averaged() {
        let truth: Vec<HashSet<u32>> = vec![[1].into(), [2].into()];
        // Run 0: both right at rank 1 → recall@90%P 1. Run 1: q1 answers
        // wrongly with the top score, so every cut that admits q0 admits q1
        // too (precision ≤ 50 %) → recall@90%P 0.
        let runs = vec![
            vec![outcome(&[(1, 0.9)], 50), outcome(&[(2, 0.8)], 30)],
            vec![outcome(&[(1, 0.5)], 100), outcome(&[(7, 0.8)], 20)],
        ];
        let setting = Setting::new(RuleSpec::new("none", None).unwrap(), 0);
        let costs = [QueryCost {
            quantize_ms_per_feature: 0.1,
            decode_ms: 0.0,
        }; 2];
        // the full search took 21 ms on every query (10 + 100 × 0.1 + 1)
        let full = vec![vec![21.0; 2]; 2];
        // extracted whole, it took 32 ms: each share of it is 21/32 of the other
        let whole = vec![vec![32.0; 2]; 2];
        let one = [SeedOutcomes {
            runs: &runs,
            costs: &costs,
            full_ms: &full,
            whole_ms: None,
        }];
        let s = summarize(&setting, &one, &truth, &[1, 1]);
        assert_eq!(s.time_share_whole, None);
        let against_whole = summarize(
            &setting,
            &[SeedOutcomes {
                whole_ms: Some(&whole),
                ..one[0]
            }],
            &truth,
            &[1, 1],
        );
        let w = against_whole.time_share_whole.unwrap();
        assert!((w.mean - s.time_share.mean * 21.0 / 32.0).abs() < 1e-12);
        assert!((w.median - s.time_share.median * 21.0 / 32.0).abs() < 1e-12);
        assert_eq!(s.runs[0][0].recall90, [1.0; 3]);
        assert_eq!(s.runs[0][1].recall90, [0.0; 3]);
        assert_eq!(s.recall90_at(5).mean, 0.5);
        // one seed: no spread over seeds, the Monte Carlo spread over runs
        assert_eq!(s.recall90_at(5).std, 0.0);
        assert!((s.recall90_at(5).runs_std - 0.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.runs[0][1].recall_at_1, 0.5);
        assert_eq!(s.recall_at_5.mean, 0.75);
        assert_eq!(s.runs[0][0].fraction, 0.4);
        assert!((s.fraction.mean - 0.5).abs() < 1e-12);
        // Quantize time is charged per feature used: 20..100 features.
        assert_eq!(s.time_ms.quantize.p95, 10.0);
        assert_eq!(s.time_ms.extract.median, 10.0);
        // 50 features: 10 + 5 + 1 = 16 ms, 16/21 of the full search
        assert!((s.time_share.mean - (16.0 + 14.0 + 21.0 + 13.0) / 4.0 / 21.0).abs() < 1e-12);
        assert_eq!(s.tiles, 1.0);
        assert_eq!(fractions(&runs), [0.5, 0.3, 1.0, 0.2]);

        // A second vocabulary on which run 1 is right too: the seeds' means
        // (0.5 and 1.0) give the mean and the spread over seeds; the spread
        // over runs is averaged (√0.5 and 0).
        let better = vec![runs[0].clone(), runs[0].clone()];
        let two = [
            one[0],
            SeedOutcomes {
                runs: &better,
                costs: &costs,
                full_ms: &full,
                whole_ms: None,
            },
        ];
        let s = summarize(&setting, &two, &truth, &[1, 1]);
        let r = s.recall90_at(5);
        assert_eq!(r.per_seed, [0.5, 1.0]);
        assert_eq!(r.mean, 0.75);
        assert!((r.std - 0.125f64.sqrt()).abs() < 1e-12);
        assert!((r.runs_std - 0.5f64.sqrt() / 2.0).abs() < 1e-12);
        assert_eq!((r.lowest(), r.highest()), (0.5, 1.0));
        assert_eq!(s.runs.len(), 2);
    }

    #[test]
    fn a_distinctness_cut_keeps_the_top_answers_at_or_above_it() {
        let truth: Vec<HashSet<u32>> = vec![[1].into(), [2].into(), [3].into()];
        // distinctness (= score here) 0.9 right, 0.7 wrong, 0.6 right
        let runs = vec![vec![
            outcome(&[(1, 0.9)], 10),
            outcome(&[(5, 0.7)], 10),
            outcome(&[(3, 0.6)], 10),
        ]];
        let costs = [QueryCost {
            quantize_ms_per_feature: 0.1,
            decode_ms: 0.0,
        }; 3];
        let full = vec![vec![21.0; 3]];
        let seeds = [SeedOutcomes {
            runs: &runs,
            costs: &costs,
            full_ms: &full,
            whole_ms: None,
        }];
        // at 90 % precision only the first answer can be kept: its cut is 0.9
        let m = run_metrics(&runs[0], &truth);
        assert_eq!(m.cut90_top1_distinct, Some(0.9));
        assert!((m.recall90_top1_distinct - 1.0 / 3.0).abs() < 1e-12);
        let at = |cut| {
            let c = at_distinct_cut(&seeds, &truth, cut);
            (c.precision.per_seed[0], c.recall.per_seed[0])
        };
        assert_eq!(at(0.9), (1.0, 1.0 / 3.0));
        assert_eq!(at(0.7), (0.5, 1.0 / 3.0));
        assert_eq!(at(0.5), (2.0 / 3.0, 2.0 / 3.0));
        // nothing kept: no precision
        assert!(at(0.95).0.is_nan());
    }
}

//! The evaluation's verification pass: the answers of a setting re-ranked by
//! geometric verification ([`crate::geometry::verify`]), each query verified
//! against the features its search used, and the recalls with and without
//! it side by side, with what verification cost per query.

use super::metrics::{self, Answer};
use super::summary::PRECISION;
use super::summary::Stat;
use super::sweep::{Outcome, seed};
use super::timing::{self, Quantiles};
use crate::geometry::Keypoint;
use crate::geometry::verify::{ModelFit, VerifyParams, rerank};
use crate::index::MapIndex;
use crate::search::{Ranked, permute};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use std::time::Instant;

/// Recalls of one set of answers, over runs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Recalls {
    pub recall_at_1: Stat,
    pub recall_at_5: Stat,
    /// Recall of the top candidate at 90 % precision.
    pub recall90_top1: Stat,
    /// Recall of the top 5 candidates at 90 % precision.
    pub recall90_top5: Stat,
}

/// One setting with and without verification.
#[derive(Debug, Clone, Serialize)]
pub struct VerifiedRow {
    /// The setting's label.
    pub label: String,
    /// Its index in the report's settings.
    pub setting: usize,
    pub without: Recalls,
    pub with: Recalls,
    /// Milliseconds of verification per query (all its top-k candidates).
    pub verify_ms: Quantiles,
    /// Share of queries whose best candidate is verified.
    pub verified_share: Stat,
    /// Of those, the share whose best candidate is a true match.
    pub verified_precision: Stat,
}

/// The verification pass of one evaluation.
#[derive(Debug, Clone, Serialize)]
pub struct VerificationReport {
    pub params: VerifyParams,
    pub rows: Vec<VerifiedRow>,
}

fn recalls(runs: &[Vec<Outcome>], truth: &[HashSet<u32>]) -> Recalls {
    let per_run: Vec<[f64; 4]> = runs
        .iter()
        .map(|r| {
            let answers: Vec<Answer<'_>> = r
                .iter()
                .zip(truth)
                .map(|(o, t)| Answer {
                    candidates: &o.candidates,
                    truth: t,
                })
                .collect();
            [
                metrics::recall_at(&answers, 1),
                metrics::recall_at(&answers, 5),
                metrics::recall_at_precision(&answers, 1, PRECISION).recall,
                metrics::recall_at_precision(&answers, 5, PRECISION).recall,
            ]
        })
        .collect();
    let over = |i: usize| Stat::of(&per_run.iter().map(|m| m[i]).collect::<Vec<_>>());
    Recalls {
        recall_at_1: over(0),
        recall_at_5: over(1),
        recall90_top1: over(2),
        recall90_top5: over(3),
    }
}

/// A query's features as verification takes them: (word, keypoint) in the
/// original feature order.
pub type QueryGeometry = Vec<(u32, Keypoint)>;

/// One query's verified answer and what it cost.
struct Verified {
    outcome: Outcome,
    ms: f64,
    top_verified: bool,
}

fn verify_one(
    map: &MapIndex,
    query: &QueryGeometry,
    outcome: &Outcome,
    seed: u64,
    fit: &dyn ModelFit,
    params: &VerifyParams,
) -> Verified {
    let started = Instant::now();
    let order = permute::permutation(query.len(), seed);
    let seen: Vec<(u32, Keypoint)> = order[..(outcome.used as usize).min(order.len())]
        .iter()
        .map(|&i| query[i as usize])
        .collect();
    let votes: Vec<(u32, f32)> = outcome.candidates.iter().map(|r| (r.id, r.score)).collect();
    let reranked = rerank(map, &votes, &seen, fit, params);
    let ms = started.elapsed().as_secs_f64() * 1e3;
    Verified {
        outcome: Outcome {
            candidates: reranked
                .iter()
                .map(|r| Ranked {
                    id: r.id,
                    score: r.score(),
                })
                .collect(),
            ..outcome.clone()
        },
        ms,
        top_verified: reranked
            .first()
            .and_then(|r| r.verification)
            .is_some_and(|v| v.verified),
    }
}

/// What every setting's verification needs: the map, each query's features
/// (`queries[q]` holds every feature of query q, in the order the sweep's
/// words came in) and the ground truth.
pub struct Inputs<'a> {
    pub map: &'a MapIndex,
    pub queries: &'a [QueryGeometry],
    pub truth: &'a [HashSet<u32>],
}

/// Verify the answers `runs[run][query]` of the setting at `index` (named
/// `label`) and compare.
pub fn verify_setting(
    inputs: &Inputs<'_>,
    label: &str,
    index: usize,
    runs: &[Vec<Outcome>],
    fit: &dyn ModelFit,
    params: &VerifyParams,
) -> VerifiedRow {
    let (map, queries, truth) = (inputs.map, inputs.queries, inputs.truth);
    let verified: Vec<Vec<Verified>> = runs
        .iter()
        .enumerate()
        .map(|(run, outcomes)| {
            outcomes
                .par_iter()
                .enumerate()
                .map(|(q, o)| verify_one(map, &queries[q], o, seed(run as u32, q), fit, params))
                .collect()
        })
        .collect();
    let ms: Vec<f64> = verified.iter().flatten().map(|v| v.ms).collect();
    let shares: Vec<(f64, f64)> = verified
        .iter()
        .map(|run| {
            let tops: Vec<(bool, bool)> = run
                .iter()
                .zip(truth)
                .map(|(v, t)| {
                    let right = v
                        .outcome
                        .candidates
                        .first()
                        .is_some_and(|c| t.contains(&c.id));
                    (v.top_verified, right)
                })
                .collect();
            let n_verified = tops.iter().filter(|t| t.0).count();
            let n_right = tops.iter().filter(|t| t.0 && t.1).count();
            (
                n_verified as f64 / tops.len().max(1) as f64,
                n_right as f64 / n_verified.max(1) as f64,
            )
        })
        .collect();
    let outcomes: Vec<Vec<Outcome>> = verified
        .into_iter()
        .map(|run| run.into_iter().map(|v| v.outcome).collect())
        .collect();
    VerifiedRow {
        label: label.to_owned(),
        setting: index,
        without: recalls(runs, truth),
        with: recalls(&outcomes, truth),
        verify_ms: timing::quantiles(&ms),
        verified_share: Stat::of(&shares.iter().map(|s| s.0).collect::<Vec<_>>()),
        verified_precision: Stat::of(&shares.iter().map(|s| s.1).collect::<Vec<_>>()),
    }
}

/// The markdown section of the verification pass.
pub fn markdown(report: &VerificationReport) -> String {
    let p = &report.params;
    let pct = |s: Stat| format!("{:.1} ± {:.1}", 100.0 * s.mean, 100.0 * s.std);
    let mut out = format!(
        "## Geometric verification\n\n\
         The top {} vote candidates of each answer verified ({:?}, {:?}, inlier threshold {} px, \
         words giving more than {} pairs skipped) and re-ranked by inliers; the score is then \
         the inlier count. A candidate is verified with at least {} inliers. Recalls in %, \
         mean ± standard deviation over runs; verification time per query in ms.\n\n\
         | setting | verify | recall@1 | recall@5 | recall top-1 @90% P | recall top-5 @90% P | verify ms median | p95 | top verified | verified top correct |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        p.top_k, p.model, p.estimator, p.threshold_px, p.max_word_pairs, p.min_inliers
    );
    for r in &report.rows {
        for (name, x) in [("no", &r.without), ("yes", &r.with)] {
            let (time, share) = if name == "yes" {
                (
                    format!("{:.2} | {:.2}", r.verify_ms.median, r.verify_ms.p95),
                    format!("{} | {}", pct(r.verified_share), pct(r.verified_precision)),
                )
            } else {
                ("– | –".to_owned(), "– | –".to_owned())
            };
            out += &format!(
                "| {} | {name} | {} | {} | {} | {} | {time} | {share} |\n",
                r.label,
                pct(x.recall_at_1),
                pct(x.recall_at_5),
                pct(x.recall90_top1),
                pct(x.recall90_top5),
            );
        }
    }
    out
}

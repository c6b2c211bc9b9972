//! The evaluation's verification table: a setting run again with its
//! answers re-ranked by geometric verification ([`crate::geometry::verify`],
//! each query verified against the features its search used, in the sweep),
//! and the recalls with and without it side by side, with what verification
//! cost per query.

use super::metrics;
use super::summary::PRECISION;
use super::summary::Stat;
use super::sweep::Outcome;
use super::timing::{self, Quantiles};
use crate::geometry::verify::VerifyParams;
use serde::Serialize;
use std::collections::HashSet;

/// Recalls of one set of answers (one vocabulary), over runs.
#[derive(Debug, Clone, Serialize)]
pub struct Recalls {
    pub recall_at_1: Stat,
    pub recall_at_5: Stat,
    /// Recall of the top candidate at 90 % precision.
    pub recall90_top1: Stat,
    /// Recall of the top 5 candidates at 90 % precision.
    pub recall90_top5: Stat,
    /// Recall of the top candidate at 90 % precision, cutting its
    /// distinctness rather than its score.
    pub recall90_top1_distinct: Stat,
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
    let per_run: Vec<[f64; 5]> = runs
        .iter()
        .map(|r| {
            let answers = super::summary::answers(r, truth);
            [
                metrics::recall_at(&answers, 1),
                metrics::recall_at(&answers, 5),
                metrics::recall_at_precision(&answers, 1, PRECISION).recall,
                metrics::recall_at_precision(&answers, 5, PRECISION).recall,
                super::summary::run_metrics(r, truth).recall90_top1_distinct,
            ]
        })
        .collect();
    let over = |i: usize| Stat::of(&[per_run.iter().map(|m| m[i]).collect::<Vec<_>>()]);
    Recalls {
        recall_at_1: over(0),
        recall_at_5: over(1),
        recall90_top1: over(2),
        recall90_top5: over(3),
        recall90_top1_distinct: over(4),
    }
}

/// The row of a setting run without (`without[run][query]`) and with
/// (`with`) geometric re-ranking: recalls side by side, what verifying cost
/// and how often the best candidate was verified (and right).
pub fn row(
    label: &str,
    index: usize,
    without: &[Vec<Outcome>],
    with: &[Vec<Outcome>],
    truth: &[HashSet<u32>],
) -> VerifiedRow {
    let ms: Vec<f64> = with.iter().flatten().map(|o| o.verify_ms as f64).collect();
    let shares: Vec<(f64, f64)> = with
        .iter()
        .map(|run| {
            let tops: Vec<(bool, bool)> = run
                .iter()
                .zip(truth)
                .map(|(o, t)| {
                    let right = o.candidates.first().is_some_and(|c| t.contains(&c.id));
                    (o.verified, right)
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
    VerifiedRow {
        label: label.to_owned(),
        setting: index,
        without: recalls(without, truth),
        with: recalls(with, truth),
        verify_ms: timing::quantiles(&ms),
        verified_share: Stat::of(&[shares.iter().map(|s| s.0).collect::<Vec<_>>()]),
        verified_precision: Stat::of(&[shares.iter().map(|s| s.1).collect::<Vec<_>>()]),
    }
}

/// The markdown section of the verification pass.
pub fn markdown(report: &VerificationReport) -> String {
    let p = &report.params;
    let pct = |s: &Stat| format!("{:.1} ± {:.1}", 100.0 * s.mean, 100.0 * s.runs_std);
    let mut out = format!(
        "## Geometric verification\n\n\
         The top {} vote candidates of each answer verified ({:?}, {:?}, inlier threshold {} px; \
         features paired within {} bits of their Hamming signatures, words giving more than {} \
         pairs skipped) and re-ranked by inliers (order `{}`, re-ranking `{}`: {}); the \
         score is then an inlier count. A candidate is verified with at least {} inliers. The \
         geometric stops check with their own pairs (within {} bits, at most {} a word) and stop \
         only on an answer at the query's scale (within e^±{}). Recalls in %, on \
         the first vocabulary, mean ± standard deviation over runs; verification time per \
         query in ms.\n\n\
         | setting | verify | recall@1 | recall@5 | recall top-1 @90% P | recall top-1 @90% P by distinctness | recall top-5 @90% P | verify ms median | p95 | top verified | verified top correct |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        p.top_k,
        p.model,
        p.fit().estimator_used(),
        p.threshold_px,
        p.max_hamming,
        p.max_word_pairs,
        p.order,
        p.rerank.name(),
        p.rerank.about(),
        p.min_inliers(),
        p.stop_max_hamming,
        p.stop_max_word_pairs,
        p.stop_log_scale
    );
    for r in &report.rows {
        for (name, x) in [("no", &r.without), ("yes", &r.with)] {
            let (time, share) = if name == "yes" {
                (
                    format!("{:.2} | {:.2}", r.verify_ms.median, r.verify_ms.p95),
                    format!(
                        "{} | {}",
                        pct(&r.verified_share),
                        pct(&r.verified_precision)
                    ),
                )
            } else {
                ("– | –".to_owned(), "– | –".to_owned())
            };
            out += &format!(
                "| {} | {name} | {} | {} | {} | {} | {} | {time} | {share} |\n",
                r.label,
                pct(&x.recall_at_1),
                pct(&x.recall_at_5),
                pct(&x.recall90_top1),
                pct(&x.recall90_top1_distinct),
                pct(&x.recall90_top5),
            );
        }
    }
    out
}

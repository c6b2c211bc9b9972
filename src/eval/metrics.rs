//! The retrieval metrics of the evaluation, defined once here (and in
//! `docs/results.md`):
//!
//! - the candidates of query q at score cut s, C_q(s), are its top-n map
//!   images whose score is ≥ s;
//! - q is a *true positive* at s when C_q(s) is non-empty and holds a
//!   ground-truth match, a *false positive* when it is non-empty and holds
//!   none (queries without any match in the map can only be false positives);
//! - precision(s) = TP / (TP + FP) (undefined when no query answers);
//!   recall(s) = TP / (queries that have a match in the map);
//! - recall at precision p = the best recall(s) over every s with
//!   precision(s) ≥ p (0 when no s reaches p); the paper's tables use p = 0.9
//!   and n = 3, 5, 10;
//! - plain recall@n = the share of queries with a match whose top n (no score
//!   cut) hold one.
//!
//! Every function takes the answers of one run; averaging over runs is the
//! caller's business.

use crate::search::Ranked;
use serde::Serialize;
use std::collections::HashSet;

/// One query's answer next to its ground truth.
#[derive(Debug, Clone, Copy)]
pub struct Answer<'a> {
    /// Ranked candidates, best first (as the search returns them).
    pub candidates: &'a [Ranked],
    /// Map ids that are correct matches (empty: the query has no match).
    pub truth: &'a HashSet<u32>,
}

impl<'a> Answer<'a> {
    /// Each query's candidates (`candidates[q]`) next to its truth.
    pub fn all(candidates: &'a [Vec<Ranked>], truth: &'a [HashSet<u32>]) -> Vec<Self> {
        candidates
            .iter()
            .zip(truth)
            .map(|(candidates, truth)| Answer { candidates, truth })
            .collect()
    }

    /// Highest score among the top n: C_q(s) is non-empty iff s ≤ this.
    fn best(&self, n: usize) -> Option<f32> {
        self.candidates
            .iter()
            .take(n)
            .map(|c| c.score)
            .reduce(f32::max)
    }

    /// Highest score of a correct match among the top n: q is a true
    /// positive at s iff s ≤ this.
    fn best_match(&self, n: usize) -> Option<f32> {
        self.candidates
            .iter()
            .take(n)
            .filter(|c| self.truth.contains(&c.id))
            .map(|c| c.score)
            .reduce(f32::max)
    }
}

/// Queries that have at least one match in the map: the recall denominator.
pub fn with_match(answers: &[Answer<'_>]) -> usize {
    answers.iter().filter(|a| !a.truth.is_empty()).count()
}

/// `part / whole`, 0 when `whole` is 0.
fn ratio(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// Counts and rates at one score cut.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PrPoint {
    /// The score cut s.
    pub threshold: f32,
    pub true_positives: usize,
    pub false_positives: usize,
    /// `None` when no query has a candidate at this cut.
    pub precision: Option<f64>,
    pub recall: f64,
}

/// Precision and recall of the top-n candidates at score cut `s`, straight
/// from the definition.
pub fn at_threshold(answers: &[Answer<'_>], n: usize, s: f32) -> PrPoint {
    let mut tp = 0;
    let mut fp = 0;
    for a in answers {
        if a.best(n).is_some_and(|b| b >= s) {
            if a.best_match(n).is_some_and(|m| m >= s) {
                tp += 1;
            } else {
                fp += 1;
            }
        }
    }
    PrPoint {
        threshold: s,
        true_positives: tp,
        false_positives: fp,
        precision: (tp + fp > 0).then(|| ratio(tp, tp + fp)),
        recall: ratio(tp, with_match(answers)),
    }
}

/// The precision–recall curve of the top-n candidates: one point per distinct
/// score at which a query starts answering or starts being right, from the
/// strictest cut to the loosest. Equal scores fall on the same side of every
/// cut, so tied queries enter together.
pub fn pr_curve(answers: &[Answer<'_>], n: usize) -> Vec<PrPoint> {
    let mut best: Vec<f32> = answers.iter().filter_map(|a| a.best(n)).collect();
    let mut hits: Vec<f32> = answers.iter().filter_map(|a| a.best_match(n)).collect();
    let descending = |a: &f32, b: &f32| b.total_cmp(a);
    best.sort_unstable_by(descending);
    hits.sort_unstable_by(descending);
    let mut cuts: Vec<f32> = best.iter().chain(&hits).copied().collect();
    cuts.sort_unstable_by(descending);
    cuts.dedup();
    let matched = with_match(answers);
    let (mut answering, mut tp) = (0, 0);
    cuts.into_iter()
        .map(|s| {
            while answering < best.len() && best[answering] >= s {
                answering += 1;
            }
            while tp < hits.len() && hits[tp] >= s {
                tp += 1;
            }
            PrPoint {
                threshold: s,
                true_positives: tp,
                false_positives: answering - tp,
                precision: Some(ratio(tp, answering)),
                recall: ratio(tp, matched),
            }
        })
        .collect()
}

/// The best recall at precision ≥ `min_precision`, and the loosest cut giving
/// it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RecallAtPrecision {
    pub recall: f64,
    /// `None` when no cut reaches the precision (recall is then 0).
    pub threshold: Option<f32>,
}

/// Recall of the top-n candidates at precision ≥ `min_precision`.
pub fn recall_at_precision(
    answers: &[Answer<'_>],
    n: usize,
    min_precision: f64,
) -> RecallAtPrecision {
    let mut out = RecallAtPrecision {
        recall: 0.0,
        threshold: None,
    };
    for p in pr_curve(answers, n) {
        let precise = p.precision.is_some_and(|v| v >= min_precision - 1e-12);
        if precise && p.true_positives > 0 && p.recall >= out.recall {
            out = RecallAtPrecision {
                recall: p.recall,
                threshold: Some(p.threshold),
            };
        }
    }
    out
}

/// Plain recall@n: the share of queries with a match that have one among
/// their top n candidates, whatever the scores.
pub fn recall_at(answers: &[Answer<'_>], n: usize) -> f64 {
    let found = answers
        .iter()
        .filter(|a| a.candidates.iter().take(n).any(|c| a.truth.contains(&c.id)))
        .count();
    ratio(found, with_match(answers))
}

/// Mean of `values` (0 for none).
pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

/// Sample standard deviation of `values` (0 for fewer than two).
pub fn std_dev(values: &[f64]) -> f64 {
    if values.len() < 2 {
        return 0.0;
    }
    let m = mean(values);
    let var = values.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (values.len() - 1) as f64;
    var.sqrt()
}

/// Counts of `values` in `bins` equal bins over [0, 1] (1 goes in the last).
pub fn histogram(values: &[f64], bins: usize) -> Vec<usize> {
    let mut counts = vec![0; bins];
    for &v in values {
        let b = ((v.clamp(0.0, 1.0) * bins as f64) as usize).min(bins - 1);
        counts[b] += 1;
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ranked(list: &[(u32, f32)]) -> Vec<Ranked> {
        list.iter()
            .map(|&(id, score)| Ranked {
                id,
                score,
                distinct: score,
            })
            .collect()
    }

    fn truth(ids: &[u32]) -> HashSet<u32> {
        ids.iter().copied().collect()
    }

    /// Four queries: q0 right at rank 1 (0.9), q1 wrong with a high score
    /// (0.8), q2 right at rank 2 (0.5 behind 0.6), q3 has no match in the
    /// map but answers (0.3), q4 answers nothing.
    struct Case {
        candidates: Vec<Vec<Ranked>>,
        truth: Vec<HashSet<u32>>,
    }

    impl Case {
        fn new() -> Self {
            Self {
                candidates: vec![
                    ranked(&[(1, 0.9), (2, 0.1)]),
                    ranked(&[(7, 0.8), (8, 0.2)]),
                    ranked(&[(4, 0.6), (3, 0.5)]),
                    ranked(&[(5, 0.3)]),
                    vec![],
                ],
                truth: vec![
                    truth(&[1]),
                    truth(&[9]),
                    truth(&[3]),
                    truth(&[]),
                    truth(&[6]),
                ],
            }
        }

        fn answers(&self) -> Vec<Answer<'_>> {
            self.candidates
                .iter()
                .zip(&self.truth)
                .map(|(c, t)| Answer {
                    candidates: c,
                    truth: t,
                })
                .collect()
        }
    }

    #[test]
    fn counts_at_a_cut_follow_the_definition() {
        let case = Case::new();
        let a = case.answers();
        assert_eq!(with_match(&a), 4);
        // s = 0.85: only q0 answers, and rightly.
        let p = at_threshold(&a, 5, 0.85);
        assert_eq!((p.true_positives, p.false_positives), (1, 0));
        assert_eq!(p.precision, Some(1.0));
        assert_eq!(p.recall, 0.25);
        // s = 0.55: q0 right; q1 wrong; q2 answers (0.6) but its match (0.5)
        // is cut, so it is a false positive.
        let p = at_threshold(&a, 5, 0.55);
        assert_eq!((p.true_positives, p.false_positives), (1, 2));
        // s = 0.5 (inclusive): q2 becomes right.
        let p = at_threshold(&a, 5, 0.5);
        assert_eq!((p.true_positives, p.false_positives), (2, 1));
        // s = 0: q3 (no match in the map) is a false positive, q4 (no
        // candidates) is neither.
        let p = at_threshold(&a, 5, 0.0);
        assert_eq!((p.true_positives, p.false_positives), (2, 2));
        assert_eq!(p.precision, Some(0.5));
        assert_eq!(p.recall, 0.5);
        // Nobody answers: precision undefined, recall 0.
        let p = at_threshold(&a, 5, 2.0);
        assert_eq!(p.precision, None);
        assert_eq!(p.recall, 0.0);
    }

    #[test]
    fn top_n_limits_the_candidates() {
        let case = Case::new();
        let a = case.answers();
        // With n = 1, q2's match at rank 2 does not count.
        let p = at_threshold(&a, 1, 0.0);
        assert_eq!((p.true_positives, p.false_positives), (1, 3));
        assert_eq!(recall_at(&a, 1), 0.25);
        assert_eq!(recall_at(&a, 2), 0.5);
        assert_eq!(recall_at(&a, 10), 0.5);
    }

    #[test]
    fn the_curve_agrees_with_the_definition_at_every_cut() {
        let case = Case::new();
        let a = case.answers();
        for n in [1, 2, 5] {
            let curve = pr_curve(&a, n);
            assert!(!curve.is_empty());
            for p in &curve {
                assert_eq!(
                    *p,
                    at_threshold(&a, n, p.threshold),
                    "n={n} s={}",
                    p.threshold
                );
            }
            // Strictest first, recall never falls as the cut loosens.
            for w in curve.windows(2) {
                assert!(w[0].threshold > w[1].threshold);
                assert!(w[0].recall <= w[1].recall);
            }
        }
    }

    #[test]
    fn recall_at_precision_takes_the_best_precise_cut() {
        let case = Case::new();
        let a = case.answers();
        // Cuts: 0.9 → P 1, R .25; 0.8 → P .5; 0.6 → 1/3; 0.5 → 2/3, R .5;
        // 0.3 → .5. Only the 0.9 cut reaches 90 %.
        let r = recall_at_precision(&a, 5, 0.9);
        assert_eq!(r.recall, 0.25);
        assert_eq!(r.threshold, Some(0.9));
        // At 60 % the 0.5 cut (P 2/3, R 0.5) wins.
        let r = recall_at_precision(&a, 5, 0.6);
        assert_eq!(r.recall, 0.5);
        assert_eq!(r.threshold, Some(0.5));
        // Exactly 90 % counts: 9 right queries above one wrong one (a query
        // with no match in the map, so recall can reach 1).
        let mut candidates: Vec<Vec<Ranked>> = (0..9)
            .map(|i| ranked(&[(i, 1.0 - i as f32 * 0.01)]))
            .collect();
        candidates.push(ranked(&[(99, 0.5)]));
        let truths: Vec<HashSet<u32>> = (0..10)
            .map(|i| if i < 9 { truth(&[i]) } else { truth(&[]) })
            .collect();
        let b: Vec<Answer<'_>> = candidates
            .iter()
            .zip(&truths)
            .map(|(c, t)| Answer {
                candidates: c,
                truth: t,
            })
            .collect();
        assert_eq!(at_threshold(&b, 1, 0.5).precision, Some(0.9));
        let r = recall_at_precision(&b, 1, 0.9);
        assert_eq!(r.recall, 1.0);
        assert_eq!(r.threshold, Some(0.5));
    }

    #[test]
    fn tied_scores_cannot_be_split_by_a_cut() {
        // Two queries with the same top score, one right and one wrong: no
        // cut separates them, so precision 90 % is out of reach.
        let c = [ranked(&[(1, 0.7)]), ranked(&[(2, 0.7)])];
        let t = [truth(&[1]), truth(&[3])];
        let a: Vec<Answer<'_>> = c
            .iter()
            .zip(&t)
            .map(|(c, t)| Answer {
                candidates: c,
                truth: t,
            })
            .collect();
        let curve = pr_curve(&a, 5);
        assert_eq!(curve.len(), 1);
        assert_eq!(curve[0].precision, Some(0.5));
        let r = recall_at_precision(&a, 5, 0.9);
        assert_eq!(r.recall, 0.0);
        assert_eq!(r.threshold, None);
        assert_eq!(recall_at_precision(&a, 5, 0.5).recall, 0.5);
    }

    #[test]
    fn empty_lists_and_unmatched_queries() {
        let empty: Vec<Ranked> = vec![];
        let none = truth(&[]);
        let some = truth(&[1]);
        // Nobody answers anything.
        let a = [
            Answer {
                candidates: &empty,
                truth: &some,
            },
            Answer {
                candidates: &empty,
                truth: &none,
            },
        ];
        assert!(pr_curve(&a, 5).is_empty());
        assert_eq!(recall_at_precision(&a, 5, 0.9).recall, 0.0);
        assert_eq!(recall_at(&a, 5), 0.0);
        // No query has a match: recall is 0, not NaN.
        let c = ranked(&[(1, 0.4)]);
        let b = [Answer {
            candidates: &c,
            truth: &none,
        }];
        assert_eq!(with_match(&b), 0);
        assert_eq!(recall_at(&b, 5), 0.0);
        assert_eq!(at_threshold(&b, 5, 0.0).false_positives, 1);
        assert_eq!(recall_at_precision(&b, 5, 0.9).recall, 0.0);
        assert!(recall_at(&[], 5) == 0.0 && pr_curve(&[], 5).is_empty());
    }

    #[test]
    fn summary_statistics() {
        assert_eq!(mean(&[]), 0.0);
        assert_eq!(mean(&[1.0, 2.0, 6.0]), 3.0);
        assert_eq!(std_dev(&[5.0]), 0.0);
        assert!((std_dev(&[1.0, 2.0, 3.0, 4.0]) - 1.290_994_4).abs() < 1e-6);
        assert_eq!(
            histogram(&[0.0, 0.05, 0.1, 0.55, 1.0, 0.999], 10),
            [2, 1, 0, 0, 0, 1, 0, 0, 0, 2]
        );
    }
}

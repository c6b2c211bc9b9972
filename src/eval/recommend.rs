//! Choosing a server default from the sweep: among the settings that lose at
//! most `tolerance` (absolute) of the full search's recall at 90 % precision
//! (top 5) and of its recall@1 **on every vocabulary seed** (the worst seed
//! decides, not the mean), the one whose worst seed uses the fewest
//! features; the full search itself when none qualifies. Degenerate grid
//! points ([`Setting::degenerate`](super::sweep::Setting)) never qualify, and
//! nothing is recommended when the full search itself is near chance
//! ([`MIN_ABOVE_CHANCE`]). The criterion ([`within`], with its [`Criterion`])
//! is also what [`super::equal_recall`] reads each rule at.

use super::metrics;
use super::summary::{SettingSummary, Stat};
use super::sweep::BASELINE;
use serde::Serialize;
use std::collections::HashSet;

/// How far above chance (absolute recall@1) the full search must be, on its
/// worst seed, for a recommendation to mean anything.
pub const MIN_ABOVE_CHANCE: f64 = 0.1;

/// Which recalls a setting must keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Criterion {
    /// Recall top-5 at 90 % precision and recall@1.
    Precision90,
    /// Plain recall@1 and recall@5 (no score cut, so no precision cliff).
    PlainRecall,
}

impl Criterion {
    /// The two figures compared with the full search's.
    pub fn figures(self, s: &SettingSummary) -> [&Stat; 2] {
        match self {
            Self::Precision90 => [s.recall90_at(5), &s.recall_at_1],
            Self::PlainRecall => [&s.recall_at_1, &s.recall_at_5],
        }
    }

    /// The figures' names, as the tables print them.
    pub fn names(self) -> [&'static str; 2] {
        match self {
            Self::Precision90 => ["recall top-5 @90%P", "recall@1"],
            Self::PlainRecall => ["recall@1", "recall@5"],
        }
    }
}

/// The chosen setting and why.
#[derive(Debug, Clone, Serialize)]
pub struct Recommendation {
    /// Index into the summaries.
    pub index: usize,
    pub label: String,
    pub tolerance: f64,
    /// Mean fraction of features over seeds, and the worst seed's.
    pub fraction: f64,
    pub worst_fraction: f64,
    /// Means over seeds.
    pub recall90_top5: f64,
    pub recall_at_1: f64,
    pub baseline_recall90_top5: f64,
    pub baseline_recall_at_1: f64,
    /// The largest loss over seeds against the full search on the same
    /// vocabulary: recall top-5 @90%P, recall@1.
    pub worst_loss: [f64; 2],
}

/// The largest loss of `s` against `base` over seeds, figure by figure.
pub fn worst_loss(s: &SettingSummary, base: &SettingSummary, criterion: Criterion) -> [f64; 2] {
    let (a, b) = (criterion.figures(s), criterion.figures(base));
    [0, 1].map(|i| {
        a[i].per_seed
            .iter()
            .zip(&b[i].per_seed)
            .map(|(x, y)| y - x)
            .fold(f64::NEG_INFINITY, f64::max)
    })
}

/// Whether `s` is a usable setting (not a degenerate grid point) that loses
/// at most `tolerance` (absolute) of `base`'s two figures of `criterion` on
/// every seed.
pub fn within(
    s: &SettingSummary,
    base: &SettingSummary,
    tolerance: f64,
    criterion: Criterion,
) -> bool {
    s.setting.degenerate.is_none()
        && worst_loss(s, base, criterion)
            .iter()
            .all(|&l| l <= tolerance + 1e-12)
}

/// Among `candidates` (indices into `summaries`), the one whose worst seed
/// uses the fewest features that is [`within`] `tolerance` of `base`; the
/// first on ties.
pub fn cheapest_within(
    summaries: &[SettingSummary],
    candidates: impl IntoIterator<Item = usize>,
    base: &SettingSummary,
    tolerance: f64,
    criterion: Criterion,
) -> Option<usize> {
    candidates
        .into_iter()
        .filter(|&i| within(&summaries[i], base, tolerance, criterion))
        .min_by(|&a, &b| {
            summaries[a]
                .fraction
                .highest()
                .total_cmp(&summaries[b].fraction.highest())
        })
}

/// Chance recall@n: the mean, over queries with a match, of the probability
/// that n of `map_images` drawn at random hold one of the query's matches.
pub fn chance_recall(truth: &[HashSet<u32>], map_images: usize, n: usize) -> f64 {
    let per_query: Vec<f64> = truth
        .iter()
        .filter(|t| !t.is_empty())
        .map(|t| {
            let (m, k) = (map_images as f64, t.len() as f64);
            // P(no match among n draws without replacement)
            let miss: f64 = (0..n.min(map_images))
                .map(|i| ((m - k - i as f64) / (m - i as f64)).max(0.0))
                .product();
            1.0 - miss
        })
        .collect();
    metrics::mean(&per_query)
}

/// The cheapest setting within `tolerance` of the baseline on both recalls
/// of [`Criterion::Precision90`] on every seed; `Err` says why there is none
/// (no full search in the sweep, or the full search near chance).
pub fn recommend(
    summaries: &[SettingSummary],
    tolerance: f64,
    chance_at_1: f64,
) -> Result<Recommendation, String> {
    let base_index = summaries
        .iter()
        .position(|s| s.setting.rule.name == BASELINE)
        .ok_or("the full search was not run")?;
    let base = &summaries[base_index];
    let floor = chance_at_1 + MIN_ABOVE_CHANCE;
    if base.recall_at_1.lowest() < floor {
        return Err(format!(
            "the full search's recall@1 ({:.1} % on its worst seed) is within {:.0} points of \
             chance ({:.1} %): no setting is worth recommending on this map",
            100.0 * base.recall_at_1.lowest(),
            100.0 * MIN_ABOVE_CHANCE,
            100.0 * chance_at_1
        ));
    }
    let criterion = Criterion::Precision90;
    let index = cheapest_within(summaries, 0..summaries.len(), base, tolerance, criterion)
        .unwrap_or(base_index);
    let s = &summaries[index];
    Ok(Recommendation {
        index,
        label: s.label.clone(),
        tolerance,
        fraction: s.fraction.mean,
        worst_fraction: s.fraction.highest(),
        recall90_top5: s.recall90_at(5).mean,
        recall_at_1: s.recall_at_1.mean,
        baseline_recall90_top5: base.recall90_at(5).mean,
        baseline_recall_at_1: base.recall_at_1.mean,
        worst_loss: worst_loss(s, base, criterion),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(rule: &str, p: Option<f64>, r90: f64, r1: f64, fraction: f64) -> SettingSummary {
        SettingSummary::hand_made(rule, p, 0, r90, r1, fraction)
    }

    #[test]
    fn picks_the_cheapest_setting_within_tolerance() {
        let s = vec![
            summary("none", None, 0.80, 0.90, 1.0),
            summary("fixed", Some(0.3), 0.60, 0.85, 0.3),
            summary("peak-mean", Some(0.1), 0.79, 0.89, 0.5),
            summary("peak-mean", Some(0.2), 0.785, 0.90, 0.6),
            summary("relative", Some(1.0), 0.81, 0.87, 0.4),
        ];
        let r = recommend(&s, 0.02, 0.0).unwrap();
        assert_eq!(r.index, 2);
        assert_eq!(r.baseline_recall90_top5, 0.80);
        // Stricter: only settings at least as good as the baseline.
        assert_eq!(recommend(&s, 0.0, 0.0).unwrap().index, 0);
        // Looser: the relative rule's recall@1 now passes too.
        assert_eq!(recommend(&s, 0.03, 0.0).unwrap().index, 4);
        assert!(recommend(&s[1..], 0.5, 0.0).is_err());
    }

    /// Two vocabulary seeds: a setting within tolerance on average but not
    /// on one seed is not recommended.
    #[test]
    fn the_worst_seed_decides() {
        let mut base = summary("none", None, 0.80, 0.90, 1.0);
        base.recall90[1].per_seed = vec![0.80, 0.80];
        base.recall_at_1.per_seed = vec![0.90, 0.90];
        let mut shaky = summary("peak-mean", Some(0.1), 0.79, 0.90, 0.4);
        // mean loss 1 point, but 5 points on the second seed
        shaky.recall90[1].per_seed = vec![0.83, 0.75];
        shaky.recall_at_1.per_seed = vec![0.90, 0.90];
        shaky.fraction.per_seed = vec![0.4, 0.4];
        let mut steady = summary("peak-mean", Some(0.2), 0.79, 0.90, 0.6);
        steady.recall90[1].per_seed = vec![0.79, 0.79];
        steady.recall_at_1.per_seed = vec![0.90, 0.89];
        steady.fraction.per_seed = vec![0.5, 0.7];
        let s = vec![base, shaky, steady];
        assert!(!within(&s[1], &s[0], 0.02, Criterion::Precision90));
        let r = recommend(&s, 0.02, 0.0).unwrap();
        assert_eq!(r.index, 2);
        assert_eq!(r.worst_fraction, 0.7);
        assert!((r.worst_loss[0] - 0.01).abs() < 1e-12);
        // The plain-recall criterion reads recall@1 and recall@5.
        assert!(within(&s[1], &s[0], 0.0, Criterion::PlainRecall));
    }

    #[test]
    fn degenerate_points_and_chance_level_full_search_are_refused() {
        let mut s = vec![
            summary("none", None, 0.80, 0.90, 1.0),
            summary("peak-mean", Some(1e-9), 0.80, 0.90, 0.6),
        ];
        assert_eq!(recommend(&s, 0.02, 0.0).unwrap().index, 1);
        s[1].setting.degenerate = Some("at the search bound".into());
        assert_eq!(recommend(&s, 0.02, 0.0).unwrap().index, 0);
        // full search at 0.9 with chance at 0.85: refused, saying why
        let why = recommend(&s, 0.02, 0.85).unwrap_err();
        assert!(why.contains("chance"), "{why}");
    }

    #[test]
    fn chance_recall_counts_matches_among_random_draws() {
        let truth: Vec<HashSet<u32>> = vec![[0, 1].into(), [2].into(), HashSet::new()];
        // 10 images: 2/10 and 1/10 at n = 1
        assert!((chance_recall(&truth, 10, 1) - 0.15).abs() < 1e-12);
        // n = 2: 1 − (8/10)(7/9) and 2/10
        let expect = ((1.0 - 0.8 * 7.0 / 9.0) + 0.2) / 2.0;
        assert!((chance_recall(&truth, 10, 2) - expect).abs() < 1e-12);
        assert_eq!(chance_recall(&truth, 2, 5), 1.0);
    }
}

//! Choosing a server default from the sweep: among the settings that lose at
//! most `tolerance` (absolute) of the full search's recall at 90 % precision
//! (top 5) and of its recall@1, averaged over runs, the one that uses the
//! fewest features. The full search itself when none qualifies. The
//! criterion ([`within`]) is also what [`super::equal_recall`] reads each
//! rule at.

use super::summary::SettingSummary;
use super::sweep::BASELINE;
use serde::Serialize;

/// The chosen setting and why.
#[derive(Debug, Clone, Serialize)]
pub struct Recommendation {
    /// Index into the summaries.
    pub index: usize,
    pub label: String,
    pub tolerance: f64,
    pub fraction: f64,
    pub recall90_top5: f64,
    pub recall_at_1: f64,
    pub baseline_recall90_top5: f64,
    pub baseline_recall_at_1: f64,
}

/// Whether `s` loses at most `tolerance` (absolute) of `base`'s recall at
/// 90 % precision (top 5) and of its recall@1.
pub fn within(s: &SettingSummary, base: &SettingSummary, tolerance: f64) -> bool {
    s.recall90_at(5).mean >= base.recall90_at(5).mean - tolerance - 1e-12
        && s.recall_at_1.mean >= base.recall_at_1.mean - tolerance - 1e-12
}

/// Among `candidates` (indices into `summaries`), the one using the fewest
/// features that is [`within`] `tolerance` of `base`; the first on ties.
pub fn cheapest_within(
    summaries: &[SettingSummary],
    candidates: impl IntoIterator<Item = usize>,
    base: &SettingSummary,
    tolerance: f64,
) -> Option<usize> {
    candidates
        .into_iter()
        .filter(|&i| within(&summaries[i], base, tolerance))
        .min_by(|&a, &b| {
            summaries[a]
                .fraction
                .mean
                .total_cmp(&summaries[b].fraction.mean)
        })
}

/// The cheapest setting within `tolerance` of the baseline on both recalls,
/// or `None` without a baseline.
pub fn recommend(summaries: &[SettingSummary], tolerance: f64) -> Option<Recommendation> {
    let base_index = summaries
        .iter()
        .position(|s| s.setting.rule.name == BASELINE)?;
    let base = &summaries[base_index];
    let index =
        cheapest_within(summaries, 0..summaries.len(), base, tolerance).unwrap_or(base_index);
    let s = &summaries[index];
    Some(Recommendation {
        index,
        label: s.label.clone(),
        tolerance,
        fraction: s.fraction.mean,
        recall90_top5: s.recall90_at(5).mean,
        recall_at_1: s.recall_at_1.mean,
        baseline_recall90_top5: base.recall90_at(5).mean,
        baseline_recall_at_1: base.recall_at_1.mean,
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
        let r = recommend(&s, 0.02).unwrap();
        assert_eq!(r.index, 2);
        assert_eq!(r.baseline_recall90_top5, 0.80);
        // Stricter: only settings at least as good as the baseline.
        assert_eq!(recommend(&s, 0.0).unwrap().index, 0);
        // Looser: the relative rule's recall@1 now passes too.
        assert_eq!(recommend(&s, 0.03).unwrap().index, 4);
        assert!(recommend(&s[1..], 0.5).is_none());
    }
}

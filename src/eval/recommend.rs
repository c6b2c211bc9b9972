//! Choosing a server default from the sweep: among the settings that lose at
//! most `tolerance` (absolute) of the full search's recall at 90 % precision
//! (top 5) and of its recall@1, averaged over runs, the one that uses the
//! fewest features. The full search itself when none qualifies.

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

/// The cheapest setting within `tolerance` of the baseline on both recalls,
/// or `None` without a baseline.
pub fn recommend(summaries: &[SettingSummary], tolerance: f64) -> Option<Recommendation> {
    let base_index = summaries
        .iter()
        .position(|s| s.setting.rule.name == BASELINE)?;
    let base = &summaries[base_index];
    let (r90, r1) = (base.recall90_at(5).mean, base.recall_at_1.mean);
    let within = |s: &SettingSummary| {
        s.recall90_at(5).mean >= r90 - tolerance - 1e-12
            && s.recall_at_1.mean >= r1 - tolerance - 1e-12
    };
    let index = summaries
        .iter()
        .enumerate()
        .filter(|(_, s)| within(s))
        .min_by(|(_, a), (_, b)| a.fraction.mean.total_cmp(&b.fraction.mean))
        .map_or(base_index, |(i, _)| i);
    let s = &summaries[index];
    Some(Recommendation {
        index,
        label: s.label.clone(),
        tolerance,
        fraction: s.fraction.mean,
        recall90_top5: s.recall90_at(5).mean,
        recall_at_1: s.recall_at_1.mean,
        baseline_recall90_top5: r90,
        baseline_recall_at_1: r1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::summary::Stat;
    use crate::eval::sweep::Setting;
    use crate::eval::timing::StageTimes;
    use crate::search::RuleSpec;

    fn summary(rule: &str, p: Option<f64>, r90: f64, r1: f64, fraction: f64) -> SettingSummary {
        let setting = Setting {
            rule: RuleSpec::new(rule, p).unwrap(),
            min_features: 0,
            target: None,
        };
        let stat = |mean| Stat { mean, std: 0.0 };
        SettingSummary {
            label: setting.label(),
            setting,
            recall90: [stat(r90); 3],
            recall_at_1: stat(r1),
            recall_at_5: stat(r1),
            fraction: stat(fraction),
            time_ms: StageTimes::default(),
            runs: vec![],
        }
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

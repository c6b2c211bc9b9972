//! Features needed at equal recall: for every rule and warm-up, the fewest
//! features (the worst vocabulary seed's mean fraction over queries and
//! runs) among the settings the sweep evaluated whose two recalls of a
//! [`Criterion`] — recall top-5 @90%P and recall@1, or plain recall@1 and
//! recall@5 — are both at most a tolerance below the full search's on every
//! seed: the recommender's test ([`recommend::within`]) applied to one rule
//! at a time, degenerate grid points left out. The resolution is that of the
//! grids: no value between two settings is interpolated. A rule none of
//! whose settings qualifies has no entry at that tolerance.

use super::recommend::{self, Criterion};
use super::summary::SettingSummary;
use super::sweep::BASELINE;
use serde::Serialize;

/// The strict tolerance: half a point of recall.
pub const STRICT_TOLERANCE: f64 = 0.005;
/// The tolerance of the plain-recall table: one point.
pub const PLAIN_TOLERANCE: f64 = 0.01;

/// The setting a rule needs at one tolerance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cheapest {
    /// Index into the summaries.
    pub index: usize,
    pub label: String,
    /// Mean fraction of features it used, over seeds.
    pub fraction: f64,
    /// The fraction of its worst seed (the one it is chosen by).
    pub worst_fraction: f64,
}

/// One rule at one warm-up.
#[derive(Debug, Clone, Serialize)]
pub struct RuleRow {
    pub rule: String,
    pub min_features: usize,
    /// Settings of this rule and warm-up that were evaluated.
    pub settings: usize,
    /// Of those, degenerate grid points (left out).
    pub degenerate: usize,
    /// For each of [`EqualRecall::tolerances`], the cheapest setting within it.
    pub cheapest: Vec<Option<Cheapest>>,
}

/// The whole table.
#[derive(Debug, Clone, Serialize)]
pub struct EqualRecall {
    pub criterion: Criterion,
    /// Allowed loss of each recall (absolute), ascending.
    pub tolerances: Vec<f64>,
    /// The full search's two figures of the criterion (means over seeds).
    pub baseline: [f64; 2],
    /// In the order of `rules` given, warm-ups ascending within a rule.
    pub rows: Vec<RuleRow>,
}

/// The tolerances of the table: the strict one and the recommender's.
pub fn tolerances(recommender: f64) -> Vec<f64> {
    let mut t = vec![STRICT_TOLERANCE, recommender];
    t.sort_by(f64::total_cmp);
    t.dedup();
    t
}

/// The table for `rules` (each at every warm-up it was evaluated at), or
/// `None` without the full search among the summaries.
pub fn equal_recall(
    summaries: &[SettingSummary],
    rules: &[String],
    tolerances: &[f64],
    criterion: Criterion,
) -> Option<EqualRecall> {
    let base = summaries.iter().find(|s| s.setting.rule.name == BASELINE)?;
    let mut rows = Vec::new();
    for rule in rules {
        let mut warmups: Vec<usize> = summaries
            .iter()
            .filter(|s| s.setting.rule.name == *rule)
            .map(|s| s.setting.min_features)
            .collect();
        warmups.sort_unstable();
        warmups.dedup();
        for w in warmups {
            let group: Vec<usize> = (0..summaries.len())
                .filter(|&i| {
                    let s = &summaries[i].setting;
                    s.rule.name == *rule && s.min_features == w
                })
                .collect();
            let cheapest = tolerances
                .iter()
                .map(|&t| {
                    recommend::cheapest_within(summaries, group.iter().copied(), base, t, criterion)
                        .map(|index| Cheapest {
                            index,
                            label: summaries[index].label.clone(),
                            fraction: summaries[index].fraction.mean,
                            worst_fraction: summaries[index].fraction.highest(),
                        })
                })
                .collect();
            rows.push(RuleRow {
                rule: rule.clone(),
                min_features: w,
                settings: group.len(),
                degenerate: group
                    .iter()
                    .filter(|&&i| summaries[i].setting.degenerate.is_some())
                    .count(),
                cheapest,
            });
        }
    }
    Some(EqualRecall {
        criterion,
        tolerances: tolerances.to_vec(),
        baseline: criterion.figures(base).map(|f| f.mean),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(rule: &str, p: Option<f64>, w: usize, r90: f64, r1: f64, f: f64) -> SettingSummary {
        SettingSummary::hand_made(rule, p, w, r90, r1, f)
    }

    /// Cheapest fraction of `row` at each tolerance.
    fn fractions(row: &RuleRow) -> Vec<Option<f64>> {
        row.cheapest
            .iter()
            .map(|c| c.as_ref().map(|c| c.fraction))
            .collect()
    }

    fn rules(names: &[&str]) -> Vec<String> {
        names.iter().map(|n| (*n).to_owned()).collect()
    }

    #[test]
    fn each_rule_gets_its_cheapest_setting_at_each_tolerance() {
        let summaries = vec![
            s("peak-mean", Some(0.1), 0, 0.70, 0.85, 0.3),
            s("none", None, 0, 0.80, 0.90, 1.0),
            // 1 point lower on top-5: only the loose tolerance admits it
            s("peak-mean", Some(0.2), 0, 0.79, 0.90, 0.4),
            // 0.3 points lower on both: admitted by both
            s("peak-mean", Some(0.3), 0, 0.797, 0.897, 0.6),
            s("peak-mean", Some(0.4), 0, 0.80, 0.90, 0.8),
            // a warm-up variant: its own row; recall@1 3 points down at 0.5
            s("peak-mean", Some(0.05), 20, 0.80, 0.87, 0.5),
            s("peak-mean", Some(0.1), 20, 0.785, 0.89, 0.7),
            // never within either tolerance
            s("relative", Some(2.0), 0, 0.10, 0.60, 0.5),
            s("relative", Some(9.0), 0, 0.77, 0.90, 0.9),
            // never saves a feature, recall equal
            s("hoeffding", Some(0.5), 0, 0.80, 0.90, 1.0),
            s("hoeffding", Some(0.1), 0, 0.80, 0.90, 1.0),
        ];
        let t = tolerances(0.02);
        assert_eq!(t, [0.005, 0.02]);
        let e = equal_recall(
            &summaries,
            &rules(&["none", "peak-mean", "relative", "stable-peak", "hoeffding"]),
            &t,
            Criterion::Precision90,
        )
        .unwrap();
        assert_eq!(e.baseline, [0.80, 0.90]);
        let keys: Vec<(&str, usize, usize)> = e
            .rows
            .iter()
            .map(|r| (r.rule.as_str(), r.min_features, r.settings))
            .collect();
        // rules in the order asked, warm-ups ascending, unevaluated rules left out
        assert_eq!(
            keys,
            [
                ("none", 0, 1),
                ("peak-mean", 0, 4),
                ("peak-mean", 20, 2),
                ("relative", 0, 2),
                ("hoeffding", 0, 2),
            ]
        );
        assert_eq!(fractions(&e.rows[0]), [Some(1.0), Some(1.0)]);
        assert_eq!(fractions(&e.rows[1]), [Some(0.6), Some(0.4)]);
        assert_eq!(e.rows[1].cheapest[0].as_ref().unwrap().index, 3);
        assert_eq!(fractions(&e.rows[2]), [None, Some(0.7)]);
        assert_eq!(
            e.rows[2].cheapest[1].as_ref().unwrap().label,
            "peak-mean 0.1 w=20"
        );
        assert_eq!(fractions(&e.rows[3]), [None, None]);
        assert_eq!(fractions(&e.rows[4]), [Some(1.0), Some(1.0)]);
    }

    #[test]
    fn needs_the_full_search_and_merges_equal_tolerances() {
        let summaries = vec![s("fixed", Some(0.5), 0, 0.8, 0.9, 0.5)];
        assert!(
            equal_recall(
                &summaries,
                &rules(&["fixed"]),
                &[0.02],
                Criterion::Precision90
            )
            .is_none()
        );
        assert_eq!(tolerances(STRICT_TOLERANCE), [STRICT_TOLERANCE]);
        assert_eq!(tolerances(0.001), [0.001, STRICT_TOLERANCE]);
    }

    #[test]
    fn degenerate_points_are_counted_and_left_out() {
        let mut summaries = vec![
            s("none", None, 0, 0.80, 0.90, 1.0),
            s("relative", Some(1e-6), 100, 0.80, 0.90, 0.7),
            s("relative", Some(3.0), 100, 0.80, 0.90, 0.8),
        ];
        summaries[1].setting.degenerate = Some("at the search bound 1e-6".into());
        for criterion in [Criterion::Precision90, Criterion::PlainRecall] {
            let e = equal_recall(&summaries, &rules(&["relative"]), &[0.01], criterion).unwrap();
            assert_eq!((e.rows[0].settings, e.rows[0].degenerate), (2, 1));
            assert_eq!(e.rows[0].cheapest[0].as_ref().unwrap().index, 2);
        }
    }
}

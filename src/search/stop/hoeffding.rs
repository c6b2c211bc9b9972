//! Rule `hoeffding` (δ): per-feature votes scaled to [0, 1] by the largest
//! possible vote; stop when the gap between the two best empirical means
//! reaches √(2·ln(2/δ)/t), Hoeffding's bound on two means of t samples each.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "hoeffding",
    parameter: Some(Parameter {
        name: "delta",
        meaning: "δ, the chance of stopping on a leader that would lose",
        range: Range::Open01,
        example: 0.05,
    }),
    grid: Grid::Values(&[0.5, 0.25, 0.1, 0.05, 0.01]),
    about: "stop when the top-2 gap of mean votes ≥ √(2·ln(2/δ)/t)",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |d, _| Ok(Box::new(Hoeffding(d))),
};

struct Hoeffding(f64);

impl StopRule for Hoeffding {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (gap, bound) = self.statistic(voter)?;
        (gap >= bound).then(|| format!("mean gap {gap:.4} ≥ Hoeffding bound {bound:.4}"))
    }

    /// The top-2 gap of mean votes (scaled to [0, 1]) and the bound.
    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let t = voter.tally();
        if t.features == 0 || t.vote_cap <= 0.0 {
            return None;
        }
        let n = t.features as f64;
        let gap = (t.max - t.second) as f64 / (n * t.vote_cap as f64);
        Some((gap, (2.0 * (2.0 / self.0).ln() / n).sqrt()))
    }
}

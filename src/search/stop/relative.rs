//! Rule 2 (`relative`): stop when (max(h) − mean(h)) / mean(h) > T.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "relative",
    parameter: Some(Parameter {
        name: "threshold",
        meaning: "T, the lead of the peak over the mean vote relative to the mean",
        range: Range::NonNegative,
        example: 2.5,
    }),
    grid: Grid::Calibrated {
        lo: 1e-6,
        hi: 1e6,
        whole: false,
    },
    about: "rule 2: stop when (max(h) − mean(h)) / mean(h) > T",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |t, _| Ok(Box::new(Relative(t))),
};

struct Relative(f64);

impl StopRule for Relative {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (ratio, threshold) = self.statistic(voter)?;
        (ratio > threshold).then(|| format!("(max − mean)/mean = {ratio:.4} > {threshold}"))
    }

    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let t = voter.tally();
        let mean = t.mean();
        (mean > 0.0).then(|| ((t.max as f64 - mean) / mean, self.0))
    }
}

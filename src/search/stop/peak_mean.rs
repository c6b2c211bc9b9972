//! Rule 1 (`peak-mean`): stop when max(h) − mean(h) > T.
//!
//! The paper's h is divided by the query's feature count N; bowloc's is not
//! (N is unknown while tiles remain), so T measures accumulated evidence: the
//! same T asks the same lead of a 100-feature and of a 2000-feature query. A
//! paper threshold T′ corresponds to T = T′·N.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "peak-mean",
    parameter: Some(Parameter {
        name: "threshold",
        meaning: "T, the lead of the peak over the mean vote (votes summed, not divided by N)",
        range: Range::NonNegative,
        example: 8.0,
    }),
    grid: Grid::Calibrated {
        lo: 1e-3,
        hi: 1e4,
        whole: false,
    },
    about: "rule 1: stop when max(h) − mean(h) > T",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |t, _| Ok(Box::new(PeakMean(t))),
};

struct PeakMean(f64);

impl StopRule for PeakMean {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (gap, threshold) = self.statistic(voter)?;
        (gap > threshold).then(|| format!("max − mean = {gap:.4} > {threshold}"))
    }

    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let t = voter.tally();
        Some((t.max as f64 - t.mean(), self.0))
    }
}

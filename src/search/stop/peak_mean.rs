//! Rule 1 (`peak-mean`): stop when max(h) − mean(h) > T.

use super::{RuleInfo, StopRule, non_negative};
use crate::search::vote::Voter;

pub const INFO: RuleInfo = RuleInfo {
    name: "peak-mean",
    parameter: Some("threshold"),
    about: "rule 1: stop when max(h) − mean(h) > T",
    make: |t, _| Ok(Box::new(PeakMean(non_negative("threshold", t)?))),
};

struct PeakMean(f64);

impl StopRule for PeakMean {
    fn check(&mut self, voter: &Voter<'_>) -> Option<String> {
        let t = voter.tally();
        let gap = t.max as f64 - t.mean();
        (gap > self.0).then(|| format!("max − mean = {gap:.4} > {}", self.0))
    }
}

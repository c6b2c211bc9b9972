//! Rule 3 (`stable-peak`): stop when the peak of h has not changed for T
//! consecutive features.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "stable-peak",
    parameter: Some(Parameter {
        name: "threshold",
        meaning: "T, the features the peak must hold the lead",
        range: Range::Count,
        example: 150.0,
    }),
    grid: Grid::Calibrated {
        lo: 1.0,
        hi: 1e5,
        whole: true,
    },
    about: "rule 3: stop when the peak has not changed for T features",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |t, _| {
        Ok(Box::new(StablePeak {
            needed: t as usize,
            leader: None,
            since: 0,
        }))
    },
};

struct StablePeak {
    needed: usize,
    leader: Option<u32>,
    /// Feature count at which the current leader took the lead.
    since: usize,
}

impl StopRule for StablePeak {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let t = voter.tally();
        if t.leader != self.leader {
            self.leader = t.leader;
            self.since = t.features;
        }
        let held = t.features - self.since;
        (self.leader.is_some() && held >= self.needed)
            .then(|| format!("peak unchanged for {held} features"))
    }

    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        self.leader?;
        let held = voter.tally().features.saturating_sub(self.since);
        Some((held as f64, self.needed as f64))
    }
}

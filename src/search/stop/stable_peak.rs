//! Rule 3 (`stable-peak`): stop when the peak of h has not changed for T
//! consecutive features.

use super::{RuleInfo, StopRule, non_negative};
use crate::search::vote::Voter;

pub const INFO: RuleInfo = RuleInfo {
    name: "stable-peak",
    parameter: Some("threshold"),
    about: "rule 3: stop when the peak has not changed for T features",
    geometric: false,
    make: |t, _| {
        let t = non_negative("threshold", t)?;
        if t.fract() != 0.0 {
            return Err(format!(
                "threshold of stable-peak counts features: a whole number, got {t}"
            ));
        }
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
    fn check(&mut self, voter: &Voter<'_>) -> Option<String> {
        let t = voter.tally();
        if t.leader != self.leader {
            self.leader = t.leader;
            self.since = t.features;
        }
        let held = t.features - self.since;
        (self.leader.is_some() && held >= self.needed)
            .then(|| format!("peak unchanged for {held} features"))
    }
}

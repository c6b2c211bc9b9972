//! Rule `fixed` (f): stop after a fixed fraction f of the features — the
//! naive baseline every adaptive rule must beat. While the query's feature
//! count N is unknown (tiles left to extract) the fraction is of its estimate.

use super::{RuleInfo, StopRule, unit_interval};
use crate::search::vote::Voter;

pub const INFO: RuleInfo = RuleInfo {
    name: "fixed",
    parameter: Some("fraction"),
    about: "stop after a fixed fraction f of the features",
    geometric: false,
    make: |f, _| Ok(Box::new(Fixed(unit_interval("fraction", f, true)?))),
};

struct Fixed(f64);

impl StopRule for Fixed {
    fn check(&mut self, voter: &Voter<'_>) -> Option<String> {
        let t = voter.tally();
        let needed = (self.0 * t.total_or_estimate()).ceil() as usize;
        (t.features >= needed.max(1)).then(|| format!("fixed fraction {} reached", self.0))
    }
}

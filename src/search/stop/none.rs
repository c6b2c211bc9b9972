//! Rule `none`: never stop early (full bag-of-words).

use super::{Grid, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "none",
    parameter: None,
    grid: Grid::Single,
    about: "full bag-of-words: quantize every feature",
    stops_early: false,
    geometric: false,
    whole_histogram: false,
    make: |_, _| Ok(Box::new(NoStop)),
};

struct NoStop;

impl StopRule for NoStop {
    fn check(&mut self, _: &dyn VoteStats) -> Option<String> {
        None
    }
}

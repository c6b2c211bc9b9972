//! Rule `fixed` (f): stop after a fixed fraction f of the features — the
//! naive baseline every adaptive rule must beat. While the query's feature
//! count N is unknown (tiles left to extract) the fraction is of its estimate.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::VoteStats;

pub const INFO: RuleInfo = RuleInfo {
    name: "fixed",
    parameter: Some(Parameter {
        name: "fraction",
        meaning: "f, the share of the query's features to use",
        range: Range::Fraction,
        example: 0.5,
    }),
    grid: Grid::Values(&[0.3, 0.5, 0.7]),
    about: "stop after a fixed fraction f of the features",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |f, _| Ok(Box::new(Fixed(f))),
};

struct Fixed(f64);

impl StopRule for Fixed {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (used, needed) = self.statistic(voter)?;
        (used >= needed).then(|| format!("fixed fraction {} reached", self.0))
    }

    /// Features voted and the features the fraction asks for.
    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let t = voter.tally();
        let needed = (self.0 * t.total_or_estimate()).ceil().max(1.0);
        Some((t.features as f64, needed))
    }
}

//! Rule `place-lead` (T): stop when the leader's votes exceed those of the
//! best image outside its place by more than T: h(j*) − h(k*) > T, with k*
//! the best-voted image farther than the place window from j* along the
//! map's order (the same comparison as a candidate's distinctness,
//! [`crate::search::rank::elsewhere`]).
//!
//! Rule 1 compares the peak with the mean of the whole map, which a few
//! strong neighbours hardly move; the runner-up of a top-2 gap (`hoeffding`)
//! is usually the leader's own neighbour, an image of the same place, so
//! that gap says little. This rule asks what decides an answer: how far the
//! leader's place leads every other place. Votes are summed, not divided by
//! N, so like `peak-mean`'s, T measures evidence and means the same for a
//! small and a large query.

use super::{Grid, Parameter, Range, RuleContext, RuleInfo, StopRule};
use crate::search::rank::elsewhere;
use crate::search::vote::{Needs, VoteStats};

pub const INFO: RuleInfo = RuleInfo {
    name: "place-lead",
    parameter: Some(Parameter {
        name: "threshold",
        meaning: "T, the lead of the peak over the best image outside its place (votes summed, not divided by N)",
        range: Range::NonNegative,
        example: 1.0,
    }),
    grid: Grid::Calibrated {
        lo: 1e-3,
        hi: 1e4,
        whole: false,
    },
    about: "stop when h(leader) − h(best image outside the leader's place) > T",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |t, ctx: &RuleContext| {
        Ok(Box::new(PlaceLead {
            threshold: t,
            window: ctx.place_window,
        }))
    },
};

struct PlaceLead {
    threshold: f64,
    window: u32,
}

impl StopRule for PlaceLead {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (lead, threshold) = self.statistic(voter)?;
        (lead > threshold)
            .then(|| format!("lead over the best other place = {lead:.4} > {threshold}"))
    }

    /// Enough leaders that one of them lies outside the leader's place.
    fn needs(&self) -> Needs {
        Needs {
            top: 2 * self.window as usize + 2,
            ..Needs::default()
        }
    }

    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let top = voter.top();
        let &(h, j) = top.first()?;
        Some(((h - elsewhere(j, top, self.window)) as f64, self.threshold))
    }
}

//! Rule `posterior` (ε): stop when the posterior probability of the leader's
//! place (the leader and the images within the prior's window of it along
//! the map's order; the leader alone without one) given the search's prior
//! and the votes so far reaches 1 − ε
//! ([`crate::search::prior`]: p(j | votes) ∝ prior(j)·exp(κ·h(j)/√t)).
//!
//! With a sequence's prior, a frame that confirms the predicted place starts
//! with most of the mass on it and stops after few features; a frame whose
//! votes disagree with the prediction must first outweigh it, so it runs
//! longer. Without a prior the prior is uniform (κ
//! [`DEFAULT_KAPPA`](crate::search::prior::DEFAULT_KAPPA)) and the rule reads
//! the votes alone. The posterior costs the tracked images plus the images
//! with votes, so it is computed once every [`CHECK_EVERY`] features: the
//! stop comes at most that many features late. It needs the whole
//! histogram, so on a sharded map it never stops (the full search).

use super::{Grid, Parameter, Range, RuleContext, RuleInfo, StopRule};
use crate::search::prior::{DEFAULT_KAPPA, Prior, leader};
use crate::search::vote::VoteStats;
use std::sync::Arc;

pub const INFO: RuleInfo = RuleInfo {
    name: "posterior",
    parameter: Some(Parameter {
        name: "epsilon",
        meaning: "ε, the posterior probability left to places other than the leader's",
        range: Range::Open01,
        example: 0.7,
    }),
    grid: Grid::Values(&[0.7, 0.5, 0.1]),
    about: "stop when the posterior of the leader's place given the prior (a sequence's prediction, else uniform) and the votes is ≥ 1 − ε",
    stops_early: true,
    geometric: false,
    whole_histogram: true,
    make: |e, ctx: &RuleContext| {
        Ok(Box::new(PosteriorRule {
            epsilon: e,
            prior: ctx.prior.clone(),
            next: 0,
        }))
    },
};

/// Features between two computations of the posterior.
pub const CHECK_EVERY: usize = 8;

struct PosteriorRule {
    epsilon: f64,
    prior: Option<Arc<Prior>>,
    next: usize,
}

impl StopRule for PosteriorRule {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let t = voter.tally().features;
        if t < self.next {
            return None;
        }
        self.next = t + CHECK_EVERY;
        // a view without the whole histogram (a sharded search) never stops
        let (hist, touched) = voter.histogram_and_touched()?;
        let images = hist.len();
        let prior = self
            .prior
            .get_or_insert_with(|| Arc::new(Prior::uniform(images, DEFAULT_KAPPA)));
        let (j, p) = leader(prior, hist, touched, t)?;
        (p >= 1.0 - self.epsilon).then(|| {
            format!(
                "posterior of image {j}'s place = {p:.4} ≥ 1 − {}",
                self.epsilon
            )
        })
    }
}

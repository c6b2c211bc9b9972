//! Rule `place-z` (z): stop when the leader's lead over the best image
//! outside its place is more than z standard errors:
//! (h(j*) − h(k*)) / √(Σv(j*)² + Σv(k*)²) > z, with k* as in `place-lead`
//! and Σv² the sum of an image's squared per-feature votes.
//!
//! The lead after t features is a sum of t per-feature differences
//! v_i(j*) − v_i(k*); Σv(j*)² + Σv(k*)² bounds the sum of their squares
//! (votes are non-negative), so the ratio is the lead in units of its own
//! spread, a self-normalised statistic: it does not change when every vote
//! is scaled (the map's idf, its size, the Hamming weights), and a query
//! with few features must lead by more per feature to reach the same z as
//! one with many. So the same z asks about the same confidence of any map
//! and any query, which a threshold on summed votes (`place-lead`,
//! `peak-mean`) cannot. It needs no N. The spread assumes the features come
//! in a random order; a tile's or a coarse pass's features are not a random
//! sample of the image, and a stop on the coarse pass alone is bolder than
//! z says (docs/results.md, "The learned plan").

use super::{Grid, Parameter, Range, RuleContext, RuleInfo, StopRule};
use crate::search::rank::best_elsewhere;
use crate::search::vote::{Needs, VoteStats};

pub const INFO: RuleInfo = RuleInfo {
    name: "place-z",
    parameter: Some(Parameter {
        name: "threshold",
        meaning: "z, the lead over the best image outside the leader's place in units of its spread √(Σv_leader² + Σv_other²)",
        range: Range::NonNegative,
        example: 2.0,
    }),
    grid: Grid::Calibrated {
        lo: 1e-3,
        hi: 1e3,
        whole: false,
    },
    about: "stop when (h(leader) − h(best image outside its place)) / √(Σv_leader² + Σv_other²) > z",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |z, ctx: &RuleContext| {
        Ok(Box::new(PlaceZ {
            z,
            window: ctx.place_window,
        }))
    },
};

struct PlaceZ {
    z: f64,
    window: u32,
}

impl StopRule for PlaceZ {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let (z, threshold) = self.statistic(voter)?;
        (z > threshold).then(|| {
            format!("lead over the best other place = {z:.3} standard errors > {threshold}")
        })
    }

    /// Enough leaders that one of them lies outside the leader's place,
    /// with their sums of squares.
    fn needs(&self) -> Needs {
        Needs {
            top: 2 * self.window as usize + 2,
            squares: true,
            ..Needs::default()
        }
    }

    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let top = voter.top();
        let &(h, j) = top.first()?;
        let (h_k, q_k) = best_elsewhere(j, top, self.window)
            .map_or((0.0, 0.0), |(h_k, k)| (h_k, voter.squares_of(k)));
        let spread = (voter.squares_of(j) as f64 + q_k as f64).sqrt();
        if spread <= 0.0 {
            return None;
        }
        Some(((h - h_k) as f64 / spread, self.z))
    }
}

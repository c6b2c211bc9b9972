//! Rule `lossless`: stop only when the features not yet voted can no longer
//! change the top-n answer, so the ranking is identical to full bag-of-words
//! by construction.
//!
//! It needs the number of features left, so it can only fire once the query's
//! feature count N is known (with tiled extraction: after the last tile).
//!
//! One more feature adds at most cap_j = max_w idf(w)·d̂_j(w) to h(j), so
//! with R features left h(j) can still grow by at most R·cap_j and never
//! shrinks. With the current leaders a_1 … a_n (best first), the answer is
//! final once
//!
//! - h(a_i) > h(a_{i+1}) + R·cap(a_{i+1}) for i < n (the order cannot change), and
//! - h(a_n) > h(j) + R·cap_j for every other image j (none can enter).
//!
//! The second test first uses the largest h outside the top n with the
//! largest cap of the whole map (one comparison). Only when that fails while
//! the gap is still positive are the images with votes scanned with their
//! own caps, and at most once every [`SCAN_EVERY`] features.

use super::{Grid, RuleContext, RuleInfo, StopRule};
use crate::search::vote::{Needs, VoteStats};

pub const INFO: RuleInfo = RuleInfo {
    name: "lossless",
    parameter: None,
    grid: Grid::Single,
    about: "stop when the remaining features cannot change the top-n answer",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |_, ctx: &RuleContext| {
        Ok(Box::new(Lossless {
            n: ctx.top_n.max(1),
            next_scan: 0,
        }))
    },
};

/// Features between two exact scans over the images with votes.
const SCAN_EVERY: usize = 8;
/// Relative slack for float rounding in the accumulated votes.
const SLACK: f32 = 1e-5;

struct Lossless {
    n: usize,
    next_scan: usize,
}

impl StopRule for Lossless {
    fn needs(&self) -> Needs {
        Needs {
            top: self.n + 1,
            squares: false,
            outside: true,
        }
    }

    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let t = voter.tally();
        let left = t.remaining()? as f32;
        let top = voter.top();
        let n = self.n.min(t.images);
        if top.len() < n {
            return None;
        }
        let slack = SLACK * t.max;
        // the order inside the top n
        for pair in top[..n].windows(2) {
            let (upper, lower) = (pair[0], pair[1]);
            if upper.0 <= lower.0 + left * voter.image_vote_cap(lower.1) + slack {
                return None;
            }
        }
        if n == t.images {
            return Some("every image is ranked and their order is final".into());
        }
        // no other image can enter the top n
        let last = top[n - 1].0;
        let outside = top.get(n).map_or(0.0, |e| e.0);
        if last > outside + left * t.vote_cap + slack {
            return Some(format!(
                "top {n} final: {left} features left cannot change it"
            ));
        }
        if last <= outside + slack || t.features < self.next_scan {
            return None;
        }
        self.next_scan = t.features + SCAN_EVERY;
        // every image outside the top n with its own cap
        let best_other = voter.best_outside(n, left);
        (last > best_other + slack)
            .then(|| format!("top {n} final: {left} features left cannot change it (exact bounds)"))
    }
}

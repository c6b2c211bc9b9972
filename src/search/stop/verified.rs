//! Rule `verified` (m): stop once the leader is geometrically verified with
//! at least m inliers against the features voted so far. Votes only choose
//! which image to check; the check itself is a robust model fit between the
//! query's keypoints and the candidate's stored keypoints (done outside the
//! core, through [`LeaderCheck`]). A query whose leader never verifies runs to
//! the end of its features, like the full search: easy queries stop early,
//! hard ones lose nothing.
//!
//! A check costs far more than a vote, so the search offers one only at the
//! end of a batch (a tile of streaming extraction: stopping inside a tile
//! saves no extraction), and the leader is checked only when it has held the
//! lead for [`STABLE`] features, at most once every [`EVERY`] features; a
//! leader that failed is checked again only after [`RECHECK`] more features.

use super::{Grid, LeaderCheck, Parameter, Range, RuleInfo, StopRule, VoteStats};

pub const INFO: RuleInfo = RuleInfo {
    name: "verified",
    parameter: Some(Parameter {
        name: "inliers",
        meaning: "m, the inliers that verify the leader (a homography needs 4 points)",
        range: Range::Whole { min: 4, max: 1000 },
        example: 12.0,
    }),
    grid: Grid::Values(&[8.0, 12.0, 16.0, 24.0]),
    about: "stop when the leader is geometrically verified with at least m inliers",
    geometric: true,
    whole_histogram: false,
    make: |m, _| {
        Ok(Box::new(Verified {
            min_inliers: m as usize,
            leader: None,
            next_check: 0,
            inliers: None,
        }))
    },
};

/// Features the leader must have held the lead before it is checked.
pub const STABLE: usize = 16;
/// Features between two checks.
pub const EVERY: usize = 32;
/// Features before a leader that failed is checked again.
pub const RECHECK: usize = 64;

struct Verified {
    min_inliers: usize,
    leader: Option<u32>,
    /// Feature count from which the leader may be checked.
    next_check: usize,
    /// Inliers of the leader's last check (none since it took the lead).
    inliers: Option<usize>,
}

impl StopRule for Verified {
    fn check(&mut self, _: &dyn VoteStats) -> Option<String> {
        None
    }

    fn check_with(
        &mut self,
        voter: &dyn VoteStats,
        voted: &[(u32, u32)],
        leader_check: Option<&mut dyn LeaderCheck>,
    ) -> Option<String> {
        let t = voter.tally();
        if t.leader != self.leader {
            self.leader = t.leader;
            self.next_check = t.features + STABLE;
            self.inliers = None;
        }
        let leader = self.leader?;
        let checker = leader_check?;
        if t.features < self.next_check {
            return None;
        }
        let inliers = checker.inliers(leader, voted);
        self.inliers = Some(inliers);
        if inliers >= self.min_inliers {
            return Some(format!(
                "leader {leader} verified: {inliers} inliers ≥ {}",
                self.min_inliers
            ));
        }
        self.next_check = t.features + if inliers > 0 { EVERY } else { RECHECK };
        None
    }

    /// The leader's inliers at its last check, against m.
    fn statistic(&self, _: &dyn VoteStats) -> Option<(f64, f64)> {
        self.inliers.map(|i| (i as f64, self.min_inliers as f64))
    }
}

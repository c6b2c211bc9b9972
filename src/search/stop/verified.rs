//! Rule `verified` (m): stop once the leader is geometrically verified with
//! at least m inliers against the features voted so far. Votes only choose
//! which image to check; the check itself is a robust model fit between the
//! query's keypoints and the candidate's stored keypoints (done outside the
//! core, through [`LeaderCheck`]). A query whose leader never verifies runs to
//! the end of its features, like the full search: easy queries stop early,
//! hard ones lose nothing.
//!
//! A check costs far more than a vote, so the search offers one only at the
//! end of a block of features. The rule takes every check offered at the end
//! of a batch (a tile of streaming extraction): a tile's extraction costs
//! more than a check, so a leader left unchecked there would cost a whole
//! tile more. Inside a tile, where stopping saves quantization and votes but
//! no extraction, it checks on a geometric schedule: once the features voted
//! have grown by [`GROWTH`] since the last check, so a query is checked
//! O(log N) times. A leader is not checked twice on the same votes.

use super::{Grid, LeaderCheck, Parameter, Range, RuleInfo, StopRule, VoteStats};
use crate::search::Voted;

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
    stops_early: true,
    geometric: true,
    whole_histogram: false,
    make: |m, _| {
        Ok(Box::new(Verified {
            min_inliers: m as usize,
            checked: None,
            inliers: None,
        }))
    },
};

/// Inside a batch, the features voted must have grown by this factor since
/// the last check for another.
pub const GROWTH: f64 = 1.5;

struct Verified {
    min_inliers: usize,
    /// The leader and the feature count of the last check.
    checked: Option<(u32, usize)>,
    /// Inliers of the last check.
    inliers: Option<usize>,
}

impl StopRule for Verified {
    fn check(&mut self, _: &dyn VoteStats) -> Option<String> {
        None
    }

    fn check_with(
        &mut self,
        voter: &dyn VoteStats,
        voted: &[Voted],
        leader_check: Option<&mut dyn LeaderCheck>,
        batch_end: bool,
    ) -> Option<String> {
        let t = voter.tally();
        let leader = t.leader?;
        let checker = leader_check?;
        if self.checked == Some((leader, t.features)) {
            return None;
        }
        if !batch_end
            && let Some((_, at)) = self.checked
            && (t.features as f64) < at as f64 * GROWTH
        {
            return None;
        }
        let inliers = checker.inliers(leader, voted);
        self.checked = Some((leader, t.features));
        self.inliers = Some(inliers);
        (inliers >= self.min_inliers).then(|| {
            format!(
                "leader {leader} verified: {inliers} inliers ≥ {}",
                self.min_inliers
            )
        })
    }

    /// A geometric rule: the coarse pass is checked as any tile.
    fn check_on_coarse(
        &mut self,
        voter: &dyn VoteStats,
        voted: &[Voted],
        leader_check: Option<&mut dyn LeaderCheck>,
        batch_end: bool,
    ) -> Option<String> {
        self.check_with(voter, voted, leader_check, batch_end)
    }

    /// The inliers of the last check, against m.
    fn statistic(&self, _: &dyn VoteStats) -> Option<(f64, f64)> {
        self.inliers.map(|i| (i as f64, self.min_inliers as f64))
    }
}

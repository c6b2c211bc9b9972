//! A vote rule that a geometric check may overtake: the search stops when
//! the vote rule fires or when its leader is verified with at least m
//! inliers against the features voted so far, whichever comes first
//! ([`RuleSpec::or_verified`](super::RuleSpec::or_verified)). The vote rule
//! stops the queries whose votes are clear; the check stops those whose
//! votes are not clear yet but whose leader already has the geometry of a
//! match. It is checked on the `verified` rule's schedule.

use super::{LeaderCheck, Needs, StopRule, VoteStats};
use crate::search::Voted;

pub struct OrVerified {
    pub votes: Box<dyn StopRule>,
    pub verified: Box<dyn StopRule>,
}

impl StopRule for OrVerified {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        self.votes.check(voter)
    }

    fn needs(&self) -> Needs {
        self.votes.needs().and(self.verified.needs())
    }

    /// The vote rule's.
    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        self.votes.statistic(voter)
    }

    fn check_with(
        &mut self,
        voter: &dyn VoteStats,
        voted: &[Voted],
        leader_check: Option<&mut dyn LeaderCheck>,
        batch_end: bool,
    ) -> Option<String> {
        self.votes.check(voter).or_else(|| {
            self.verified
                .check_with(voter, voted, leader_check, batch_end)
        })
    }
}

//! A vote rule that a geometric check may overtake: the search stops when
//! the vote rule fires or when the answer verification would give now has at
//! least m inliers and shows the scene at the query's scale, whichever comes
//! first ([`RuleSpec::or_verified`](super::RuleSpec::or_verified)). The vote
//! rule stops the queries whose votes are clear; the check stops those whose
//! votes are not clear yet but whose answer already has the geometry of a
//! match taken from where the query was.
//!
//! The scale matters: a map image taken a few steps before or after the query
//! shares its geometry too (the scene smaller or larger in it), and such near
//! misses are most of a route's wrong answers. An answer whose inliers show
//! the scene at the query's scale, within the verification's `stop_log_scale`
//! ([`MAX_LOG_SCALE`](super::MAX_LOG_SCALE) by default), is one taken
//! where the query was.
//!
//! Stopping saves time only where it saves extraction, so the check runs at
//! the end of each tile of a streamed query but the last (a check re-ranks
//! the candidates the search returns, as the final verification does: up to
//! its `verify.top_k` model fits, about half a millisecond each); a search
//! with no tile left, or extracted whole, has the vote rule alone.

use super::{Needs, Progress, StopRule, VoteStats, check_answer};

pub struct OrVerified {
    pub votes: Box<dyn StopRule>,
    pub min_inliers: usize,
    /// The candidates handed to the check: the search's top n
    /// ([`RuleContext::top_n`](super::RuleContext::top_n)), which a
    /// verifying search sets to at least its `verify.top_k`.
    pub candidates: usize,
}

impl StopRule for OrVerified {
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        self.votes.check(voter)
    }

    fn needs(&self) -> Needs {
        self.votes.needs().and(Needs {
            top: self.candidates,
            ..Needs::default()
        })
    }

    /// The vote rule's.
    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        self.votes.statistic(voter)
    }

    /// The vote rule's check, unless on a coarse pass; then, at the end of
    /// a tile with tiles left (N not known yet), the geometric check.
    fn check_with(&mut self, voter: &dyn VoteStats, progress: Progress<'_>) -> Option<String> {
        if !progress.coarse
            && let Some(why) = self.votes.check(voter)
        {
            return Some(why);
        }
        if !progress.batch_end || voter.tally().total.is_some() {
            return None;
        }
        check_answer(voter, progress, self.candidates, self.min_inliers)?.why
    }
}

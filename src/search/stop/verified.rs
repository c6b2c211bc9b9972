//! Rule `verified` (m): stop once the answer verification would give now is
//! geometrically verified with at least m inliers against the features voted
//! so far, and its inliers show the scene at the query's scale
//! ([`CheckedAnswer::verified_at_scale`](super::CheckedAnswer::verified_at_scale)). Votes only choose which images to
//! check: the search's top candidates, verified and re-ranked as the final
//! answer is, through a robust model fit between the query's keypoints and
//! each candidate's stored keypoints (done outside the core, through
//! [`LeaderCheck`]). A query whose answer never verifies runs to the end of
//! its features, like the full search: easy queries stop early, hard ones
//! lose nothing.
//!
//! The scale is the check [`or_verified`](super::or_verified) makes too: a
//! map image a few steps before or after the query shares its geometry, and
//! stopping on such a near miss loses the answer taken where the query was
//! (docs/results.md, "The verified stop at the query's scale").
//!
//! A check costs far more than a vote, so the search offers one only at the
//! end of a block of features. The rule takes every check offered at the end
//! of a batch (a tile of streaming extraction): a tile's extraction costs
//! more than a check, so an answer left unchecked there would cost a whole
//! tile more. Inside a tile, where stopping saves quantization and votes but
//! no extraction, it checks on a geometric schedule: once the features voted
//! have grown by [`GROWTH`] since the last check, so a query is checked
//! O(log N) times. The same votes are not checked twice.

use super::{Grid, Needs, Parameter, Progress, Range, RuleInfo, StopRule, VoteStats, check_answer};

pub const INFO: RuleInfo = RuleInfo {
    name: "verified",
    parameter: Some(Parameter {
        name: "inliers",
        meaning: "m, the inliers that verify the answer (and always more than the pairs the model's fit takes, which agree with it by construction)",
        range: Range::Whole { min: 4, max: 1000 },
        example: 12.0,
    }),
    grid: Grid::Values(&[8.0, 12.0, 16.0, 24.0]),
    about: "stop when the answer is geometrically verified with at least m inliers at the query's scale",
    stops_early: true,
    geometric: true,
    whole_histogram: false,
    make: |m, context| {
        Ok(Box::new(Verified {
            min_inliers: m as usize,
            candidates: context.top_n.max(1),
            checked_at: None,
            last: None,
        }))
    },
};

/// Inside a batch, the features voted must have grown by this factor since
/// the last check for another.
pub const GROWTH: f64 = 1.5;

struct Verified {
    min_inliers: usize,
    candidates: usize,
    /// The features voted at the last check.
    checked_at: Option<usize>,
    /// Inliers of the last check, and the inliers it needed to stop.
    last: Option<(usize, usize)>,
}

impl StopRule for Verified {
    fn needs(&self) -> Needs {
        Needs {
            top: self.candidates,
            ..Needs::default()
        }
    }

    fn check(&mut self, _: &dyn VoteStats) -> Option<String> {
        None
    }

    /// The coarse pass is checked as any tile.
    fn check_with(&mut self, voter: &dyn VoteStats, progress: Progress<'_>) -> Option<String> {
        let features = voter.tally().features;
        if let Some(at) = self.checked_at
            && (features == at || !progress.batch_end && (features as f64) < at as f64 * GROWTH)
        {
            return None;
        }
        let check = check_answer(voter, progress, self.candidates, self.min_inliers)?;
        self.checked_at = Some(features);
        self.last = Some((check.inliers, check.needed));
        check.why
    }

    /// The inliers of the last check, against those it needed (m, or more
    /// than the model's fit takes).
    fn statistic(&self, _: &dyn VoteStats) -> Option<(f64, f64)> {
        self.last.map(|(i, needed)| (i as f64, needed as f64))
    }
}

//! The geometric side of a stop: the check a search offers its rule
//! ([`LeaderCheck`], implemented outside the core, where the model fit is
//! OpenCV's), the answer it gives ([`CheckedAnswer`]) and the stop that
//! `verified` and a vote rule's `or_verified` both make from it.

use super::Progress;
use crate::search::Voted;
use crate::search::vote::VoteStats;

/// A geometric check against the query features voted so far. Implemented
/// outside the core (the model fit is OpenCV's).
pub trait LeaderCheck {
    /// The answer verification would give now: `candidates` (id, votes;
    /// best first) verified and re-ranked as the final answer is, with
    /// `min_inliers` (the stop's m) as the floor of a verified candidate if
    /// it is above the verification's own, so that the answer checked is
    /// one that can stop the search; and its first. `None` without
    /// candidates.
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[Voted],
        min_inliers: usize,
    ) -> Option<CheckedAnswer>;

    /// Largest |ln scale| of an answer at the query's scale
    /// ([`CheckedAnswer::verified_at_scale`]): the verification's settings
    /// say it, [`MAX_LOG_SCALE`] unless they do.
    fn max_log_scale(&self) -> f32 {
        MAX_LOG_SCALE
    }

    /// Pairs the model's fit takes: any that many agree with the model
    /// fitted to them, so only inliers beyond them are evidence, and a stop
    /// asks for at least one more whatever its m (0: no such floor).
    fn fit_needs(&self) -> usize {
        0
    }
}

/// The first answer of a [`LeaderCheck::answer`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedAnswer {
    pub id: u32,
    /// Its inliers (0 when it was not verified).
    pub inliers: usize,
    /// The scale its inliers show the scene at in the map image against the
    /// query (1: the same; `None` with too few inliers to tell).
    pub scale: Option<f32>,
}

/// The default largest |ln scale| of an answer taken where the query was:
/// its inliers spread at most e^0.2 ≈ 1.22 times more (or less) in the map
/// image than in the query. Chosen on gardens-point with
/// `scripts/tile-ends.sh` for `or_verified` (docs/results.md, "A verified
/// stop beside the rule"); the verification's `stop_log_scale` setting.
pub const MAX_LOG_SCALE: f32 = 0.2;

impl CheckedAnswer {
    /// Verified with at least `min_inliers` inliers that show the scene at
    /// the query's scale (|ln scale| at most `max_log_scale`): an answer
    /// taken where the query was, not a few steps before or after it.
    pub fn verified_at_scale(&self, min_inliers: usize, max_log_scale: f32) -> bool {
        self.inliers >= min_inliers
            && self
                .scale
                .is_some_and(|s| s > 0.0 && s.ln().abs() <= max_log_scale)
    }
}

/// What a geometric stop's check found.
pub(super) struct GeometricCheck {
    /// The answer's inliers.
    pub(super) inliers: usize,
    /// The inliers it needed to stop: m, or more than the model's fit takes.
    pub(super) needed: usize,
    /// Why the search stops, when the answer is verified.
    pub(super) why: Option<String>,
}

/// The geometric stop both `verified` and a vote rule's `or_verified` make:
/// the voter's top `candidates` handed to the check the search offers,
/// which verifies and re-ranks them as the final answer is. `None` without
/// a check or candidates; else the answer's inliers, those it needed (at
/// least `min_inliers`, and more than [`LeaderCheck::fit_needs`]) and, when
/// it has them at the query's scale, why the search stops.
pub(super) fn check_answer(
    voter: &dyn VoteStats,
    progress: Progress<'_>,
    candidates: usize,
    min_inliers: usize,
) -> Option<GeometricCheck> {
    let checker = progress.leader_check?;
    let top: Vec<(u32, f32)> = voter
        .top()
        .iter()
        .take(candidates)
        .map(|&(h, id)| (id, h))
        .collect();
    let needed = min_inliers.max(checker.fit_needs() + 1);
    let answer = checker.answer(&top, progress.voted, needed)?;
    let why = answer
        .verified_at_scale(needed, checker.max_log_scale())
        .then(|| {
            format!(
                "answer {} verified at the query's scale: {} inliers ≥ {needed}, scale {:.2}",
                answer.id,
                answer.inliers,
                answer.scale.unwrap_or(0.0)
            )
        });
    Some(GeometricCheck {
        inliers: answer.inliers,
        needed,
        why,
    })
}

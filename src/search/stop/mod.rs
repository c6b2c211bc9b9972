//! Stopping rules: after every vote, a rule looks at the histogram's running
//! statistics and may declare the winner clear. Each rule is one type in its
//! own file plus one line in the registry ([`RULES`], `registry.rs`); a
//! caller's choice of rule is validated against it (`spec.rs`), and the
//! geometric stops share one check (`geometric.rs`). The rest of the
//! pipeline only knows the [`StopRule`] trait and [`RuleSpec`].

mod confident;
mod fixed;
mod geometric;
mod hoeffding;
mod lossless;
mod none;
mod or_verified;
mod peak_mean;
mod place_lead;
mod place_z;
mod posterior;
mod registry;
mod relative;
mod spec;
mod stable_peak;
mod verified;

pub use geometric::{CheckedAnswer, LeaderCheck, MAX_LOG_SCALE};
pub use registry::{
    GENERIC_PARAMETER, Grid, MakeRule, OR_VERIFIED, Parameter, RULES, Range, RuleInfo,
    parameter_names, rule_info, rule_names, rules_markdown,
};
pub use spec::{RuleError, RuleSpec, parse_rule};

use super::Voted;
use super::prior::Prior;
use super::vote::{Needs, VoteStats};
use geometric::check_answer;
use std::sync::Arc;

/// A rule instance for one query.
pub trait StopRule: Send {
    /// Called after each feature's vote; `Some(why)` stops the search.
    fn check(&mut self, voter: &dyn VoteStats) -> Option<String>;

    /// What the voter must track for this rule.
    fn needs(&self) -> Needs {
        Needs::default()
    }

    /// The number the rule compares with a threshold, and that threshold,
    /// as of the last check (for traces of the vote race); `None` for a rule
    /// that compares no single number.
    fn statistic(&self, voter: &dyn VoteStats) -> Option<(f64, f64)> {
        let _ = voter;
        None
    }

    /// [`check`](Self::check) with what a geometric rule needs besides the
    /// votes: where the search stands ([`Progress`]). A vote rule reads the
    /// votes alone, and does not stop a search on a coarse pass.
    fn check_with(&mut self, voter: &dyn VoteStats, progress: Progress<'_>) -> Option<String> {
        if progress.coarse {
            None
        } else {
            self.check(voter)
        }
    }
}

/// Where a search stands when it asks its rule, besides the votes.
pub struct Progress<'a> {
    /// Every feature voted so far, in voting order.
    pub voted: &'a [Voted],
    /// A way to check candidates against them geometrically, offered only
    /// at the end of a block of features (a check costs far more than a
    /// vote).
    pub leader_check: Option<&'a mut dyn LeaderCheck>,
    /// Whether this vote ends a batch: the last of a tile, after which the
    /// next tile must be extracted.
    pub batch_end: bool,
    /// Whether the batch is the coarse pass of a streamed query (the whole
    /// frame at half size, extracted first). Its features are the image's
    /// coarser scales, not a random sample of the image, so a vote
    /// statistic on them claims more than it knows: only a geometric check
    /// may stop there.
    pub coarse: bool,
}

impl<'a> Progress<'a> {
    /// Outside a coarse pass: the features `voted`, the check offered (at
    /// a block's end) and whether the batch ends.
    pub fn new(
        voted: &'a [Voted],
        leader_check: Option<&'a mut dyn LeaderCheck>,
        batch_end: bool,
    ) -> Self {
        Self {
            voted,
            leader_check,
            batch_end,
            coarse: false,
        }
    }
}

/// What a rule may know about the search it runs in.
#[derive(Debug, Clone)]
pub struct RuleContext {
    /// Candidates the search returns.
    pub top_n: usize,
    /// The search's prior over map images (a sequence's prediction, a pose
    /// restriction), if it has one.
    pub prior: Option<Arc<Prior>>,
    /// The images on each side of an image, along the map's order, that
    /// belong to its place ([`crate::search::SearchOptions::place_window`]).
    pub place_window: u32,
}

impl Default for RuleContext {
    fn default() -> Self {
        Self {
            top_n: 1,
            prior: None,
            place_window: crate::search::SearchOptions::PLACE_WINDOW,
        }
    }
}

#[cfg(test)]
mod tests;

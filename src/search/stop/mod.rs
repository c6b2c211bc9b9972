//! Stopping rules: after every vote, a rule looks at the histogram's running
//! statistics and may declare the winner clear. Each rule is one type in its
//! own file plus one line in [`RULES`]; the rest of the pipeline only knows
//! the [`StopRule`] trait and [`RuleSpec`].

mod confident;
mod fixed;
mod hoeffding;
mod lossless;
mod none;
mod or_verified;
mod peak_mean;
mod place_lead;
mod place_z;
mod posterior;
mod relative;
mod stable_peak;
mod verified;

use super::Voted;
use super::prior::Prior;
use super::vote::{Needs, VoteStats};
use serde::{Deserialize, Serialize};
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

/// A geometric check against the query features voted so far. Implemented
/// outside the core (the model fit is OpenCV's).
pub trait LeaderCheck {
    /// How many of them are inliers of a model relating map image `image`
    /// to the query.
    fn inliers(&mut self, image: u32, voted: &[Voted]) -> usize;

    /// The answer verification would give now: `candidates` (id, votes;
    /// best first) verified and re-ranked as the final answer is, and its
    /// first. `None` without candidates.
    fn answer(&mut self, candidates: &[(u32, f32)], voted: &[Voted]) -> Option<CheckedAnswer>;

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
struct GeometricCheck {
    /// The answer's inliers.
    inliers: usize,
    /// The inliers it needed to stop: m, or more than the model's fit takes.
    needed: usize,
    /// Why the search stops, when the answer is verified.
    why: Option<String>,
}

/// The geometric stop both `verified` and a vote rule's `or_verified` make:
/// the voter's top `candidates` handed to the check the search offers,
/// which verifies and re-ranks them as the final answer is. `None` without
/// a check or candidates; else the answer's inliers, those it needed (at
/// least `min_inliers`, and more than [`LeaderCheck::fit_needs`]) and, when
/// it has them at the query's scale, why the search stops.
fn check_answer(
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
    let answer = checker.answer(&top, progress.voted)?;
    let needed = min_inliers.max(checker.fit_needs() + 1);
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

/// Builds a rule instance from its parameter, or says why the value is refused.
pub type MakeRule = fn(f64, &RuleContext) -> Result<Box<dyn StopRule>, String>;

/// The values a parameter accepts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    /// A finite number ≥ 0.
    NonNegative,
    /// A whole number ≥ 0.
    Count,
    /// A whole number in `min..=max`.
    Whole { min: u32, max: u32 },
    /// A number in (0, 1).
    Open01,
    /// A number in (0, 1].
    Fraction,
}

impl Range {
    /// `v` if it lies in the range, else why not.
    pub fn check(self, name: &str, v: f64) -> Result<f64, String> {
        let ok = v.is_finite()
            && match self {
                Self::NonNegative => v >= 0.0,
                Self::Count => v >= 0.0 && v.fract() == 0.0,
                Self::Whole { min, max } => v >= min as f64 && v <= max as f64 && v.fract() == 0.0,
                Self::Open01 => v > 0.0 && v < 1.0,
                Self::Fraction => v > 0.0 && v <= 1.0,
            };
        if ok {
            Ok(v)
        } else {
            Err(format!("{name} must be {}, got {v}", self.describe()))
        }
    }

    /// The range in words, for messages and help.
    pub fn describe(self) -> String {
        match self {
            Self::NonNegative => "a finite number ≥ 0".into(),
            Self::Count => "a whole number ≥ 0".into(),
            Self::Whole { min, max } => format!("a whole number in {min}..={max}"),
            Self::Open01 => "a number in (0, 1)".into(),
            Self::Fraction => "a number in (0, 1]".into(),
        }
    }

    /// Smallest value and whether it is excluded, largest value (if any)
    /// and whether it is excluded: the range as an API document states it.
    pub fn bounds(self) -> (f64, bool, Option<f64>, bool) {
        match self {
            Self::NonNegative | Self::Count => (0.0, false, None, false),
            Self::Whole { min, max } => (min as f64, false, Some(max as f64), false),
            Self::Open01 => (0.0, true, Some(1.0), true),
            Self::Fraction => (0.0, true, Some(1.0), false),
        }
    }
}

/// A rule's one parameter.
#[derive(Debug, Clone, Copy)]
pub struct Parameter {
    /// Its name in the CLI (`--NAME`), the API (`NAME=`) and the docs.
    pub name: &'static str,
    /// What it means.
    pub meaning: &'static str,
    pub range: Range,
    /// A typical value, for help texts and examples.
    pub example: f64,
}

/// How the evaluation sweeps a rule's parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Grid {
    /// No parameter: one setting.
    Single,
    /// These values.
    Values(&'static [f64]),
    /// Values found by bisection in `[lo, hi]` so the mean fraction of
    /// features used hits the evaluation's targets (`whole`: whole numbers).
    Calibrated { lo: f64, hi: f64, whole: bool },
}

/// A rule's entry in the registry: everything each surface (CLI, config,
/// HTTP, API document, protobuf, evaluation, calibration, docs) knows of it.
pub struct RuleInfo {
    /// Name used in the CLI, the API and the config.
    pub name: &'static str,
    /// Its parameter, if it takes one.
    pub parameter: Option<Parameter>,
    /// One line for help texts.
    pub about: &'static str,
    /// How the evaluation sweeps it.
    pub grid: Grid,
    /// Whether the rule can end a search before its last feature (`none`
    /// cannot: a query searched with it is best extracted whole, since tiles
    /// only pay for themselves when the search may stop).
    pub stops_early: bool,
    /// Whether the rule verifies candidates geometrically (it needs a
    /// [`LeaderCheck`], and its answers are re-ranked by verification).
    pub geometric: bool,
    /// Whether the rule reads every image's votes (with the search's
    /// prior), which the shards of a sharded map do not send.
    pub whole_histogram: bool,
    /// Build an instance from a parameter value within its range.
    pub make: MakeRule,
}

impl RuleInfo {
    /// Whether a sharded map runs the rule as one machine does
    /// ([`crate::search::shard`]): neither a geometric check nor the whole
    /// histogram.
    pub fn shardable(&self) -> bool {
        !self.geometric && !self.whole_histogram
    }
}

/// The name every rule's parameter also answers to (`threshold=` in the API
/// and the config, `--threshold` in the CLI).
pub const GENERIC_PARAMETER: &str = "threshold";

/// The name of a vote rule's verified stop (`or_verified=` in the API and
/// the config, `--or-verified` in the CLI; [`RuleSpec::or_verified`]).
pub const OR_VERIFIED: &str = "or_verified";

/// The rule table of the docs, generated from the registry (`bowloc rules`).
pub fn rules_markdown() -> String {
    let mut out = String::from(
        "| rule | parameter | accepted values | example | stops when |\n| --- | --- | --- | --- | --- |\n",
    );
    for r in RULES {
        let (p, range, example) = match &r.parameter {
            Some(p) => (
                format!("`{}`: {}", p.name, p.meaning),
                p.range.describe(),
                format!("{}", p.example),
            ),
            None => ("–".into(), "–".into(), "–".into()),
        };
        out += &format!(
            "| `{}` | {p} | {range} | {example} | {} |\n",
            r.name, r.about
        );
    }
    out
}

/// Every rule bowloc knows.
pub const RULES: &[RuleInfo] = &[
    none::INFO,
    peak_mean::INFO,
    place_lead::INFO,
    place_z::INFO,
    relative::INFO,
    stable_peak::INFO,
    hoeffding::INFO,
    fixed::INFO,
    lossless::INFO,
    confident::INFO,
    verified::INFO,
    posterior::INFO,
];

/// Look a rule up by name.
pub fn rule_info(name: &str) -> Option<&'static RuleInfo> {
    RULES.iter().find(|r| r.name == name)
}

/// All rule names, for error messages and help.
pub fn rule_names() -> Vec<&'static str> {
    RULES.iter().map(|r| r.name).collect()
}

/// A rule with its parameter, validated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RuleSpec {
    pub name: String,
    /// The rule's parameter (ignored by rules that take none).
    #[serde(default)]
    pub parameter: f64,
    /// Also stop when the answer is verified with this many inliers at the
    /// query's scale ([`RuleSpec::or_verified`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub or_verified: Option<u32>,
}

impl RuleSpec {
    /// Validate `name` and `parameter` by building the rule once.
    pub fn new(name: &str, parameter: Option<f64>) -> Result<Self, String> {
        let info = rule_info(name).ok_or_else(|| {
            format!(
                "unknown rule `{name}`; known rules: {}",
                rule_names().join(", ")
            )
        })?;
        let parameter = match (&info.parameter, parameter) {
            (None, None) => 0.0,
            (None, Some(_)) => return Err(format!("rule `{name}` takes no parameter")),
            (Some(p), None) => {
                return Err(format!(
                    "rule `{name}` needs its {} ({})",
                    p.name, p.meaning
                ));
            }
            (Some(p), Some(v)) => p.range.check(p.name, v)?,
        };
        (info.make)(parameter, &RuleContext::default())?;
        Ok(Self {
            name: info.name.to_owned(),
            parameter,
            or_verified: None,
        })
    }

    /// The rule, which also stops at a tile's end (tiles left) once the
    /// answer verification would give then has at least `inliers` inliers
    /// against the features voted so far and shows the scene at the query's
    /// scale (`or_verified.rs`); with `None`, the rule as it is; with 0,
    /// the rule without such a check. Refused for a rule that cannot stop early (`none`: use `verified`
    /// itself) and for a geometric one.
    pub fn or_verified(self, inliers: Option<f64>) -> Result<Self, String> {
        let Some(inliers) = inliers else {
            return Ok(self);
        };
        if inliers == 0.0 {
            return Ok(Self {
                or_verified: None,
                ..self
            });
        }
        let info = self.info();
        if !info.stops_early || info.geometric {
            return Err(format!(
                "rule `{}` cannot be combined with a verified stop{}",
                self.name,
                if info.geometric {
                    ": it verifies already"
                } else {
                    "; use rule `verified`"
                }
            ));
        }
        let range = verified::INFO.parameter.expect("verified takes m").range;
        let m = range.check(OR_VERIFIED, inliers)?;
        Ok(Self {
            or_verified: Some(m as u32),
            ..self
        })
    }

    pub fn info(&self) -> &'static RuleInfo {
        rule_info(&self.name).expect("validated on construction")
    }

    /// Whether the search verifies candidates geometrically: a geometric
    /// rule, or a vote rule with a verified stop.
    pub fn geometric(&self) -> bool {
        self.info().geometric || self.or_verified.is_some()
    }

    /// Whether a sharded map runs it as one machine does.
    pub fn shardable(&self) -> bool {
        self.info().shardable() && self.or_verified.is_none()
    }

    /// A fresh instance for one query.
    pub fn build(&self, context: &RuleContext) -> Box<dyn StopRule> {
        let rule = (self.info().make)(self.parameter, context).expect("validated on construction");
        match self.or_verified {
            None => rule,
            Some(m) => Box::new(or_verified::OrVerified {
                votes: rule,
                min_inliers: m as usize,
                candidates: context.top_n.max(1),
            }),
        }
    }

    /// Name of the parameter, if the rule takes one.
    pub fn parameter_name(&self) -> Option<&'static str> {
        self.info().parameter.as_ref().map(|p| p.name)
    }
}

impl std::fmt::Display for RuleSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.parameter_name() {
            Some(p) => write!(f, "{} ({p} {})", self.name, self.parameter)?,
            None => write!(f, "{}", self.name)?,
        }
        match self.or_verified {
            Some(m) => write!(f, " or verified at scale (inliers {m})"),
            None => Ok(()),
        }
    }
}

/// A rule's parameter given by name: the rule's own name for it or
/// [`GENERIC_PARAMETER`]. Refuses a parameter the rule does not take, a name
/// that belongs to another rule, and more than one value. Used by every
/// front end (CLI flags, query strings), so they accept the same things.
pub fn parse_rule(name: &str, given: &[(&str, f64)]) -> Result<RuleSpec, RuleError> {
    let info = rule_info(name).ok_or_else(|| RuleError {
        parameter: None,
        message: format!(
            "unknown rule `{name}`; known rules: {}",
            rule_names().join(", ")
        ),
    })?;
    if given.len() > 1 {
        let names: Vec<&str> = given.iter().map(|g| g.0).collect();
        return Err(RuleError {
            parameter: Some(given[1].0.to_owned()),
            message: format!("give one parameter, not {}", names.join(" and ")),
        });
    }
    let value = match (given.first(), &info.parameter) {
        (None, _) => None,
        (Some(&(what, _)), None) => {
            return Err(RuleError {
                parameter: Some(what.to_owned()),
                message: format!("rule `{name}` takes no parameter"),
            });
        }
        (Some(&(what, v)), Some(p)) => {
            if what != p.name && what != GENERIC_PARAMETER {
                return Err(RuleError {
                    parameter: Some(what.to_owned()),
                    message: format!("rule `{name}` takes `{}`, not `{what}`", p.name),
                });
            }
            Some(v)
        }
    };
    RuleSpec::new(name, value).map_err(|message| RuleError {
        parameter: Some(
            given
                .first()
                .map_or_else(|| "rule".to_owned(), |g| g.0.to_owned()),
        ),
        message,
    })
}

/// Why a rule and its parameter were refused, and which parameter it was.
#[derive(Debug, Clone, PartialEq)]
pub struct RuleError {
    /// The parameter at fault (`None`: the rule's name).
    pub parameter: Option<String>,
    pub message: String,
}

impl std::fmt::Display for RuleError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// Every distinct parameter name of the registry, the generic one first.
pub fn parameter_names() -> Vec<&'static str> {
    let mut names = vec![GENERIC_PARAMETER];
    for r in RULES {
        if let Some(p) = &r.parameter
            && !names.contains(&p.name)
        {
            names.push(p.name);
        }
    }
    names
}

#[cfg(test)]
mod tests;

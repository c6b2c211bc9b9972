//! Stopping rules: after every vote, a rule looks at the histogram's running
//! statistics and may declare the winner clear. Each rule is one type in its
//! own file plus one line in [`RULES`]; the rest of the pipeline only knows
//! the [`StopRule`] trait and [`RuleSpec`].

mod confident;
mod fixed;
mod hoeffding;
mod lossless;
mod none;
mod peak_mean;
mod relative;
mod stable_peak;
mod verified;

use super::vote::{Needs, Voter};
use serde::{Deserialize, Serialize};

/// A rule instance for one query.
pub trait StopRule: Send {
    /// Called after each feature's vote; `Some(why)` stops the search.
    fn check(&mut self, voter: &Voter<'_>) -> Option<String>;

    /// What the voter must track for this rule.
    fn needs(&self) -> Needs {
        Needs::default()
    }

    /// [`check`](Self::check) with what a geometric rule needs besides the
    /// votes: the (feature, word) pairs voted so far and a way to check a
    /// candidate against them. Vote rules ignore both.
    fn check_with(
        &mut self,
        voter: &Voter<'_>,
        voted: &[(u32, u32)],
        leader_check: Option<&mut dyn LeaderCheck>,
    ) -> Option<String> {
        let _ = (voted, leader_check);
        self.check(voter)
    }
}

/// A geometric check of a map image against the query features voted so
/// far, given as (feature number, word) pairs: how many of them are inliers
/// of a model relating the two images. Implemented outside the core (the
/// model fit is OpenCV's).
pub trait LeaderCheck {
    fn inliers(&mut self, image: u32, voted: &[(u32, u32)]) -> usize;
}

/// What a rule may know about the search it runs in.
#[derive(Debug, Clone, Copy)]
pub struct RuleContext {
    /// Candidates the search returns.
    pub top_n: usize,
}

impl Default for RuleContext {
    fn default() -> Self {
        Self { top_n: 1 }
    }
}

/// Builds a rule instance from its parameter, or says why the value is refused.
pub type MakeRule = fn(f64, &RuleContext) -> Result<Box<dyn StopRule>, String>;

/// A rule's entry in the registry.
pub struct RuleInfo {
    /// Name used in the CLI, the API and the config.
    pub name: &'static str,
    /// What its single parameter is called (`threshold`, `delta`, ...).
    pub parameter: Option<&'static str>,
    /// One line for help texts.
    pub about: &'static str,
    /// Whether the rule verifies candidates geometrically (it needs a
    /// [`LeaderCheck`], and its answers are re-ranked by verification).
    pub geometric: bool,
    /// Check a parameter value and build an instance.
    pub make: MakeRule,
}

/// Every rule bowloc knows.
pub const RULES: &[RuleInfo] = &[
    none::INFO,
    peak_mean::INFO,
    relative::INFO,
    stable_peak::INFO,
    hoeffding::INFO,
    fixed::INFO,
    lossless::INFO,
    confident::INFO,
    verified::INFO,
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
        let parameter = match (info.parameter, parameter) {
            (None, _) => 0.0,
            (Some(p), None) => return Err(format!("rule `{name}` needs a {p}")),
            (Some(_), Some(v)) => v,
        };
        (info.make)(parameter, &RuleContext::default())?;
        Ok(Self {
            name: info.name.to_owned(),
            parameter,
        })
    }

    pub fn info(&self) -> &'static RuleInfo {
        rule_info(&self.name).expect("validated on construction")
    }

    /// A fresh instance for one query.
    pub fn build(&self, context: &RuleContext) -> Box<dyn StopRule> {
        (self.info().make)(self.parameter, context).expect("validated on construction")
    }

    /// Name of the parameter, if the rule takes one.
    pub fn parameter_name(&self) -> Option<&'static str> {
        self.info().parameter
    }
}

impl std::fmt::Display for RuleSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.parameter_name() {
            Some(p) => write!(f, "{} ({p} {})", self.name, self.parameter),
            None => write!(f, "{}", self.name),
        }
    }
}

/// A finite, non-negative parameter.
fn non_negative(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be a finite number ≥ 0, got {v}"))
    }
}

/// A parameter in the open interval (0, 1) (or (0, 1] when `one_ok`).
fn unit_interval(what: &str, v: f64, one_ok: bool) -> Result<f64, String> {
    if v > 0.0 && (v < 1.0 || (one_ok && v == 1.0)) {
        Ok(v)
    } else {
        let hi = if one_ok { "1]" } else { "1)" };
        Err(format!("{what} must lie in (0, {hi}, got {v}"))
    }
}

#[cfg(test)]
mod tests;

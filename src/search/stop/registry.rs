//! The one registry of stopping rules ([`RULES`]): each rule's name, its
//! parameter and the values it accepts, how the evaluation sweeps it and
//! how an instance is built. Every surface (CLI, config, HTTP, API
//! document, protobuf, evaluation, calibration, docs) reads its rules here.

use super::{
    RuleContext, StopRule, confident, fixed, hoeffding, lossless, none, peak_mean, place_lead,
    place_z, posterior, relative, stable_peak, verified,
};

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
    /// [`LeaderCheck`](super::LeaderCheck), and its answers are re-ranked by verification).
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
/// the config, `--or-verified` in the CLI; [`RuleSpec::or_verified`](super::RuleSpec::or_verified)).
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

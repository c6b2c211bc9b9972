//! A rule chosen by a caller: its name and parameter validated against the
//! registry ([`RuleSpec`], [`parse_rule`]), with a verified stop beside it
//! or not, and built into a fresh instance for each query.

use super::registry::{GENERIC_PARAMETER, OR_VERIFIED, RuleInfo, rule_info, rule_names};
use super::{RuleContext, StopRule, or_verified, verified};
use serde::{Deserialize, Serialize};

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
        let info = rule_info(name).ok_or_else(|| unknown_rule(name))?;
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
        message: unknown_rule(name),
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

/// The message for a rule name the registry does not know.
fn unknown_rule(name: &str) -> String {
    format!(
        "unknown rule `{name}`; known rules: {}",
        rule_names().join(", ")
    )
}

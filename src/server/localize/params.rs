//! The query parameters of `POST /localize`: what each one may say, its
//! checks (a clear 400 naming the parameter), and the search options they
//! ask for on top of the configured defaults.

use crate::features::TileGrid;
use crate::index::MapRead;
use crate::pipeline::Tracing;
use crate::search::stop::{GENERIC_PARAMETER, OR_VERIFIED, parse_rule};
use crate::search::{RuleSpec, SearchOptions};
use crate::server::errors::ApiError;
use serde::Deserialize;
use utoipa::IntoParams;

/// Query parameters of `POST /localize`. Each one absent takes the
/// configured default; unknown parameters are errors.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct LocalizeParams {
    /// Candidates to return, 1 to the configured `limits.max_top_n`.
    #[param(value_type = Option<u32>, minimum = 1)]
    pub top_n: Option<String>,
    /// Stopping rule (see the enumeration). Without a parameter it takes the
    /// configured one if it is the configured rule.
    #[param(value_type = Option<String>)]
    pub rule: Option<String>,
    // The rule parameters (the generic one and each registry rule's) are
    // described, with their ranges, from the registry in the API document.
    #[param(value_type = Option<f64>)]
    pub threshold: Option<String>,
    #[param(value_type = Option<f64>)]
    pub delta: Option<String>,
    #[param(value_type = Option<f64>)]
    pub fraction: Option<String>,
    #[param(value_type = Option<u32>)]
    pub inliers: Option<String>,
    #[param(value_type = Option<f64>)]
    pub epsilon: Option<String>,
    /// Also stop at a tile's end (tiles left) when the answer verification
    /// would give then has at least this many inliers against the features
    /// voted so far and shows the scene at the query's scale, whichever of
    /// the rule and this check comes first (a vote rule only). Default: the
    /// configured `search.or_verified` (12) when the request uses the
    /// configured rule, none when it names another rule or gives a
    /// parameter.
    // its range, the `verified` rule's, is set from the registry in the API
    // document
    #[param(value_type = Option<u32>)]
    pub or_verified: Option<String>,
    /// Seed of the feature permutation (0 to 2^63−1, the API document's
    /// int64). Without it each request draws its own, below 2^53 so that it
    /// survives a JSON number; the answer reports the seed used.
    #[param(value_type = Option<i64>, minimum = 0)]
    pub seed: Option<String>,
    /// Drop candidates scoring below this (≥ 0).
    #[param(value_type = Option<f32>)]
    pub min_score: Option<String>,
    /// Drop candidates whose `distinct` is below this (0 to 1; after
    /// verification, if any): 0.6 answers only when the leader stands out
    /// of the map. Default: the configured `search.min_distinct`.
    #[param(value_type = Option<f32>, minimum = 0, maximum = 1)]
    pub min_distinct: Option<String>,
    /// Features voted before the rule is first consulted (the warm-up).
    /// Defaults to the configured warm-up when the request uses the configured
    /// rule, to 0 when it names another.
    #[param(value_type = Option<u32>, minimum = 0)]
    pub min_features: Option<String>,
    /// Streaming extraction's tile grid, `COLSxROWS` or `COLSxROWS+MARGIN`
    /// (`1x1`: extract the whole image first), optionally followed by
    /// `,coarse` (a half-size pass over the whole image before the tiles).
    /// Default: the configured grid.
    #[param(value_type = Option<String>, example = "2x2+24")]
    pub tiles: Option<String>,
    /// The order the tiles are extracted in: `richest` (most FAST corners
    /// first), `spread` (the richest tile, then the farthest from those
    /// taken) or `random` (drawn from the seed). Default: the configured order.
    #[param(value_type = Option<String>, example = "richest")]
    pub tile_order: Option<String>,
    /// A time budget in milliseconds from the start of decoding (queueing
    /// and the network not counted): a streamed query's next tile is
    /// extracted only when it is expected to end within it, so the answer
    /// comes at about that time at the latest, with stop kind `budget` when
    /// the budget cut it short (the first tile is always extracted; a budget
    /// too tight for three tiles starts with the coarse pass, unless `tiles`
    /// is given; a query extracted whole is never cut). Default: the
    /// configured `search.budget_ms`, else none.
    #[param(value_type = Option<f64>, exclusive_minimum = 0, maximum = 600000, example = 30)]
    pub budget_ms: Option<String>,
    /// Verify the top vote candidates geometrically and re-rank them by
    /// inliers (`true` or `false`; default from the `[verify]` section).
    /// With verification the score is an inlier count: by default the
    /// inliers of the candidate's place (its own and its checked neighbours').
    #[param(value_type = Option<bool>)]
    pub verify: Option<String>,
    /// Let the ORB pass look first (`true` or `false`; default from
    /// `orb_pass.enabled`): ORB's words voted over the map's ORB side and
    /// the best-voted images verified; a verified one at the query's scale
    /// answers without SIFT (stop kind `orb-pass`). It runs only when the
    /// map has its ORB side, for a search that may stop early, without
    /// `sequence`, `near` or `trace`; the answer's `orb_pass` says whether it
    /// ran and answered.
    #[param(value_type = Option<bool>)]
    pub orb_pass: Option<String>,
    /// Return the vote race in `trace` (`true`): the leader's and the
    /// runner-up's votes, the mean vote and the rule's statistic against its
    /// threshold as the features arrived (at most 256 points). `full` also
    /// extracts every tile and votes every feature without a rule, to show
    /// where the full search ends and what it answers (that extra work is
    /// not in `timings_ms`). Default `false`.
    #[param(value_type = Option<String>, pattern = "^(true|false|full)$")]
    pub trace: Option<String>,
    /// Name of the sequence this frame belongs to (1 to 128 letters, digits,
    /// `-`, `_`, `.`, `:`): the service keeps a belief over map images per
    /// sequence, and the answer's `sequence` carries the filtered candidates.
    /// Without a rule, the frame uses the configured `sequence.rule`.
    #[param(value_type = Option<String>, example = "robot-1")]
    pub sequence: Option<String>,
    /// With `sequence`: the frame's index (0 to 2^63−1). A frame not after the
    /// previous one, or more than `sequence.max_gap` after it, restarts the
    /// sequence. Default: the previous frame's + 1.
    #[param(value_type = Option<i64>, minimum = 0)]
    pub frame: Option<String>,
    /// `x,y,radius`: only map images whose pose (fields x, y) lies within
    /// the radius of (x, y) may be candidates (maps with poses).
    #[param(value_type = Option<String>, example = "12.5,-3,10")]
    pub near: Option<String>,
}

/// A pose restriction: (x, y, radius).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

impl Near {
    /// The images of `map` within the radius (read in place: no list of
    /// every image's position is made); `None` when the map has no poses
    /// with fields x and y.
    pub fn images(&self, map: &dyn MapRead) -> Option<Vec<u32>> {
        let mut within = Vec::new();
        map.each_position(&mut |j, [x, y]| {
            if ((x - self.x).powi(2) + (y - self.y).powi(2)).sqrt() <= self.radius {
                within.push(j);
            }
        })
        .then_some(within)
    }
}

/// What a request may ask for within the configuration.
#[derive(Debug, Clone)]
pub struct Defaults {
    /// Everything but the seed, which each request draws.
    pub options: SearchOptions,
    pub max_top_n: usize,
}

impl LocalizeParams {
    /// Parse a raw query string (`None`: no query).
    pub fn from_query(query: Option<&str>) -> Result<Self, ApiError> {
        serde_urlencoded::from_str(query.unwrap_or(""))
            .map_err(|e| ApiError::bad_request("invalid_parameter", e.to_string()))
    }

    /// The search these parameters ask for, on top of `defaults`.
    pub fn options(&self, defaults: &Defaults) -> Result<SearchOptions, ApiError> {
        let mut o = defaults.options.clone();
        o.rule = self.rule(&defaults.options.rule)?;
        if o.rule.name != defaults.options.rule.name {
            // the configured warm-up belongs to the configured rule
            o.min_features = 0;
        }
        if let Some(v) = &self.min_features {
            // the API document's int32
            o.min_features = whole("min_features", v, i32::MAX as u64)? as usize;
        }
        if let Some(v) = &self.top_n {
            let n: usize = v.trim().parse().map_err(|_| {
                ApiError::invalid_parameter("top_n", format!("`{v}` is not a whole number"))
            })?;
            if n == 0 || n > defaults.max_top_n {
                return Err(ApiError::invalid_parameter(
                    "top_n",
                    format!("must lie in 1..={}, got {n}", defaults.max_top_n),
                ));
            }
            o.top_n = n;
        }
        o.orb_pass = flag("orb_pass", self.orb_pass.as_deref(), o.orb_pass)?;
        o.seed = match &self.seed {
            // the API document's int64
            Some(v) => whole("seed", v, i64::MAX as u64)?,
            None => crate::report::draw_seed(),
        };
        if let Some(v) = &self.tile_order {
            o.tile_order = v
                .trim()
                .parse()
                .map_err(|e: String| ApiError::invalid_parameter("tile_order", e))?;
        }
        if let Some(v) = &self.min_score {
            let s = number("min_score", v)?;
            if !(0.0..=f32::MAX as f64).contains(&s) {
                return Err(ApiError::invalid_parameter(
                    "min_score",
                    format!(
                        "must be a number ≥ 0 (at most {:e}), got `{}`",
                        f32::MAX,
                        v.trim()
                    ),
                ));
            }
            o.min_score = s as f32;
        }
        if let Some(v) = &self.min_distinct {
            o.min_distinct = SearchOptions::check_min_distinct(number("min_distinct", v)?)
                .map_err(|e| ApiError::invalid_parameter("min_distinct", e))?;
        }
        if let Some(v) = &self.budget_ms {
            let budget = crate::search::budget::check_ms(number("budget_ms", v)?)
                .map_err(|e| ApiError::invalid_parameter("budget_ms", e))?;
            o.budget = Some(budget);
        }
        Ok(o)
    }

    /// The tile grid asked for, if any.
    pub fn tiles(&self) -> Result<Option<TileGrid>, ApiError> {
        self.tiles
            .as_deref()
            .map(|v| {
                // `tiles=2x2+24` typed into a URL as is arrives as "2x2 24":
                // a query string's `+` is a space. A grid never holds a
                // space, so it is read as the `+` that was meant.
                v.trim()
                    .replace(' ', "+")
                    .parse()
                    .map_err(|e: String| ApiError::invalid_parameter("tiles", e))
            })
            .transpose()
    }

    /// The sequence named, checked.
    pub fn sequence(&self) -> Result<Option<&str>, ApiError> {
        let name = self.sequence.as_deref();
        if name.is_none() && self.frame.is_some() {
            return Err(ApiError::invalid_parameter(
                "frame",
                "a frame index needs a sequence",
            ));
        }
        name.map(|n| {
            crate::server::sequences::valid_name(n)
                .map_err(|e| ApiError::invalid_parameter("sequence", e))
        })
        .transpose()
    }

    /// The frame index given, if any.
    pub fn frame(&self) -> Result<Option<u64>, ApiError> {
        self.frame
            .as_deref()
            .map(|v| whole("frame", v, i64::MAX as u64))
            .transpose()
    }

    /// The pose restriction asked for, if any.
    pub fn near(&self) -> Result<Option<Near>, ApiError> {
        let Some(v) = &self.near else { return Ok(None) };
        let parts: Vec<&str> = v.split(',').collect();
        let [x, y, r] = parts[..] else {
            return Err(ApiError::invalid_parameter(
                "near",
                format!("`{v}` is not x,y,radius"),
            ));
        };
        let (x, y, radius) = (number("near", x)?, number("near", y)?, number("near", r)?);
        if radius < 0.0 {
            return Err(ApiError::invalid_parameter(
                "near",
                format!("the radius must be ≥ 0, got {radius}"),
            ));
        }
        Ok(Some(Near { x, y, radius }))
    }

    /// The rule parameters as given, by name: [`GENERIC_PARAMETER`] and the
    /// name of each registry rule's parameter (a test holds this list to the
    /// registry, so a rule with a new parameter needs its field here).
    fn rule_parameters(&self) -> [(&'static str, &Option<String>); 5] {
        [
            (GENERIC_PARAMETER, &self.threshold),
            ("delta", &self.delta),
            ("fraction", &self.fraction),
            ("inliers", &self.inliers),
            ("epsilon", &self.epsilon),
        ]
    }

    /// Whether the request names a rule or a rule parameter.
    pub fn names_a_rule(&self) -> bool {
        self.rule.is_some() || self.rule_parameters().iter().any(|(_, v)| v.is_some())
    }

    /// Whether to verify, on top of the configured default.
    pub fn verify(&self, default: bool) -> Result<bool, ApiError> {
        flag("verify", self.verify.as_deref(), default)
    }

    /// What to record of the vote race.
    pub fn tracing(&self) -> Result<Tracing, ApiError> {
        match self.trace.as_deref().map(str::trim) {
            None | Some("false") => Ok(Tracing::Off),
            Some("true") => Ok(Tracing::On),
            Some("full") => Ok(Tracing::Full),
            Some(v) => Err(ApiError::invalid_parameter(
                "trace",
                format!("`{v}` is not `true`, `false` or `full`"),
            )),
        }
    }

    /// The rule and its parameter, through the registry's one parser.
    fn rule(&self, default: &RuleSpec) -> Result<RuleSpec, ApiError> {
        let mut given = Vec::new();
        for (name, value) in self.rule_parameters() {
            if let Some(v) = value {
                given.push((name, number(name, v)?));
            }
        }
        let name = self.rule.as_deref().unwrap_or(&default.name);
        let rule = if given.is_empty() && name == default.name {
            default.clone()
        } else {
            parse_rule(name, &given).map_err(|e| match e.parameter {
                None => ApiError::bad_request("unknown_rule", e.message),
                Some(p) => ApiError::invalid_parameter(&p, e.message),
            })?
        };
        let inliers = self
            .or_verified
            .as_deref()
            .map(|v| number(OR_VERIFIED, v))
            .transpose()?;
        if inliers == Some(0.0) {
            // 0 turns a configured check off in the configuration and the
            // CLI; here naming the rule and its parameter does
            return Err(ApiError::invalid_parameter(
                OR_VERIFIED,
                "must be at least 4; a request that names the rule and its parameter \
                 runs without the configured check",
            ));
        }
        rule.or_verified(inliers)
            .map_err(|e| ApiError::invalid_parameter(OR_VERIFIED, e))
    }
}

/// A `true` or `false` parameter, `default` when absent.
fn flag(name: &str, value: Option<&str>, default: bool) -> Result<bool, ApiError> {
    match value.map(str::trim) {
        None => Ok(default),
        Some("true") => Ok(true),
        Some("false") => Ok(false),
        Some(v) => Err(ApiError::invalid_parameter(
            name,
            format!("`{v}` is not `true` or `false`"),
        )),
    }
}

/// A whole number in `0..=max`.
fn whole(name: &str, v: &str, max: u64) -> Result<u64, ApiError> {
    v.trim()
        .parse::<u64>()
        .ok()
        .filter(|&n| n <= max)
        .ok_or_else(|| {
            ApiError::invalid_parameter(name, format!("`{v}` is not a whole number in 0..={max}"))
        })
}

/// A finite number.
fn number(name: &str, v: &str) -> Result<f64, ApiError> {
    let x: f64 = v
        .trim()
        .parse()
        .map_err(|_| ApiError::invalid_parameter(name, format!("`{v}` is not a number")))?;
    if !x.is_finite() {
        return Err(ApiError::invalid_parameter(
            name,
            format!("must be a finite number, got `{v}`"),
        ));
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tile_margin_sent_with_an_unescaped_plus_is_read_as_meant() {
        let tiles = |q: &str| LocalizeParams::from_query(Some(q)).unwrap().tiles();
        let escaped = tiles("tiles=2x2%2B24,coarse").unwrap();
        assert_eq!(tiles("tiles=2x2+24,coarse").unwrap(), escaped);
        let grid = escaped.expect("a grid");
        assert_eq!(
            (grid.cols, grid.rows, grid.margin, grid.coarse),
            (2, 2, 24, true)
        );
        assert_eq!(tiles("tiles=3x3+16").unwrap().map(|g| g.margin), Some(16));
        let e = tiles("tiles=2x2+x").unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (400, "invalid_parameter"));
        assert!(tiles("").unwrap().is_none());
    }

    fn defaults() -> Defaults {
        Defaults {
            options: SearchOptions {
                rule: RuleSpec::new("peak-mean", Some(0.5)).unwrap(),
                ..Default::default()
            },
            max_top_n: 50,
        }
    }

    fn parse(q: &str) -> Result<SearchOptions, ApiError> {
        LocalizeParams::from_query(Some(q))?.options(&defaults())
    }

    fn code(q: &str) -> (&'static str, String) {
        let e = parse(q).unwrap_err();
        assert_eq!(e.status, 400, "{q}");
        (e.code, e.message)
    }

    #[test]
    fn near_reads_the_map_positions_added_images_included() {
        let s = crate::live::tests::posed_snapshot();
        let near = |x, y, radius| Near { x, y, radius }.images(&s).unwrap();
        assert_eq!(near(6.0, 7.0, 1.5), [2, 3]);
        assert_eq!(near(7.0, 8.0, 0.0), [3]);
        assert_eq!(near(1.0, 2.0, 0.5), [0]);
        assert!(near(100.0, 0.0, 1.0).is_empty());
        let unposed = crate::live::Snapshot::new(s.base().clone());
        let none = crate::index::MapBuilder::new(4).build("t", "v", None);
        assert!(
            Near {
                x: 0.0,
                y: 0.0,
                radius: 1.0
            }
            .images(&none)
            .is_none()
        );
        assert!(
            Near {
                x: 0.0,
                y: 0.0,
                radius: 1.0
            }
            .images(&unposed)
            .is_some()
        );
    }

    #[test]
    fn rule_parameters_are_the_registry_parameters() {
        use crate::search::stop::RULES;
        use std::collections::BTreeSet;
        let mut registry: BTreeSet<&str> = RULES
            .iter()
            .filter_map(|r| r.parameter.map(|p| p.name))
            .collect();
        registry.insert(GENERIC_PARAMETER);
        let listed: BTreeSet<&str> = LocalizeParams::default()
            .rule_parameters()
            .iter()
            .map(|(name, _)| *name)
            .collect();
        assert_eq!(listed, registry);
        // each name is the query parameter that fills its field
        for name in registry {
            let p = LocalizeParams::from_query(Some(&format!("{name}=0.5"))).unwrap();
            let given: Vec<&str> = p
                .rule_parameters()
                .iter()
                .filter(|(_, v)| v.is_some())
                .map(|(n, _)| *n)
                .collect();
            assert_eq!(given, [name]);
            assert!(p.names_a_rule(), "{name}");
        }
    }

    #[test]
    fn defaults_apply_when_absent() {
        let o = LocalizeParams::from_query(None)
            .unwrap()
            .options(&defaults())
            .unwrap();
        assert_eq!(o.rule, defaults().options.rule);
        assert_eq!(o.top_n, defaults().options.top_n);
        // The configured rule without a parameter keeps the configured one.
        assert_eq!(parse("rule=peak-mean").unwrap().rule.parameter, 0.5);
    }

    #[test]
    fn parameters_are_taken() {
        let o = parse(
            "top_n=3&rule=hoeffding&delta=0.1&seed=42&min_score=0.2&min_distinct=0.6&budget_ms=2.5",
        )
        .unwrap();
        assert_eq!(o.min_distinct, 0.6);
        assert_eq!(o.budget, Some(std::time::Duration::from_micros(2500)));
        assert_eq!(o.top_n, 3);
        assert_eq!(o.rule, RuleSpec::new("hoeffding", Some(0.1)).unwrap());
        assert_eq!(o.seed, 42);
        assert_eq!(o.min_score, 0.2);
        assert_eq!(
            parse("rule=hoeffding&threshold=0.1")
                .unwrap()
                .rule
                .parameter,
            0.1
        );
        assert_eq!(
            parse("rule=fixed&fraction=0.5").unwrap().rule.parameter,
            0.5
        );
        assert_eq!(parse("threshold=2").unwrap().rule.parameter, 2.0);
        assert_eq!(parse("rule=none").unwrap().rule.name, "none");
        assert_eq!(
            parse(&format!("seed={}", i64::MAX)).unwrap().seed,
            i64::MAX as u64
        );
    }

    #[test]
    fn bad_parameters_are_400_with_a_code() {
        let cases = [
            ("rule=fastest", "unknown_rule", "fastest"),
            ("top_n=0", "invalid_parameter", "top_n"),
            ("top_n=51", "invalid_parameter", "top_n"),
            (
                "top_n=99999999999999999999999",
                "invalid_parameter",
                "top_n",
            ),
            ("top_n=-1", "invalid_parameter", "top_n"),
            ("threshold=NaN", "invalid_parameter", "threshold"),
            ("threshold=inf", "invalid_parameter", "threshold"),
            ("threshold=-1", "invalid_parameter", "threshold"),
            ("threshold=abc", "invalid_parameter", "threshold"),
            ("threshold=", "invalid_parameter", "threshold"),
            ("seed=abc", "invalid_parameter", "seed"),
            ("seed=-3", "invalid_parameter", "seed"),
            ("seed=1.5", "invalid_parameter", "seed"),
            ("seed=9223372036854775808", "invalid_parameter", "seed"),
            ("min_score=-0.1", "invalid_parameter", "min_score"),
            ("min_score=1e39", "invalid_parameter", "min_score"),
            ("min_distinct=1.5", "invalid_parameter", "min_distinct"),
            ("min_distinct=-0.1", "invalid_parameter", "min_distinct"),
            ("min_distinct=NaN", "invalid_parameter", "min_distinct"),
            ("budget_ms=0", "invalid_parameter", "budget_ms"),
            ("budget_ms=-3", "invalid_parameter", "budget_ms"),
            ("budget_ms=abc", "invalid_parameter", "budget_ms"),
            ("budget_ms=600001", "invalid_parameter", "budget_ms"),
            (
                "min_features=2147483648",
                "invalid_parameter",
                "min_features",
            ),
            ("rule=relative", "invalid_parameter", "needs its threshold"),
            (
                "rule=none&threshold=1",
                "invalid_parameter",
                "takes no parameter",
            ),
            ("rule=peak-mean&delta=0.1", "invalid_parameter", "delta"),
            (
                "rule=hoeffding&fraction=0.1",
                "invalid_parameter",
                "fraction",
            ),
            ("rule=hoeffding&delta=1.5", "invalid_parameter", "delta"),
            (
                "rule=stable-peak&threshold=2.5",
                "invalid_parameter",
                "whole number",
            ),
            (
                "threshold=1&delta=0.1",
                "invalid_parameter",
                "give one parameter",
            ),
            ("top_k=3", "invalid_parameter", "top_k"),
            ("top_n=1&top_n=2", "invalid_parameter", "top_n"),
        ];
        for (q, expected_code, mentions) in cases {
            let (c, m) = code(q);
            assert_eq!(c, expected_code, "{q}: {m}");
            assert!(m.contains(mentions), "{q}: {m}");
        }
    }

    #[test]
    fn verify_defaults_to_the_configuration() {
        let p = |q: &str| LocalizeParams::from_query(Some(q)).unwrap();
        assert!(p("").verify(true).unwrap());
        assert!(!p("").verify(false).unwrap());
        assert!(p("verify=true").verify(false).unwrap());
        assert!(!p("verify=false").verify(true).unwrap());
        assert_eq!(p("verify=1").verify(true).unwrap_err().status, 400);
        let orb = |q: &str, enabled: bool| {
            let defaults = Defaults {
                options: SearchOptions {
                    orb_pass: enabled,
                    ..SearchOptions::default()
                },
                max_top_n: 10,
            };
            p(q).options(&defaults).map(|o| o.orb_pass)
        };
        assert!(orb("", true).unwrap());
        assert!(!orb("orb_pass=false", true).unwrap());
        assert!(orb("orb_pass=true", false).unwrap());
        assert_eq!(orb("orb_pass=yes", false).unwrap_err().status, 400);
    }

    #[test]
    fn trace_is_off_unless_asked() {
        let p = |q: &str| LocalizeParams::from_query(Some(q)).unwrap().tracing();
        assert_eq!(p("").unwrap(), Tracing::Off);
        assert_eq!(p("trace=false").unwrap(), Tracing::Off);
        assert_eq!(p("trace=true").unwrap(), Tracing::On);
        assert_eq!(p("trace=full").unwrap(), Tracing::Full);
        for bad in ["trace=1", "trace=", "trace=yes"] {
            assert_eq!(p(bad).unwrap_err().status, 400, "{bad}");
        }
    }

    #[test]
    fn seeds_are_drawn_when_absent() {
        let seeds: std::collections::HashSet<u64> =
            (0..1000).map(|_| parse("").unwrap().seed).collect();
        assert!(seeds.len() > 1);
        // JSON-safe: a u64 drawn at random would be above 2^53 but for 1 in 2048
        assert!(seeds.iter().all(|&s| s <= crate::report::MAX_DRAWN_SEED));
    }
}

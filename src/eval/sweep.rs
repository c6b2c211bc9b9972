//! The sweep: which rules run with which parameters (each rule's grid is
//! declared in the rule registry, [`crate::search::stop::RULES`]), how calibrated grids are
//! found for a dataset, and running every setting over every Monte Carlo run
//! and query on pre-quantized words.

use super::summary::{QueryCost, served_ms};
use super::tiles::Query;
use crate::calibrate::median_features;
use crate::features::CoarseChoice;
use crate::index::MapIndex;
use crate::search::stop::RULES;
use crate::search::{
    KnownFeatures, Ranked, RuleSpec, SearchOptions, StopKind, TileOrder, search_words,
};
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::{Serialize, Serializer};
use std::sync::LazyLock;

pub use crate::search::stop::Grid;

/// A rule and how its parameter is swept.
#[derive(Debug, Clone, Copy)]
pub struct RuleGrid {
    pub rule: &'static str,
    pub grid: Grid,
}

/// The full search every other setting is compared with.
pub const BASELINE: &str = "none";

/// Every rule of the registry with its grid, in registry order (the full
/// search first): a rule cannot be left out of the sweep. Calibrated grids
/// are run at every warm-up (`min_features`) asked for; the others only at
/// the first.
pub static RULE_GRIDS: LazyLock<Vec<RuleGrid>> = LazyLock::new(|| {
    RULES
        .iter()
        .map(|r| RuleGrid {
            rule: r.name,
            grid: r.grid,
        })
        .collect()
});

/// Range searched when calibrating a rule's parameter: the calibrated grid's
/// range, or δ ∈ [10⁻⁹, 0.5] for the confidence rules.
pub fn parameter_range(rule: &str) -> Option<(f64, f64, bool)> {
    match rule_grid(rule)?.grid {
        Grid::Calibrated { lo, hi, whole } => Some((lo, hi, whole)),
        _ if RuleSpec::new(rule, None).is_err() && RuleSpec::new(rule, Some(0.5)).is_ok() => {
            Some((1e-9, 0.5, false))
        }
        _ => None,
    }
}

/// Look a rule's grid up by name.
pub fn rule_grid(name: &str) -> Option<&'static RuleGrid> {
    RULE_GRIDS.iter().find(|g| g.rule == name)
}

/// One configuration of the search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Setting {
    pub rule: RuleSpec,
    /// Warm-up: features voted before the rule is consulted.
    pub min_features: usize,
    /// The fraction of features its parameter was calibrated for, if any.
    pub target: Option<f64>,
    /// Candidates re-ranked by geometric verification.
    pub verify: bool,
    /// Why this grid point does not measure the rule (calibration hit a
    /// search bound, or the warm-up leaves the rule unconsulted): such points
    /// are shown, marked, but kept out of the equal-recall tables and the
    /// recommendation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub degenerate: Option<String>,
}

impl Setting {
    /// A setting at warm-up `min_features`, not calibrated; verified when
    /// the rule is a geometric one.
    pub fn new(rule: RuleSpec, min_features: usize) -> Self {
        Self {
            verify: rule.geometric(),
            rule,
            min_features,
            target: None,
            degenerate: None,
        }
    }

    /// The rule's parameter, for rules that take one.
    pub fn parameter(&self) -> Option<f64> {
        self.rule.parameter_name().map(|_| self.rule.parameter)
    }

    /// Short name, e.g. `peak-mean T=0.05 w=10`.
    pub fn label(&self) -> String {
        let mut s = self.rule.name.clone();
        if let Some(p) = self.parameter() {
            s += &format!(" {}", format_parameter(p));
        }
        if let Some(m) = self.rule.or_verified {
            s += &format!(" or verified {m}");
        }
        if self.min_features > 0 {
            s += &format!(" w={}", self.min_features);
        }
        if self.verify {
            s += " +verify";
        }
        s
    }

    /// Search options for one query of one run.
    pub fn options(&self, seed: u64, ranking: Ranking) -> SearchOptions {
        SearchOptions {
            rule: self.rule.clone(),
            top_n: ranking.top_n,
            place_window: ranking.place_window,
            tile_order: ranking.tile_order,
            given_order: ranking.given_order,
            seed,
            min_features: self.min_features,
            // as the service searches a query it verifies
            finish_tile: self.verify,
            ..SearchOptions::default()
        }
    }
}

/// How every search of a sweep runs besides its setting: the candidates it
/// keeps, the place window their distinctness (and the rule `place-lead`)
/// is measured with, the order its query's tiles are replayed in, and
/// whether each tile's features are voted in the order the query holds them
/// ([`SearchOptions::given_order`]) rather than a random one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ranking {
    pub top_n: usize,
    pub place_window: u32,
    pub tile_order: TileOrder,
    pub given_order: bool,
}

impl Ranking {
    /// The top `n`, with the service's default place window and tile order.
    pub fn top(n: usize) -> Self {
        Self {
            top_n: n,
            place_window: SearchOptions::PLACE_WINDOW,
            tile_order: TileOrder::default(),
            given_order: false,
        }
    }
}

/// A setting written `RULE=VALUE` or `RULE=VALUE@WARMUP` (warm-up
/// `warmup` when not given), or `RULE` for a rule without a parameter; a
/// vote rule followed by `+verified=M` also stops once its leader is
/// verified with M inliers (`place-z=2+verified=16@20`).
pub fn parse_setting(spec: &str, warmup: usize) -> anyhow::Result<Setting> {
    let (body, min_features) = match spec.split_once('@') {
        Some((b, w)) => (
            b,
            w.trim()
                .parse()
                .map_err(|e| anyhow::anyhow!("`{spec}`: warm-up: {e}"))?,
        ),
        None => (spec, warmup),
    };
    let (body, or_verified) = match body.split_once('+') {
        Some((b, extra)) => {
            let m = extra
                .trim()
                .strip_prefix("verified=")
                .ok_or_else(|| anyhow::anyhow!("`{spec}`: after `+`, only `verified=M`"))?;
            let m: f64 = m
                .trim()
                .parse()
                .map_err(|e| anyhow::anyhow!("`{spec}`: verified inliers: {e}"))?;
            (b, Some(m))
        }
        None => (body, None),
    };
    let (name, value) = match body.split_once('=') {
        Some((n, v)) => (
            n.trim(),
            Some(
                v.trim()
                    .parse::<f64>()
                    .map_err(|e| anyhow::anyhow!("`{spec}`: value: {e}"))?,
            ),
        ),
        None => (body.trim(), None),
    };
    let rule = RuleSpec::new(name, value)
        .and_then(|r| r.or_verified(or_verified))
        .map_err(|e| anyhow::anyhow!("`{spec}`: {e}"))?;
    Ok(Setting::new(rule, min_features))
}

/// A parameter value as tables show it (up to 3 significant digits).
pub fn format_parameter(p: f64) -> String {
    let s = format!("{}", round_significant(p, 3));
    if s.len() > 9 { format!("{p:.2e}") } else { s }
}

/// `v` rounded to `digits` significant digits.
pub fn round_significant(v: f64, digits: i32) -> f64 {
    round_with(v, digits, f64::round)
}

/// `v` rounded to `digits` significant digits, upwards (`up`) or downwards.
pub fn round_significant_toward(v: f64, digits: i32, up: bool) -> f64 {
    round_with(v, digits, if up { f64::ceil } else { f64::floor })
}

fn round_with(v: f64, digits: i32, round: fn(f64) -> f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(digits - 1 - v.abs().log10().floor() as i32);
    let r = round(v * scale) / scale;
    // dividing back can land one ulp off: keep the shortest form
    format!("{r:.12e}").parse().unwrap_or(r)
}

/// The run number the calibration pass uses: its permutations are not those
/// of any evaluation run.
pub const CALIBRATION_RUN: u32 = u32::MAX;

/// Seed of the permutation of `query` in `run`: every setting of a run sees
/// the same order for a query, so settings are compared on the same draws.
pub fn seed(run: u32, query: usize) -> u64 {
    ((run as u64) << 32) | query as u64
}

/// The result of one search, kept for the metrics and written, per query,
/// into `results.json` so it can be re-scored.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome {
    /// Ranked candidates as `[id, score]` pairs.
    #[serde(serialize_with = "id_score_pairs")]
    pub candidates: Vec<Ranked>,
    /// Features voted when the search ended: its stop point.
    pub used: u32,
    pub total: u32,
    /// Why it ended.
    pub stop: StopKind,
    /// Time spent voting (and checking the rule), in milliseconds.
    #[serde(skip)]
    pub vote_ms: f32,
    /// Decoding and extracting the tiles extracted, in milliseconds.
    #[serde(skip)]
    pub extract_ms: f32,
    /// Verifying the candidates after the search, in milliseconds.
    #[serde(skip)]
    pub verify_ms: f32,
    /// Tiles extracted (1 for a query extracted whole).
    pub tiles: u16,
    /// The best candidate is geometrically verified.
    pub verified: bool,
    /// Its extraction started with the coarse pass.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub coarse: bool,
}

fn id_score_pairs<S: Serializer>(list: &[Ranked], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(list.iter().map(|r| (r.id, r.score)))
}

impl Outcome {
    /// Fraction of the query's features used (1 for a query without any).
    pub fn fraction(&self) -> f64 {
        if self.total == 0 {
            1.0
        } else {
            self.used as f64 / self.total as f64
        }
    }
}

/// One search of a query known by its words and signatures, extracted whole
/// at no cost.
pub fn search_one(
    map: &MapIndex,
    features: KnownFeatures<'_>,
    setting: &Setting,
    seed: u64,
    ranking: Ranking,
) -> Outcome {
    let o = search_words(map, features, &setting.options(seed, ranking));
    Outcome {
        candidates: o.candidates,
        used: o.features_used as u32,
        total: features.len() as u32,
        stop: o.stop.kind,
        vote_ms: o.timings.vote.as_secs_f32() * 1e3,
        extract_ms: 0.0,
        verify_ms: 0.0,
        tiles: 1,
        verified: false,
        coarse: false,
    }
}

/// One search of a cached query, its tiles streamed as the service would.
pub fn search_query(
    map: &MapIndex,
    query: &Query,
    setting: &Setting,
    seed: u64,
    ranking: Ranking,
) -> Outcome {
    let r = query.search(map, &setting.options(seed, ranking), setting.verify);
    Outcome {
        candidates: r.outcome.candidates,
        used: r.outcome.features_used as u32,
        total: query.feature_count() as u32,
        stop: r.outcome.stop.kind,
        vote_ms: r.outcome.timings.vote.as_secs_f32() * 1e3,
        extract_ms: r.extract_ms as f32,
        verify_ms: r.verify_ms as f32,
        tiles: r.tiles as u16,
        verified: r.verified,
        coarse: query.coarse_first,
    }
}

/// Mean fraction of features `setting` uses over all queries in `run`,
/// each search otherwise run as `ranking` says (keeping its top candidate).
pub fn mean_fraction(
    map: &MapIndex,
    queries: &[Query],
    setting: &Setting,
    run: u32,
    ranking: Ranking,
) -> f64 {
    let ranking = Ranking {
        top_n: 1,
        ..ranking
    };
    let total: f64 = queries
        .par_iter()
        .enumerate()
        .map(|(q, query)| search_query(map, query, setting, seed(run, q), ranking).fraction())
        .sum();
    total / queries.len().max(1) as f64
}

/// A calibrated parameter value.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    pub rule: String,
    pub min_features: usize,
    pub target: f64,
    pub parameter: f64,
    /// Mean fraction it gave in the calibration run.
    pub fraction: f64,
    /// Why the value does not measure the rule, if it does not (see
    /// [`Setting::degenerate`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub degenerate: Option<String>,
}

/// Stop bisecting once the fraction is this close to the target.
const CALIBRATION_TOLERANCE: f64 = 0.005;
/// Bisection steps at most per target.
const CALIBRATION_STEPS: usize = 40;

/// The parameter of `rule` in `[lo, hi]` whose mean fraction `f` is nearest
/// `target`: bisection on ln(parameter), in whichever direction `f` moves.
fn bisect(target: f64, lo: f64, hi: f64, whole: bool, f: &dyn Fn(f64) -> f64) -> (f64, f64) {
    let (f_lo, f_hi) = (f(lo), f(hi));
    let rising = f_hi >= f_lo;
    let mut best = if (f_lo - target).abs() <= (f_hi - target).abs() {
        (lo, f_lo)
    } else {
        (hi, f_hi)
    };
    let (mut a, mut b) = (lo, hi);
    for _ in 0..CALIBRATION_STEPS {
        if (best.1 - target).abs() <= CALIBRATION_TOLERANCE {
            break;
        }
        let mut p = ((a.ln() + b.ln()) * 0.5).exp();
        if whole {
            p = p.round();
            if p <= a || p >= b {
                break;
            }
        }
        let v = f(p);
        if (v - target).abs() < (best.1 - target).abs() {
            best = (p, v);
        }
        if (v < target) == rising {
            a = p;
        } else {
            b = p;
        }
    }
    best
}

/// The most aggressive parameter between a `conservative` and an
/// `aggressive` end at which `ok` still holds, for an `ok` that changes at
/// most once along the range: `aggressive` itself if `ok` holds there, `None`
/// if it fails even at `conservative`, else the edge found by bisection on
/// ln(parameter) (whole numbers when `whole`).
pub fn bisect_edge(
    conservative: f64,
    aggressive: f64,
    whole: bool,
    ok: &dyn Fn(f64) -> bool,
) -> Option<f64> {
    if ok(aggressive) {
        return Some(aggressive);
    }
    if !ok(conservative) {
        return None;
    }
    let (mut good, mut bad) = (conservative, aggressive);
    for _ in 0..CALIBRATION_STEPS {
        let mut p = ((good.ln() + bad.ln()) * 0.5).exp();
        if whole {
            p = p.round();
        }
        if p == good || p == bad || (good - bad).abs() / good.abs().max(bad.abs()) < 1e-3 {
            break;
        }
        if ok(p) {
            good = p;
        } else {
            bad = p;
        }
    }
    Some(good)
}

/// What [`calibrate`] calibrates: a rule, the range its parameter is
/// searched in (`lo`, `hi`, whole numbers only) and its warm-up.
#[derive(Debug, Clone, Copy)]
pub struct Subject<'a> {
    pub rule: &'a str,
    pub range: (f64, f64, bool),
    pub min_features: usize,
}

/// Parameters of `rule` (grid `Calibrated { lo, hi, whole }`) at warm-up
/// `min_features` for each target fraction, rounded to 3 significant digits,
/// from one calibration run over all queries. A value is marked degenerate
/// when the bisection ended on a bound of `[lo, hi]` (the target is out of
/// the rule's reach: the value says nothing about the rule) or when the
/// warm-up is at least the median query's feature count (the rule is not
/// consulted on most queries).
pub fn calibrate(
    map: &MapIndex,
    queries: &[Query],
    subject: Subject<'_>,
    targets: &[f64],
    ranking: Ranking,
    bar: &ProgressBar,
) -> anyhow::Result<Vec<Calibration>> {
    let Subject {
        rule,
        range: (lo, hi, whole),
        min_features,
    } = subject;
    let setting = |p: f64| -> anyhow::Result<Setting> {
        Ok(Setting::new(
            RuleSpec::new(rule, Some(p)).map_err(anyhow::Error::msg)?,
            min_features,
        ))
    };
    setting(lo)?;
    setting(hi)?;
    let memo = std::sync::Mutex::new(std::collections::HashMap::<u64, f64>::new());
    let f = |p: f64| -> f64 {
        if let Some(&v) = memo.lock().expect("not poisoned").get(&p.to_bits()) {
            return v;
        }
        let s = setting(p).expect("within the checked range");
        let v = mean_fraction(map, queries, &s, CALIBRATION_RUN, ranking);
        memo.lock().expect("not poisoned").insert(p.to_bits(), v);
        v
    };
    let lengths: Vec<usize> = queries.iter().map(|q| q.feature_count()).collect();
    let median = median_features(&lengths);
    let mut out = Vec::with_capacity(targets.len());
    for &target in targets {
        let (raw, _) = bisect(target, lo, hi, whole, &f);
        let p = if whole {
            raw
        } else {
            round_significant(raw, 3)
        };
        let fraction = f(p);
        let degenerate = if min_features >= median {
            Some(format!(
                "warm-up {min_features} ≥ the median query's {median} features"
            ))
        } else if raw == lo || raw == hi {
            Some(format!(
                "target {:.0} % out of reach: bisection ended on the search bound {} ({:.1} % \
                 of the features)",
                100.0 * target,
                format_parameter(raw),
                100.0 * fraction
            ))
        } else {
            None
        };
        out.push(Calibration {
            rule: rule.to_owned(),
            min_features,
            target,
            parameter: p,
            fraction,
            degenerate,
        });
        bar.inc(1);
    }
    Ok(out)
}

/// Every setting to run for `grids`: single and listed values at the first
/// warm-up, calibrated grids at every warm-up. Also returns the calibrations.
pub fn plan(
    map: &MapIndex,
    queries: &[Query],
    grids: &[&RuleGrid],
    warmups: &[usize],
    targets: &[f64],
    ranking: Ranking,
    bar: &ProgressBar,
) -> anyhow::Result<(Vec<Setting>, Vec<Calibration>)> {
    let first = warmups.first().copied().unwrap_or(0);
    let mut settings = Vec::new();
    let mut calibrations = Vec::new();
    let spec = |name: &str, p: Option<f64>| RuleSpec::new(name, p).map_err(anyhow::Error::msg);
    for g in grids {
        match g.grid {
            Grid::Single => settings.push(Setting::new(spec(g.rule, None)?, first)),
            Grid::Values(values) => {
                for &v in values {
                    settings.push(Setting::new(spec(g.rule, Some(v))?, first));
                }
            }
            Grid::Calibrated { lo, hi, whole } => {
                for &w in warmups {
                    let subject = Subject {
                        rule: g.rule,
                        range: (lo, hi, whole),
                        min_features: w,
                    };
                    let found = calibrate(map, queries, subject, targets, ranking, bar)?;
                    let mut seen: Vec<f64> = Vec::new();
                    for c in &found {
                        if seen.contains(&c.parameter) {
                            continue;
                        }
                        seen.push(c.parameter);
                        settings.push(Setting {
                            target: Some(c.target),
                            degenerate: c.degenerate.clone(),
                            ..Setting::new(spec(g.rule, Some(c.parameter))?, w)
                        });
                    }
                    calibrations.extend(found);
                }
            }
        }
    }
    Ok((settings, calibrations))
}

/// Run every setting on every query in every run: `result[setting][run][query]`.
pub fn run_all(
    map: &MapIndex,
    queries: &[Query],
    settings: &[Setting],
    runs: u32,
    ranking: Ranking,
    bar: &ProgressBar,
) -> Vec<Vec<Vec<Outcome>>> {
    let per_query: Vec<Vec<Outcome>> = queries
        .par_iter()
        .enumerate()
        .map(|(q, query)| {
            let mut out = Vec::with_capacity(settings.len() * runs as usize);
            for s in settings {
                for run in 0..runs {
                    out.push(search_query(map, query, s, seed(run, q), ranking));
                }
            }
            bar.inc(1);
            out
        })
        .collect();
    let mut result: Vec<Vec<Vec<Outcome>>> = (0..settings.len())
        .map(|_| {
            (0..runs)
                .map(|_| Vec::with_capacity(queries.len()))
                .collect()
        })
        .collect();
    for outcomes in per_query {
        for (i, o) in outcomes.into_iter().enumerate() {
            result[i / runs as usize][i % runs as usize].push(o);
        }
    }
    result
}

/// A learned coarse pass's queries: each one cut without and with the
/// coarse pass (timed together), and what quantizing a feature of each cost.
#[derive(Clone, Copy)]
pub struct LearnedPlan<'a> {
    pub plain: (&'a [Query], &'a [QueryCost]),
    pub coarse: (&'a [Query], &'a [QueryCost]),
}

/// [`run_all`] for a learned coarse pass, replayed as the service learns it:
/// for each setting, a fresh [`CoarseChoice`] (a server just started) sees
/// the runs one after the other, each the queries in order, picks each
/// search's plan, and is told what the search cost (every stage but
/// decoding, as the server measures it, from the cache's timings) and whether it ended on its first unit. A setting whose
/// rule never stops early searches without the coarse pass and learns
/// nothing, as the service's does. The progress bar advances once per
/// setting and run.
pub fn run_learned(
    map: &MapIndex,
    plan: LearnedPlan<'_>,
    settings: &[Setting],
    runs: u32,
    ranking: Ranking,
    bar: &ProgressBar,
) -> Vec<Vec<Vec<Outcome>>> {
    settings
        .par_iter()
        .map(|setting| {
            let choice = setting.rule.info().stops_early.then(CoarseChoice::default);
            (0..runs)
                .map(|run| {
                    let out = (0..plan.plain.0.len())
                        .map(|q| {
                            let at = seed(run, q);
                            learned_search(map, plan, setting, choice.as_ref(), q, at, ranking)
                        })
                        .collect();
                    bar.inc(1);
                    out
                })
                .collect()
        })
        .collect()
}

/// One search under a learned plan: `choice` (none: a rule that never
/// stops early, which searches without the coarse pass and learns nothing)
/// picks the plan and is told what the search cost and whether it ended on
/// its first unit.
pub fn learned_search(
    map: &MapIndex,
    plan: LearnedPlan<'_>,
    setting: &Setting,
    choice: Option<&CoarseChoice>,
    query: usize,
    seed: u64,
    ranking: Ranking,
) -> Outcome {
    let coarse = choice.is_some_and(CoarseChoice::choose);
    let o = search_query(map, &plan.side(coarse).0[query], setting, seed, ranking);
    if let Some(choice) = choice {
        choice.record(coarse, served_ms(&o, plan.cost(&o, query)), o.tiles <= 1);
    }
    o
}

impl<'a> LearnedPlan<'a> {
    /// The queries and costs without (`false`) or with the coarse pass.
    fn side(&self, coarse: bool) -> (&'a [Query], &'a [QueryCost]) {
        if coarse { self.coarse } else { self.plain }
    }

    /// What query `query` cost in the plan its outcome `o` was searched in.
    pub fn cost(&self, o: &Outcome, query: usize) -> &'a QueryCost {
        &self.side(o.coarse).1[query]
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::index::{ImageWords, MapBuilder};
    use crate::search::stop::rule_info;

    #[test]
    fn every_grid_names_a_known_rule_with_valid_values() {
        for g in RULE_GRIDS.iter() {
            let info = rule_info(g.rule).unwrap_or_else(|| panic!("unknown rule {}", g.rule));
            match g.grid {
                Grid::Single => assert!(info.parameter.is_none(), "{}", g.rule),
                Grid::Values(vs) => {
                    assert!(!vs.is_empty());
                    for &v in vs {
                        RuleSpec::new(g.rule, Some(v)).unwrap();
                    }
                }
                Grid::Calibrated { lo, hi, .. } => {
                    assert!(lo > 0.0 && lo < hi, "{}", g.rule);
                    RuleSpec::new(g.rule, Some(lo)).unwrap();
                    RuleSpec::new(g.rule, Some(hi)).unwrap();
                }
            }
        }
        assert!(rule_grid(BASELINE).is_some());
    }

    #[test]
    fn settings_parse_from_text() {
        let s = parse_setting("relative=2.5@100", 0).unwrap();
        assert_eq!(
            (s.rule.name.as_str(), s.rule.parameter, s.min_features),
            ("relative", 2.5, 100)
        );
        let s = parse_setting("peak-mean=0.01", 20).unwrap();
        assert_eq!((s.rule.parameter, s.min_features), (0.01, 20));
        assert_eq!(parse_setting("none", 3).unwrap().label(), "none w=3");
        assert!(parse_setting("peak-mean", 0).is_err());
        assert!(parse_setting("nope=1", 0).is_err());
        assert!(parse_setting("fixed=0.5@x", 0).is_err());
        assert!(parse_setting("fixed=2", 0).is_err());
        // a vote rule with a verified stop: verified, and labelled so
        let s = parse_setting("place-z=2+verified=16@20", 0).unwrap();
        assert_eq!(s.rule.or_verified, Some(16));
        assert!(s.verify);
        assert_eq!(s.label(), "place-z 2 or verified 16 w=20 +verify");
        assert!(parse_setting("place-z=2+verify=16", 0).is_err());
        assert!(parse_setting("none+verified=16", 0).is_err());
        assert!(parse_setting("place-z=2+verified=3", 0).is_err());
    }

    #[test]
    fn rounding_and_seeds() {
        assert_eq!(round_significant(0.012345, 3), 0.0123);
        assert_eq!(round_significant_toward(0.012301, 3, true), 0.0124);
        assert_eq!(round_significant_toward(0.012399, 3, false), 0.0123);
        assert_eq!(round_significant_toward(742.2, 3, true), 743.0);
        assert_eq!(round_significant(98765.0, 3), 98800.0);
        assert_eq!(format_parameter(0.05), "0.05");
        assert_ne!(seed(0, 1), seed(1, 0));
        assert_ne!(seed(CALIBRATION_RUN, 0), seed(0, 0));
    }

    #[test]
    fn bisection_finds_targets_either_way() {
        // A rising step-free function: fraction = p / 100 on [1, 100].
        let rising = |p: f64| p / 100.0;
        let (p, v) = bisect(0.5, 1.0, 100.0, false, &rising);
        assert!((v - 0.5).abs() <= CALIBRATION_TOLERANCE && (p - 50.0).abs() < 1.0);
        // Falling, with whole numbers.
        let falling = |p: f64| 1.0 - p / 100.0;
        let (p, v) = bisect(0.3, 1.0, 100.0, true, &falling);
        assert_eq!(p.fract(), 0.0);
        assert!((v - 0.3).abs() <= 0.01, "{p} {v}");
        // Out of reach: the nearest end.
        assert_eq!(bisect(0.0, 10.0, 100.0, false, &rising).0, 10.0);
    }

    pub(in crate::eval) fn toy_map() -> MapIndex {
        let mut b = MapBuilder::new(8);
        let images: [&[u32]; 4] = [&[0, 1, 2, 2], &[2, 3, 4], &[4, 5, 6, 6], &[6, 7, 0, 1]];
        for (i, w) in images.iter().enumerate() {
            b.add(ImageWords::from_words(format!("{i}"), w));
        }
        b.build("t", "0", None)
    }

    #[test]
    fn fixed_fraction_uses_that_share_and_runs_are_laid_out_by_setting() {
        let map = toy_map();
        let queries: Vec<Query> = (0..5)
            .map(|q| Query::whole((0..40).map(|i| ((i * 7 + q) % 8) as u32).collect()))
            .collect();
        let settings = vec![
            Setting::new(RuleSpec::new("none", None).unwrap(), 0),
            Setting::new(RuleSpec::new("fixed", Some(0.5)).unwrap(), 0),
        ];
        let bar = ProgressBar::hidden();
        let r = run_all(&map, &queries, &settings, 3, Ranking::top(2), &bar);
        assert_eq!((r.len(), r[0].len(), r[0][0].len()), (2, 3, 5));
        for run in &r[0] {
            assert!(run.iter().all(|o| o.used == 40 && o.fraction() == 1.0));
        }
        for run in &r[1] {
            assert!(run.iter().all(|o| o.used == 20 && o.candidates.len() <= 2));
        }
        assert_eq!(
            mean_fraction(&map, &queries, &settings[1], 0, Ranking::top(1)),
            0.5
        );
    }

    /// `n` identical queries of four tiles of 10 features, all on image 0 of
    /// [`toy_map`]; with the coarse pass, 8 of them found first at a fifth of
    /// a tile's cost: (plain, coarse, costs).
    pub(in crate::eval) fn toy_learned(n: usize) -> (Vec<Query>, Vec<Query>, Vec<QueryCost>) {
        use super::super::tiles::Tile;
        let tile = |features: u32, ms: f32| Tile {
            features,
            area: 0.25,
            ms,
            corners: 0.0,
            cell: [0, 0],
        };
        let plain = Query {
            words: vec![0; 40],
            tiles: vec![tile(10, 10.0); 4],
            ..Query::default()
        };
        let coarse = Query {
            words: vec![0; 40],
            tiles: [tile(8, 2.0)]
                .into_iter()
                .chain([tile(8, 10.0); 4])
                .collect(),
            coarse_first: true,
            ..Query::default()
        };
        let costs = vec![
            QueryCost {
                quantize_ms_per_feature: 0.01,
                decode_ms: 0.0,
            };
            n
        ];
        (vec![plain; n], vec![coarse; n], costs)
    }

    #[test]
    fn the_learned_plan_is_replayed_query_by_query_as_the_service_learns_it() {
        let map = toy_map();
        let n = 100;
        let (plain, coarse, costs) = toy_learned(n);
        let plan = LearnedPlan {
            plain: (&plain, &costs),
            coarse: (&coarse, &costs),
        };
        // `fixed 0.2` would stop on the coarse pass's 8 features, but a vote
        // statistic may not stop there: the coarse plan costs more, and is
        // tried only in the trials and then one request in EXPLORE_EVERY;
        // the full search never learns
        let settings = vec![
            Setting::new(RuleSpec::new("none", None).unwrap(), 0),
            Setting::new(RuleSpec::new("fixed", Some(0.2)).unwrap(), 0),
        ];
        let bar = ProgressBar::hidden();
        let r = run_learned(&map, plan, &settings, 2, Ranking::top(1), &bar);
        assert_eq!((r.len(), r[0].len(), r[0][0].len()), (2, 2, n));
        assert!(r[0].iter().flatten().all(|o| !o.coarse && o.tiles == 4));
        // one choice learns over both runs, as one server would
        let started: Vec<bool> = r[1].iter().flatten().map(|o| o.coarse).collect();
        let explored = (2 * CoarseChoice::TRIAL + 1..=2 * n as u64)
            .filter(|k| k.is_multiple_of(CoarseChoice::EXPLORE_EVERY))
            .count();
        assert_eq!(
            started.iter().filter(|&&c| c).count(),
            CoarseChoice::TRIAL as usize + explored
        );
        // trials alternate, plain first
        assert!(!started[0] && started[1]);
        for o in r[1].iter().flatten() {
            assert_eq!(o.tiles, if o.coarse { 2 } else { 1 }, "{o:?}");
        }
    }

    #[test]
    fn unreachable_targets_and_large_warm_ups_are_marked_degenerate() {
        let map = toy_map();
        let queries: Vec<Query> = (0..6)
            .map(|q| Query::whole((0..40).map(|i| ((i * 5 + q * 3) % 8) as u32).collect()))
            .collect();
        let bar = ProgressBar::hidden();
        // `fixed` cannot use less than 20 % when its range starts at 0.2:
        // the bisection ends on that bound.
        let found = calibrate(
            &map,
            &queries,
            Subject {
                rule: "fixed",
                range: (0.2, 1.0, false),
                min_features: 0,
            },
            &[0.1, 0.5],
            Ranking::top(1),
            &bar,
        )
        .unwrap();
        let why = found[0].degenerate.as_deref().unwrap();
        assert!(why.contains("search bound 0.2"), "{why}");
        assert_eq!(found[1].degenerate, None);
        // A warm-up of all 40 features: every point is degenerate, and the
        // plan carries the mark to its settings.
        let (settings, _) = plan(
            &map,
            &queries,
            &[rule_grid("stable-peak").unwrap()],
            &[40],
            &[0.5],
            Ranking::top(1),
            &bar,
        )
        .unwrap();
        let why = settings[0].degenerate.as_deref().unwrap();
        assert!(
            why.contains("warm-up 40 ≥ the median query's 40 features"),
            "{why}"
        );
    }

    #[test]
    fn calibration_hits_reachable_targets_of_a_real_rule() {
        let map = toy_map();
        let queries: Vec<Query> = (0..6)
            .map(|q| {
                Query::whole(
                    (0..200)
                        .map(|i| ((i * 5 + q * 3 + i / 7) % 8) as u32)
                        .collect(),
                )
            })
            .collect();
        let bar = ProgressBar::hidden();
        // `fixed` is listed, not calibrated, but its fraction is its
        // parameter, which makes it a checkable calibration subject.
        let found = calibrate(
            &map,
            &queries,
            Subject {
                rule: "fixed",
                range: (0.01, 1.0, false),
                min_features: 0,
            },
            &[0.3, 0.7],
            Ranking::top(1),
            &bar,
        )
        .unwrap();
        assert_eq!(found.len(), 2);
        for c in &found {
            assert!(
                (c.fraction - c.target).abs() <= CALIBRATION_TOLERANCE,
                "{c:?}"
            );
            assert!((c.parameter - c.target).abs() < 0.02, "{c:?}");
        }
        let (settings, cal) = plan(
            &map,
            &queries,
            &[
                rule_grid("none").unwrap(),
                rule_grid("stable-peak").unwrap(),
            ],
            &[0, 5],
            &[0.5, 0.9],
            Ranking::top(1),
            &bar,
        )
        .unwrap();
        assert_eq!(cal.len(), 4);
        assert_eq!(settings[0].rule.name, "none");
        assert!(
            settings[1..]
                .iter()
                .all(|s| s.rule.name == "stable-peak" && s.target.is_some())
        );
        assert!(settings.iter().any(|s| s.min_features == 5));
    }
}

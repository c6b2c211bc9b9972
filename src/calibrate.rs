//! Calibration without ground truth: choose, for one map, the parameter of
//! each stopping rule at which the early answer disagrees with full
//! bag-of-words' top-1 on at most a given fraction of pseudo-queries.
//!
//! The pseudo-queries come from the map itself. Each image's words are
//! recovered from the postings ([`MapIndex::image_words`]). The images with
//! even ids form a calibration map and those with odd ids become queries
//! against it, each with a random 30 % of its features dropped. A query's
//! neighbours along a route are then in the map but the query itself is not,
//! as with real queries. The parameter is found by bisection with the eval's
//! grids (`eval::sweep`). [`server_config`] writes a choice as a
//! configuration file `bowloc serve --config` reads.
//!
//! A calibration can fail, and says so ([`Failure`]) rather than returning a
//! search bound as a value: the warm-up leaves the rule unconsulted, the
//! target is met only at a bound of the parameter's range, or not at all.
//! Given real queries, [`Transfer`] checks that the choice holds on them too.
//!
//! The warm-up (features voted before a rule is consulted) is defined here,
//! once: [`auto_warmup`] adapts it to the queries' feature count.

use crate::eval::sweep::{
    Ranking, Setting, bisect_edge, format_parameter, parameter_range, round_significant_toward,
    search_one, seed,
};
use crate::index::{ImageWords, MapBuilder, MapIndex};
use crate::search::{CodedFeatures, RuleSpec};
use anyhow::Context;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

/// Share of each pseudo-query's features that is dropped.
const DROP: f64 = 0.3;

/// The largest warm-up [`auto_warmup`] gives.
pub const MAX_WARMUP: usize = 100;
/// The share of the median query's features [`auto_warmup`] gives at most.
pub const WARMUP_SHARE: f64 = 0.25;

/// The median of `counts` (0 for none).
pub fn median_features(counts: &[usize]) -> usize {
    if counts.is_empty() {
        return 0;
    }
    // linear time (a selection, not a sort): a live map counts again after each change
    let mut counts = counts.to_vec();
    let middle = counts.len() / 2;
    *counts.select_nth_unstable(middle).1
}

/// The warm-up for queries with these feature counts: [`MAX_WARMUP`]
/// features, but at most [`WARMUP_SHARE`] of the median query's, so a rule
/// is consulted on most queries and still sees a few votes before it may
/// stop. A map of small images (say 78 features a query) gets 19, one of
/// large images (1000 and more) 100.
pub fn auto_warmup(counts: &[usize]) -> usize {
    let share = (WARMUP_SHARE * median_features(counts) as f64).floor() as usize;
    share.min(MAX_WARMUP)
}

/// A warm-up as asked for: a number of features, or `auto` ([`auto_warmup`]
/// of the feature counts at hand: the queries' in an evaluation, the map
/// images' in a sequence's rule). In a configuration file, `"auto"` or a
/// number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "WarmupValue", into = "WarmupValue")]
pub enum Warmup {
    Auto,
    Features(usize),
}

impl Warmup {
    /// The number of features, `auto` being `auto`.
    pub fn resolve(self, auto: usize) -> usize {
        match self {
            Self::Auto => auto,
            Self::Features(n) => n,
        }
    }
}

impl std::str::FromStr for Warmup {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            n => n
                .parse()
                .map(Self::Features)
                .map_err(|_| format!("`{s}` is neither a number of features nor `auto`")),
        }
    }
}

impl std::fmt::Display for Warmup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Auto => f.write_str("auto"),
            Self::Features(n) => write!(f, "{n}"),
        }
    }
}

/// A warm-up as a configuration file writes it.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
enum WarmupValue {
    Features(usize),
    Text(String),
}

impl TryFrom<WarmupValue> for Warmup {
    type Error = String;
    fn try_from(v: WarmupValue) -> Result<Self, String> {
        match v {
            WarmupValue::Features(n) => Ok(Self::Features(n)),
            WarmupValue::Text(s) => s.parse(),
        }
    }
}

impl From<Warmup> for WarmupValue {
    fn from(w: Warmup) -> Self {
        match w {
            Warmup::Auto => Self::Text("auto".into()),
            Warmup::Features(n) => Self::Features(n),
        }
    }
}

/// A calibration map and its pseudo-queries.
pub struct PseudoQueries {
    pub map: MapIndex,
    pub queries: Vec<CodedFeatures>,
}

/// Split `map` into a calibration map (even ids) and perturbed pseudo-queries
/// (odd ids).
pub fn pseudo_queries(map: &MapIndex, seed: u64) -> PseudoQueries {
    let words = map.image_words();
    let mut builder = MapBuilder::new(map.words());
    let mut queries = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for (j, w) in words.into_iter().enumerate() {
        let stored = map.geometry(j as u32);
        if j % 2 == 0 {
            let mut image = ImageWords::from_words(map.image(j as u32).name, &w);
            image.geometry = stored.to_vec();
            builder.add(image);
        } else {
            // the stored features (word and signature) when the map keeps
            // them, else the words alone
            let mut features: Vec<(u32, u64)> = if stored.len() == w.len() {
                stored.iter().map(|f| (f.word, f.signature())).collect()
            } else {
                w.iter().map(|&w| (w, 0)).collect()
            };
            features.shuffle(&mut rng);
            features.truncate(((1.0 - DROP) * features.len() as f64).round() as usize);
            queries.push(CodedFeatures {
                words: features.iter().map(|f| f.0).collect(),
                signatures: features.iter().map(|f| f.1).collect(),
            });
        }
    }
    PseudoQueries {
        map: builder.build("calibration", &map.meta().vocab_hash, None),
        queries,
    }
}

/// The calibrated parameter of one rule.
#[derive(Debug, Clone, Serialize)]
pub struct Calibrated {
    pub rule: String,
    pub parameter: f64,
    pub min_features: usize,
    /// Disagreement with full top-1 on the pseudo-queries.
    pub disagreement: f64,
    /// Mean fraction of features used on the pseudo-queries.
    pub fraction: f64,
}

/// Disagreement with the full top-1 and mean fraction used, over `runs`
/// permutations of every query.
pub fn measure(
    map: &MapIndex,
    queries: &[CodedFeatures],
    full_top1: &[Option<u32>],
    setting: &Setting,
    runs: u32,
) -> (f64, f64) {
    let (disagree, fraction, n) = (0..runs)
        .into_par_iter()
        .flat_map(|run| (0..queries.len()).into_par_iter().map(move |q| (run, q)))
        .filter(|&(_, q)| full_top1[q].is_some())
        .map(|(run, q)| {
            let o = search_one(
                map,
                queries[q].known(),
                setting,
                seed(run, q),
                Ranking::top(1),
            );
            let top = o.candidates.first().map(|c| c.id);
            ((top != full_top1[q]) as usize, o.fraction(), 1usize)
        })
        .reduce(|| (0, 0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    let n = n.max(1) as f64;
    (disagree as f64 / n, fraction / n)
}

/// Full bag-of-words' top-1 of every query.
pub fn full_top1(map: &MapIndex, queries: &[CodedFeatures]) -> Vec<Option<u32>> {
    let none = Setting::new(RuleSpec::new("none", None).expect("built in"), 0);
    queries
        .par_iter()
        .map(|w| {
            search_one(map, w.known(), &none, 0, Ranking::top(1))
                .candidates
                .first()
                .map(|c| c.id)
        })
        .collect()
}

/// Why a rule could not be calibrated.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Failure {
    #[error(
        "warm-up {warmup} ≥ the median pseudo-query's {features} features: the rule would not be \
         consulted on most queries (lower --min-features, or leave it out for {auto})"
    )]
    WarmupTooLarge {
        warmup: usize,
        features: usize,
        auto: usize,
    },
    #[error(
        "even at its most conservative value ({bound}) it disagrees with full search on \
         {disagreement:.3} of the pseudo-queries (target {target})"
    )]
    Unreachable {
        bound: String,
        disagreement: f64,
        target: f64,
    },
    #[error(
        "the target is met only at the search bound {bound}, where it uses {percent:.1} % of the \
         features: the bound is not a calibrated value"
    )]
    AtBound { bound: String, percent: f64 },
}

/// The most aggressive parameter of `rule` whose disagreement is at most
/// `max_disagreement`, rounded to 3 significant digits on the conservative
/// side; or why there is none worth the name.
pub fn calibrate_rule(
    pseudo: &PseudoQueries,
    full: &[Option<u32>],
    rule: &str,
    min_features: usize,
    max_disagreement: f64,
    runs: u32,
) -> anyhow::Result<Result<Calibrated, Failure>> {
    let (lo, hi, whole) = parameter_range(rule)
        .with_context(|| format!("rule `{rule}` has no parameter to calibrate"))?;
    let counts: Vec<usize> = pseudo.queries.iter().map(|q| q.words.len()).collect();
    let features = median_features(&counts);
    if min_features >= features {
        return Ok(Err(Failure::WarmupTooLarge {
            warmup: min_features,
            features,
            auto: auto_warmup(&counts),
        }));
    }
    let setting = |p: f64| {
        Setting::new(
            RuleSpec::new(rule, Some(p)).expect("within the rule's range"),
            min_features,
        )
    };
    let run = |p: f64| measure(&pseudo.map, &pseudo.queries, full, &setting(p), runs);
    // the aggressive end is the one using fewer features
    let (conservative, aggressive) = if run(lo).1 < run(hi).1 {
        (hi, lo)
    } else {
        (lo, hi)
    };
    let ok = |p: f64| run(p).0 <= max_disagreement;
    let Some(p) = bisect_edge(conservative, aggressive, whole, &ok) else {
        return Ok(Err(Failure::Unreachable {
            bound: format_parameter(conservative),
            disagreement: run(conservative).0,
            target: max_disagreement,
        }));
    };
    if p == conservative || p == aggressive {
        return Ok(Err(Failure::AtBound {
            bound: format_parameter(p),
            percent: 100.0 * run(p).1,
        }));
    }
    // three significant digits, towards the conservative end (which stays
    // within the target when the disagreement moves one way along the range)
    let rounded = round_significant_toward(p, 3, conservative > aggressive);
    let p = if ok(rounded) { rounded } else { p };
    let (disagreement, fraction) = measure(&pseudo.map, &pseudo.queries, full, &setting(p), runs);
    Ok(Ok(Calibrated {
        rule: rule.to_owned(),
        parameter: p,
        min_features,
        disagreement,
        fraction,
    }))
}

/// How a calibrated rule does on real queries.
#[derive(Debug, Clone, Serialize)]
pub struct Transfer {
    /// Disagreement with full search's top-1.
    pub disagreement: f64,
    /// Mean fraction of features used.
    pub fraction: f64,
    pub recall_full: f64,
    pub recall_early: f64,
    /// Whether the disagreement meets the calibration's target.
    pub passed: bool,
}

/// The rule `--out` writes: of the calibrated rules that passed the transfer
/// check (all of them without one), the one using the fewest pseudo-query
/// features. With none passing, an error naming the rules and their real
/// disagreement, unless `force`, which takes the cheapest calibrated rule.
pub fn choose(
    chosen: &[(Calibrated, Option<Transfer>)],
    max_disagreement: f64,
    force: bool,
) -> anyhow::Result<&Calibrated> {
    let cheapest = |passing: bool| {
        chosen
            .iter()
            .filter(|(_, t)| !passing || t.as_ref().is_none_or(|t| t.passed))
            .min_by(|x, y| x.0.fraction.total_cmp(&y.0.fraction))
            .map(|(c, _)| c)
    };
    if chosen.is_empty() {
        anyhow::bail!("no rule could be calibrated; nothing written");
    }
    if let Some(c) = cheapest(true) {
        return Ok(c);
    }
    if force {
        return Ok(cheapest(false).expect("not empty"));
    }
    let misses: Vec<String> = chosen
        .iter()
        .filter_map(|(c, t)| {
            t.as_ref().map(|t| {
                format!(
                    "{} {}: {:.3}",
                    c.rule,
                    format_parameter(c.parameter),
                    t.disagreement
                )
            })
        })
        .collect();
    anyhow::bail!(
        "the transfer check failed: on the dataset's real queries every calibrated rule \
         disagrees with full search more than the target {max_disagreement} ({}); the \
         pseudo-queries are unlike the real ones, so nothing was written (--force writes \
         the cheapest rule anyway)",
        misses.join(", ")
    )
}

/// A configuration file for `bowloc serve --config` that serves `map` (built
/// with `vocab`) with the calibrated rule as the default of every request:
/// `[files]` names the two files, `[search]` the rule, its parameter and its
/// warm-up; every other key keeps its built-in default (config/default.toml).
/// Give absolute paths for a file that works from any working directory.
pub fn server_config(best: &Calibrated, vocab: &Path, map: &Path, max_disagreement: f64) -> String {
    // A JSON string is a valid TOML basic string.
    let quote =
        |p: &Path| serde_json::to_string(&p.to_string_lossy()).expect("a string serializes");
    format!(
        "# Written by `bowloc calibrate --max-disagreement {max_disagreement}`: of the rules\n\
         # whose early top-1 disagreed with full search on at most that share of\n\
         # pseudo-queries, the one using the fewest features ({:.3} disagreement, {:.1}%).\n\
         # Serve with `bowloc serve --config FILE`; other keys: config/default.toml.\n\
         [files]\nvocabulary = {}\nmap = {}\n\n\
         [search]\nrule = \"{}\"\nthreshold = {}\nmin_features = {}\n",
        best.disagreement,
        100.0 * best.fraction,
        quote(vocab),
        quote(map),
        best.rule,
        best.parameter,
        best.min_features
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::sweep::bisect_edge;

    #[test]
    fn warm_up_adapts_to_the_feature_count() {
        assert_eq!(median_features(&[5, 1, 9]), 5);
        assert_eq!(median_features(&[]), 0);
        assert_eq!(auto_warmup(&[78, 80, 70]), 19);
        assert_eq!(auto_warmup(&[1053, 900, 2000]), MAX_WARMUP);
        assert_eq!(auto_warmup(&[]), 0);
    }

    fn calibrated(rule: &str, fraction: f64) -> Calibrated {
        Calibrated {
            rule: rule.into(),
            parameter: 1.5,
            min_features: 10,
            disagreement: 0.01,
            fraction,
        }
    }

    fn transfer(passed: bool) -> Option<Transfer> {
        Some(Transfer {
            disagreement: if passed { 0.01 } else { 0.093 },
            fraction: 0.5,
            recall_full: 0.9,
            recall_early: 0.8,
            passed,
        })
    }

    #[test]
    fn out_takes_the_cheapest_rule_that_transfers_and_refuses_when_none_does() {
        let both = vec![
            (calibrated("stable-peak", 0.4), transfer(false)),
            (calibrated("peak-mean", 0.6), transfer(true)),
        ];
        assert_eq!(choose(&both, 0.01, false).unwrap().rule, "peak-mean");
        let none = vec![
            (calibrated("stable-peak", 0.4), transfer(false)),
            (calibrated("peak-mean", 0.6), transfer(false)),
        ];
        let e = choose(&none, 0.01, false).unwrap_err().to_string();
        assert!(
            e.contains("transfer check failed") && e.contains("--force"),
            "{e}"
        );
        assert!(e.contains("stable-peak 1.5: 0.093"), "{e}");
        assert_eq!(choose(&none, 0.01, true).unwrap().rule, "stable-peak");
        // without a dataset there is no check
        let unchecked = vec![(calibrated("relative", 0.7), None)];
        assert_eq!(choose(&unchecked, 0.01, false).unwrap().rule, "relative");
        assert!(choose(&[], 0.01, true).is_err());
    }

    #[test]
    fn bisect_edge_finds_the_boundary_from_either_side() {
        // thresholds: high is conservative
        let up = bisect_edge(1e3, 1e-3, false, &|p| p >= 2.0).unwrap();
        assert!((2.0..2.01).contains(&up), "{up}");
        // confidence δ: low is conservative
        let down = bisect_edge(1e-3, 1e3, false, &|p| p <= 5.0).unwrap();
        assert!((4.99..=5.0).contains(&down), "{down}");
        assert_eq!(bisect_edge(100.0, 1.0, true, &|p| p >= 37.0), Some(37.0));
        assert_eq!(bisect_edge(1.0, 10.0, false, &|_| false), None);
        assert_eq!(bisect_edge(100.0, 1.0, false, &|_| true), Some(1.0));
    }

    #[test]
    fn pseudo_queries_split_the_map() {
        let map = crate::index::synthetic::zipf_map(21, 300, 50, 4);
        let p = pseudo_queries(&map, 1);
        assert_eq!(p.map.images(), 11);
        assert_eq!(p.queries.len(), 10);
        // about 70 % of each image's (voting) features remain
        let words = map.image_words();
        assert!((p.queries[0].words.len() as f64 - 0.7 * words[1].len() as f64).abs() <= 1.0);
    }

    #[test]
    fn server_config_is_a_configuration_bowloc_serve_loads() {
        use crate::server::config::Config;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calibrated.toml");
        // a whole-number threshold, and a path that needs escaping
        let best = Calibrated {
            rule: "stable-peak".into(),
            parameter: 730.0,
            min_features: 100,
            disagreement: 0.01,
            fraction: 0.936,
        };
        let vocab = dir.path().join("my \"maps\"/vocab.bowvoc");
        let map = dir.path().join("map.bowmap");
        std::fs::write(&path, server_config(&best, &vocab, &map, 0.01)).unwrap();
        let config = Config::load(&path).unwrap();
        assert_eq!(config.files.vocabulary, vocab);
        assert_eq!(config.files.map, map);
        let rule = config.default_rule().unwrap();
        assert_eq!((rule.name.as_str(), rule.parameter), ("stable-peak", 730.0));
        assert_eq!(config.search.min_features, 100);
        // the keys not written keep the built-in defaults
        let defaults = Config::default();
        assert_eq!(config.search.top_n, defaults.search.top_n);
        assert_eq!(config.server, defaults.server);

        let best = Calibrated {
            rule: "peak-mean".into(),
            parameter: 0.034_231_334_326_241_04,
            ..best
        };
        std::fs::write(&path, server_config(&best, &vocab, &map, 0.01)).unwrap();
        let rule = Config::load(&path).unwrap().default_rule().unwrap();
        assert_eq!(
            (rule.name.as_str(), rule.parameter),
            ("peak-mean", best.parameter)
        );
    }
}

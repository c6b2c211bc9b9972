//! Argument groups shared by several subcommands.

use bowloc::Choice;
use bowloc::features::{ExtractConfig, SiftParams};
use bowloc::geometry::verify::{Estimator, Model, Order, Rerank, VerifyParams};
use bowloc::search::stop::{GENERIC_PARAMETER, RULES, parse_rule};
use bowloc::search::{RuleSpec, SearchOptions, TileOrder};
use bowloc::sequence::{Motion, SequenceModel};
use bowloc::server::config::FilesConfig;
use clap::Args;
use clap::builder::{PossibleValue, PossibleValuesParser};
use std::path::PathBuf;

/// The vocabulary and map a command reads: the service's files (which
/// `make run` builds) unless named.
#[derive(Args, Debug, Clone)]
pub struct MapFiles {
    /// Vocabulary file (the service's by default, built by `make run`).
    #[arg(long, default_value_os_t = FilesConfig::default().vocabulary)]
    pub vocab: PathBuf,
    /// Map file, built with that vocabulary (the service's by default).
    #[arg(long, default_value_os_t = FilesConfig::default().map)]
    pub map: PathBuf,
}

impl MapFiles {
    /// An error that says how to get the default files, where one of them
    /// is taken by default and missing.
    pub fn check_defaults(&self) -> anyhow::Result<()> {
        let defaults = FilesConfig::default();
        for (given, default) in [
            (&self.vocab, &defaults.vocabulary),
            (&self.map, &defaults.map),
        ] {
            if given == default && !given.exists() {
                anyhow::bail!(
                    "{}: no such file; `make run` builds the default vocabulary and map, \
                     or give --vocab and --map",
                    given.display()
                );
            }
        }
        Ok(())
    }
}

/// How descriptors are extracted (recorded in the vocabulary).
#[derive(Args, Debug, Clone)]
pub struct ExtractArgs {
    /// Downscale images so the longer side is at most this (0 = never).
    #[arg(long, default_value_t = ExtractConfig::default().max_side)]
    pub max_side: u32,
    /// Use plain SIFT descriptors instead of RootSIFT.
    #[arg(long)]
    pub no_rootsift: bool,
    /// Keep at most this many strongest keypoints per image (0 = all).
    #[arg(long, default_value_t = 0)]
    pub max_features: u32,
    /// SIFT contrast threshold.
    #[arg(long, default_value_t = SiftParams::default().contrast_threshold)]
    pub contrast_threshold: f64,
    /// SIFT edge threshold.
    #[arg(long, default_value_t = SiftParams::default().edge_threshold)]
    pub edge_threshold: f64,
    /// SIFT layers per octave.
    #[arg(long, default_value_t = SiftParams::default().octave_layers)]
    pub octave_layers: u32,
    /// SIFT Gaussian sigma of the first octave.
    #[arg(long, default_value_t = SiftParams::default().sigma)]
    pub sigma: f64,
}

impl ExtractArgs {
    pub fn config(&self) -> ExtractConfig {
        ExtractConfig {
            max_side: self.max_side,
            rootsift: !self.no_rootsift,
            sift: SiftParams {
                max_features: self.max_features,
                octave_layers: self.octave_layers,
                contrast_threshold: self.contrast_threshold,
                edge_threshold: self.edge_threshold,
                sigma: self.sigma,
            },
        }
    }
}

/// A place window, checked as the configuration checks it.
pub fn place_window(text: &str) -> Result<u32, String> {
    let window: u32 = text
        .parse()
        .map_err(|e| format!("not a whole number ≥ 0: {e}"))?;
    SearchOptions::check_place_window(window)
}

/// A distinctness cut, checked as the configuration checks it.
pub fn min_distinct(text: &str) -> Result<f32, String> {
    let cut: f64 = text.parse().map_err(|e| format!("not a number: {e}"))?;
    SearchOptions::check_min_distinct(cut)
}

/// A [`Choice`]'s names, each with what it does, parsed to the choice.
pub fn choice_parser<T: Choice>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser as _;
    PossibleValuesParser::new(
        T::ALL
            .iter()
            .map(|c| PossibleValue::new(c.name()).help(c.about())),
    )
    .map(|name: String| T::from_name(&name).expect("a listed name"))
}

fn rule_parser() -> PossibleValuesParser {
    PossibleValuesParser::new(
        RULES
            .iter()
            .map(|r| PossibleValue::new(r.name).help(r.about)),
    )
}

/// The search: rule, its parameter, and ranking. Defaults are the service's
/// (`SearchOptions::recommended`), and the rule and its parameter go through
/// the registry's parser, as the service's query string does.
#[derive(Args, Debug, Clone)]
pub struct SearchArgs {
    /// Stopping rule. Default: the service's, place-z (with `query
    /// --sequence`, the sequence's: posterior).
    #[arg(long, value_parser = rule_parser())]
    pub rule: Option<String>,
    /// The rule's parameter, whatever its name (T of peak-mean, relative and
    /// stable-peak; also δ, f or m). Default: the recommended value when the
    /// rule is the recommended one.
    #[arg(long)]
    pub threshold: Option<f64>,
    /// δ of rules hoeffding and confident, in (0, 1).
    #[arg(long)]
    pub delta: Option<f64>,
    /// f of rule fixed: the share of the features to use, in (0, 1].
    #[arg(long)]
    pub fraction: Option<f64>,
    /// m of rule verified: the inliers that verify the answer (at the query's scale).
    #[arg(long)]
    pub inliers: Option<f64>,
    /// ε of rule posterior: the probability left to places other than the leader's.
    #[arg(long)]
    pub epsilon: Option<f64>,
    /// Also stop at a tile's end when the answer is geometrically verified
    /// with this many inliers at the query's scale (a vote rule only; the
    /// default rule has 12, 0 turns it off).
    #[arg(long)]
    pub or_verified: Option<f64>,
    /// Candidates to return.
    #[arg(long, default_value_t = SearchOptions::recommended().top_n)]
    pub top_n: usize,
    /// Permutation seed (random when absent; the answer reports it).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Features quantized per batch.
    #[arg(long, default_value_t = SearchOptions::recommended().block)]
    pub block: usize,
    /// Features voted before the rule is consulted (the warm-up). Default:
    /// 20 (with `query --sequence` and its rule, the sequence's: `auto`, a
    /// quarter of the map images' median feature count, at most 100).
    #[arg(long)]
    pub min_features: Option<usize>,
    /// Drop candidates scoring below this.
    #[arg(long, default_value_t = SearchOptions::recommended().min_score)]
    pub min_score: f32,
    /// Drop candidates whose distinctness is below this (0 to 1; 0.6 answers
    /// only when the leader stands out).
    #[arg(long, default_value_t = SearchOptions::recommended().min_distinct, value_parser = min_distinct)]
    pub min_distinct: f32,
    /// Vote plain tf-idf, without weighing votes by Hamming signatures.
    #[arg(long)]
    pub no_hamming: bool,
    /// Images on each side, along the map's order, that count as one place when a candidate's distinctness is measured.
    #[arg(long, default_value_t = SearchOptions::recommended().place_window, value_parser = place_window)]
    pub place_window: u32,
    /// The order tiles are extracted in.
    #[arg(long, default_value_t = SearchOptions::recommended().tile_order, value_parser = choice_parser::<TileOrder>())]
    pub tile_order: TileOrder,
    /// A time budget per image, in milliseconds from the start of decoding:
    /// a next tile is extracted only when it is expected to end within it
    /// (the first tile always; the stop kind is then `budget`). A budget
    /// too tight for three tiles starts with the coarse pass, unless
    /// `--tiles` is given.
    #[arg(long, value_parser = budget_ms)]
    pub budget_ms: Option<std::time::Duration>,
}

/// `--budget-ms`, checked as the service checks `budget_ms`.
fn budget_ms(text: &str) -> Result<std::time::Duration, String> {
    let ms: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    bowloc::search::budget::check_ms(ms)
}

impl SearchArgs {
    /// The parameters given, by name.
    fn given(&self) -> Vec<(&'static str, f64)> {
        [
            (GENERIC_PARAMETER, self.threshold),
            ("delta", self.delta),
            ("fraction", self.fraction),
            ("inliers", self.inliers),
            ("epsilon", self.epsilon),
        ]
        .into_iter()
        .filter_map(|(n, v)| v.map(|v| (n, v)))
        .collect()
    }

    /// The search asked for, the service's defaults for what is not.
    pub fn options(&self) -> anyhow::Result<SearchOptions> {
        let recommended = SearchOptions::recommended();
        self.options_over(&recommended.rule, recommended.min_features)
    }

    /// The search asked for, with `default_rule` and its warm-up
    /// `default_warmup` when no rule or parameter is given.
    pub fn options_over(
        &self,
        default_rule: &RuleSpec,
        default_warmup: usize,
    ) -> anyhow::Result<SearchOptions> {
        let recommended = SearchOptions::recommended();
        let given = self.given();
        let name = self.rule.as_deref().unwrap_or(&default_rule.name);
        let the_default = given.is_empty() && name == default_rule.name;
        let rule = if the_default {
            default_rule.clone()
        } else {
            parse_rule(name, &given).map_err(|e| match e.parameter {
                Some(p) if p != "rule" => anyhow::anyhow!("--{p}: {}", e.message),
                _ => anyhow::anyhow!("--rule: {}", e.message),
            })?
        };
        let rule = rule
            .or_verified(self.or_verified)
            .map_err(|e| anyhow::anyhow!("--or-verified: {e}"))?;
        anyhow::ensure!(self.top_n >= 1, "--top-n must be at least 1");
        anyhow::ensure!(self.block >= 1, "--block must be at least 1");
        Ok(SearchOptions {
            // set by the pipeline when the answer is verified
            finish_tile: false,
            rule,
            top_n: self.top_n,
            seed: self.seed.unwrap_or_else(bowloc::report::draw_seed),
            block: self.block,
            min_features: self.min_features.unwrap_or(if the_default {
                default_warmup
            } else {
                recommended.min_features
            }),
            min_score: self.min_score,
            min_distinct: self.min_distinct,
            deadline: None,
            budget: self.budget_ms,
            prior: None,
            hamming: if self.no_hamming {
                None
            } else {
                recommended.hamming
            },
            place_window: self.place_window,
            tile_order: self.tile_order,
            given_order: false,
            spare_core: None,
            // `query` turns it on when the map has its ORB side
            orb_pass: false,
        })
    }
}

/// The sequence filter's model (`--sequence`), defaults as the service's.
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// Evidence weight κ: a frame's summed vote h(j) after t features counts as log-likelihood κ·h(j)/√t.
    #[arg(long, default_value_t = SequenceModel::default().kappa)]
    pub kappa: f64,
    /// Chance per frame that the camera jumps anywhere in the map.
    #[arg(long, default_value_t = SequenceModel::default().motion.teleport)]
    pub teleport: f64,
    /// Spread σ of one frame's move (map images along the order).
    #[arg(long, default_value_t = SequenceModel::default().motion.sigma)]
    pub motion_sigma: f64,
    /// Expected move per frame along the map's order (map images).
    #[arg(long, default_value_t = SequenceModel::default().motion.drift)]
    pub drift: f64,
    /// Farthest move per frame from the expected position.
    #[arg(long, default_value_t = SequenceModel::default().motion.reach)]
    pub reach: f64,
    /// Map images the belief tracks.
    #[arg(long, default_value_t = SequenceModel::default().track)]
    pub track: usize,
    /// The leader's place for the rule posterior: map images within this many ids.
    #[arg(long, default_value_t = SequenceModel::default().window)]
    pub window: u32,
}

impl SequenceArgs {
    pub fn model(&self) -> anyhow::Result<SequenceModel> {
        let m = SequenceModel {
            kappa: self.kappa,
            track: self.track,
            window: self.window,
            motion: Motion {
                sigma: self.motion_sigma,
                drift: self.drift,
                reach: self.reach,
                teleport: self.teleport,
            },
            ..SequenceModel::default()
        };
        m.check().map_err(anyhow::Error::msg)?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bowloc::search::stop::parameter_names;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        search: SearchArgs,
    }

    fn parse(args: &[&str]) -> anyhow::Result<SearchOptions> {
        let mut all = vec!["t"];
        all.extend_from_slice(args);
        Cli::try_parse_from(all)?.search.options()
    }

    #[test]
    fn defaults_are_the_services_and_every_parameter_has_a_flag() {
        let o = parse(&[]).unwrap();
        let r = SearchOptions::recommended();
        assert_eq!(
            (o.rule, o.min_features, o.top_n),
            (r.rule, r.min_features, r.top_n)
        );
        let flags: Vec<String> = SearchArgs::augment_args(clap::Command::new("t"))
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .collect();
        for name in parameter_names() {
            assert!(flags.iter().any(|f| f == name), "no --{name}");
        }
        for rule in RULES {
            assert!(
                parse(&["--rule", rule.name]).is_ok() || rule.parameter.is_some(),
                "{}",
                rule.name
            );
        }
    }

    #[test]
    fn the_cli_refuses_what_the_api_refuses() {
        assert!(parse(&["--rule", "none", "--threshold", "2.5"]).is_err());
        assert!(parse(&["--rule", "peak-mean", "--delta", "0.1"]).is_err());
        assert!(parse(&["--rule", "relative", "--threshold", "1", "--delta", "0.1"]).is_err());
        assert!(parse(&["--rule", "nope"]).is_err());
        assert_eq!(
            parse(&["--rule", "hoeffding", "--delta", "0.1"])
                .unwrap()
                .rule
                .parameter,
            0.1
        );
        assert_eq!(
            parse(&["--rule", "verified", "--inliers", "12"])
                .unwrap()
                .rule
                .parameter,
            12.0
        );
    }
}

/// Geometric verification of the top vote candidates.
#[derive(Args, Debug, Clone)]
pub struct VerifyArgs {
    /// Verify the top vote candidates geometrically and re-rank them by
    /// inliers (the score becomes an inlier count, see --verify-order).
    #[arg(long)]
    pub verify: bool,
    /// Vote candidates verified.
    #[arg(long, default_value_t = VerifyParams::default().top_k)]
    pub verify_top_k: usize,
    /// Inliers for a candidate to count as verified (and word pairs for it
    /// to be fitted at all); unset, the model's own.
    #[arg(long, help = min_inliers_help())]
    pub min_inliers: Option<usize>,
    /// Skip words giving more (query, map) pairs than this between two
    /// images (the answer's re-ranking; the geometric stops check with
    /// --stop-max-word-pairs).
    #[arg(long, default_value_t = VerifyParams::default().max_word_pairs)]
    pub max_word_pairs: usize,
    /// Pair two features of a word only when their Hamming signatures differ
    /// in at most this many bits (64: every pair; the answer's re-ranking,
    /// the geometric stops check with --stop-max-hamming).
    #[arg(long, default_value_t = VerifyParams::default().max_hamming)]
    pub max_hamming: u32,
    /// Order of the verified candidates.
    #[arg(long, default_value_t = VerifyParams::default().order, value_parser = choice_parser::<Order>())]
    pub verify_order: Order,
    /// Which checked candidates that order moves.
    #[arg(long, default_value_t = VerifyParams::default().rerank, value_parser = choice_parser::<Rerank>())]
    pub verify_rerank: Rerank,
    /// Geometric model.
    #[arg(long, default_value_t = VerifyParams::default().model, value_parser = choice_parser::<Model>())]
    pub model: Model,
    /// Robust estimator.
    #[arg(long, default_value_t = VerifyParams::default().estimator, value_parser = choice_parser::<Estimator>())]
    pub estimator: Estimator,
    /// Inlier threshold in pixels of the extraction frame.
    #[arg(long, default_value_t = VerifyParams::default().threshold_px)]
    pub inlier_px: f64,
    /// Iteration cap of the robust estimator.
    #[arg(long, default_value_t = VerifyParams::default().max_iters)]
    pub fit_iters: u32,
    /// The rules `verified` and `or_verified` stop only on an answer whose
    /// inliers show the scene within e^±this of the query's scale.
    #[arg(long, default_value_t = VerifyParams::default().stop_log_scale)]
    pub stop_log_scale: f32,
    /// --max-hamming for the checks of the rules `verified` and
    /// `or_verified`.
    #[arg(long, default_value_t = VerifyParams::default().stop_max_hamming)]
    pub stop_max_hamming: u32,
    /// --max-word-pairs for the checks of the rules `verified` and
    /// `or_verified`.
    #[arg(long, default_value_t = VerifyParams::default().stop_max_word_pairs)]
    pub stop_max_word_pairs: usize,
}

/// `--min-inliers`'s help, with every model's default floor.
fn min_inliers_help() -> String {
    format!(
        "Inliers for a candidate to count as verified (and word pairs for it to be fitted at all) [default: the model's: {}]",
        Model::default_floors()
    )
}

impl VerifyArgs {
    pub fn params(&self) -> anyhow::Result<VerifyParams> {
        let p = VerifyParams {
            enabled: self.verify,
            top_k: self.verify_top_k,
            min_inliers: self.min_inliers,
            max_word_pairs: self.max_word_pairs,
            max_hamming: self.max_hamming,
            order: self.verify_order,
            rerank: self.verify_rerank,
            model: self.model,
            estimator: self.estimator,
            threshold_px: self.inlier_px,
            max_iters: self.fit_iters,
            stop_log_scale: self.stop_log_scale,
            stop_max_hamming: self.stop_max_hamming,
            stop_max_word_pairs: self.stop_max_word_pairs,
            ..VerifyParams::default()
        };
        p.validate().map_err(anyhow::Error::msg)?;
        Ok(p.resolved())
    }
}

/// `--vocab-seeds`: N (k-means seeds 1..=N) or a list of seeds, a seed
/// repeated counting once (`7,7` is seed 7 alone).
pub fn vocab_seeds(given: &[u64]) -> Vec<u64> {
    match given {
        [n] => (1..=*n).collect(),
        list => list.iter().fold(Vec::new(), |mut seeds, &s| {
            if !seeds.contains(&s) {
                seeds.push(s);
            }
            seeds
        }),
    }
}

/// A dataset folder's name (the last component of its canonical path), for
/// default output and cache folders.
pub fn dataset_name(dataset: &std::path::Path) -> String {
    dataset
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "dataset".into())
}

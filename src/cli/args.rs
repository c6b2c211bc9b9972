//! Argument groups shared by several subcommands.

use bowloc::features::{ExtractConfig, SiftParams};
use bowloc::geometry::verify::{Estimator, Model, VerifyParams};
use bowloc::search::{RuleSpec, SearchOptions};
use clap::Args;

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

/// The search: rule, its parameter, and ranking.
#[derive(Args, Debug, Clone)]
pub struct SearchArgs {
    /// Stopping rule: none, peak-mean, relative, stable-peak, hoeffding, fixed.
    #[arg(long, default_value = "none")]
    pub rule: String,
    /// Parameter of rules that take a threshold (T of rules 1–3).
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Parameter of rules that take a confidence δ (hoeffding).
    #[arg(long, conflicts_with = "threshold")]
    pub delta: Option<f64>,
    /// Parameter of rule `fixed` (fraction of features).
    #[arg(long, conflicts_with_all = ["threshold", "delta"])]
    pub fraction: Option<f64>,
    /// Candidates to return.
    #[arg(long, default_value_t = 5)]
    pub top_n: usize,
    /// Permutation seed (random when absent; the answer reports it).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Features quantized per batch.
    #[arg(long, default_value_t = 32)]
    pub block: usize,
    /// Features voted before the rule is consulted.
    #[arg(long, default_value_t = 0)]
    pub min_features: usize,
    /// Drop candidates scoring below this.
    #[arg(long, default_value_t = 0.0)]
    pub min_score: f32,
}

impl SearchArgs {
    pub fn options(&self) -> anyhow::Result<SearchOptions> {
        let parameter = self.threshold.or(self.delta).or(self.fraction);
        let rule = RuleSpec::new(&self.rule, parameter).map_err(anyhow::Error::msg)?;
        anyhow::ensure!(self.top_n >= 1, "--top-n must be at least 1");
        anyhow::ensure!(self.block >= 1, "--block must be at least 1");
        Ok(SearchOptions {
            rule,
            top_n: self.top_n,
            seed: self.seed.unwrap_or_else(bowloc::report::draw_seed),
            block: self.block,
            min_features: self.min_features,
            min_score: self.min_score,
            deadline: None,
        })
    }
}

/// Geometric verification of the top vote candidates.
#[derive(Args, Debug, Clone)]
pub struct VerifyArgs {
    /// Verify the top vote candidates geometrically and re-rank them by
    /// inliers (the score becomes the inlier count).
    #[arg(long)]
    pub verify: bool,
    /// Vote candidates verified.
    #[arg(long, default_value_t = VerifyParams::default().top_k)]
    pub verify_top_k: usize,
    /// Inliers for a candidate to count as verified.
    #[arg(long, default_value_t = VerifyParams::default().min_inliers)]
    pub min_inliers: usize,
    /// Skip words giving more (query, map) pairs than this between two images.
    #[arg(long, default_value_t = VerifyParams::default().max_word_pairs)]
    pub max_word_pairs: usize,
    /// Geometric model: homography or fundamental.
    #[arg(long, default_value = "homography")]
    pub model: Model,
    /// Robust estimator: ransac or magsac.
    #[arg(long, default_value = "magsac")]
    pub estimator: Estimator,
    /// Inlier threshold in pixels of the extraction frame.
    #[arg(long, default_value_t = VerifyParams::default().threshold_px)]
    pub inlier_px: f64,
    /// Iteration cap of the robust estimator.
    #[arg(long, default_value_t = VerifyParams::default().max_iters)]
    pub fit_iters: u32,
}

impl VerifyArgs {
    pub fn params(&self) -> anyhow::Result<VerifyParams> {
        let p = VerifyParams {
            enabled: self.verify,
            top_k: self.verify_top_k,
            min_inliers: self.min_inliers,
            max_word_pairs: self.max_word_pairs,
            model: self.model,
            estimator: self.estimator,
            threshold_px: self.inlier_px,
            max_iters: self.fit_iters,
            ..VerifyParams::default()
        };
        p.validate().map_err(anyhow::Error::msg)?;
        Ok(p)
    }
}

//! Argument groups shared by several subcommands.

use bowloc::features::{ExtractConfig, SiftParams};
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

//! The early-stopping search, the heart of bowloc. Given a query's N
//! descriptors it runs permute → quantize → vote → stop → rank:
//!
//! - [`permute`]: a seeded random order of the features;
//! - quantize: blocks of `block` features at a time through a
//!   [`Quantizer`](crate::quantize::Quantizer);
//! - [`vote`]: one feature at a time, in permuted order, into the histogram;
//! - [`stop`]: the rule is checked after every vote, so a stop in mid-block
//!   wastes at most one block of quantization;
//! - [`rank`]: top-n images with scores comparable across stop points.
//!
//! Pure Rust over plain arrays: no OpenCV, no HTTP.

pub mod permute;
pub mod rank;
pub mod stop;
pub mod vote;

pub use rank::Ranked;
pub use stop::{RuleSpec, StopRule};
pub use vote::{Needs, Tally, Voter};

use crate::index::MapIndex;
use crate::quantize::Quantizer;
use ndarray::{Array2, ArrayView2};
use serde::Serialize;
use std::time::{Duration, Instant};

/// How to run one search.
#[derive(Debug, Clone)]
pub struct SearchOptions {
    pub rule: RuleSpec,
    /// Candidates to return.
    pub top_n: usize,
    /// Seed of the feature permutation.
    pub seed: u64,
    /// Features quantized per batch.
    pub block: usize,
    /// The rule is not consulted before this many features have voted.
    pub min_features: usize,
    /// Candidates scoring below this are dropped.
    pub min_score: f32,
    /// Give up (returning the answer so far) once this instant passes.
    pub deadline: Option<Instant>,
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self {
            rule: RuleSpec::new("none", None).expect("built-in rule"),
            top_n: 5,
            seed: 0,
            block: 32,
            min_features: 0,
            min_score: 0.0,
            deadline: None,
        }
    }
}

/// Why the search ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopKind {
    /// The stopping rule fired.
    Rule,
    /// Every feature was used.
    Exhausted,
    /// The deadline passed.
    Deadline,
}

/// Where and why the search stopped.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct StopInfo {
    pub kind: StopKind,
    /// Features voted when it stopped.
    pub at_feature: usize,
    pub detail: String,
}

/// Time spent in the search's own stages.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct SearchTimings {
    pub quantize: Duration,
    pub vote: Duration,
}

/// The answer of one search.
#[derive(Debug, Clone)]
pub struct SearchOutcome {
    pub candidates: Vec<Ranked>,
    pub features_total: usize,
    pub features_used: usize,
    pub stop: StopInfo,
    pub timings: SearchTimings,
}

impl SearchOutcome {
    /// Fraction of the features that were quantized and voted (1 for none).
    pub fn fraction_used(&self) -> f64 {
        if self.features_total == 0 {
            1.0
        } else {
            self.features_used as f64 / self.features_total as f64
        }
    }
}

/// Search with descriptors: quantize each block of permuted rows with `quantizer`.
pub fn search(
    quantizer: &dyn Quantizer,
    map: &MapIndex,
    descriptors: ArrayView2<'_, f32>,
    options: &SearchOptions,
) -> SearchOutcome {
    let dim = descriptors.ncols();
    let mut block = Array2::<f32>::zeros((options.block.max(1), dim));
    search_with(map, descriptors.nrows(), options, |indices, words| {
        for (dst, &i) in block.rows_mut().into_iter().zip(indices) {
            let mut dst = dst;
            dst.assign(&descriptors.row(i as usize));
        }
        quantizer.quantize(block.slice(ndarray::s![..indices.len(), ..]), words);
    })
}

/// Search over words already known: feature i quantizes to `words[i]`. Gives
/// exactly the outcome of [`search`] with a quantizer that returns those words
/// (used by evaluation, which quantizes each query once and votes many times).
pub fn search_words(map: &MapIndex, words: &[u32], options: &SearchOptions) -> SearchOutcome {
    search_with(map, words.len(), options, |indices, out| {
        for (o, &i) in out.iter_mut().zip(indices) {
            *o = words[i as usize];
        }
    })
}

/// The driver. `quantize(indices, words)` fills `words[..indices.len()]` with
/// the words of the features at `indices` (original numbering).
pub fn search_with(
    map: &MapIndex,
    total: usize,
    options: &SearchOptions,
    mut quantize: impl FnMut(&[u32], &mut [u32]),
) -> SearchOutcome {
    let view = map.view();
    let order = permute::permutation(total, options.seed);
    let mut rule = options.rule.build(&stop::RuleContext {
        top_n: options.top_n,
    });
    let mut voter = Voter::with_needs(&view, total, rule.needs());
    let mut words = vec![0u32; options.block.max(1)];
    let mut timings = SearchTimings::default();
    let mut stop = None;
    'blocks: for indices in order.chunks(options.block.max(1)) {
        if options.deadline.is_some_and(|d| Instant::now() >= d) {
            stop = Some((StopKind::Deadline, "deadline passed".to_owned()));
            break;
        }
        let started = Instant::now();
        quantize(indices, &mut words[..indices.len()]);
        let quantized = Instant::now();
        timings.quantize += quantized - started;
        for &w in &words[..indices.len()] {
            voter.vote(w);
            if voter.tally().features >= options.min_features
                && let Some(why) = rule.check(&voter)
            {
                stop = Some((StopKind::Rule, why));
                timings.vote += quantized.elapsed();
                break 'blocks;
            }
        }
        timings.vote += quantized.elapsed();
    }
    let (kind, detail) =
        stop.unwrap_or_else(|| (StopKind::Exhausted, "all features used".to_owned()));
    let used = voter.tally().features;
    SearchOutcome {
        candidates: rank::top_n(&voter, options.top_n, options.min_score),
        features_total: total,
        features_used: used,
        stop: StopInfo {
            kind,
            at_feature: used,
            detail,
        },
        timings,
    }
}

#[cfg(test)]
mod tests;

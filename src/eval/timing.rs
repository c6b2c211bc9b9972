//! What each stage of a query costs in time: extraction (measured when the
//! query's descriptors were extracted, kept in the cache), quantization (the
//! real blocked quantizer timed over all of the query's descriptors once,
//! then charged per feature used) and voting (timed inside the search), with
//! their median and 95th percentile over queries. Extraction and
//! quantization, and geometric verification, are timed by the working
//! thread's CPU time, so figures taken while other processes share the cores
//! price the work closer to what a quiet machine would (not exactly: a busy
//! sibling hyperthread still slows a core); voting is timed on the wall clock
//! inside the search (a small share of a request).

use crate::quantize::Quantizer;
use crate::vocabulary::HammingEmbedding;
use crate::vocabulary::hamming::sign_or_zero;
use cpu_time::ThreadTime;
use ndarray::{ArrayView2, Axis};
use serde::Serialize;

/// A query's words and signatures, and what quantizing one of its features
/// cost.
#[derive(Debug, Clone)]
pub struct QueryWords {
    /// Word of each descriptor, in the original order.
    pub words: Vec<u32>,
    /// Hamming signature of each descriptor (all 0 without an embedding).
    pub signatures: Vec<u64>,
    /// Milliseconds per feature with the blocked quantizer, signing included.
    pub quantize_ms_per_feature: f64,
}

/// Quantize every row of `descriptors` in blocks of `block` rows, as the
/// search does, timed by the thread's CPU time. The pass runs twice and the
/// faster one is kept (the first warms the caches).
pub fn quantize_timed(
    quantizer: &dyn Quantizer,
    signer: Option<&HammingEmbedding>,
    descriptors: ArrayView2<'_, f32>,
    block: usize,
) -> QueryWords {
    let mut words = vec![0u32; descriptors.nrows()];
    let mut signatures = vec![0u64; descriptors.nrows()];
    let mut fastest = f64::INFINITY;
    for _ in 0..2 {
        let started = ThreadTime::now();
        for ((rows, out), signed) in descriptors
            .axis_chunks_iter(Axis(0), block.max(1))
            .zip(words.chunks_mut(block.max(1)))
            .zip(signatures.chunks_mut(block.max(1)))
        {
            quantizer.quantize(rows, out);
            sign_or_zero(signer, rows, out, signed);
        }
        fastest = fastest.min(started.elapsed().as_secs_f64() * 1e3);
    }
    QueryWords {
        quantize_ms_per_feature: if words.is_empty() {
            0.0
        } else {
            fastest / words.len() as f64
        },
        words,
        signatures,
    }
}

/// Median and 95th percentile.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Quantiles {
    pub median: f64,
    pub p95: f64,
}

/// The value at quantile `q` by the nearest-rank rule (`values` sorted).
fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Median and p95 of `values` (nearest rank; zeros when empty).
pub fn quantiles(values: &[f64]) -> Quantiles {
    let mut sorted = values.to_vec();
    sorted.sort_unstable_by(f64::total_cmp);
    Quantiles {
        median: nearest_rank(&sorted, 0.5),
        p95: nearest_rank(&sorted, 0.95),
    }
}

/// The median of `values` (nearest rank; 0 when empty).
pub fn median(values: &[f64]) -> f64 {
    quantiles(values).median
}

/// One query's stage times in one run, in milliseconds.
#[derive(Debug, Clone, Copy, Default)]
pub struct StageSample {
    pub extract: f64,
    pub quantize: f64,
    pub vote: f64,
    /// Re-ranking by geometric verification (0 without).
    pub verify: f64,
}

impl StageSample {
    /// The request's time: every stage.
    pub fn total(&self) -> f64 {
        self.extract + self.quantize + self.vote + self.verify
    }
}

/// Quantiles of each stage and of their sum, in milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StageTimes {
    pub extract: Quantiles,
    pub quantize: Quantiles,
    pub vote: Quantiles,
    pub verify: Quantiles,
    /// Quantize + vote: the part the stopping rule saves.
    pub search: Quantiles,
    pub total: Quantiles,
}

/// Summarise per-query samples stage by stage.
pub fn summarize(samples: &[StageSample]) -> StageTimes {
    let of = |f: fn(&StageSample) -> f64| quantiles(&samples.iter().map(f).collect::<Vec<_>>());
    StageTimes {
        extract: of(|s| s.extract),
        quantize: of(|s| s.quantize),
        vote: of(|s| s.vote),
        verify: of(|s| s.verify),
        search: of(|s| s.quantize + s.vote),
        total: of(StageSample::total),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quantize::naive_nearest;
    use crate::vocabulary::{Vocabulary, VocabularyMeta};
    use ndarray::Array2;

    #[test]
    fn nearest_rank_quantiles() {
        let v: Vec<f64> = (1..=20).rev().map(f64::from).collect();
        assert_eq!(
            quantiles(&v),
            Quantiles {
                median: 10.0,
                p95: 19.0
            }
        );
        assert_eq!(
            quantiles(&[7.0]),
            Quantiles {
                median: 7.0,
                p95: 7.0
            }
        );
        assert_eq!(quantiles(&[]), Quantiles::default());
        let s = summarize(&[
            StageSample {
                extract: 1.0,
                quantize: 2.0,
                vote: 3.0,
                verify: 0.0,
            },
            StageSample {
                extract: 10.0,
                quantize: 20.0,
                vote: 30.0,
                verify: 0.0,
            },
        ]);
        assert_eq!(
            s.total,
            Quantiles {
                median: 6.0,
                p95: 60.0
            }
        );
        assert_eq!(s.vote.median, 3.0);
    }

    #[test]
    fn blocked_quantization_gives_the_nearest_words() {
        let centroids = Array2::from_shape_fn((7, 4), |(i, j)| ((i * 37 + j * 101) as f32).sin());
        let vocab = Vocabulary::from_centroids(centroids.clone(), VocabularyMeta::default());
        let rows = Array2::from_shape_fn((45, 4), |(i, j)| ((i * 53 + j * 17 + 5) as f32).cos());
        let q = quantize_timed(&vocab.exact_quantizer(), None, rows.view(), 8);
        assert_eq!(q.words.len(), 45);
        for (row, &w) in rows.rows().into_iter().zip(&q.words) {
            assert_eq!(w, naive_nearest(centroids.view(), row.as_slice().unwrap()));
        }
        assert!(q.quantize_ms_per_feature >= 0.0);
        let empty = Array2::<f32>::zeros((0, 4));
        assert_eq!(
            quantize_timed(&vocab.exact_quantizer(), None, empty.view(), 8).quantize_ms_per_feature,
            0.0
        );
    }
}

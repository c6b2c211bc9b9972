//! Hamming embedding: a 64-bit signature per feature that says where in its
//! visual word's cell the descriptor lies (Jégou, Douze & Schmid, "Hamming
//! embedding and weak geometric consistency for large scale image search",
//! ECCV 2008).
//!
//! A fixed random orthogonal projection P (64 × D, drawn from the
//! vocabulary's seed) maps a descriptor x to 64 values Px; bit b of the
//! signature is set when (Px)_b exceeds the median of that value over the
//! training descriptors of the same word. Two features of one word whose
//! signatures differ in few bits have close descriptors, so a vote between
//! them can be trusted more than a vote between two far corners of the cell
//! (`crate::search::vote` weighs votes by it).
//!
//! A vocabulary without an embedding signs every feature 0: all distances
//! are 0 and voting is plain tf-idf.

use ndarray::{Array2, ArrayView2};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Bits per signature.
pub const BITS: usize = 64;

/// A word needs this many training descriptors for medians of its own;
/// fewer, and it uses the medians over all words.
const MIN_PER_WORD: usize = 8;

/// Number of bits in which two signatures differ.
#[inline]
pub fn distance(a: u64, b: u64) -> u32 {
    (a ^ b).count_ones()
}

/// The projection and the per-word thresholds.
#[derive(Debug, Clone, PartialEq)]
pub struct HammingEmbedding {
    dim: usize,
    /// `BITS × dim`, rows orthonormal.
    projection: Array2<f32>,
    /// `words × BITS`: the medians.
    thresholds: Array2<f32>,
}

impl HammingEmbedding {
    /// Learn the thresholds from training descriptors (rows) and their words
    /// (`words[i]` is row i's word, below `k`).
    pub fn train(descriptors: ArrayView2<'_, f32>, words: &[u32], k: usize, seed: u64) -> Self {
        let dim = descriptors.ncols();
        let projection = random_orthonormal(BITS, dim, seed);
        let projected = descriptors.dot(&projection.t());
        let mut by_word: Vec<Vec<usize>> = vec![Vec::new(); k];
        for (i, &w) in words.iter().enumerate().take(projected.nrows()) {
            if let Some(list) = by_word.get_mut(w as usize) {
                list.push(i);
            }
        }
        let all: Vec<usize> = (0..projected.nrows()).collect();
        let global = medians(&projected, &all);
        let mut thresholds = Array2::<f32>::zeros((k, BITS));
        for (w, rows) in by_word.iter().enumerate() {
            let m = if rows.len() >= MIN_PER_WORD {
                medians(&projected, rows)
            } else {
                global.clone()
            };
            thresholds.row_mut(w).assign(&ndarray::ArrayView1::from(&m));
        }
        Self {
            dim,
            projection,
            thresholds,
        }
    }

    /// An embedding from stored parts: `projection` is `BITS × dim` and
    /// `thresholds` is `words × BITS`, row-major.
    pub fn from_parts(
        projection: &[f32],
        thresholds: &[f32],
        dim: usize,
        words: usize,
    ) -> Result<Self, String> {
        if projection.len() != BITS * dim || thresholds.len() != words * BITS {
            return Err(format!(
                "Hamming embedding holds {} projection and {} threshold values for {words} words of {dim} dimensions",
                projection.len(),
                thresholds.len()
            ));
        }
        if projection.iter().chain(thresholds).any(|v| !v.is_finite()) {
            return Err("Hamming embedding holds NaN or infinite values".into());
        }
        Ok(Self {
            dim,
            projection: Array2::from_shape_vec((BITS, dim), projection.to_vec())
                .map_err(|e| e.to_string())?,
            thresholds: Array2::from_shape_vec((words, BITS), thresholds.to_vec())
                .map_err(|e| e.to_string())?,
        })
    }

    pub fn projection(&self) -> &[f32] {
        self.projection.as_slice().expect("standard layout")
    }

    pub fn thresholds(&self) -> &[f32] {
        self.thresholds.as_slice().expect("standard layout")
    }

    /// Signatures of `descriptors` (rows) quantized to `words`, into `out`
    /// (one per row). A word beyond the thresholds, or a row of another
    /// width, signs 0.
    pub fn sign(&self, descriptors: ArrayView2<'_, f32>, words: &[u32], out: &mut [u64]) {
        if descriptors.ncols() != self.dim {
            out.fill(0);
            return;
        }
        let projected = descriptors.dot(&self.projection.t());
        let thresholds = self.thresholds();
        for ((row, &w), o) in projected.outer_iter().zip(words).zip(out.iter_mut()) {
            let at = w as usize * BITS;
            *o = match thresholds.get(at..at + BITS) {
                Some(t) => row
                    .iter()
                    .zip(t)
                    .enumerate()
                    .fold(0u64, |s, (b, (&v, &m))| s | (((v > m) as u64) << b)),
                None => 0,
            };
        }
    }
}

/// Signatures of `descriptors` quantized to `words` by `embedding`, or all 0
/// without one (plain tf-idf).
pub fn sign_or_zero(
    embedding: Option<&HammingEmbedding>,
    descriptors: ArrayView2<'_, f32>,
    words: &[u32],
    out: &mut [u64],
) {
    match embedding {
        Some(he) => he.sign(descriptors, words, out),
        None => out.fill(0),
    }
}

/// Per-column medians of the rows `rows` of `values`.
fn medians(values: &Array2<f32>, rows: &[usize]) -> Vec<f32> {
    let mut column = Vec::with_capacity(rows.len());
    (0..values.ncols())
        .map(|b| {
            column.clear();
            column.extend(rows.iter().map(|&i| values[[i, b]]));
            if column.is_empty() {
                return 0.0;
            }
            let mid = column.len() / 2;
            *column.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
        })
        .collect()
}

/// `rows × dim` with orthonormal rows (Gram–Schmidt on Gaussian draws;
/// `rows ≤ dim`).
fn random_orthonormal(rows: usize, dim: usize, seed: u64) -> Array2<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4841_4d4d_494e_4721);
    let mut p = Array2::<f64>::zeros((rows, dim));
    for i in 0..rows {
        let mut row: Vec<f64> = (0..dim)
            .map(|_| {
                let u: f64 = rng.random::<f64>().max(1e-12);
                let v: f64 = rng.random::<f64>();
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            })
            .collect();
        for k in 0..i.min(dim) {
            let d: f64 = row.iter().zip(p.row(k)).map(|(a, b)| a * b).sum();
            for (r, b) in row.iter_mut().zip(p.row(k)) {
                *r -= d * b;
            }
        }
        let n = row.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
        for (c, r) in row.iter().enumerate() {
            p[[i, c]] = r / n;
        }
    }
    p.mapv(|v| v as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gaussian(n: usize, dim: usize, seed: u64) -> Array2<f32> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        Array2::from_shape_fn((n, dim), |_| rng.random::<f32>() - 0.5)
    }

    #[test]
    fn the_projection_is_orthonormal() {
        let p = random_orthonormal(BITS, 128, 3);
        let g = p.dot(&p.t());
        for i in 0..BITS {
            for j in 0..BITS {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g[[i, j]] - want).abs() < 1e-4, "{i},{j}: {}", g[[i, j]]);
            }
        }
    }

    #[test]
    fn each_bit_splits_its_words_training_set_in_half() {
        let d = gaussian(2000, 16, 1);
        let words: Vec<u32> = (0..2000).map(|i| (i % 2) as u32).collect();
        let he = HammingEmbedding::train(d.view(), &words, 2, 7);
        let mut sigs = vec![0u64; 2000];
        he.sign(d.view(), &words, &mut sigs);
        for b in 0..BITS {
            let set = sigs.iter().filter(|s| *s >> b & 1 == 1).count();
            assert!((950..=1050).contains(&set), "bit {b}: {set} of 2000 set");
        }
    }

    #[test]
    fn near_descriptors_get_near_signatures() {
        let d = gaussian(1000, 32, 2);
        let words = vec![0u32; 1000];
        let he = HammingEmbedding::train(d.view(), &words, 1, 1);
        let x = d.slice(ndarray::s![0..1, ..]).to_owned();
        let near = &x + 0.01;
        let far = gaussian(1, 32, 99);
        let mut s = [0u64; 3];
        he.sign(x.view(), &[0], &mut s[0..1]);
        he.sign(near.view(), &[0], &mut s[1..2]);
        he.sign(far.view(), &[0], &mut s[2..3]);
        assert!(distance(s[0], s[1]) < 8, "{}", distance(s[0], s[1]));
        assert!(distance(s[0], s[2]) > distance(s[0], s[1]));
    }

    #[test]
    fn parts_round_trip_and_bad_parts_are_refused() {
        let d = gaussian(100, 8, 4);
        let he = HammingEmbedding::train(d.view(), &vec![0; 100], 3, 1);
        let back = HammingEmbedding::from_parts(he.projection(), he.thresholds(), 8, 3).unwrap();
        assert_eq!(back, he);
        assert!(HammingEmbedding::from_parts(he.projection(), he.thresholds(), 8, 4).is_err());
        let mut nan = he.thresholds().to_vec();
        nan[0] = f32::NAN;
        assert!(HammingEmbedding::from_parts(he.projection(), &nan, 8, 3).is_err());
    }

    #[test]
    fn unknown_words_and_other_widths_sign_zero() {
        let d = gaussian(50, 8, 5);
        let he = HammingEmbedding::train(d.view(), &[0; 50], 1, 1);
        let mut s = [7u64; 2];
        he.sign(d.slice(ndarray::s![0..2, ..]), &[5, 9], &mut s);
        assert_eq!(s, [0, 0]);
        let wide = gaussian(2, 9, 1);
        he.sign(wide.view(), &[0, 0], &mut s);
        assert_eq!(s, [0, 0]);
    }
}

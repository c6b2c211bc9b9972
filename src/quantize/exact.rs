//! Exact nearest-centroid search as a blocked matrix multiply:
//! ‖x − c‖² = ‖x‖² − 2·x·c + ‖c‖², and ‖x‖² does not change the argmin, so the
//! kernel computes ‖c‖² − 2·X·Cᵀ with `gemm` over tiles of centroids and keeps
//! the running minimum per row. Centroid norms are precomputed once.

use super::Quantizer;
use ndarray::ArrayView2;
use std::cell::RefCell;

/// Centroids per tile: the distance tile of a block stays in L2.
const TILE: usize = 2048;

/// Exact quantizer over a borrowed centroid matrix (`K × D`, row-major).
pub struct ExactQuantizer<'a> {
    centroids: &'a [f32],
    norms: &'a [f32],
    k: usize,
    dim: usize,
}

thread_local! {
    static SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

impl<'a> ExactQuantizer<'a> {
    /// `norms[k]` must be ‖centroid k‖².
    pub fn new(centroids: &'a [f32], norms: &'a [f32], dim: usize) -> Self {
        assert!(dim > 0 && centroids.len() % dim == 0);
        let k = centroids.len() / dim;
        assert_eq!(norms.len(), k, "one norm per centroid");
        Self {
            centroids,
            norms,
            k,
            dim,
        }
    }
}

/// ‖row‖² of each row of a row-major matrix.
pub fn squared_norms(rows: &[f32], dim: usize) -> Vec<f32> {
    rows.chunks_exact(dim)
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect()
}

impl Quantizer for ExactQuantizer<'_> {
    fn words(&self) -> usize {
        self.k
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn quantize(&self, block: ArrayView2<'_, f32>, out: &mut [u32]) {
        let b = block.nrows();
        if b == 0 {
            return;
        }
        assert_eq!(block.ncols(), self.dim, "descriptor dimension");
        let block = block.as_standard_layout();
        let x = block.as_slice().expect("standard layout");
        let mut best = vec![f32::INFINITY; b];
        SCRATCH.with_borrow_mut(|scratch| {
            let tile = TILE.min(self.k);
            scratch.resize(b * tile, 0.0);
            for start in (0..self.k).step_by(tile) {
                let n = tile.min(self.k - start);
                let c = &self.centroids[start * self.dim..(start + n) * self.dim];
                let dst = &mut scratch[..b * n];
                // dst[i, j] = x_i · c_j; dst row-major b × n, lhs b × d row-major,
                // rhs d × n = Cᵀ (element (p, j) at c[j·d + p]).
                // SAFETY: all pointers cover the extents given, strides match the
                // layouts described above, dst does not alias lhs or rhs.
                unsafe {
                    gemm::gemm(
                        b,
                        n,
                        self.dim,
                        dst.as_mut_ptr(),
                        1,
                        n as isize,
                        false,
                        x.as_ptr(),
                        1,
                        self.dim as isize,
                        c.as_ptr(),
                        self.dim as isize,
                        1,
                        0.0,
                        1.0,
                        false,
                        false,
                        false,
                        gemm::Parallelism::None,
                    );
                }
                let norms = &self.norms[start..start + n];
                for (i, row) in dst.chunks_exact(n).enumerate() {
                    let (mut best_d, mut best_k) = (best[i], out[i]);
                    for (j, (&dot, &norm)) in row.iter().zip(norms).enumerate() {
                        let d = norm - 2.0 * dot;
                        if d < best_d {
                            best_d = d;
                            best_k = (start + j) as u32;
                        }
                    }
                    best[i] = best_d;
                    out[i] = best_k;
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quantize::naive_nearest;
    use ndarray::Array2;
    use rand::{RngExt, SeedableRng};

    fn random(rows: usize, dim: usize, seed: u64) -> Array2<f32> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        Array2::from_shape_fn((rows, dim), |_| rng.random::<f32>())
    }

    #[test]
    fn blocked_kernel_matches_naive_argmin() {
        for &(k, b) in &[(1, 1), (7, 3), (300, 32), (TILE + 17, 64), (5000, 5)] {
            let dim = 128;
            let c = random(k, dim, k as u64);
            let x = random(b, dim, 99 + b as u64);
            let norms = squared_norms(c.as_slice().unwrap(), dim);
            let q = ExactQuantizer::new(c.as_slice().unwrap(), &norms, dim);
            let mut out = vec![0u32; b];
            q.quantize(x.view(), &mut out);
            for (i, row) in x.rows().into_iter().enumerate() {
                let want = naive_nearest(c.view(), row.as_slice().unwrap());
                if out[i] != want {
                    // ties or rounding: the distances must agree closely
                    let d = |k: u32| -> f32 {
                        c.row(k as usize)
                            .iter()
                            .zip(row.iter())
                            .map(|(a, b)| (a - b) * (a - b))
                            .sum()
                    };
                    assert!(
                        (d(out[i]) - d(want)).abs() < 1e-3,
                        "k={k} b={b} row {i}: got {} want {want}",
                        out[i]
                    );
                }
            }
        }
    }

    #[test]
    fn exact_hit_on_centroid_itself() {
        let c = random(1000, 128, 5);
        let norms = squared_norms(c.as_slice().unwrap(), 128);
        let q = ExactQuantizer::new(c.as_slice().unwrap(), &norms, 128);
        let mut out = vec![0u32; 1000];
        q.quantize(c.view(), &mut out);
        assert!(out.iter().enumerate().all(|(i, &w)| w == i as u32));
    }
}

//! Exact nearest-centroid search, blocked. ‖x − c‖² = ‖x‖² − 2·x·c + ‖c‖² and
//! ‖x‖² does not change the argmin, so the kernels compute ‖c‖² − 2·x·c for a
//! block of descriptors against every centroid and keep a running minimum.
//!
//! Centroids are packed once into panels of 16 (`[panel][dim][16]`), so one
//! vector load yields one component of 16 centroids; a register tile of
//! several descriptors × 32 centroids is accumulated with FMAs, and the
//! argmin is taken lane-wise in registers. Panels are walked in L2-sized
//! tiles, each reused by every descriptor of the block. The kernel is picked
//! at run time (AVX-512, AVX2+FMA); elsewhere a `gemm` matrix multiply does
//! the same computation.

use super::Quantizer;
use super::kernels::{self, Kernel, LANES};
use ndarray::ArrayView2;
use std::cell::RefCell;

/// Panels per L2 tile (16 panels × 128 dims × 16 lanes × 4 B = 128 KiB).
const TILE_PANELS: usize = 16;

/// Exact quantizer owning a packed copy of the centroids.
pub struct ExactQuantizer {
    k: usize,
    dim: usize,
    /// `n_panels × dim × LANES`; padding centroids are zero.
    panels: Vec<f32>,
    /// `n_panels × LANES` squared norms; padding is +∞ so it never wins.
    norms: Vec<f32>,
    /// Row-major centroids, for the `gemm` kernel.
    rows: Vec<f32>,
    kernel: Kernel,
}

thread_local! {
    static BEST: RefCell<(Vec<f32>, Vec<u32>, Vec<f32>)> =
        const { RefCell::new((Vec::new(), Vec::new(), Vec::new())) };
}

/// ‖row‖² of each row of a row-major matrix.
pub fn squared_norms(rows: &[f32], dim: usize) -> Vec<f32> {
    rows.chunks_exact(dim)
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect()
}

impl ExactQuantizer {
    /// Pack `centroids` (`K × dim`, row-major) with the fastest kernel this
    /// CPU supports.
    pub fn new(centroids: &[f32], dim: usize) -> Self {
        Self::with_kernel(centroids, dim, Kernel::detect())
    }

    /// Pack for a given kernel (benchmarks and tests compare them).
    pub fn with_kernel(centroids: &[f32], dim: usize, kernel: Kernel) -> Self {
        assert!(
            dim > 0 && centroids.len().is_multiple_of(dim),
            "K × dim centroids"
        );
        assert!(
            kernel.available(),
            "{kernel:?} is not supported on this CPU"
        );
        let k = centroids.len() / dim;
        // an even number of panels: the kernels take them two at a time
        let n_panels = k.div_ceil(LANES).next_multiple_of(2);
        let mut panels = vec![0f32; n_panels * dim * LANES];
        let mut norms = vec![f32::INFINITY; n_panels * LANES];
        let row_norms = squared_norms(centroids, dim);
        for (c, row) in centroids.chunks_exact(dim).enumerate() {
            let (p, lane) = (c / LANES, c % LANES);
            for (d, &v) in row.iter().enumerate() {
                panels[(p * dim + d) * LANES + lane] = v;
            }
            norms[c] = row_norms[c];
        }
        Self {
            k,
            dim,
            panels,
            norms,
            rows: centroids.to_vec(),
            kernel,
        }
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }
}

impl Quantizer for ExactQuantizer {
    fn words(&self) -> usize {
        self.k
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn quantize(&self, block: ArrayView2<'_, f32>, out: &mut [u32]) {
        self.nearest(block, out, None);
    }
}

impl ExactQuantizer {
    /// The nearest word of each row into `words`, and, when asked, its
    /// distance up to the row's own ‖x‖² (‖c‖² − 2·x·c) into `distances`.
    pub fn nearest(
        &self,
        block: ArrayView2<'_, f32>,
        words: &mut [u32],
        mut distances: Option<&mut [f32]>,
    ) {
        let b = block.nrows();
        if b == 0 {
            return;
        }
        assert_eq!(block.ncols(), self.dim, "descriptor dimension");
        assert!(words.len() >= b, "one output per row");
        let block = block.as_standard_layout();
        let x = block.as_slice().expect("standard layout");
        BEST.with_borrow_mut(|(best_v, best_i, scratch)| {
            best_v.clear();
            best_v.resize(b * LANES, f32::INFINITY);
            best_i.clear();
            best_i.resize(b * LANES, 0);
            if self.kernel == Kernel::Gemm {
                let norms = &self.norms[..self.k];
                kernels::gemm_block(x, self.dim, &self.rows, norms, scratch, best_v, best_i);
            } else {
                let n_panels = self.norms.len() / LANES;
                let panel_len = self.dim * LANES;
                for start in (0..n_panels).step_by(TILE_PANELS) {
                    let end = (start + TILE_PANELS).min(n_panels);
                    kernels::panels_block(
                        self.kernel,
                        x,
                        self.dim,
                        &self.panels[start * panel_len..end * panel_len],
                        &self.norms[start * LANES..end * LANES],
                        (start * LANES) as u32,
                        best_v,
                        best_i,
                    );
                }
            }
            for r in 0..b {
                let (d, w) = kernels::reduce_lanes(
                    &best_v[r * LANES..(r + 1) * LANES],
                    &best_i[r * LANES..(r + 1) * LANES],
                );
                words[r] = w;
                if let Some(out) = distances.as_deref_mut() {
                    out[r] = d;
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

    fn distance(c: &Array2<f32>, k: u32, x: &[f32]) -> f32 {
        c.row(k as usize)
            .iter()
            .zip(x)
            .map(|(a, b)| (a - b) * (a - b))
            .sum()
    }

    #[test]
    fn every_kernel_matches_naive_argmin() {
        let kernels: Vec<Kernel> = Kernel::ALL.into_iter().filter(|k| k.available()).collect();
        assert!(kernels.contains(&Kernel::Gemm));
        for &(k, b, dim) in &[
            (1, 1, 128),
            (7, 3, 128),
            (300, 32, 128),
            (TILE_PANELS * LANES + 17, 64, 128),
            (5000, 13, 128),
            (40, 9, 5),
        ] {
            let c = random(k, dim, k as u64);
            let x = random(b, dim, 99 + b as u64);
            for &kernel in &kernels {
                let q = ExactQuantizer::with_kernel(c.as_slice().unwrap(), dim, kernel);
                let mut out = vec![0u32; b];
                q.quantize(x.view(), &mut out);
                for (i, row) in x.rows().into_iter().enumerate() {
                    let row = row.as_slice().unwrap();
                    let want = naive_nearest(c.view(), row);
                    // equal, or a tie within rounding of the distance
                    assert!(
                        out[i] == want
                            || (distance(&c, out[i], row) - distance(&c, want, row)).abs() < 1e-3,
                        "{kernel:?} k={k} b={b} row {i}: got {} want {want}",
                        out[i]
                    );
                }
            }
        }
    }

    #[test]
    fn each_centroid_quantizes_to_itself() {
        let c = random(1000, 128, 5);
        for kernel in Kernel::ALL.into_iter().filter(|k| k.available()) {
            let q = ExactQuantizer::with_kernel(c.as_slice().unwrap(), 128, kernel);
            let mut out = vec![0u32; 1000];
            q.quantize(c.view(), &mut out);
            assert!(
                out.iter().enumerate().all(|(i, &w)| w == i as u32),
                "{kernel:?}"
            );
        }
    }
}

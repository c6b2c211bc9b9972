//! The inner loops of exact quantization, one per instruction set, over
//! centroids packed in panels of [`LANES`]. Each keeps, per descriptor, the
//! best distance and index seen in each lane; [`reduce_lanes`] finishes the
//! argmin. All compute ‖c‖² − 2·x·c; they differ only in summation order.

/// Centroids per panel (one AVX-512 vector of f32).
pub const LANES: usize = 16;

/// Which inner loop a quantizer runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// AVX-512F: 8 descriptors × 32 centroids per register tile.
    Avx512,
    /// AVX2 + FMA: 6 descriptors × 16 centroids per register tile.
    Avx2,
    /// A `gemm` matrix multiply per block (any CPU).
    Gemm,
}

impl Kernel {
    pub const ALL: [Kernel; 3] = [Kernel::Avx512, Kernel::Avx2, Kernel::Gemm];

    /// Whether this CPU can run the kernel.
    pub fn available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            Kernel::Gemm => true,
            #[allow(unreachable_patterns)]
            _ => false,
        }
    }

    /// The fastest available kernel.
    pub fn detect() -> Self {
        Self::ALL
            .into_iter()
            .find(|k| k.available())
            .unwrap_or(Kernel::Gemm)
    }

    pub fn name(self) -> &'static str {
        match self {
            Kernel::Avx512 => "avx512",
            Kernel::Avx2 => "avx2",
            Kernel::Gemm => "gemm",
        }
    }
}

/// Fold the 16 lanes of one descriptor into its nearest centroid (ties: the
/// lower index): (distance, index).
pub fn reduce_lanes(values: &[f32], indices: &[u32]) -> (f32, u32) {
    let mut best = (f32::INFINITY, u32::MAX);
    for (&v, &i) in values.iter().zip(indices) {
        if v < best.0 || (v == best.0 && i < best.1) {
            best = (v, i);
        }
    }
    if best.1 == u32::MAX {
        (f32::INFINITY, 0)
    } else {
        best
    }
}

/// Update `best_v`/`best_i` (`rows × LANES`) of every descriptor in `x`
/// (`rows × dim`) with the panels given; `first` is the index of the first
/// centroid of the first panel.
#[allow(clippy::too_many_arguments)]
pub fn panels_block(
    kernel: Kernel,
    x: &[f32],
    dim: usize,
    panels: &[f32],
    norms: &[f32],
    first: u32,
    best_v: &mut [f32],
    best_i: &mut [u32],
) {
    let rows = x.len() / dim;
    assert_eq!(panels.len(), norms.len() * dim);
    assert_eq!(norms.len() % (2 * LANES), 0, "panels come in pairs");
    assert!(best_v.len() >= rows * LANES && best_i.len() >= rows * LANES);
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 => {
            assert!(kernel.available());
            // SAFETY: avx512f is present (checked above); slices are sized as
            // asserted, and the kernels stay within them.
            unsafe { x86::avx512_rows(x, dim, panels, norms, first, best_v, best_i) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => {
            assert!(kernel.available());
            // SAFETY: avx2 and fma are present; bounds as above.
            unsafe { x86::avx2_rows(x, dim, panels, norms, first, best_v, best_i) }
        }
        _ => unreachable!("gemm does not use packed panels"),
    }
}

/// x·c for every row x of `x` (`b × dim`) and every row c of `centroids`
/// (`k × dim`), by one `gemm` call, into `out` (`b × k`, row-major).
pub fn gemm_dots(x: &[f32], dim: usize, centroids: &[f32], out: &mut Vec<f32>) {
    let b = x.len() / dim;
    let k = centroids.len() / dim;
    out.clear();
    out.resize(b * k, 0.0);
    // SAFETY: dst is b × k row-major, lhs b × dim row-major, rhs = centroidsᵀ
    // (dim × k, element (p, j) at centroids[j·dim + p]); extents match.
    unsafe {
        gemm::gemm(
            b,
            k,
            dim,
            out.as_mut_ptr(),
            1,
            k as isize,
            false,
            x.as_ptr(),
            1,
            dim as isize,
            centroids.as_ptr(),
            dim as isize,
            1,
            0.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// The portable path: distances of the block to all centroids by one `gemm`
/// call into `scratch`, then a lane-wise running minimum.
pub fn gemm_block(
    x: &[f32],
    dim: usize,
    centroids: &[f32],
    norms: &[f32],
    scratch: &mut Vec<f32>,
    best_v: &mut [f32],
    best_i: &mut [u32],
) {
    let k = norms.len();
    gemm_dots(x, dim, centroids, scratch);
    for (r, dots) in scratch.chunks_exact(k).enumerate() {
        let (bv, bi) = (
            &mut best_v[r * LANES..(r + 1) * LANES],
            &mut best_i[r * LANES..(r + 1) * LANES],
        );
        for (j, (&dot, &norm)) in dots.iter().zip(norms).enumerate() {
            let d = norm - 2.0 * dot;
            let lane = j % LANES;
            if d < bv[lane] {
                bv[lane] = d;
                bi[lane] = j as u32;
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(clippy::needless_range_loop)] // register tiles indexed in lock-step
mod x86 {
    use super::LANES;
    use std::arch::x86_64::*;

    /// Descriptors per AVX-512 register tile.
    const R512: usize = 8;
    /// Descriptors per AVX2 register tile.
    const R256: usize = 6;

    /// Hand `tile` the descriptors of `x` (`dim` floats each) at most `max`
    /// at a time: how many, their floats and their rows of `best_v` /
    /// `best_i`. The register tiles of both instruction sets share it.
    fn by_tiles(
        x: &[f32],
        dim: usize,
        max: usize,
        best_v: &mut [f32],
        best_i: &mut [u32],
        mut tile: impl FnMut(usize, &[f32], &mut [f32], &mut [u32]),
    ) {
        let rows = x.len() / dim;
        let mut r = 0;
        while r < rows {
            let n = (rows - r).min(max);
            tile(
                n,
                &x[r * dim..],
                &mut best_v[r * LANES..],
                &mut best_i[r * LANES..],
            );
            r += n;
        }
    }

    #[target_feature(enable = "avx512f")]
    pub unsafe fn avx512_rows(
        x: &[f32],
        dim: usize,
        panels: &[f32],
        norms: &[f32],
        first: u32,
        best_v: &mut [f32],
        best_i: &mut [u32],
    ) {
        by_tiles(x, dim, R512, best_v, best_i, |n, xs, bv, bi| {
            // SAFETY: n rows remain in xs; the caller checked avx512f.
            unsafe {
                match n {
                    8 => avx512_tile::<8>(xs, dim, panels, norms, first, bv, bi),
                    7 => avx512_tile::<7>(xs, dim, panels, norms, first, bv, bi),
                    6 => avx512_tile::<6>(xs, dim, panels, norms, first, bv, bi),
                    5 => avx512_tile::<5>(xs, dim, panels, norms, first, bv, bi),
                    4 => avx512_tile::<4>(xs, dim, panels, norms, first, bv, bi),
                    3 => avx512_tile::<3>(xs, dim, panels, norms, first, bv, bi),
                    2 => avx512_tile::<2>(xs, dim, panels, norms, first, bv, bi),
                    _ => avx512_tile::<1>(xs, dim, panels, norms, first, bv, bi),
                }
            }
        });
    }

    /// R descriptors against every pair of panels.
    #[target_feature(enable = "avx512f")]
    unsafe fn avx512_tile<const R: usize>(
        x: &[f32],
        dim: usize,
        panels: &[f32],
        norms: &[f32],
        first: u32,
        best_v: &mut [f32],
        best_i: &mut [u32],
    ) {
        assert!(x.len() >= R * dim && best_v.len() >= R * LANES && best_i.len() >= R * LANES);
        let pairs = norms.len() / (2 * LANES);
        let xp = x.as_ptr();
        let pp = panels.as_ptr();
        let np = norms.as_ptr();
        let two = _mm512_set1_ps(2.0);
        let lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        // SAFETY: every pointer offset below stays inside the slices whose
        // lengths were asserted: p < pairs, d < dim, r < R.
        unsafe {
            let mut bv = [_mm512_setzero_ps(); R];
            let mut bi = [_mm512_setzero_si512(); R];
            for r in 0..R {
                bv[r] = _mm512_loadu_ps(best_v.as_ptr().add(r * LANES));
                bi[r] = _mm512_loadu_si512(best_i.as_ptr().add(r * LANES) as *const _);
            }
            for p in 0..pairs {
                let c0 = pp.add(2 * p * dim * LANES);
                let c1 = c0.add(dim * LANES);
                let mut a0 = [_mm512_setzero_ps(); R];
                let mut a1 = [_mm512_setzero_ps(); R];
                for d in 0..dim {
                    let v0 = _mm512_loadu_ps(c0.add(d * LANES));
                    let v1 = _mm512_loadu_ps(c1.add(d * LANES));
                    for r in 0..R {
                        let xv = _mm512_set1_ps(*xp.add(r * dim + d));
                        a0[r] = _mm512_fmadd_ps(xv, v0, a0[r]);
                        a1[r] = _mm512_fmadd_ps(xv, v1, a1[r]);
                    }
                }
                let n0 = _mm512_loadu_ps(np.add(2 * p * LANES));
                let n1 = _mm512_loadu_ps(np.add(2 * p * LANES + LANES));
                let base = first as i32 + (2 * p * LANES) as i32;
                let i0 = _mm512_add_epi32(lane, _mm512_set1_epi32(base));
                let i1 = _mm512_add_epi32(lane, _mm512_set1_epi32(base + LANES as i32));
                for r in 0..R {
                    let d0 = _mm512_fnmadd_ps(two, a0[r], n0);
                    let m0 = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(d0, bv[r]);
                    bv[r] = _mm512_mask_mov_ps(bv[r], m0, d0);
                    bi[r] = _mm512_mask_mov_epi32(bi[r], m0, i0);
                    let d1 = _mm512_fnmadd_ps(two, a1[r], n1);
                    let m1 = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(d1, bv[r]);
                    bv[r] = _mm512_mask_mov_ps(bv[r], m1, d1);
                    bi[r] = _mm512_mask_mov_epi32(bi[r], m1, i1);
                }
            }
            for r in 0..R {
                _mm512_storeu_ps(best_v.as_mut_ptr().add(r * LANES), bv[r]);
                _mm512_storeu_si512(best_i.as_mut_ptr().add(r * LANES) as *mut _, bi[r]);
            }
        }
    }

    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn avx2_rows(
        x: &[f32],
        dim: usize,
        panels: &[f32],
        norms: &[f32],
        first: u32,
        best_v: &mut [f32],
        best_i: &mut [u32],
    ) {
        by_tiles(x, dim, R256, best_v, best_i, |n, xs, bv, bi| {
            // SAFETY: n rows remain in xs; the caller checked avx2 and fma.
            unsafe {
                match n {
                    6 => avx2_tile::<6>(xs, dim, panels, norms, first, bv, bi),
                    5 => avx2_tile::<5>(xs, dim, panels, norms, first, bv, bi),
                    4 => avx2_tile::<4>(xs, dim, panels, norms, first, bv, bi),
                    3 => avx2_tile::<3>(xs, dim, panels, norms, first, bv, bi),
                    2 => avx2_tile::<2>(xs, dim, panels, norms, first, bv, bi),
                    _ => avx2_tile::<1>(xs, dim, panels, norms, first, bv, bi),
                }
            }
        });
    }

    /// R descriptors against every panel, each panel as two 8-lane halves.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn avx2_tile<const R: usize>(
        x: &[f32],
        dim: usize,
        panels: &[f32],
        norms: &[f32],
        first: u32,
        best_v: &mut [f32],
        best_i: &mut [u32],
    ) {
        assert!(x.len() >= R * dim && best_v.len() >= R * LANES && best_i.len() >= R * LANES);
        let n_panels = norms.len() / LANES;
        let xp = x.as_ptr();
        let pp = panels.as_ptr();
        let np = norms.as_ptr();
        let two = _mm256_set1_ps(2.0);
        let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        // SAFETY: offsets stay inside the asserted slice lengths.
        unsafe {
            let mut bv = [[_mm256_setzero_ps(); 2]; R];
            let mut bi = [[_mm256_setzero_si256(); 2]; R];
            for r in 0..R {
                for h in 0..2 {
                    bv[r][h] = _mm256_loadu_ps(best_v.as_ptr().add(r * LANES + 8 * h));
                    bi[r][h] =
                        _mm256_loadu_si256(best_i.as_ptr().add(r * LANES + 8 * h) as *const _);
                }
            }
            for p in 0..n_panels {
                let c = pp.add(p * dim * LANES);
                let mut a = [[_mm256_setzero_ps(); 2]; R];
                for d in 0..dim {
                    let lo = _mm256_loadu_ps(c.add(d * LANES));
                    let hi = _mm256_loadu_ps(c.add(d * LANES + 8));
                    for r in 0..R {
                        let xv = _mm256_set1_ps(*xp.add(r * dim + d));
                        a[r][0] = _mm256_fmadd_ps(xv, lo, a[r][0]);
                        a[r][1] = _mm256_fmadd_ps(xv, hi, a[r][1]);
                    }
                }
                for h in 0..2 {
                    let n = _mm256_loadu_ps(np.add(p * LANES + 8 * h));
                    let base = first as i32 + (p * LANES + 8 * h) as i32;
                    let idx = _mm256_add_epi32(lane, _mm256_set1_epi32(base));
                    for r in 0..R {
                        let dist = _mm256_fnmadd_ps(two, a[r][h], n);
                        let m = _mm256_cmp_ps::<_CMP_LT_OQ>(dist, bv[r][h]);
                        bv[r][h] = _mm256_blendv_ps(bv[r][h], dist, m);
                        bi[r][h] = _mm256_castps_si256(_mm256_blendv_ps(
                            _mm256_castsi256_ps(bi[r][h]),
                            _mm256_castsi256_ps(idx),
                            m,
                        ));
                    }
                }
            }
            for r in 0..R {
                for h in 0..2 {
                    _mm256_storeu_ps(best_v.as_mut_ptr().add(r * LANES + 8 * h), bv[r][h]);
                    _mm256_storeu_si256(
                        best_i.as_mut_ptr().add(r * LANES + 8 * h) as *mut _,
                        bi[r][h],
                    );
                }
            }
        }
    }
}

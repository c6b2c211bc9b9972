//! k-means for vocabulary training: k-means++ seeding on a subsample, then
//! Lloyd iterations whose assignment step is the same batched exact kernel
//! used at query time. Parallel over all cores, and reproducible for a seed:
//! every parallel step is element-wise or reduced in a fixed order.

use crate::quantize::{ExactQuantizer, Quantizer, squared_norms};
use indicatif::ProgressBar;
use ndarray::{Array2, ArrayView2};
use rand::{RngExt, SeedableRng, seq::index::sample};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Rows per parallel assignment task.
const CHUNK: usize = 256;

#[derive(Debug, Clone)]
pub struct KmeansConfig {
    pub k: usize,
    pub seed: u64,
    /// Upper bound on Lloyd iterations.
    pub max_iter: usize,
    /// Stop once fewer than this fraction of points change cluster.
    pub tolerance: f64,
    /// Points k-means++ seeding runs on (0 = automatic: 8·k, at least 20 000).
    pub seeding_sample: usize,
    /// Points Lloyd iterations run on (0 = all).
    pub train_sample: usize,
}

impl Default for KmeansConfig {
    fn default() -> Self {
        Self {
            k: 1000,
            seed: 0,
            max_iter: 25,
            tolerance: 1e-3,
            seeding_sample: 0,
            train_sample: 200_000,
        }
    }
}

#[derive(Debug, Clone)]
pub struct KmeansReport {
    pub iterations: usize,
    /// Fraction of points that changed cluster in the last iteration.
    pub last_change: f64,
    /// Points the Lloyd iterations ran on.
    pub trained_on: usize,
    /// Empty clusters re-seeded over all iterations.
    pub reseeded: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum KmeansError {
    #[error("cannot train {k} words from {n} descriptors: need at least as many descriptors as words")]
    TooFewPoints { k: usize, n: usize },
    #[error("the number of words must be at least 1")]
    ZeroWords,
}

/// Cluster the rows of `data` into `config.k` centroids.
pub fn kmeans(
    data: ArrayView2<'_, f32>,
    config: &KmeansConfig,
    progress: &ProgressBar,
) -> Result<(Array2<f32>, KmeansReport), KmeansError> {
    let (n, dim) = data.dim();
    let k = config.k;
    if k == 0 {
        return Err(KmeansError::ZeroWords);
    }
    if n < k {
        return Err(KmeansError::TooFewPoints { k, n });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let data = data.as_standard_layout();
    let train = subsample(data.view(), config.train_sample, &mut rng);
    let train = train.as_ref().map_or(data.view(), |a| a.view());
    let train_n = train.nrows();

    let seeding_n = match config.seeding_sample {
        0 => (8 * k).max(20_000),
        s => s.max(k),
    };
    let seeding = subsample(train, seeding_n, &mut rng);
    let seeding = seeding.as_ref().map_or(train, |a| a.view());
    progress.set_length(k as u64);
    progress.set_message("k-means++ seeding");
    let mut centroids = kmeans_plus_plus(seeding, k, &mut rng, progress);

    progress.set_position(0);
    progress.set_length(config.max_iter as u64);
    progress.set_message("Lloyd iterations");
    let x = train.as_slice().expect("standard layout");
    let mut assign = vec![u32::MAX; train_n];
    let mut next = vec![0u32; train_n];
    let mut report = KmeansReport {
        iterations: 0,
        last_change: 1.0,
        trained_on: train_n,
        reseeded: 0,
    };
    for _ in 0..config.max_iter {
        assign_all(x, dim, &centroids, &mut next);
        let changed = next.iter().zip(&assign).filter(|(a, b)| a != b).count();
        std::mem::swap(&mut assign, &mut next);
        report.iterations += 1;
        report.last_change = changed as f64 / train_n as f64;
        report.reseeded += update_centroids(train, &assign, &mut centroids, &mut rng);
        progress.inc(1);
        if report.last_change < config.tolerance {
            break;
        }
    }
    Ok((centroids, report))
}

/// Up to `max` rows drawn without replacement (`None`: use all rows).
fn subsample(data: ArrayView2<'_, f32>, max: usize, rng: &mut ChaCha8Rng) -> Option<Array2<f32>> {
    let n = data.nrows();
    if max == 0 || n <= max {
        return None;
    }
    let mut idx = sample(rng, n, max).into_vec();
    idx.sort_unstable();
    Some(data.select(ndarray::Axis(0), &idx))
}

fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// k-means++ (Arthur & Vassilvitskii 2007): each next centre drawn with
/// probability proportional to the squared distance to the nearest centre so far.
fn kmeans_plus_plus(
    data: ArrayView2<'_, f32>,
    k: usize,
    rng: &mut ChaCha8Rng,
    progress: &ProgressBar,
) -> Array2<f32> {
    let (n, dim) = data.dim();
    let x = data.as_slice().expect("standard layout");
    let mut centroids = Array2::<f32>::zeros((k, dim));
    let first = rng.random_range(0..n);
    centroids.row_mut(0).assign(&data.row(first));
    let mut d2: Vec<f32> = x
        .par_chunks_exact(dim)
        .map(|r| squared_distance(r, &x[first * dim..(first + 1) * dim]))
        .collect();
    progress.inc(1);
    for c in 1..k {
        let total: f64 = d2.iter().map(|&d| d as f64).sum();
        let pick = if total > 0.0 {
            let mut r = rng.random::<f64>() * total;
            let mut pick = n - 1;
            for (i, &d) in d2.iter().enumerate() {
                r -= d as f64;
                if r < 0.0 {
                    pick = i;
                    break;
                }
            }
            pick
        } else {
            rng.random_range(0..n)
        };
        let centre = &x[pick * dim..(pick + 1) * dim];
        centroids.row_mut(c).assign(&data.row(pick));
        d2.par_iter_mut()
            .zip(x.par_chunks_exact(dim))
            .with_min_len(1024)
            .for_each(|(d, r)| *d = d.min(squared_distance(r, centre)));
        progress.inc(1);
    }
    centroids
}

/// Nearest centroid of every row, in parallel blocks.
fn assign_all(x: &[f32], dim: usize, centroids: &Array2<f32>, out: &mut [u32]) {
    let c = centroids.as_slice().expect("standard layout");
    let norms = squared_norms(c, dim);
    let q = ExactQuantizer::new(c, &norms, dim);
    x.par_chunks(CHUNK * dim)
        .zip(out.par_chunks_mut(CHUNK))
        .for_each(|(rows, words)| {
            let block = ArrayView2::from_shape((rows.len() / dim, dim), rows).expect("block");
            q.quantize(block, words);
        });
}

/// Each centroid becomes the mean of its members (summed in index order, so
/// the result does not depend on thread scheduling). Empty clusters are moved
/// to random points. Returns how many were moved.
fn update_centroids(
    data: ArrayView2<'_, f32>,
    assign: &[u32],
    centroids: &mut Array2<f32>,
    rng: &mut ChaCha8Rng,
) -> usize {
    let (k, dim) = centroids.dim();
    // counting sort of point indices by cluster
    let mut start = vec![0usize; k + 1];
    for &a in assign {
        start[a as usize + 1] += 1;
    }
    for i in 0..k {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut members = vec![0u32; assign.len()];
    for (i, &a) in assign.iter().enumerate() {
        members[fill[a as usize]] = i as u32;
        fill[a as usize] += 1;
    }
    centroids
        .as_slice_mut()
        .expect("standard layout")
        .par_chunks_exact_mut(dim)
        .enumerate()
        .for_each(|(c, centroid)| {
            let m = &members[start[c]..start[c + 1]];
            if m.is_empty() {
                return;
            }
            let mut sum = vec![0f64; dim];
            for &i in m {
                for (s, &v) in sum.iter_mut().zip(data.row(i as usize)) {
                    *s += v as f64;
                }
            }
            for (dst, s) in centroid.iter_mut().zip(sum) {
                *dst = (s / m.len() as f64) as f32;
            }
        });
    let mut reseeded = 0;
    for c in 0..k {
        if start[c] == start[c + 1] {
            let i = rng.random_range(0..data.nrows());
            centroids.row_mut(c).assign(&data.row(i));
            reseeded += 1;
        }
    }
    reseeded
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three well separated blobs.
    fn blobs(seed: u64) -> Array2<f32> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let centres = [[0.0f32, 0.0], [10.0, 0.0], [0.0, 10.0]];
        Array2::from_shape_fn((300, 2), |(i, j)| centres[i % 3][j] + rng.random::<f32>() - 0.5)
    }

    #[test]
    fn finds_separated_blobs() {
        let data = blobs(1);
        let config = KmeansConfig {
            k: 3,
            seed: 7,
            ..Default::default()
        };
        let (c, report) = kmeans(data.view(), &config, &ProgressBar::hidden()).unwrap();
        assert!(report.iterations >= 1);
        let mut found: Vec<(i32, i32)> = c
            .rows()
            .into_iter()
            .map(|r| (r[0].round() as i32, r[1].round() as i32))
            .collect();
        found.sort();
        assert_eq!(found, vec![(0, 0), (0, 10), (10, 0)]);
    }

    #[test]
    fn same_seed_same_centroids_other_seed_differs() {
        let data = Array2::from_shape_fn((2000, 8), |(i, j)| ((i * 31 + j * 17) % 97) as f32);
        let run = |seed| {
            let config = KmeansConfig {
                k: 20,
                seed,
                ..Default::default()
            };
            kmeans(data.view(), &config, &ProgressBar::hidden()).unwrap().0
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }

    #[test]
    fn too_few_points_is_an_error() {
        let data = Array2::<f32>::zeros((5, 4));
        let config = KmeansConfig {
            k: 6,
            ..Default::default()
        };
        let err = kmeans(data.view(), &config, &ProgressBar::hidden()).unwrap_err();
        assert!(matches!(err, KmeansError::TooFewPoints { k: 6, n: 5 }));
    }
}

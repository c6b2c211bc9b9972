//! Where does scene overlap peak, for a dataset whose queries and map were
//! recorded along the same route (gardens-point)? For each query, every map
//! image within ±`WINDOW` of the query's index is matched against it three
//! ways, and the map image with the highest score is compared with the
//! ground truth:
//!
//! - `word pairs + homography`: what verification does in the service — pairs
//!   of features sharing a visual word (K = 5000, vocabulary seed 1), inliers
//!   of a homography (MAGSAC++, 8 px);
//! - `descriptor matches`: nearest-neighbour descriptor matches passing
//!   Lowe's ratio test (0.8), counted;
//! - `descriptor matches + homography`: the inliers of a homography fitted
//!   to those matches.
//!
//! Each score is also summed over the map image and its neighbours (±1, ±2),
//! a place-level score. The fraction printed is an upper bound for recall@1
//! of a re-ranking by that score: a real search also meets candidates from
//! outside the window.
//!
//! ```sh
//! cargo run --release --example overlap -- ../shared/datasets/gardens-point
//! ```
//!
//! It reads (or fills) the eval's descriptor and vocabulary caches in
//! `data/eval-cache/<dataset>` (whole queries, the default extraction).

use bowloc::dataset::Dataset;
use bowloc::eval::cache;
use bowloc::features::fit::OpenCvFit;
use bowloc::features::{ExtractConfig, TileGrid};
use bowloc::geometry::Keypoint;
use bowloc::geometry::matches::{QueryFeatures, tentative};
use bowloc::geometry::packed::pack_image;
use bowloc::geometry::ratio_matches::{RATIO, ratio_correspondences};
use bowloc::geometry::verify::{VerifyParams, count_inliers};
use bowloc::quantize::Quantizer;
use bowloc::vocabulary::kmeans::KmeansConfig;
use ndarray::ArrayView2;
use rayon::prelude::*;
use std::path::PathBuf;

const WINDOW: i64 = 10;
const WORDS: usize = 5000;

fn main() -> anyhow::Result<()> {
    let root = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "../shared/datasets/gardens-point".into()),
    );
    let dataset = Dataset::open(&root)?;
    let cache_dir = PathBuf::from("data/eval-cache").join(&dataset.name);
    std::fs::create_dir_all(&cache_dir)?;
    let config = ExtractConfig::default();
    let (map, queries) =
        cache::dataset_descriptors(&cache_dir, &dataset, &config, TileGrid::WHOLE)?;
    let vocab = cache::vocabulary(
        &cache_dir,
        &map,
        &KmeansConfig {
            k: WORDS,
            seed: 1,
            ..KmeansConfig::default()
        },
    )?;
    let quantizer = vocab.exact_quantizer();
    let words = |d: ArrayView2<'_, f32>| {
        let mut w = vec![0u32; d.nrows()];
        quantizer.quantize(d, &mut w);
        w
    };
    let fit = OpenCvFit::new(VerifyParams::default().fit());
    let params = VerifyParams::default();
    let n_map = map.len() as i64;
    // each map image's words and keypoints, packed once
    let packed: Vec<_> = (0..map.len())
        .map(|j| {
            map.image(j)
                .map(|d| pack_image(&words(d), &[], &map.keypoints(j)))
        })
        .collect();

    // scores[q] = (map id, [word pairs + H, matches, matches + H]) over the window
    let scores: Vec<Vec<(i64, [f64; 3])>> = (0..queries.len())
        .into_par_iter()
        .map(|qi| {
            let Some(qd) = queries.image(qi) else {
                return Vec::new();
            };
            let qk = queries.keypoints(qi);
            let qw = words(qd);
            let qf: Vec<(u32, Keypoint)> = qw.iter().copied().zip(qk.iter().copied()).collect();
            let qf = QueryFeatures::new(&qf);
            let lo = (qi as i64 - WINDOW).max(0);
            let hi = (qi as i64 + WINDOW).min(n_map - 1);
            (lo..=hi)
                .map(|j| {
                    let (Some(md), Some(packed)) = (map.image(j as usize), &packed[j as usize])
                    else {
                        return (j, [0.0; 3]);
                    };
                    let mk = map.keypoints(j as usize);
                    let by_words =
                        tentative(&qf, packed, params.max_word_pairs, params.max_hamming);
                    let word_h = count_inliers(&by_words, &fit, 0).inliers;
                    let c = ratio_correspondences((qd, &qk), (md, &mk), RATIO);
                    let desc_h = count_inliers(&c, &fit, 0).inliers;
                    (j, [word_h as f64, c.len() as f64, desc_h as f64])
                })
                .collect()
        })
        .collect();

    let names = [
        "word pairs + homography",
        "descriptor matches",
        "descriptor matches + homography",
    ];
    let n_queries = scores.len();
    println!(
        "{}: {} queries, map images within ±{WINDOW} of each; best map image within the ground truth:",
        dataset.name, n_queries
    );
    for (s, name) in names.iter().enumerate() {
        let mut line = format!("{name:<32}");
        for radius in [0i64, 1, 2] {
            let hits = scores
                .iter()
                .enumerate()
                .filter(|(qi, row)| {
                    let score = |j: i64| -> f64 {
                        row.iter()
                            .filter(|(k, _)| (k - j).abs() <= radius)
                            .map(|(_, v)| v[s])
                            .sum()
                    };
                    row.iter()
                        .map(|&(j, _)| (j, score(j)))
                        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
                        .is_some_and(|(j, _)| dataset.truth[*qi].contains(&(j as u32)))
                })
                .count();
            let label = if radius == 0 {
                "alone".to_owned()
            } else {
                format!("summed ±{radius}")
            };
            line += &format!("  {label}: {:.1} %", 100.0 * hits as f64 / n_queries as f64);
        }
        println!("{line}");
    }
    Ok(())
}

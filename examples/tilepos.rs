//! Which tiles of a query carry its place? For each subset of a `2x2+24`
//! query's tiles, the full search's recall@1 / recall@5 on those tiles'
//! features alone (one vocabulary seed).
//!
//! ```sh
//! cargo run --release --example tilepos -- ../shared/datasets/gardens-point 5000 1
//! ```

use bowloc::dataset::Dataset;
use bowloc::eval::cache;
use bowloc::features::{ExtractConfig, TileGrid};
use bowloc::pipeline::code;
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use bowloc::vocabulary::kmeans::KmeansConfig;
use opencv::core::{Mat, Rect, Size, Vector};
use opencv::prelude::*;
use rayon::prelude::*;

/// Per tile core (grid order), two cheap guesses of its SIFT richness: mean
/// |Laplacian| of the quarter-size frame, and FAST corners of the half-size one.
fn guesses(path: &std::path::Path, grid: TileGrid) -> (Vec<f64>, Vec<f64>) {
    let img =
        opencv::imgcodecs::imread(path.to_str().unwrap(), opencv::imgcodecs::IMREAD_GRAYSCALE)
            .unwrap();
    let (w0, h0) = (img.cols() as f64, img.rows() as f64);
    let s = (640.0 / w0.max(h0)).min(1.0);
    let (w, h) = ((w0 * s).round() as i32, (h0 * s).round() as i32);
    let cores = grid.cores(w as u32, h as u32);
    let mut lap = Vec::new();
    let mut fast = Vec::new();
    for (f, out) in [(4, &mut lap), (2, &mut fast)] {
        let mut small = Mat::default();
        opencv::imgproc::resize(
            &img,
            &mut small,
            Size::new(w / f, h / f),
            0.0,
            0.0,
            opencv::imgproc::INTER_AREA,
        )
        .unwrap();
        if f == 4 {
            let mut l = Mat::default();
            opencv::imgproc::laplacian(
                &small,
                &mut l,
                opencv::core::CV_32F,
                3,
                1.0,
                0.0,
                opencv::core::BORDER_REFLECT,
            )
            .unwrap();
            let mut a = Mat::default();
            opencv::core::absdiff(&l, &opencv::core::Scalar::all(0.0), &mut a).unwrap();
            for &(x, y, cw, ch) in &cores {
                let r = Rect::new(
                    x as i32 / f,
                    y as i32 / f,
                    (cw as i32 / f).max(1),
                    (ch as i32 / f).max(1),
                );
                let roi = Mat::roi(&a, r).unwrap();
                out.push(
                    opencv::core::mean(&roi, &opencv::core::no_array()).unwrap()[0]
                        * (cw * ch) as f64,
                );
            }
        } else {
            let mut kps = Vector::<opencv::core::KeyPoint>::new();
            opencv::features2d::fast(&small, &mut kps, 20, true).unwrap();
            for &(x, y, cw, ch) in &cores {
                let n = kps
                    .iter()
                    .filter(|k| {
                        let (px, py) = (k.pt().x * f as f32, k.pt().y * f as f32);
                        px >= x as f32
                            && px < (x + cw) as f32
                            && py >= y as f32
                            && py < (y + ch) as f32
                    })
                    .count();
                out.push(n as f64);
            }
        }
    }
    (lap, fast)
}
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = PathBuf::from(
        args.get(1)
            .map_or("../shared/datasets/gardens-point", |s| s),
    );
    let words: usize = args.get(2).map_or(Ok(5000), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    let dataset = Dataset::open(&root)?;
    let dir = PathBuf::from("data/eval-cache").join(&dataset.name);
    let (map_desc, queries) =
        cache::dataset_descriptors(&dir, &dataset, &ExtractConfig::default(), TileGrid::DEFAULT)?;
    let kmeans = KmeansConfig {
        k: words,
        seed,
        ..KmeansConfig::default()
    };
    let vocab = cache::vocabulary(&dir, &map_desc, &kmeans)?;
    let map = cache::map_index(&dir, &vocab, &map_desc, &dataset.name)?;
    let coded: Vec<_> = (0..queries.len())
        .into_par_iter()
        .map(|q| queries.image(q).map(|d| code(&vocab, d)))
        .collect();
    let tiles = queries.meta().tiles[0].len();
    let guessed: Vec<(Vec<f64>, Vec<f64>)> = (0..queries.len())
        .into_par_iter()
        .map(|q| guesses(&dataset.queries[q].path, TileGrid::DEFAULT))
        .collect();
    let by_guess = |q: usize, k: usize, which: usize| -> u32 {
        let g = if which == 0 {
            &guessed[q].0
        } else {
            &guessed[q].1
        };
        let mut by: Vec<usize> = (0..g.len()).collect();
        by.sort_by(|&a, &b| g[b].total_cmp(&g[a]));
        by[..k].iter().fold(0, |m, &i| m | (1 << i))
    };
    println!(
        "{}: K = {words}, seed {seed}; tiles kept (bit i = tile i, grid order): recall@1 / recall@5, share of features",
        dataset.name
    );
    // per query, the mask of its k richest tiles (most features), k = 1..tiles
    let richest = |q: usize, k: usize| -> u32 {
        let t = &queries.meta().tiles[q];
        let mut by: Vec<usize> = (0..t.len()).collect();
        by.sort_by_key(|&i| std::cmp::Reverse(t[i].features));
        by[..k].iter().fold(0, |m, &i| m | (1 << i))
    };
    let masks: Vec<(String, Box<dyn Fn(usize) -> u32 + Sync>)> = (1u32..(1 << tiles))
        .map(|m| {
            (
                format!("{m:0w$b}", w = tiles),
                Box::new(move |_| m) as Box<dyn Fn(usize) -> u32 + Sync>,
            )
        })
        .chain((1..=tiles).map(|k| {
            (
                format!("{k} richest"),
                Box::new(move |q| richest(q, k)) as Box<dyn Fn(usize) -> u32 + Sync>,
            )
        }))
        .chain((1..=tiles).map(|k| {
            (
                format!("{k} by |Laplacian|"),
                Box::new(move |q| by_guess(q, k, 0)) as Box<dyn Fn(usize) -> u32 + Sync>,
            )
        }))
        .chain((1..=tiles).map(|k| {
            (
                format!("{k} by FAST"),
                Box::new(move |q| by_guess(q, k, 1)) as Box<dyn Fn(usize) -> u32 + Sync>,
            )
        }))
        .collect();
    for (name, mask_of) in &masks {
        let hits: Vec<(bool, bool, f64, f64)> = (0..coded.len())
            .into_par_iter()
            .filter(|&q| !dataset.truth[q].is_empty())
            .map(|q| {
                let Some(c) = &coded[q] else {
                    return (false, false, 0.0, 0.0);
                };
                let mask = mask_of(q);
                let mut at = 0usize;
                let (mut ms, mut all_ms) = (0.0f64, 0.0f64);
                let (mut w, mut s) = (Vec::new(), Vec::new());
                for (t, tile) in queries.meta().tiles[q].iter().enumerate() {
                    let n = tile.features as usize;
                    all_ms += tile.ms as f64;
                    if mask & (1 << t) != 0 {
                        ms += tile.ms as f64;
                    }
                    if mask & (1 << t) != 0 {
                        w.extend_from_slice(&c.words[at..at + n]);
                        s.extend_from_slice(&c.signatures[at..at + n]);
                    }
                    at += n;
                }
                let options = SearchOptions {
                    rule: RuleSpec::new("none", None).expect("built-in rule"),
                    top_n: 5,
                    ..SearchOptions::default()
                };
                let o = search_words(
                    &map,
                    KnownFeatures {
                        words: &w,
                        signatures: &s,
                    },
                    &options,
                );
                let hit = |n: usize| {
                    o.candidates
                        .iter()
                        .take(n)
                        .any(|c| dataset.truth[q].contains(&c.id))
                };
                (
                    hit(1),
                    hit(5),
                    w.len() as f64 / c.words.len().max(1) as f64,
                    ms / all_ms.max(1e-9),
                )
            })
            .collect();
        let n = hits.len().max(1) as f64;
        println!(
            "{name}: {:.1} / {:.1}  ({:.2} of the features, {:.2} of the tiles' time)",
            100.0 * hits.iter().filter(|h| h.0).count() as f64 / n,
            100.0 * hits.iter().filter(|h| h.1).count() as f64 / n,
            hits.iter().map(|h| h.2).sum::<f64>() / n,
            hits.iter().map(|h| h.3).sum::<f64>() / n,
        );
    }
    Ok(())
}

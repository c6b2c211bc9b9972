//! Which tiles of a query carry its place, and which order finds them? For
//! one vocabulary seed, the full search on the features of some of a
//! `2x2+24` query's tiles: recall@1 / recall@5, and the share of the query's
//! features and of its tiles' extraction time (CPU time per tile, as the
//! eval cache timed it) those tiles hold. Printed for every subset of tiles
//! (bit i = tile i, grid order), then for the first k tiles of four orders:
//!
//! - `at random`: the mean over every subset of k tiles (what a random order
//!   gives on average);
//! - `most features`: the k tiles with most SIFT features (known only after
//!   extracting them: the best a guess can do);
//! - `most corners`: the k tiles with most FAST corners on the half-size
//!   frame, counted before extraction (`search.tile_order = "richest"`);
//! - `corners, spread`: the tile with most corners, then each next the one
//!   farthest from those taken (`search.tile_order = "spread"`);
//! - `most |Laplacian|`: the k tiles with the largest summed |Laplacian| of
//!   the quarter-size frame, another cheap guess.
//!
//! ```sh
//! cargo run --release --example tilepos -- ../shared/datasets/gardens-point 5000 1
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::features::{ExtractConfig, TileGrid};
use bowloc::pipeline::code;
use bowloc::search::permute::TileGuide;
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, TileOrder, permute, search_words};
use opencv::core::{Mat, Rect, Size};
use opencv::prelude::*;
use rayon::prelude::*;
use std::path::Path;

/// Per tile core of `grid` (grid order): the summed |Laplacian| of the image
/// at a quarter of the extraction frame's size.
fn laplacian_per_tile(path: &Path, config: &ExtractConfig, grid: TileGrid) -> Vec<f64> {
    let read =
        |p: &Path| opencv::imgcodecs::imread(p.to_str()?, opencv::imgcodecs::IMREAD_GRAYSCALE).ok();
    let Some(img) = read(path) else {
        return Vec::new();
    };
    let (w0, h0) = (img.cols() as f64, img.rows() as f64);
    let s = (config.max_side as f64 / w0.max(h0)).min(1.0);
    let (w, h) = ((w0 * s).round() as i32, (h0 * s).round() as i32);
    let mut small = Mat::default();
    let mut lap = Mat::default();
    let mut abs = Mat::default();
    let quarter = Size::new((w / 4).max(1), (h / 4).max(1));
    let ok = opencv::imgproc::resize(
        &img,
        &mut small,
        quarter,
        0.0,
        0.0,
        opencv::imgproc::INTER_AREA,
    )
    .and_then(|_| {
        opencv::imgproc::laplacian(
            &small,
            &mut lap,
            opencv::core::CV_32F,
            3,
            1.0,
            0.0,
            opencv::core::BORDER_REFLECT,
        )
    })
    .and_then(|_| opencv::core::absdiff(&lap, &opencv::core::Scalar::all(0.0), &mut abs));
    if ok.is_err() {
        return Vec::new();
    }
    grid.cores(w as u32, h as u32)
        .iter()
        .map(|&(x, y, cw, ch)| {
            let r = Rect::new(
                x as i32 / 4,
                y as i32 / 4,
                (cw as i32 / 4).max(1),
                (ch as i32 / 4).max(1),
            );
            Mat::roi(&abs, r)
                .and_then(|roi| opencv::core::sum_elems(&roi))
                .map_or(0.0, |s| s[0])
        })
        .collect()
}

/// The mask of the `k` tiles with the largest `score` (ties in grid order).
fn top(score: &[f64], k: usize) -> u32 {
    let mut by: Vec<usize> = (0..score.len()).collect();
    by.sort_by(|&a, &b| score[b].total_cmp(&score[a]));
    by.iter().take(k).fold(0, |m, &i| m | (1 << i))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let config = ExtractConfig::default();
    let cache::Prepared {
        dataset,
        queries,
        vocab,
        map,
        ..
    } = cache::prepare_from_args(&args, TileGrid::DEFAULT)?;
    let (words, seed) = (vocab.words(), vocab.meta().seed);
    let coded: Vec<_> = (0..queries.len())
        .into_par_iter()
        .map(|q| queries.image(q).map(|d| code(&vocab, d)))
        .collect();
    let tiles_of = |q: usize| &queries.meta().tiles[q];
    let tiles = tiles_of(0).len();
    let laplacian: Vec<Vec<f64>> = (0..queries.len())
        .into_par_iter()
        .map(|q| laplacian_per_tile(&dataset.queries[q].path, &config, TileGrid::DEFAULT))
        .collect();
    let with_match: Vec<usize> = (0..coded.len())
        .filter(|&q| !dataset.truth[q].is_empty())
        .collect();
    // (recall@1, recall@5, share of features, share of tile time) over the
    // queries, keeping the tiles `mask(q)` of each query q
    let measure = |mask: &(dyn Fn(usize) -> u32 + Sync)| -> [f64; 4] {
        let rows: Vec<[f64; 4]> = with_match
            .par_iter()
            .map(|&q| {
                let Some(c) = &coded[q] else { return [0.0; 4] };
                let m = mask(q);
                let (mut w, mut s) = (Vec::new(), Vec::new());
                let (mut at, mut ms, mut all_ms) = (0usize, 0.0, 0.0);
                for (t, tile) in tiles_of(q).iter().enumerate() {
                    let n = tile.features as usize;
                    all_ms += tile.ms as f64;
                    if m & (1 << t) != 0 {
                        w.extend_from_slice(&c.words[at..at + n]);
                        s.extend_from_slice(&c.signatures[at..at + n]);
                        ms += tile.ms as f64;
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
                    let found = o
                        .candidates
                        .iter()
                        .take(n)
                        .any(|c| dataset.truth[q].contains(&c.id));
                    if found { 1.0 } else { 0.0 }
                };
                [
                    hit(1),
                    hit(5),
                    w.len() as f64 / c.words.len().max(1) as f64,
                    ms / f64::max(all_ms, 1e-9),
                ]
            })
            .collect();
        let n = rows.len().max(1) as f64;
        std::array::from_fn(|i| rows.iter().map(|r| r[i]).sum::<f64>() / n)
    };
    let line = |name: &str, r: [f64; 4]| {
        println!(
            "{name:<20} recall@1 {:5.1} / recall@5 {:5.1}   {:.2} of the features, {:.2} of the tiles' time",
            100.0 * r[0],
            100.0 * r[1],
            r[2],
            r[3]
        )
    };
    println!(
        "{}: K = {words}, vocabulary seed {seed}, {} queries; the full search on some of each query's `{}` tiles",
        dataset.name,
        with_match.len(),
        TileGrid::DEFAULT
    );
    let subsets: Vec<(u32, [f64; 4])> = (1u32..(1 << tiles))
        .map(|m| (m, measure(&move |_| m)))
        .collect();
    for (m, r) in &subsets {
        line(&format!("tiles {m:0w$b}", w = tiles), *r);
    }
    for k in 1..=tiles {
        let of_k: Vec<&[f64; 4]> = subsets
            .iter()
            .filter(|(m, _)| m.count_ones() as usize == k)
            .map(|(_, r)| r)
            .collect();
        let mean =
            std::array::from_fn(|i| of_k.iter().map(|r| r[i]).sum::<f64>() / of_k.len() as f64);
        line(&format!("{k} at random"), mean);
        let features =
            |q: usize| -> Vec<f64> { tiles_of(q).iter().map(|t| t.features as f64).collect() };
        line(
            &format!("{k} most features"),
            measure(&|q| top(&features(q), k)),
        );
        // the service's orders, as `permute::tile_order` draws them
        let ordered = |q: usize, order: TileOrder| -> u32 {
            let t = tiles_of(q);
            let corners: Vec<f32> = t.iter().map(|t| t.corners).collect();
            let cells: Vec<[u32; 2]> = t.iter().map(|t| t.cell).collect();
            let guide = TileGuide {
                corners: &corners,
                cells: &cells,
            };
            permute::tile_order(t.len(), false, q as u64, order, Some(guide))
                .iter()
                .take(k)
                .fold(0, |m, &t| m | (1 << t))
        };
        line(
            &format!("{k} most corners"),
            measure(&|q| ordered(q, TileOrder::Richest)),
        );
        line(
            &format!("{k} corners, spread"),
            measure(&|q| ordered(q, TileOrder::Spread)),
        );
        line(
            &format!("{k} most |Laplacian|"),
            measure(&|q| top(&laplacian[q], k)),
        );
    }
    // How well the first tile (most corners) estimates the query's feature
    // count N: features / expected share, the share by corners (the
    // service's, `permute::expected_shares`), by area, or their mean.
    let mut errors: [Vec<f64>; 3] = Default::default();
    for &q in &with_match {
        let t = tiles_of(q);
        let n: f64 = t.iter().map(|t| t.features as f64).sum();
        let corners: Vec<f32> = t.iter().map(|t| t.corners).collect();
        let area: Vec<f64> = t.iter().map(|t| t.area as f64).collect();
        let first = top(&corners.iter().map(|&c| c as f64).collect::<Vec<_>>(), 1).trailing_zeros()
            as usize;
        let by_corners = permute::expected_shares(&area, false, Some(&corners));
        for (e, share) in errors.iter_mut().zip([
            by_corners[first],
            area[first],
            (by_corners[first] + area[first]) / 2.0,
        ]) {
            if n > 0.0 && share > 0.0 && t[first].features > 0 {
                e.push((t[first].features as f64 / share / n).ln().abs());
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let [a, b, c] = &mut errors;
    println!(
        "N estimated from the first tile (most corners): median |ln(estimate / N)| {:.3} by corners, {:.3} by area, {:.3} by their mean",
        median(a),
        median(b),
        median(c)
    );
    Ok(())
}

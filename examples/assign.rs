//! Does assigning each query feature to more than one word help? For one
//! vocabulary seed, recall@1 / recall@5 at 25, 50, 75 and 100 % of each
//! query's features, with each feature voting for its nearest word only, or
//! also for its next nearest words (those whose squared distance is within a
//! ratio of the nearest's, or all of them): multiple assignment, Jégou et
//! al. 2010, each assignment signed for its own word. The fraction is of
//! the features in a random order on whole queries, or, with `tiles`, of a
//! `2x2+24` query's whole tiles in a random order, as the service streams
//! them (docs/results.md, "More words per feature").
//!
//! ```sh
//! cargo run --release --example assign -- ../shared/datasets/gardens-point 5000 1 [tiles]
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::features::TileGrid;
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use ndarray::{Array2, Axis};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;

const RUNS: u64 = 3;

/// A query's descriptors, and for each its 3 nearest words with their
/// squared distances, nearest first.
type Nearest = (Array2<f32>, Vec<[(u32, f32); 3]>);

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let tiled = args.get(4).is_some_and(|s| s == "tiles");
    let grid = if tiled {
        TileGrid::DEFAULT
    } else {
        TileGrid::WHOLE
    };
    let cache::Prepared {
        dataset,
        queries,
        vocab,
        map,
        ..
    } = cache::prepare_from_args(&args, grid)?;
    let (words, seed) = (vocab.words(), vocab.meta().seed);
    let centroids = vocab.centroids().to_owned();
    let cnorm: Vec<f32> = centroids.rows().into_iter().map(|r| r.dot(&r)).collect();
    // Per query: for each feature, its 3 nearest words and squared distances.
    let nearest: Vec<Option<Nearest>> = (0..queries.len())
        .into_par_iter()
        .map(|q| {
            queries.image(q).map(|d| {
                let d = d.to_owned();
                let dots = d.dot(&centroids.t());
                let near = dots
                    .axis_iter(Axis(0))
                    .zip(d.rows())
                    .map(|(row, x)| {
                        let xn = x.dot(&x);
                        let mut best = [(0u32, f32::INFINITY); 3];
                        for (k, &dot) in row.iter().enumerate() {
                            let dist = xn + cnorm[k] - 2.0 * dot;
                            if dist < best[2].1 {
                                best[2] = (k as u32, dist);
                                best.sort_by(|a, b| a.1.total_cmp(&b.1));
                            }
                        }
                        best
                    })
                    .collect();
                (d, near)
            })
        })
        .collect();
    println!(
        "{}: K = {words}, vocabulary seed {seed}, {RUNS} runs; recall@1 / recall@5 (%) at a fraction of the features",
        dataset.name
    );
    let settings: [(&str, usize, f32); 6] = [
        ("nearest word", 1, 1.0),
        ("2 words ≤ 1.1", 2, 1.1),
        ("2 words ≤ 1.2", 2, 1.2),
        ("2 words", 2, f32::INFINITY),
        ("3 words ≤ 1.2", 3, 1.2),
        ("3 words", 3, f32::INFINITY),
    ];
    for (name, k, ratio) in settings {
        let mut line = format!("{name:<16}");
        let mut expansion = 0.0;
        for fraction in [0.25, 0.5, 0.75, 1.0] {
            let hits: Vec<(bool, bool, f64)> = (0..RUNS)
                .flat_map(|run| (0..nearest.len()).map(move |q| (run, q)))
                .collect::<Vec<_>>()
                .into_par_iter()
                .filter(|&(_, q)| !dataset.truth[q].is_empty())
                .map(|(run, q)| {
                    let Some((d, near)) = &nearest[q] else {
                        return (false, false, 1.0);
                    };
                    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64((run << 32) | q as u64);
                    let (order, take) = if tiled {
                        // whole tiles, in a random order: the first fraction of them
                        let tiles = &queries.meta().tiles[q];
                        let mut starts = Vec::new();
                        let mut at = 0usize;
                        for t in tiles {
                            starts.push((at, t.features as usize));
                            at += t.features as usize;
                        }
                        starts.shuffle(&mut rng);
                        let keep = (tiles.len() as f64 * fraction).round() as usize;
                        let order: Vec<usize> =
                            starts[..keep].iter().flat_map(|&(a, n)| a..a + n).collect();
                        let n = order.len();
                        (order, n)
                    } else {
                        let mut order: Vec<usize> = (0..near.len()).collect();
                        order.shuffle(&mut rng);
                        (
                            order,
                            ((near.len() as f64 * fraction).ceil() as usize).min(near.len()),
                        )
                    };
                    let mut rows = Vec::new();
                    let mut ws = Vec::new();
                    for &i in &order[..take] {
                        let best = near[i];
                        for (j, &(w, dist)) in best.iter().enumerate().take(k) {
                            if j == 0 || dist <= ratio * best[0].1 {
                                rows.push(i);
                                ws.push(w);
                            }
                        }
                    }
                    let desc = d.select(Axis(0), &rows);
                    let mut sigs = vec![0u64; ws.len()];
                    vocab.sign(desc.view(), &ws, &mut sigs);
                    let options = SearchOptions {
                        rule: RuleSpec::new("none", None).expect("built-in rule"),
                        top_n: 5,
                        seed: 0,
                        ..SearchOptions::default()
                    };
                    let o = search_words(
                        &map,
                        KnownFeatures {
                            words: &ws,
                            signatures: &sigs,
                        },
                        &options,
                    );
                    let hit = |n: usize| {
                        o.candidates
                            .iter()
                            .take(n)
                            .any(|c| dataset.truth[q].contains(&c.id))
                    };
                    (hit(1), hit(5), ws.len() as f64 / take.max(1) as f64)
                })
                .collect();
            let rate = |f: fn(&(bool, bool, f64)) -> bool| {
                100.0 * hits.iter().filter(|h| f(h)).count() as f64 / hits.len().max(1) as f64
            };
            expansion = hits.iter().map(|h| h.2).sum::<f64>() / hits.len().max(1) as f64;
            line += &format!("  {fraction}: {:.1} / {:.1}", rate(|h| h.0), rate(|h| h.1));
        }
        println!("{line}  ({expansion:.2} words per feature)");
    }
    Ok(())
}

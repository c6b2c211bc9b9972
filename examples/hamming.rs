//! How much do Hamming weights help, and which? For one vocabulary seed,
//! the full search's recall@1 and recall@5 on whole queries, with plain
//! tf-idf votes and with several [`HammingWeights`], at 25, 50, 75 and 100 %
//! of each query's features (rule `fixed`, 3 random feature orders).
//!
//! ```sh
//! cargo run --release --example hamming -- ../shared/datasets/gardens-point 5000 1
//! ```
//!
//! It reads (or fills) the eval's descriptor, vocabulary and map caches in
//! `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::features::TileGrid;
use bowloc::pipeline::code;
use bowloc::search::{HammingWeights, KnownFeatures, RuleSpec, SearchOptions, search_words};
use rayon::prelude::*;

const RUNS: u64 = 3;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let cache::Prepared {
        dataset,
        queries,
        vocab,
        map,
        ..
    } = cache::prepare_from_args(&args, TileGrid::WHOLE)?;
    let (words, seed) = (vocab.words(), vocab.meta().seed);
    let coded: Vec<_> = (0..queries.len())
        .into_par_iter()
        .map(|q| {
            queries.image(q).map(|d| {
                let c = code(&vocab, d);
                (c.words, c.signatures)
            })
        })
        .collect();
    let weights = |max_distance, sigma| {
        Some(HammingWeights {
            max_distance,
            sigma,
        })
    };
    let settings: [(&str, Option<HammingWeights>); 6] = [
        ("plain tf-idf", None),
        ("d ≤ 20", weights(20, f32::INFINITY)),
        ("d ≤ 24", weights(24, f32::INFINITY)),
        ("d ≤ 28", weights(28, f32::INFINITY)),
        ("d ≤ 24, σ = 16", weights(24, 16.0)),
        ("d ≤ 28, σ = 16", weights(28, 16.0)),
    ];
    println!(
        "{}: K = {words}, vocabulary seed {seed}, {RUNS} runs; recall@1 / recall@5 (%) at a fraction of the features",
        dataset.name
    );
    for (name, hamming) in settings {
        let mut line = format!("{name:<16}");
        for fraction in [0.25, 0.5, 0.75, 1.0] {
            let hits: Vec<(bool, bool)> = (0..RUNS)
                .flat_map(|run| (0..coded.len()).map(move |q| (run, q)))
                .collect::<Vec<_>>()
                .into_par_iter()
                .filter(|&(_, q)| !dataset.truth[q].is_empty())
                .map(|(run, q)| {
                    let Some((w, s)) = &coded[q] else {
                        return (false, false);
                    };
                    let options = SearchOptions {
                        rule: RuleSpec::new("fixed", Some(fraction)).expect("built-in rule"),
                        top_n: 5,
                        seed: (run << 32) | q as u64,
                        hamming,
                        ..SearchOptions::default()
                    };
                    let features = KnownFeatures {
                        words: w,
                        signatures: s,
                    };
                    let o = search_words(&map, features, &options);
                    let hit = |n: usize| {
                        o.candidates
                            .iter()
                            .take(n)
                            .any(|c| dataset.truth[q].contains(&c.id))
                    };
                    (hit(1), hit(5))
                })
                .collect();
            let rate = |f: fn(&(bool, bool)) -> bool| {
                100.0 * hits.iter().filter(|h| f(h)).count() as f64 / hits.len().max(1) as f64
            };
            line += &format!("  {fraction}: {:.1} / {:.1}", rate(|h| h.0), rate(|h| h.1));
        }
        println!("{line}");
    }
    Ok(())
}

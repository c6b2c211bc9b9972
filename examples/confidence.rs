//! Which number says a full search's top answer can be trusted? For one
//! vocabulary seed, every query is searched in full (whole image, Hamming
//! weights) and its top candidate scored by its distinctness,
//! h / (h + h_elsewhere), and by place-z's statistic, (h − h_elsewhere) /
//! √(Σv² + Σv_elsewhere²), the lead over the best image outside its place
//! in units of its spread. Prints recall@1 and the top-1 recall at 90 %
//! precision when answers are kept by each (docs/results.md,
//! "Distinctness").
//!
//! ```sh
//! cargo run --release --example confidence -- ../shared/datasets/gardens-point 5000 1
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::eval::metrics::{self, Answer};
use bowloc::features::TileGrid;
use bowloc::pipeline::code;
use bowloc::search::rank::distinctness;
use bowloc::search::stop::RuleContext;
use bowloc::search::{HammingWeights, Ranked, RuleSpec, SearchOptions, VoteStats, Voter};
use std::collections::HashSet;

/// A query's top candidate, its distinctness and place-z's statistic.
type Top = (u32, f64, f64);

/// Recall of the top answer at 90 % precision when each query's top
/// candidate (`None`: no answer) is scored by a confidence, as the eval
/// measures it ([`metrics::recall_at_precision`]).
fn recall_at_90(tops: &[Option<(u32, f64)>], truth: &[HashSet<u32>]) -> f64 {
    let ranked: Vec<Vec<Ranked>> = tops
        .iter()
        .map(|top| {
            top.iter()
                .map(|&(id, confidence)| Ranked {
                    id,
                    score: confidence as f32,
                    distinct: 0.0,
                })
                .collect()
        })
        .collect();
    metrics::recall_at_precision(&Answer::all(&ranked, truth), 1, 0.9).recall
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let cache::Prepared {
        dataset,
        queries,
        vocab,
        map,
        ..
    } = cache::prepare_from_args(&args, TileGrid::WHOLE)?;
    let window = SearchOptions::PLACE_WINDOW;
    let context = RuleContext {
        place_window: window,
        ..RuleContext::default()
    };
    let z_rule = RuleSpec::new("place-z", Some(2.0))
        .map_err(anyhow::Error::msg)?
        .build(&context);
    let view = map.view();
    // what place-z reads: the leaders a place needs, and their Σv²
    let needs = z_rule.needs();
    // per query: its top candidate with its distinctness and z
    let tops: Vec<Option<Top>> = (0..queries.len())
        .map(|q| {
            let coded = code(&vocab, queries.image(q)?);
            let mut voter =
                Voter::with_needs(&view, needs).with_hamming(&map, HammingWeights::DEFAULT);
            for (&w, &s) in coded.words.iter().zip(&coded.signatures) {
                voter.vote(w, s);
            }
            let &(h, top) = voter.top().first()?;
            let distinct = distinctness(top, h, voter.top(), window) as f64;
            let z = z_rule.statistic(&voter).map_or(0.0, |s| s.0);
            Some((top, distinct, z))
        })
        .collect();
    // each confidence's rank, a share of the queries with an answer
    let ranks = |confidence: fn(&Top) -> f64| -> Vec<f64> {
        let mut order: Vec<usize> = (0..tops.len()).filter(|&q| tops[q].is_some()).collect();
        order.sort_by(|&a, &b| {
            let c = |q: usize| tops[q].as_ref().map_or(0.0, confidence);
            c(a).total_cmp(&c(b))
        });
        let mut r = vec![0.0; tops.len()];
        for (k, &q) in order.iter().enumerate() {
            r[q] = k as f64 / order.len() as f64;
        }
        r
    };
    let (rank_d, rank_z) = (ranks(|t| t.1), ranks(|t| t.2));
    let scored = |confidence: &dyn Fn(usize, &Top) -> f64| -> Vec<Option<(u32, f64)>> {
        tops.iter()
            .enumerate()
            .map(|(q, t)| t.as_ref().map(|t| (t.0, confidence(q, t))))
            .collect()
    };
    let with_match = dataset.truth.iter().filter(|t| !t.is_empty()).count();
    let right = tops
        .iter()
        .zip(&dataset.truth)
        .filter(|(t, truth)| t.is_some_and(|t| truth.contains(&t.0)))
        .count();
    println!(
        "{}: K = {}, vocabulary seed {}; full search, whole queries: recall@1 {:.1} %",
        dataset.name,
        vocab.words(),
        vocab.meta().seed,
        100.0 * right as f64 / with_match as f64
    );
    println!(
        "top-1 recall at 90 % precision: by distinctness {:.1} %, by place-z's statistic {:.1} %, by the lower rank of the two {:.1} %",
        100.0 * recall_at_90(&scored(&|_, t| t.1), &dataset.truth),
        100.0 * recall_at_90(&scored(&|_, t| t.2), &dataset.truth),
        100.0 * recall_at_90(&scored(&|q, _| rank_d[q].min(rank_z[q])), &dataset.truth)
    );
    Ok(())
}

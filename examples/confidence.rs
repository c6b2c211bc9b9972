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
use bowloc::features::TileGrid;
use bowloc::pipeline::code;
use bowloc::search::stop::RuleContext;
use bowloc::search::{HammingWeights, Needs, RuleSpec, SearchOptions, VoteStats, Voter};

/// Recall of the top answer at 90 % precision when the answers are kept in
/// order of `confidence` (highest first): the most correct answers any
/// cut keeps at a precision of at least 0.9, over the queries with a match.
fn recall_at_90(answers: &[(f64, bool)], with_match: usize) -> f64 {
    let mut sorted = answers.to_vec();
    sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut kept, mut right, mut best) = (0usize, 0usize, 0usize);
    for (_, correct) in sorted {
        kept += 1;
        right += usize::from(correct);
        if right as f64 >= 0.9 * kept as f64 {
            best = best.max(right);
        }
    }
    best as f64 / with_match as f64
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
    let (mut by_distinct, mut by_z) = (Vec::new(), Vec::new());
    let mut by_rank = Vec::new();
    let with_match = dataset.truth.iter().filter(|t| !t.is_empty()).count();
    for q in 0..queries.len() {
        if dataset.truth[q].is_empty() {
            continue;
        }
        let Some(d) = queries.image(q) else {
            continue;
        };
        let coded = code(&vocab, d);
        let needs = Needs {
            top: 2 * window as usize + 2,
            squares: true,
            ..Needs::default()
        };
        let mut voter = Voter::with_needs(&view, needs).with_hamming(&map, HammingWeights::DEFAULT);
        for (&w, &s) in coded.words.iter().zip(&coded.signatures) {
            voter.vote(w, s);
        }
        let Some(&(h, top)) = voter.top().first() else {
            continue;
        };
        let correct = dataset.truth[q].contains(&top);
        let elsewhere = bowloc::search::rank::elsewhere(top, voter.top(), window);
        by_distinct.push(((h / (h + elsewhere)) as f64, correct));
        let z = z_rule.statistic(&voter).map_or(0.0, |s| s.0);
        by_z.push((z, correct));
    }
    // both, by the lower of the two ranks (each a share of the queries)
    let ranks = |v: &[(f64, bool)]| -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&a, &b| v[a].0.total_cmp(&v[b].0));
        let mut r = vec![0.0; v.len()];
        for (k, &i) in idx.iter().enumerate() {
            r[i] = k as f64 / v.len() as f64;
        }
        r
    };
    let (rd, rz) = (ranks(&by_distinct), ranks(&by_z));
    for i in 0..by_z.len() {
        by_rank.push((rd[i].min(rz[i]), by_z[i].1));
    }
    let right = by_z.iter().filter(|a| a.1).count();
    println!(
        "{}: K = {}, vocabulary seed {}; full search, whole queries: recall@1 {:.1} %",
        dataset.name,
        vocab.words(),
        vocab.meta().seed,
        100.0 * right as f64 / with_match as f64
    );
    println!(
        "top-1 recall at 90 % precision: by distinctness {:.1} %, by place-z's statistic {:.1} %, by the lower rank of the two {:.1} %",
        100.0 * recall_at_90(&by_distinct, with_match),
        100.0 * recall_at_90(&by_z, with_match),
        100.0 * recall_at_90(&by_rank, with_match)
    );
    Ok(())
}

//! Would smaller queries buy the time? For one vocabulary seed, the full
//! search (whole images, Hamming weights) with the queries extracted at the
//! map's 640 px and at a smaller longest side: recall@1, recall@5 and the
//! median decode + extraction time against 640 px (the map is extracted at
//! 640 px either way; docs/results.md, "What a stop at tile ends can reach").
//!
//! ```sh
//! cargo run --release --example query_side -- ../shared/datasets/gardens-point 5000 1 480
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::features::{ExtractConfig, TileGrid};
use bowloc::pipeline::code;
use bowloc::search::rank::top_n;
use bowloc::search::{HammingWeights, Needs, SearchOptions, Voter};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let side: u32 = args.get(4).map_or(Ok(480), |s| s.parse())?;
    let p = cache::prepare_from_args(&args, TileGrid::WHOLE)?;
    let dir = Path::new("data/eval-cache").join(&p.dataset.name);
    let config = ExtractConfig {
        max_side: side,
        ..ExtractConfig::default()
    };
    let small = cache::descriptors(
        &dir.join(format!("queries-whole-side{side}.bowdesc")),
        &p.dataset.queries,
        &config,
        TileGrid::WHOLE,
        "small",
    )?;
    let view = p.map.view();
    let window = SearchOptions::PLACE_WINDOW;
    let smaller = format!("{side} px");
    for (name, set) in [("640 px", &p.queries), (smaller.as_str(), &small)] {
        let (mut r1, mut r5, mut n, mut ms) = (0, 0, 0, vec![]);
        for q in 0..set.len() {
            let truth = &p.dataset.truth[q];
            if truth.is_empty() {
                continue;
            }
            n += 1;
            ms.push(set.extract_ms(q) / p.queries.extract_ms(q));
            let Some(d) = set.image(q) else { continue };
            let coded = code(&p.vocab, d);
            let mut voter = Voter::with_needs(&view, Needs::default())
                .with_hamming(&p.map, HammingWeights::DEFAULT);
            for (&w, &s) in coded.words.iter().zip(&coded.signatures) {
                voter.vote(w, s);
            }
            let top = top_n(&voter, 5, 0.0, None, window);
            r1 += usize::from(top.first().is_some_and(|r| truth.contains(&r.id)));
            r5 += usize::from(top.iter().any(|r| truth.contains(&r.id)));
        }
        ms.sort_by(f64::total_cmp);
        println!(
            "{} seed {}, queries at {name}: recall@1 {:.1} %, recall@5 {:.1} %, median time {:.3}× that of 640 px",
            p.dataset.name,
            p.vocab.meta().seed,
            100.0 * r1 as f64 / n as f64,
            100.0 * r5 as f64 / n as f64,
            ms[ms.len() / 2]
        );
    }
    Ok(())
}

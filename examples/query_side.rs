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
    let smaller = format!("{side} px");
    for (name, set) in [("640 px", &p.queries), (smaller.as_str(), &small)] {
        let with_match = (0..set.len()).filter(|&q| !p.dataset.truth[q].is_empty());
        let mut ms: Vec<f64> = with_match
            .map(|q| set.extract_ms(q) / p.queries.extract_ms(q))
            .collect();
        ms.sort_by(f64::total_cmp);
        let images: Vec<_> = (0..set.len()).map(|q| set.image(q)).collect();
        let (r1, r5) = p.full_search_recall(&images);
        println!(
            "{} seed {}, queries at {name}: recall@1 {r1:.1} %, recall@5 {r5:.1} %, median time {:.3}× that of 640 px",
            p.dataset.name,
            p.vocab.meta().seed,
            ms[ms.len() / 2]
        );
    }
    Ok(())
}

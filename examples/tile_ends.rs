//! What a streamed query looks like at the end of each tile: for one
//! vocabulary seed and three feature orders, every query's tiles are voted in
//! the service's order (`2x2+24` or the grid given, richest first, Hamming weights) and, after
//! each tile, one CSV row says whether the top-1 and the top-5 so far hold a
//! true match, place-z's statistic, whether that tile's own votes (taken
//! alone) lead in the same place as all the votes so far, the share of the
//! whole image's decode and extraction time spent up to then, and the
//! leader's inliers and its place's (verified as the service's geometric
//! stops verify, with their word pairs, against the features voted so far),
//! and the answer the service would give then with verification on (the top
//! k re-ranked in the configured order: its top-1 and top-5 right or not),
//! with the inliers and the |ln| of the relative scale (−1 when it has none)
//! of the first answer a geometric stop would check then (the same re-ranking
//! with the stops' word pairs): at the default floor (`v_`, what `verified 6`
//! checks) and at the floors of m = 8 and 12 (`v8_`, `v12_`), which a stop
//! asking for m inliers raises. A rule that stops at tile ends can be tried
//! on these rows without a new search.
//!
//! ```sh
//! cargo run --release --example tile_ends -- ../shared/datasets/gardens-point 5000 1 [GRID] > ends.csv
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::eval::sweep::seed;
use bowloc::features::TileGrid;
use bowloc::features::fit::OpenCvFit;
use bowloc::geometry::verify::{VerifyParams, rerank, verify_leader, with_keypoints};
use bowloc::pipeline::code;
use bowloc::search::rank::top_n;
use bowloc::search::stop::RuleContext;
use bowloc::search::{HammingWeights, RuleSpec, SearchOptions, TileOrder, VoteStats, Voted, Voter};

const RUNS: u32 = 3;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let grid: TileGrid = match args.get(4) {
        Some(g) => g.parse().map_err(anyhow::Error::msg)?,
        None => TileGrid::DEFAULT,
    };
    let cache::Prepared {
        dataset,
        queries,
        whole_queries,
        vocab,
        map,
        ..
    } = cache::prepare_from_args(&args, grid)?;
    // extracted with the tiles, image by image, so their times compare
    let whole = whole_queries.as_ref().unwrap_or(&queries);
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
    let same_place = |a: u32, b: u32| a.abs_diff(b) <= window;
    bowloc::features::set_opencv_threads(1);
    let verify = VerifyParams::default();
    // what the geometric stops check, with their word pairs, at the
    // default floor (`verified 6`) and at the floors of m = 8 and 12
    let stops = [0, 8, 12].map(|m| verify.for_stop(m));
    let fit = OpenCvFit::new(verify.fit());
    let images = map.images() as u32;
    println!(
        "seed,run,query,tile,tiles,time_share,top1,top5,z,tile_agrees,tile_leader_z,leader,tile_leader,features,total,leader_inliers,place_inliers,vtop1,vtop5,v_inliers,v_log_scale,v8_inliers,v8_log_scale,v12_inliers,v12_log_scale"
    );
    for q in 0..queries.len() {
        let truth = &dataset.truth[q];
        if truth.is_empty() {
            continue;
        }
        let Some(descriptors) = queries.image(q) else {
            continue;
        };
        let coded = code(&vocab, descriptors);
        let query = queries.query(q, coded.words.clone(), coded.signatures.clone());
        let whole_ms = whole.extract_ms(q);
        for run in 0..RUNS {
            let (order, spans) = query.tile_order(seed(run, q), TileOrder::Richest);
            let mut voter =
                Voter::with_needs(&view, needs).with_hamming(&map, HammingWeights::DEFAULT);
            let mut spent = query.fixed_ms as f64;
            let mut voted: Vec<Voted> = Vec::new();
            for (k, (&t, &(a, b, _))) in order.iter().zip(&spans).enumerate() {
                let mut alone =
                    Voter::with_needs(&view, needs).with_hamming(&map, HammingWeights::DEFAULT);
                for i in a..b {
                    voter.vote(coded.words[i], coded.signatures[i]);
                    alone.vote(coded.words[i], coded.signatures[i]);
                    voted.push(Voted {
                        feature: i as u32,
                        word: coded.words[i],
                        signature: coded.signatures[i],
                    });
                }
                // the leader's inliers against the features so far, and its
                // place's (the map images within the window, each checked)
                let seen = with_keypoints(&voted, &query.keypoints);
                let inliers = |j: u32| verify_leader(&map, j, &seen, &fit, &stops[0]).inliers;
                let (leader_inliers, place_inliers) = voter.tally().leader.map_or((0, 0), |l| {
                    let place = l.saturating_sub(window)..=(l + window).min(images - 1);
                    (inliers(l), place.map(inliers).sum::<usize>())
                });
                spent += query.tiles.get(t).map_or(0.0, |t| t.ms as f64);
                let top = top_n(&voter, 5, 0.0, None, window);
                let top1 = top.first().is_some_and(|r| truth.contains(&r.id));
                // the answer the service gives after verifying the top k
                let candidates = top_n(&voter, verify.top_k, 0.0, None, window);
                let votes: Vec<(u32, f32)> = candidates.iter().map(|r| (r.id, r.score)).collect();
                let reranked = rerank(&map, &votes, &seen, &fit, &verify, window);
                let vtop1 = reranked.first().is_some_and(|r| truth.contains(&r.id));
                let vtop5 = reranked.iter().take(5).any(|r| truth.contains(&r.id));
                // what a geometric stop checks: the same, with its pairs and
                // its floor
                let [v, v8, v12] = stops.each_ref().map(|stop| {
                    let checked = rerank(&map, &votes, &seen, &fit, stop, window);
                    checked.first().map_or((0, -1.0), |r| {
                        (r.inliers(), r.scale().map_or(-1.0, |s| s.ln().abs()))
                    })
                });
                let top5 = top.iter().any(|r| truth.contains(&r.id));
                let z = z_rule.statistic(&voter).map_or(0.0, |s| s.0);
                let alone_z = z_rule.statistic(&alone).map_or(0.0, |s| s.0);
                let agrees = match (voter.tally().leader, alone.tally().leader) {
                    (Some(l), Some(m)) => same_place(l, m),
                    _ => false,
                };
                println!(
                    "{},{run},{q},{},{},{:.4},{},{},{z:.4},{},{alone_z:.4},{},{},{},{},{leader_inliers},{place_inliers},{},{},{},{:.4},{},{:.4},{},{:.4}",
                    vocab.meta().seed,
                    k + 1,
                    order.len(),
                    spent / whole_ms,
                    u8::from(top1),
                    u8::from(top5),
                    u8::from(agrees),
                    voter.tally().leader.map_or(-1, i64::from),
                    alone.tally().leader.map_or(-1, i64::from),
                    voter.tally().features,
                    coded.words.len(),
                    u8::from(vtop1),
                    u8::from(vtop5),
                    v.0,
                    v.1,
                    v8.0,
                    v8.1,
                    v12.0,
                    v12.1,
                );
            }
        }
    }
    Ok(())
}

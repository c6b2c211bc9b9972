//! Every query's top vote candidates with what could rank them: for one
//! vocabulary seed, each query is searched in full (whole image, Hamming
//! weights) and its top 10 candidates verified as the service verifies them.
//! One CSV row per candidate: its vote rank, vote score, distinctness,
//! inliers and whether it is a true match (rank -1: a query without
//! features). `scripts/verify-orders.sh` orders the rows as each
//! verification order would.
//!
//! ```sh
//! cargo run --release --example candidates -- ../shared/datasets/gardens-point 5000 1 > candidates.csv
//! ```
use bowloc::eval::cache;
use bowloc::features::TileGrid;
use bowloc::features::fit::OpenCvFit;
use bowloc::geometry::verify::{VerifyParams, rerank, with_keypoints};
use bowloc::pipeline::code;
use bowloc::search::rank::top_n;
use bowloc::search::{HammingWeights, Needs, SearchOptions, Voted, Voter};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let grid: TileGrid = match args.get(4) {
        Some(g) => g.parse().map_err(anyhow::Error::msg)?,
        None => TileGrid::WHOLE,
    };
    let p = cache::prepare_from_args(&args, grid)?;
    bowloc::features::set_opencv_threads(1);
    let params = VerifyParams::default();
    let fit = OpenCvFit::new(params.fit());
    let view = p.map.view();
    let window = SearchOptions::PLACE_WINDOW;
    println!("seed,query,rank,id,votes,distinct,inliers,verified,correct,features");
    for q in 0..p.queries.len() {
        let truth = &p.dataset.truth[q];
        if truth.is_empty() {
            continue;
        }
        // a query without features: one row without a candidate
        let no_candidate = || println!("{},{q},-1,-1,0,0,0,0,0,0", p.vocab.meta().seed);
        let Some(d) = p.queries.image(q) else {
            no_candidate();
            continue;
        };
        let coded = code(&p.vocab, d);
        let mut voter = Voter::with_needs(&view, Needs::default())
            .with_hamming(&p.map, HammingWeights::DEFAULT);
        for (&w, &s) in coded.words.iter().zip(&coded.signatures) {
            voter.vote(w, s);
        }
        let top = top_n(&voter, params.top_k, 0.0, None, window);
        if top.is_empty() {
            no_candidate();
            continue;
        }
        let voted: Vec<Voted> = coded
            .words
            .iter()
            .zip(&coded.signatures)
            .enumerate()
            .map(|(i, (&word, &signature))| Voted {
                feature: i as u32,
                word,
                signature,
            })
            .collect();
        let keypoints = p.queries.keypoints(q);
        let votes: Vec<(u32, f32)> = top.iter().map(|r| (r.id, r.score)).collect();
        let reranked = rerank(
            &p.map,
            &votes,
            &with_keypoints(&voted, &keypoints),
            &fit,
            &params,
            window,
        );
        for (rank, r) in top.iter().enumerate() {
            let v = reranked
                .iter()
                .find(|x| x.id == r.id)
                .and_then(|x| x.verification);
            println!(
                "{},{q},{rank},{},{},{},{},{},{},{}",
                p.vocab.meta().seed,
                r.id,
                r.score,
                r.distinct,
                v.map_or(0, |v| v.inliers),
                u8::from(v.is_some_and(|v| v.verified)),
                u8::from(truth.contains(&r.id)),
                coded.words.len()
            );
        }
    }
    Ok(())
}

//! Every query's top vote candidates with what could rank them: for one
//! vocabulary seed, each query is searched in full (whole image, Hamming
//! weights) and its top 10 candidates verified as the service verifies them.
//! One CSV row per candidate: its vote rank, vote score, distinctness,
//! inliers, whether it is a true match and the relative scale its inliers
//! show (`geometry::relative_scale`, 1 without one; rank -1: a query without
//! features). `scripts/verify-orders.sh` orders the rows as each
//! verification order would.
//!
//! With a fifth argument `descriptors`, each candidate also gets
//! `desc_inliers`: the inliers of the same fit to descriptor matches (Lowe's
//! ratio test) instead of word pairs, what a map that kept its descriptors
//! could verify with; and per query the milliseconds each way took for all
//! candidates, `words_ms` and `desc_ms` (`scripts/verify-descriptors.sh`).
//!
//! ```sh
//! cargo run --release --example candidates -- ../shared/datasets/gardens-point 5000 1 [GRID] [descriptors] > candidates.csv
//! ```
use bowloc::eval::cache;
use bowloc::features::TileGrid;
use bowloc::features::fit::OpenCvFit;
use bowloc::geometry::ratio_matches::{RATIO, ratio_correspondences};
use bowloc::geometry::verify::{VerifyParams, count_inliers, rerank, with_keypoints};
use bowloc::pipeline::code;
use bowloc::search::rank::top_n;
use bowloc::search::{HammingWeights, Needs, SearchOptions, Voted, Voter};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let grid: TileGrid = match args.get(4) {
        Some(g) => g.parse().map_err(anyhow::Error::msg)?,
        None => TileGrid::WHOLE,
    };
    let descriptors = match args.get(5).map(String::as_str) {
        None => false,
        Some("descriptors") => true,
        Some(other) => anyhow::bail!("fifth argument: `descriptors` or nothing, not {other:?}"),
    };
    let p = cache::prepare_from_args(&args, grid)?;
    bowloc::features::set_opencv_threads(1);
    let params = VerifyParams::default();
    let fit = OpenCvFit::new(params.fit());
    let view = p.map.view();
    let window = SearchOptions::PLACE_WINDOW;
    let desc_column = if descriptors {
        ",desc_inliers,words_ms,desc_ms"
    } else {
        ""
    };
    println!(
        "seed,query,rank,id,votes,distinct,inliers,verified,correct,features,scale{desc_column}"
    );
    for q in 0..p.queries.len() {
        let truth = &p.dataset.truth[q];
        if truth.is_empty() {
            continue;
        }
        // a query without features: one row without a candidate
        let no_candidate = || {
            let desc = if descriptors { ",0,0,0" } else { "" };
            println!("{},{q},-1,-1,0,0,0,0,0,0,1{desc}", p.vocab.meta().seed)
        };
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
        let started = std::time::Instant::now();
        let reranked = rerank(
            &p.map,
            &votes,
            &with_keypoints(&voted, &keypoints),
            &fit,
            &params,
            window,
        );
        let words_ms = started.elapsed().as_secs_f64() * 1e3;
        // descriptor matches + the same fit, for each candidate
        let started = std::time::Instant::now();
        let desc_inliers: Vec<usize> = if descriptors {
            top.iter()
                .map(|r| {
                    let Some(md) = p.map_descriptors.image(r.id as usize) else {
                        return 0;
                    };
                    let mk = p.map_descriptors.keypoints(r.id as usize);
                    let c = ratio_correspondences((d, &keypoints), (md, &mk), RATIO);
                    count_inliers(&c, &fit, 0).inliers
                })
                .collect()
        } else {
            Vec::new()
        };
        let desc_ms = started.elapsed().as_secs_f64() * 1e3;
        for (rank, r) in top.iter().enumerate() {
            let x = reranked.iter().find(|x| x.id == r.id);
            let v = x.and_then(|x| x.verification);
            let scale = x.and_then(|x| x.scale()).unwrap_or(1.0);
            let desc = if descriptors {
                format!(",{},{words_ms:.3},{desc_ms:.3}", desc_inliers[rank])
            } else {
                String::new()
            };
            println!(
                "{},{q},{rank},{},{},{},{},{},{},{},{scale}{desc}",
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

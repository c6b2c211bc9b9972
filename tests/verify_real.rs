//! Geometric verification on real images (`rtabmap-loop`, K = 1000): the
//! recall@1 gain of re-ranking an early-stopped search by inliers, and the
//! localizer's verified answers, including a query without features.

mod common;

use bowloc::features::fit::OpenCvFit;
use bowloc::geometry::Keypoint;
use bowloc::geometry::matches::QueryFeature;
use bowloc::geometry::verify::{VerifyParams, rerank};
use bowloc::pipeline::{Localizer, words_per_image};
use bowloc::search::{RuleSpec, SearchOptions, permute, search_words};

/// Recall@1 of rule `fixed` at 10 % of the features over three feature
/// orders, measured on this dataset at K = 1000, seed 1 (printed by this
/// test; `bowloc eval --dataset ../shared/datasets/rtabmap-loop --words 1000
/// --rules none --set fixed=0.1 --runs 3 --verify` prints the same figures):
/// 74.2 % by votes, 80.3 % after verification. The test asserts a gain of at
/// least 3 points.
const MIN_GAIN: f64 = 0.03;

#[test]
fn verification_raises_recall_at_1_of_an_early_stopped_search() {
    let common::RealMap {
        data,
        vocab,
        map,
        queries: query_features,
    } = common::real_map("rtabmap-loop", 1000);
    let query_words = words_per_image(&vocab, &query_features);

    let params = VerifyParams::default();
    let fit = OpenCvFit::new(params.fit());
    let (mut by_votes, mut verified, mut answered) = (0, 0, 0);
    for run in 0..3u64 {
        for (q, (words, features)) in query_words.iter().zip(&query_features).enumerate() {
            let truth = &data.truth[q];
            if truth.is_empty() {
                continue;
            }
            answered += 1;
            let seed = (run << 32) | q as u64;
            let options = SearchOptions {
                rule: RuleSpec::new("fixed", Some(0.1)).unwrap(),
                top_n: 10,
                seed,
                ..Default::default()
            };
            let outcome = search_words(&map, words.known(), &options);
            if outcome
                .candidates
                .first()
                .is_some_and(|c| truth.contains(&c.id))
            {
                by_votes += 1;
            }
            let keypoints: &[Keypoint] = features.as_ref().map_or(&[], |f| &f.keypoints);
            let seen: Vec<QueryFeature> = permute::permutation(words.words.len(), seed)
                [..outcome.features_used]
                .iter()
                .map(|&i| QueryFeature {
                    word: words.words[i as usize],
                    signature: words.signatures[i as usize],
                    keypoint: keypoints[i as usize],
                })
                .collect();
            let votes: Vec<(u32, f32)> =
                outcome.candidates.iter().map(|c| (c.id, c.score)).collect();
            let reranked = rerank(&map, &votes, &seen, &fit, &params);
            if reranked.first().is_some_and(|c| truth.contains(&c.id)) {
                verified += 1;
            }
        }
    }
    let (r_votes, r_verified) = (
        by_votes as f64 / answered as f64,
        verified as f64 / answered as f64,
    );
    println!(
        "rtabmap-loop, fixed 0.1, K=1000, 3 runs: recall@1 {r_votes:.3} by votes, {r_verified:.3} verified"
    );
    assert!(
        r_verified >= r_votes + MIN_GAIN,
        "recall@1 {r_verified:.3} verified vs {r_votes:.3} by votes"
    );

    // The localizer end to end: verified answers carry inliers and the time.
    let dir = tempfile::tempdir().unwrap();
    let (vpath, mpath) = (dir.path().join("v.bowvoc"), dir.path().join("m.bowmap"));
    vocab.save(&vpath).unwrap();
    map.save(&mpath).unwrap();
    let mut localizer = Localizer::open(&vpath, &mpath, true).unwrap();
    localizer.set_verify(VerifyParams {
        enabled: true,
        ..VerifyParams::default()
    });
    let options = SearchOptions {
        top_n: 3,
        seed: 1,
        ..Default::default()
    };
    let q = &data.queries[0];
    let answer = localizer.localize_file(&q.path, &options, None).unwrap();
    assert_eq!(answer.candidates.len(), 3);
    let top = &answer.candidates[0];
    assert!(top.inliers.unwrap() >= params.min_inliers as u32, "{top:?}");
    assert_eq!(top.verified, Some(true));
    assert_eq!(top.score, top.inliers.unwrap() as f32);
    assert!(data.truth[0].contains(&top.id), "{top:?}");
    assert!(answer.timings_ms.verify > 0.0);
    assert_eq!(answer.verified, Some(true));
    // scores are inliers, best first
    assert!(
        answer
            .candidates
            .windows(2)
            .all(|w| w[0].score >= w[1].score)
    );
    // min_score now counts inliers
    let strict = SearchOptions {
        min_score: 1e6,
        ..options.clone()
    };
    let none = localizer.localize_file(&q.path, &strict, None).unwrap();
    assert!(none.candidates.is_empty());
    assert_eq!(none.verified, Some(false));

    // A query without features answers cleanly, verified or not.
    let uniform =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/uniform.png");
    for verify in [true, false] {
        let bytes = std::fs::read(&uniform).unwrap();
        let a = localizer
            .localize_tiled(&bytes, &options, localizer.tiles, verify)
            .unwrap();
        assert!(a.candidates.is_empty());
        assert_eq!(a.features.total, 0);
    }
}

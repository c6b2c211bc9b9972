//! The search on random maps: the full search equals brute-force tf-idf
//! cosine, seeds and block sizes change nothing they should not, early
//! scores estimate the full ones, deadlines, warm-ups, traces and a stop
//! inside a tile.

use super::*;
use crate::index::{ImageWords, MapBuilder, MapIndex};
use crate::quantize::ExactQuantizer;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

const K: usize = 300;

/// Random map: images draw words from overlapping ranges so rankings are
/// informative; returns the map and each image's raw word list.
fn random_map(images: usize, seed: u64) -> (MapIndex, Vec<Vec<u32>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut b = MapBuilder::new(K);
    let mut lists = Vec::new();
    for j in 0..images {
        let centre = rng.random_range(0..K);
        let n = rng.random_range(20..80);
        let words: Vec<u32> = (0..n)
            .map(|_| ((centre + rng.random_range(0..40)) % K) as u32)
            .collect();
        b.add(ImageWords::from_words(format!("img{j}"), &words));
        lists.push(words);
    }
    (b.build("random", "0", None), lists)
}

/// tf-idf cosine ranking computed directly from raw counts, independently of
/// the index: score_j = q·d̂_j with q(w) = count_q(w)/N·idf(w).
fn brute_force(lists: &[Vec<u32>], query: &[u32]) -> Vec<(u32, f64)> {
    let n_images = lists.len() as f64;
    let count = |l: &[u32]| {
        let mut m: HashMap<u32, f64> = HashMap::new();
        for &w in l {
            *m.entry(w).or_default() += 1.0;
        }
        m
    };
    let counts: Vec<HashMap<u32, f64>> = lists.iter().map(|l| count(l)).collect();
    let mut df: HashMap<u32, f64> = HashMap::new();
    for c in &counts {
        for &w in c.keys() {
            *df.entry(w).or_default() += 1.0;
        }
    }
    let idf = |w: u32| df.get(&w).map_or(0.0, |&d| (n_images / d).ln());
    let q = count(query);
    let nq = query.len() as f64;
    let mut scores: Vec<(u32, f64)> = counts
        .iter()
        .zip(lists)
        .enumerate()
        .map(|(j, (c, l))| {
            let nj = l.len() as f64;
            let d: HashMap<u32, f64> = c.iter().map(|(&w, &k)| (w, k / nj * idf(w))).collect();
            let norm = d.values().map(|v| v * v).sum::<f64>().sqrt();
            let dot: f64 = q
                .iter()
                .map(|(&w, &k)| k / nq * idf(w) * d.get(&w).copied().unwrap_or(0.0))
                .sum();
            (j as u32, if norm > 0.0 { dot / norm } else { 0.0 })
        })
        .filter(|&(_, s)| s > 0.0)
        .collect();
    scores.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    scores
}

fn opts(rule: &str, p: Option<f64>, seed: u64) -> SearchOptions {
    SearchOptions {
        rule: RuleSpec::new(rule, p).unwrap(),
        top_n: 10,
        seed,
        ..Default::default()
    }
}

#[test]
fn full_bow_ranking_equals_brute_force_tfidf_cosine() {
    let (map, lists) = random_map(60, 1);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for q in 0..20 {
        // queries: noisy copies of map images
        let base = &lists[q * 3];
        let query: Vec<u32> = base
            .iter()
            .map(|&w| {
                if rng.random::<f32>() < 0.3 {
                    rng.random_range(0..K as u32)
                } else {
                    w
                }
            })
            .collect();
        let got = search_words(
            &map,
            KnownFeatures::words(&query),
            &opts("none", None, q as u64),
        );
        assert_eq!(got.features_used, query.len());
        assert_eq!(got.stop.kind, StopKind::Exhausted);
        let want = brute_force(&lists, &query);
        assert_eq!(got.candidates.len(), 10.min(want.len()));
        for (g, w) in got.candidates.iter().zip(&want) {
            assert!(
                (g.score as f64 - w.1).abs() < 1e-4,
                "query {q}: score {} vs {}",
                g.score,
                w.1
            );
            // equal ids unless two brute-force scores tie within rounding
            if g.id != w.0 {
                let other = want.iter().find(|x| x.0 == g.id).unwrap();
                assert!((other.1 - w.1).abs() < 1e-5, "query {q}: rank differs");
            }
        }
    }
}

#[test]
fn same_seed_same_outcome_different_seeds_differ() {
    let (map, lists) = random_map(40, 3);
    let query = &lists[5];
    let run = |seed| {
        search_words(
            &map,
            KnownFeatures::words(query),
            &opts("stable-peak", Some(8.0), seed),
        )
    };
    let a = run(7);
    let b = run(7);
    assert_eq!(a.candidates, b.candidates);
    assert_eq!(a.stop, b.stop);
    let stops: std::collections::HashSet<usize> = (0..30).map(|s| run(s).stop.at_feature).collect();
    assert!(stops.len() > 1, "every seed stopped at the same feature");
}

#[test]
fn stop_point_does_not_depend_on_block_size() {
    let (map, lists) = random_map(40, 4);
    let query = &lists[9];
    let reference = search_words(
        &map,
        KnownFeatures::words(query),
        &opts("fixed", Some(0.37), 5),
    );
    assert_eq!(
        reference.features_used,
        (0.37 * query.len() as f64).ceil() as usize
    );
    for block in [1, 3, 7, 32, 1000] {
        let o = SearchOptions {
            block,
            ..opts("fixed", Some(0.37), 5)
        };
        let got = search_words(&map, KnownFeatures::words(query), &o);
        assert_eq!(got.features_used, reference.features_used, "block {block}");
        assert_eq!(got.candidates, reference.candidates, "block {block}");
    }
}

#[test]
fn early_scores_are_unbiased_estimates_of_full_scores() {
    let (map, lists) = random_map(30, 6);
    let query = &lists[2];
    let full = search_words(&map, KnownFeatures::words(query), &opts("none", None, 0));
    let target = full.candidates[0];
    let runs = 3000;
    let mut sum = 0.0f64;
    for seed in 0..runs {
        let o = SearchOptions {
            top_n: 30,
            ..opts("fixed", Some(0.5), seed)
        };
        let got = search_words(&map, KnownFeatures::words(query), &o);
        sum += got
            .candidates
            .iter()
            .find(|c| c.id == target.id)
            .map_or(0.0, |c| c.score as f64);
    }
    let mean = sum / runs as f64;
    let rel = (mean - target.score as f64).abs() / target.score as f64;
    assert!(
        rel < 0.02,
        "mean early score {mean} vs full {}",
        target.score
    );
}

#[test]
fn descriptor_search_equals_search_over_precomputed_words() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let dim = 16;
    let centroids: Vec<f32> = (0..K * dim).map(|_| rng.random::<f32>()).collect();
    let q = ExactQuantizer::new(&centroids, dim);
    let (map, _) = random_map(30, 9);
    let desc = ndarray::Array2::from_shape_fn((150, dim), |_| rng.random::<f32>());
    let mut words = vec![0u32; 150];
    q.quantize(desc.view(), &mut words);
    for rule in [
        ("none", None),
        ("peak-mean", Some(0.05)),
        ("stable-peak", Some(10.0)),
    ] {
        let o = opts(rule.0, rule.1, 11);
        let a = search(&q, None, &map, desc.view(), &o);
        let b = search_words(&map, KnownFeatures::words(&words), &o);
        assert_eq!(a.candidates, b.candidates, "{rule:?}");
        assert_eq!(a.stop, b.stop, "{rule:?}");
    }
}

#[test]
fn passed_deadline_and_empty_query_are_defined() {
    let (map, lists) = random_map(10, 10);
    let o = SearchOptions {
        deadline: Some(Instant::now()),
        ..opts("none", None, 1)
    };
    let got = search_words(&map, KnownFeatures::words(&lists[0]), &o);
    assert_eq!(got.stop.kind, StopKind::Deadline);
    assert_eq!(got.features_used, 0);
    assert!(got.candidates.is_empty());

    let got = search_words(
        &map,
        KnownFeatures::words(&[]),
        &opts("peak-mean", Some(0.1), 1),
    );
    assert_eq!(got.stop.kind, StopKind::Exhausted);
    assert_eq!(got.features_total, 0);
    assert_eq!(got.fraction_used(), 1.0);
    assert!(got.candidates.is_empty());
}

#[test]
fn min_features_delays_the_rule() {
    let (map, lists) = random_map(20, 12);
    let query = &lists[3];
    let eager = search_words(
        &map,
        KnownFeatures::words(query),
        &opts("stable-peak", Some(0.0), 1),
    );
    assert_eq!(eager.features_used, 1);
    let o = SearchOptions {
        min_features: 15,
        ..opts("stable-peak", Some(0.0), 1)
    };
    assert_eq!(
        search_words(&map, KnownFeatures::words(query), &o).features_used,
        15
    );
}

/// A traced search: the same answer as untraced, a bounded race whose last
/// point is the stop, and each rule's statistic passing its threshold only
/// there.
#[test]
fn traces_record_the_race_without_changing_it() {
    let (map, lists) = random_map(80, 5);
    let query: Vec<u32> = lists[7]
        .iter()
        .chain(&lists[9])
        .copied()
        .cycle()
        .take(900)
        .collect();
    let tiles: Vec<&[u32]> = query.chunks(300).collect();
    let mut stopped_early = 0;
    for (rule, p) in [
        ("peak-mean", Some(3.0)),
        ("relative", Some(1.5)),
        ("stable-peak", Some(60.0)),
        ("hoeffding", Some(0.1)),
        ("fixed", Some(0.4)),
        ("none", None),
    ] {
        let o = opts(rule, p, 11);
        let run = |traced: bool| {
            let mut s = Search::new(&map, &o);
            if traced {
                s = s.trace(1, 64);
            }
            for (k, words) in tiles.iter().enumerate() {
                let quantize = |indices: &[u32], out: &mut [u32], signed: &mut [u64]| {
                    for (o, &i) in out.iter_mut().zip(indices) {
                        *o = words[i as usize];
                    }
                    signed.fill(0);
                };
                let share = (k + 1) as f64 / tiles.len() as f64;
                let step = TileStep {
                    share,
                    last: k + 1 == tiles.len(),
                    coarse: false,
                };
                if s.feed_tile(words.len(), step, quantize, None) {
                    break;
                }
            }
            s.finish()
        };
        let (plain, traced) = (run(false), run(true));
        assert!(plain.trace.is_none());
        assert_eq!(plain.stop, traced.stop, "{rule}");
        assert_eq!(plain.candidates, traced.candidates, "{rule}");
        let t = traced.trace.unwrap();
        assert!(t.points.len() <= 65, "{rule}: {}", t.points.len());
        let last = t.points.last().unwrap();
        assert_eq!(last.features as usize, traced.stop.at_feature, "{rule}");
        assert_eq!(t.batch_ends, vec![300u32, 600, 900][..t.batch_ends.len()]);
        for w in t.points.windows(2) {
            assert!(w[0].features < w[1].features);
            assert!(
                w[0].leader_votes <= w[1].leader_votes,
                "{rule}: votes only grow"
            );
        }
        if rule == "none" {
            assert_eq!(traced.stop.kind, StopKind::Exhausted);
            assert!(t.points.iter().all(|p| p.statistic.is_none()));
            continue;
        }
        // rules 1 and 2 stop above their threshold, the others at it
        let passed = |(s, threshold): (f64, f64)| match rule {
            "peak-mean" | "relative" => s > threshold,
            _ => s >= threshold,
        };
        for p in &t.points[..t.points.len() - 1] {
            assert!(
                !p.statistic.is_some_and(passed),
                "{rule}: passed before the stop"
            );
        }
        let stopped = traced.stop.kind == StopKind::Rule;
        assert_eq!(
            last.statistic.is_some_and(passed),
            stopped,
            "{rule}: {last:?}"
        );
        stopped_early += usize::from(stopped);
    }
    assert!(
        stopped_early >= 3,
        "only {stopped_early} rules stopped early"
    );
}

#[test]
fn the_frame_posterior_is_the_posterior_under_a_uniform_prior() {
    let (map, lists) = random_map(40, 11);
    let query = &lists[5];
    let with = |prior: Prior| {
        search_words(
            &map,
            KnownFeatures::words(query),
            &SearchOptions {
                prior: Some(Arc::new(prior)),
                ..opts("none", None, 3)
            },
        )
    };
    let model = crate::sequence::SequenceModel::default();
    let uniform = with(model.uniform_prior(40));
    let posterior = uniform.posterior.expect("a posterior");
    assert!(posterior.top.len() > 1 && posterior.leader().unwrap().0 == 5);
    assert_eq!(uniform.frame_posterior, Some(posterior.clone()));
    // a prior of its own: the frame's posterior is still the uniform one
    let skewed = with(Prior::new(40, vec![(7, 50.0)], 1.0, model.kappa).keeping(model.track));
    assert_ne!(skewed.posterior, Some(posterior.clone()));
    assert_eq!(skewed.frame_posterior, Some(posterior));
}

/// With `finish_tile`, a rule that fires inside a tile of a streamed query
/// stops at the tile's end, having voted the tile's other features; on a
/// query extracted whole, or without it, the search stops where it fires.
#[test]
fn a_stop_inside_a_tile_votes_the_rest_of_the_tile() {
    let (map, lists) = random_map(80, 5);
    let query: Vec<u32> = lists[7].iter().copied().cycle().take(900).collect();
    let o = SearchOptions {
        finish_tile: true,
        ..opts("stable-peak", Some(30.0), 11)
    };
    let quantize_from = |words: &[u32]| {
        let words = words.to_vec();
        move |indices: &[u32], out: &mut [u32], signed: &mut [u64]| {
            for (o, &i) in out.iter_mut().zip(indices) {
                *o = words[i as usize];
            }
            signed.fill(0);
        }
    };
    // whole: one batch, it stops where the rule fires
    let mut whole = Search::new(&map, &o);
    let step = |share: f64, last: bool| TileStep {
        share,
        last,
        coarse: false,
    };
    assert!(whole.feed_tile(900, step(1.0, true), quantize_from(&query), None));
    let whole = whole.finish();
    assert_eq!(whole.stop.kind, StopKind::Rule);
    assert!(whole.stop.at_feature < 100, "{:?}", whole.stop);
    // three tiles: it fires inside the first and the first's 300 are voted
    let mut streamed = Search::new(&map, &o);
    let tiles: Vec<&[u32]> = query.chunks(300).collect();
    assert!(streamed.feed_tile(300, step(1.0 / 3.0, false), quantize_from(tiles[0]), None));
    let streamed = streamed.finish();
    assert_eq!(streamed.stop.kind, StopKind::Rule);
    assert_eq!(streamed.stop.at_feature, 300);
    assert!(
        streamed.stop.detail.contains("the rest of the tile"),
        "{}",
        streamed.stop.detail
    );
    // without finish_tile it stops where the rule fires, as on the whole
    let plain = SearchOptions {
        finish_tile: false,
        ..o.clone()
    };
    let mut unfinished = Search::new(&map, &plain);
    assert!(unfinished.feed_tile(300, step(1.0 / 3.0, false), quantize_from(tiles[0]), None));
    let unfinished = unfinished.finish();
    assert_eq!(unfinished.stop.kind, StopKind::Rule);
    assert!(unfinished.stop.at_feature < 100, "{:?}", unfinished.stop);
    // the same first tile as a coarse pass: the vote rule does not stop
    // there; the next tile starts the search over, and the rule fires in
    // it as in a first tile, which is then voted to its end
    let mut coarse = Search::new(&map, &o);
    let first = TileStep {
        coarse: true,
        ..step(1.0 / 3.0, false)
    };
    assert!(!coarse.feed_tile(300, first, quantize_from(tiles[0]), None));
    assert!(coarse.feed_tile(300, step(1.0 / 3.0, false), quantize_from(tiles[1]), None));
    let coarse = coarse.finish();
    assert_eq!(coarse.stop.kind, StopKind::Rule);
    assert_eq!(coarse.stop.at_feature, 300);
    assert_eq!((coarse.features_used, coarse.features_total), (300, 300));
    // ended after the pass (a time budget), the answer is the pass's
    let mut probe = Search::new(&map, &o);
    assert!(!probe.feed_tile(300, first, quantize_from(tiles[0]), None));
    probe.end(StopKind::Budget, "budget".into());
    let probe = probe.finish();
    assert_eq!(
        (probe.stop.kind, probe.features_used),
        (StopKind::Budget, 300)
    );
    assert!(!probe.candidates.is_empty());
}

/// A coarse pass that does not end the search is left behind: the search
/// starts over on the tiles and answers exactly as it would on them alone,
/// its feature numbers going on after the pass's.
#[test]
fn a_coarse_pass_that_does_not_stop_is_left_behind() {
    let (map, lists) = random_map(40, 11);
    let probe: Vec<u32> = (0..60).map(|i| (i * 7 % K) as u32).collect();
    let tiles: Vec<Vec<u32>> = (0..4).map(|t| lists[3 + t].clone()).collect();
    let o = opts("none", None, 5);
    let alone: Vec<(KnownFeatures<'_>, f64)> = tiles
        .iter()
        .map(|w| (KnownFeatures::words(w), 0.25))
        .collect();
    let (plain, plain_voted, plain_used) = search_tiles(&map, &alone, &o, false, None);
    let mut units = vec![(KnownFeatures::words(&probe), 0.3)];
    units.extend(alone.iter().cloned());
    let (probed, probed_voted, probed_used) = search_tiles(&map, &units, &o, true, None);
    assert_eq!(probed_used, plain_used + 1);
    assert_eq!(probed.features_used, plain.features_used);
    assert_eq!(probed.features_total, plain.features_total);
    let ids = |o: &SearchOutcome| {
        o.candidates
            .iter()
            .map(|r| (r.id, r.score))
            .collect::<Vec<_>>()
    };
    assert_eq!(ids(&probed), ids(&plain));
    // the same words voted, numbered after the probe's 60 features
    assert_eq!(probed_voted.len(), plain_voted.len());
    for (p, q) in probed_voted.iter().zip(&plain_voted) {
        assert_eq!((p.feature, p.word), (q.feature + 60, q.word));
    }
}

//! The guaranteed rules on real images. On every query of both shared
//! datasets and several permutation seeds:
//! - `lossless` returns exactly the top-n of full bag-of-words;
//! - `confident` agrees with full bag-of-words' top-1 on at least 1 − δ of
//!   the (query, seed) pairs.
//!
//! Each query is quantized once and voted many times (`search_words`).

mod common;

use bowloc::pipeline::words_per_image;
use bowloc::search::{RuleSpec, SearchOptions, search_words};

struct Prepared {
    name: String,
    map: bowloc::index::MapIndex,
    queries: Vec<bowloc::search::CodedFeatures>,
}

fn prepare(dataset: &str, words: usize) -> Prepared {
    let common::RealMap {
        vocab,
        map,
        queries: query_desc,
        ..
    } = common::real_map(dataset, words);
    let queries = words_per_image(&vocab, &query_desc);
    Prepared {
        name: dataset.to_owned(),
        map,
        queries,
    }
}

fn options(rule: &str, parameter: Option<f64>, seed: u64, top_n: usize) -> SearchOptions {
    SearchOptions {
        rule: RuleSpec::new(rule, parameter).unwrap(),
        top_n,
        seed,
        ..Default::default()
    }
}

const SEEDS: u64 = 3;
const DELTA: f64 = 0.05;

fn check(p: &Prepared) {
    let (mut used, mut total) = (0usize, 0usize);
    let (mut used1, mut total1) = (0usize, 0usize);
    let (mut agree, mut pairs) = (0usize, 0usize);
    let (mut conf_used, mut conf_total) = (0usize, 0usize);
    for seed in 0..SEEDS {
        for (q, words) in p.queries.iter().enumerate() {
            let full = search_words(&p.map, words.known(), &options("none", None, seed, 5));
            let lossless = search_words(&p.map, words.known(), &options("lossless", None, seed, 5));
            let ids = |o: &bowloc::search::SearchOutcome| {
                o.candidates.iter().map(|c| c.id).collect::<Vec<_>>()
            };
            assert_eq!(
                ids(&lossless),
                ids(&full),
                "{} query {q} seed {seed}",
                p.name
            );
            used += lossless.features_used;
            total += lossless.features_total;
            let full1 = search_words(&p.map, words.known(), &options("none", None, seed, 1));
            let lossless1 =
                search_words(&p.map, words.known(), &options("lossless", None, seed, 1));
            assert_eq!(
                ids(&lossless1),
                ids(&full1),
                "{} query {q} seed {seed} top-1",
                p.name
            );
            used1 += lossless1.features_used;
            total1 += lossless1.features_total;

            let conf = search_words(
                &p.map,
                words.known(),
                &options("confident", Some(DELTA), seed, 1),
            );
            if full.candidates.is_empty() {
                continue;
            }
            pairs += 1;
            if conf.candidates.first().map(|c| c.id) == Some(full.candidates[0].id) {
                agree += 1;
            }
            conf_used += conf.features_used;
            conf_total += conf.features_total;
        }
    }
    let agreement = agree as f64 / pairs as f64;
    println!(
        "{}: lossless identical on {} (query, seed) pairs, using {:.1}% of features for top-5 \
         and {:.1}% for top-1; confident δ={DELTA}: top-1 agrees on {agree}/{pairs} = {agreement:.3} \
         using {:.1}% of features",
        p.name,
        p.queries.len() as u64 * SEEDS,
        100.0 * used as f64 / total as f64,
        100.0 * used1 as f64 / total1 as f64,
        100.0 * conf_used as f64 / conf_total as f64,
    );
    assert!(
        agreement >= 1.0 - DELTA,
        "{}: agreement {agreement}",
        p.name
    );
}

#[test]
fn guaranteed_rules_on_rtabmap_loop() {
    check(&prepare("rtabmap-loop", 1000));
}

#[test]
fn guaranteed_rules_on_gardens_point() {
    check(&prepare("gardens-point", 1000));
}

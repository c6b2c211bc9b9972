//! Voting plus stop check per feature on synthetic Zipf maps of 1 000,
//! 100 000 and 1 000 000 images (K = 5 000 words, 200 features per image).
//! Throughput is set in posting entries visited, so "elem/s" shows whether a
//! vote's cost follows its posting list (constant elem/s across map sizes) or
//! the map size. `BOWLOC_BENCH_IMAGES=1000,100000` limits the sizes.

use bowloc::index::MapIndex;
use bowloc::index::synthetic::{zipf_map, zipf_query};
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;

const WORDS: usize = 5_000;
const FEATURES: usize = 200;
const QUERY_FEATURES: usize = 1_000;

/// Postings visited by a full vote of `query` (words of idf 0 cast no vote).
fn postings_visited(map: &MapIndex, query: &[u32]) -> u64 {
    let v = map.view();
    query
        .iter()
        .filter(|&&w| v.idf[w as usize] > 0.0)
        .map(|&w| v.postings.list(w).0.len() as u64)
        .sum()
}

fn vote(c: &mut Criterion) {
    let sizes: Vec<usize> = std::env::var("BOWLOC_BENCH_IMAGES")
        .map(|v| v.split(',').filter_map(|k| k.parse().ok()).collect())
        .unwrap_or_else(|_| vec![1_000, 100_000, 1_000_000]);
    let query = zipf_query(WORDS, QUERY_FEATURES, 7);
    let mut group = c.benchmark_group("vote");
    group.sample_size(10);
    for images in sizes {
        let map = zipf_map(images, WORDS, FEATURES, 1);
        let visited = postings_visited(&map, &query);
        eprintln!(
            "map of {images} images: {} postings; a {QUERY_FEATURES}-feature query visits {visited} ({:.0} per feature)",
            map.meta().postings,
            visited as f64 / QUERY_FEATURES as f64
        );
        group.throughput(Throughput::Elements(visited));
        for (rule, p) in [
            ("none", None),
            ("peak-mean", Some(f64::MAX)),
            ("confident", Some(0.05)),
        ] {
            // thresholds that never fire: every feature votes and is checked
            let options = SearchOptions {
                rule: RuleSpec::new(rule, p).unwrap(),
                top_n: 5,
                ..Default::default()
            };
            group.bench_with_input(BenchmarkId::new(rule, images), &images, |b, _| {
                b.iter(|| search_words(black_box(&map), KnownFeatures::words(&query), &options))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, vote);
criterion_main!(benches);

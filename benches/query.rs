//! A query end to end on real images from `../shared/datasets/gardens-point`
//! (K = 5 000): decode, extract, and the whole localization with full
//! bag-of-words and with the service's default rule (read from
//! `config/default.toml`). Before the criterion runs it prints the median
//! time of every stage over the query set, the share of a request that is not
//! SIFT extraction, and search time against the fraction of features used
//! (fixed fractions from 0.1 to 1), whose ratio to the full search shows
//! whether time saved follows features skipped. The vocabulary and map are
//! built once into `data/gardens-5000/` (shared with `scripts/latency.sh`) and
//! reused.

use bowloc::dataset::Dataset;
use bowloc::eval::timing::median;
use bowloc::features::{self, DecodeLimits};
use bowloc::pipeline::{Localizer, build_map, build_vocabulary};
use bowloc::search::{RuleSpec, SearchOptions};
use bowloc::server::config::Config;
use bowloc::vocabulary::kmeans::KmeansConfig;
use criterion::{Criterion, criterion_group, criterion_main};
use std::path::PathBuf;

fn localizer() -> (Localizer, Vec<Vec<u8>>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let data = Dataset::open(&root.join("../shared/datasets/gardens-point")).unwrap();
    let dir = root.join("data/gardens-5000");
    std::fs::create_dir_all(&dir).unwrap();
    let (vpath, mpath) = (dir.join("vocab.bowvoc"), dir.join("map.bowmap"));
    if Localizer::open(&vpath, &mpath, true).is_err() {
        eprintln!("building the gardens-point vocabulary (K = 5000) and map");
        let config = KmeansConfig {
            k: 5000,
            seed: 1,
            ..Default::default()
        };
        let vocab = build_vocabulary(&data.map, &Default::default(), &config, false).unwrap();
        vocab.save(&vpath).unwrap();
        build_map(&vocab, &data.map, None, "gardens-point", false)
            .unwrap()
            .save(&mpath)
            .unwrap();
    }
    let queries = data
        .queries
        .iter()
        .step_by(10)
        .map(|q| std::fs::read(&q.path).unwrap())
        .collect();
    features::set_opencv_threads(1);
    (Localizer::open(&vpath, &mpath, true).unwrap(), queries)
}

/// Median per stage over the query set, printed for docs/performance.md.
/// Returns the median search time (quantize + vote, per query) and the median
/// fraction of features used.
fn stage_summary(
    loc: &Localizer,
    queries: &[Vec<u8>],
    options: &SearchOptions,
    label: &str,
) -> (f64, f64) {
    let mut stages: [Vec<f64>; 7] = Default::default();
    for _ in 0..3 {
        for q in queries {
            let r = loc.localize(q, options).unwrap();
            let t = r.timings_ms;
            for (s, v) in stages.iter_mut().zip([
                t.decode,
                t.extract,
                t.quantize,
                t.vote,
                t.total,
                r.features.fraction,
                t.quantize + t.vote,
            ]) {
                s.push(v);
            }
        }
    }
    let [decode, extract, quantize, vote, total, fraction, search] = stages.map(|s| median(&s));
    eprintln!(
        "{label}: median ms decode {decode:.2}, extract {extract:.2}, quantize {quantize:.2}, vote {vote:.3}, \
         search (quantize + vote) {search:.2}, total {total:.2}; \
         non-extraction share {:.1}%; median fraction of features {fraction:.2}",
        100.0 * (total - extract) / total
    );
    (search, fraction)
}

/// The search options `bowloc serve` uses when a request names no rule.
fn service_defaults() -> SearchOptions {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/default.toml");
    let config = Config::load(&path).unwrap();
    SearchOptions {
        rule: config.default_rule().unwrap(),
        min_features: config.search.min_features,
        block: config.search.block,
        ..Default::default()
    }
}

/// Search time (quantize + vote) against the fraction of features used, with
/// the naive fixed-fraction rule so the fraction is the same for every query.
fn time_versus_fraction(loc: &Localizer, queries: &[Vec<u8>], full_search_ms: f64) {
    for f in [0.1, 0.25, 0.5, 0.75, 1.0] {
        let options = SearchOptions {
            rule: RuleSpec::new("fixed", Some(f)).unwrap(),
            ..Default::default()
        };
        let (search, fraction) = stage_summary(loc, queries, &options, &format!("rule fixed {f}"));
        eprintln!(
            "time versus fraction: fraction {fraction:.2}, search {search:.2} ms, \
             {:.2} of the full search's time",
            search / full_search_ms
        );
    }
}

fn query(c: &mut Criterion) {
    let (loc, queries) = localizer();
    let full = SearchOptions {
        rule: RuleSpec::new("none", None).unwrap(),
        ..Default::default()
    };
    let early = service_defaults();
    let (full_search_ms, _) = stage_summary(&loc, &queries, &full, "rule none");
    let label = format!(
        "default rule {} {} after {} features",
        early.rule.name, early.rule.parameter, early.min_features
    );
    stage_summary(&loc, &queries, &early, &label);
    time_versus_fraction(&loc, &queries, full_search_ms);
    let config = &loc.vocab.meta().extract;
    let mut group = c.benchmark_group("query/gardens-point");
    group.sample_size(10);
    let q = &queries[0];
    group.bench_function("decode", |b| {
        b.iter(|| features::decode(q, DecodeLimits::default(), config.max_side).unwrap())
    });
    let image = features::decode(q, DecodeLimits::default(), config.max_side).unwrap();
    group.bench_function("extract", |b| {
        b.iter(|| features::extract(&image, config).unwrap())
    });
    group.bench_function("localize/none", |b| {
        b.iter(|| loc.localize(q, &full).unwrap())
    });
    group.bench_function("localize/default-rule", |b| {
        b.iter(|| loc.localize(q, &early).unwrap())
    });
    group.finish();
}

criterion_group!(benches, query);
criterion_main!(benches);

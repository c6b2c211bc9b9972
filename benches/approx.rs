//! Approximate (tree) versus exact quantization on real descriptors: a
//! K = 50 000 vocabulary trained on gardens-point's map images, queried with
//! descriptors of its query images. Prints, for several numbers of probes,
//! the share of descriptors given the same word as exact search and the
//! speed-up per descriptor (blocks of 32), then benchmarks both.

use bowloc::dataset::Dataset;
use bowloc::features::{DecodeLimits, ExtractConfig};
use bowloc::pipeline::{extract_all, stack, train_vocabulary};
use bowloc::quantize::Quantizer;
use bowloc::vocabulary::Vocabulary;
use bowloc::vocabulary::kmeans::KmeansConfig;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use ndarray::{Array2, Axis};
use std::path::PathBuf;
use std::time::Instant;

const K: usize = 50_000;
const BLOCK: usize = 32;

fn setup() -> (Vocabulary, Array2<f32>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let data = Dataset::open(&root.join("../shared/datasets/gardens-point")).unwrap();
    let path = root.join(format!("target/bench-data/gardens-{K}.bowvoc"));
    let extract = ExtractConfig::default();
    let limits = DecodeLimits::default();
    let vocab = Vocabulary::open(&path, true).unwrap_or_else(|_| {
        eprintln!("training a {K}-word vocabulary (3 Lloyd iterations)");
        let map = extract_all(&data.map, &extract, limits, false, "map").unwrap();
        let parts: Vec<_> = map.iter().flatten().collect();
        let config = KmeansConfig {
            k: K,
            seed: 1,
            max_iter: 3,
            ..Default::default()
        };
        let v = train_vocabulary(stack(&parts).view(), &extract, &config).unwrap();
        v.save(&path).unwrap();
        v
    });
    let some: Vec<_> = data.queries.iter().step_by(20).cloned().collect();
    let q = extract_all(&some, &extract, limits, false, "queries").unwrap();
    let parts: Vec<_> = q.iter().flatten().collect();
    (vocab, stack(&parts))
}

fn words_and_time(q: &dyn Quantizer, x: &Array2<f32>) -> (Vec<u32>, f64) {
    let mut out = vec![0u32; x.nrows()];
    let start = Instant::now();
    for (block, o) in x
        .axis_chunks_iter(Axis(0), BLOCK)
        .zip(out.chunks_mut(BLOCK))
    {
        q.quantize(block, o);
    }
    (out, start.elapsed().as_secs_f64() / x.nrows() as f64)
}

fn approx(c: &mut Criterion) {
    bowloc::features::set_opencv_threads(1);
    let (vocab, x) = setup();
    let built = Instant::now();
    let groups = vocab.tree_quantizer().groups();
    eprintln!(
        "tree of {groups} groups over {K} words built in {:.1} s",
        built.elapsed().as_secs_f64()
    );
    let (exact, t_exact) = words_and_time(vocab.exact_quantizer(), &x);
    eprintln!(
        "exact: {:.1} µs per descriptor over {} descriptors",
        t_exact * 1e6,
        x.nrows()
    );
    let probe_counts = [4usize, 8, 16, 32];
    for probes in probe_counts {
        let tree = vocab.tree_quantizer().with_probes(probes);
        let (words, t) = words_and_time(&tree, &x);
        let same = words.iter().zip(&exact).filter(|(a, b)| a == b).count();
        eprintln!(
            "tree, {probes} probes: {:.2}% same word as exact, {:.1} µs per descriptor, {:.1}× faster",
            100.0 * same as f64 / exact.len() as f64,
            t * 1e6,
            t_exact / t
        );
    }
    let block = x.slice(ndarray::s![..BLOCK, ..]).to_owned();
    let mut out = vec![0u32; BLOCK];
    let mut group = c.benchmark_group(format!("approx/K={K}/block={BLOCK}"));
    group.sample_size(10);
    group.bench_function("exact", |b| {
        b.iter(|| vocab.exact_quantizer().quantize(block.view(), &mut out))
    });
    for probes in probe_counts {
        let tree = vocab.tree_quantizer().with_probes(probes);
        group.bench_with_input(BenchmarkId::new("tree", probes), &probes, |b, _| {
            b.iter(|| tree.quantize(block.view(), &mut out))
        });
    }
    group.finish();
}

criterion_group!(benches, approx);
criterion_main!(benches);

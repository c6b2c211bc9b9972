//! SIFT extraction cost against its knobs on gardens-point query images
//! (960×540): the maximum image side, and OpenCV's own threads (one request
//! on two threads) versus request-level parallelism (two requests at once on
//! one thread each). Prints medians and feature counts, then benchmarks.

use bowloc::dataset::Dataset;
use bowloc::features::{self, DecodeLimits, ExtractConfig};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::path::PathBuf;
use std::time::Instant;

fn images() -> Vec<Vec<u8>> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/gardens-point");
    let data = Dataset::open(&root).unwrap();
    data.queries
        .iter()
        .step_by(20)
        .map(|q| std::fs::read(&q.path).unwrap())
        .collect()
}

fn config(max_side: u32) -> ExtractConfig {
    ExtractConfig {
        max_side,
        ..Default::default()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn extract_ms(image: &[u8], c: &ExtractConfig) -> (f64, usize) {
    let start = Instant::now();
    let d = features::extract(
        &features::decode(image, DecodeLimits::default()).unwrap(),
        c,
    )
    .unwrap();
    (start.elapsed().as_secs_f64() * 1e3, d.nrows())
}

fn summary(images: &[Vec<u8>]) {
    features::set_opencv_threads(1);
    for side in [0u32, 800, 640, 480, 320] {
        let c = config(side);
        let runs: Vec<(f64, usize)> = images.iter().map(|i| extract_ms(i, &c)).collect();
        eprintln!(
            "max_side {side:>4}: median {:.1} ms per image, median {} features",
            median(runs.iter().map(|r| r.0).collect()),
            median(runs.iter().map(|r| r.1 as f64).collect())
        );
    }
    let c = config(640);
    let n = images.len() as f64;
    features::set_opencv_threads(2);
    let start = Instant::now();
    for i in images {
        extract_ms(i, &c);
    }
    let opencv2 = n / start.elapsed().as_secs_f64();
    features::set_opencv_threads(1);
    let start = Instant::now();
    let c = &c;
    std::thread::scope(|s| {
        for half in images.chunks(images.len().div_ceil(2)) {
            s.spawn(move || {
                half.iter().for_each(|i| {
                    extract_ms(i, c);
                })
            });
        }
    });
    let requests2 = n / start.elapsed().as_secs_f64();
    let start = Instant::now();
    for i in images {
        extract_ms(i, c);
    }
    let single = n / start.elapsed().as_secs_f64();
    eprintln!(
        "max_side 640 throughput: 1 request × 1 OpenCV thread {single:.1} images/s; \
         1 request × 2 OpenCV threads {opencv2:.1} images/s ({:.2}×); \
         2 requests × 1 thread {requests2:.1} images/s ({:.2}×)",
        opencv2 / single,
        requests2 / single
    );
}

fn extract(c: &mut Criterion) {
    let images = images();
    summary(&images);
    features::set_opencv_threads(1);
    let mut group = c.benchmark_group("extract/gardens-point");
    group.sample_size(10);
    for side in [0u32, 640, 480] {
        let cfg = config(side);
        group.bench_with_input(BenchmarkId::new("max_side", side), &side, |b, _| {
            b.iter(|| extract_ms(&images[0], &cfg))
        });
    }
    group.finish();
}

criterion_group!(benches, extract);
criterion_main!(benches);

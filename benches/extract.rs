//! SIFT extraction cost against its knobs on gardens-point query images
//! (960×540): the maximum image side, and OpenCV's own threads (one request
//! on two threads) versus request-level parallelism (two requests at once on
//! one thread each). Prints medians and feature counts, then benchmarks.
//!
//! Then the streaming extraction plans ([`TileGrid`]) against the whole
//! image: each image goes through every plan in turn (three rounds, the
//! cheapest kept), so the ratios compare plans under the same load; costs are
//! the extracting thread's CPU time. For each plan: the full extraction's
//! cost and keypoints against the whole image's, and what the first unit
//! (the coarse pass, or one tile) costs and finds.
//!
//! Last, what ordering the tiles costs: preparing a `2x2+24` image for
//! streaming (downscaling) in the random tile order, and in the richest-first
//! order, which also counts FAST corners per tile.

use bowloc::dataset::Dataset;
use bowloc::eval::timing::median;
use bowloc::features::{self, DecodeLimits, ExtractConfig, TileGrid, Tiles};
use bowloc::pipeline::extract_interleaved;
use bowloc::search::TileOrder;
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

fn extract_ms(image: &[u8], c: &ExtractConfig) -> (f64, usize) {
    let start = Instant::now();
    let d = features::extract(
        &features::decode(image, DecodeLimits::default(), c.max_side).unwrap(),
        c,
    )
    .unwrap();
    (start.elapsed().as_secs_f64() * 1e3, d.len())
}

fn summary(images: &[Vec<u8>]) {
    features::set_opencv_threads(1);
    for side in [0u32, 800, 640, 480, 320] {
        let c = config(side);
        let runs: Vec<(f64, usize)> = images.iter().map(|i| extract_ms(i, &c)).collect();
        eprintln!(
            "max_side {side:>4}: median {:.1} ms per image, median {} features",
            median(&runs.iter().map(|r| r.0).collect::<Vec<_>>()),
            median(&runs.iter().map(|r| r.1 as f64).collect::<Vec<_>>())
        );
    }
    contrast_thresholds(images);
    thread_layouts(images, &config(640));
    tile_plans(images, &config(640));
}

/// SIFT's contrast threshold at max side 640: a lower one keeps weaker
/// keypoints, more features for verification to match, at a cost. Each image
/// goes through every threshold in turn, so the ratios compare them under the
/// same load.
fn contrast_thresholds(images: &[Vec<u8>]) {
    let default = config(640).sift.contrast_threshold;
    let thresholds = [default, 0.03, 0.02, 0.01];
    let configs: Vec<ExtractConfig> = thresholds
        .iter()
        .map(|&t| {
            let mut c = config(640);
            c.sift.contrast_threshold = t;
            c
        })
        .collect();
    // per threshold, per image: (ms, features)
    let mut runs = vec![Vec::new(); configs.len()];
    for image in images {
        for (c, r) in configs.iter().zip(&mut runs) {
            r.push(extract_ms(image, c));
        }
    }
    let base = &runs[0];
    for (t, r) in thresholds.iter().zip(&runs) {
        eprintln!(
            "contrast_threshold {t:.2} (max_side 640): median {:.1} ms per image ({:.2}× {default}'s), \
             median {} features ({:.2}×)",
            median(&r.iter().map(|x| x.0).collect::<Vec<_>>()),
            median_ratio(r.len(), |i| r[i].0 / base[i].0),
            median(&r.iter().map(|x| x.1 as f64).collect::<Vec<_>>()),
            median_ratio(r.len(), |i| r[i].1 as f64 / base[i].1.max(1) as f64),
        );
    }
}

/// The median over images `0..n` of a per-image ratio.
fn median_ratio(n: usize, ratio: impl Fn(usize) -> f64) -> f64 {
    median(&(0..n).map(ratio).collect::<Vec<_>>())
}

/// Streaming extraction plans against the whole image, image by image.
fn tile_plans(images: &[Vec<u8>], c: &ExtractConfig) {
    features::set_opencv_threads(1);
    let plans: Vec<TileGrid> = [
        "1x1+0",
        "2x2+24",
        "1x1+0,coarse",
        "2x2+24,coarse",
        "3x3+16,coarse",
        "4x4+16,coarse",
    ]
    .iter()
    .map(|p| p.parse().unwrap())
    .collect();
    // per plan, per image: (full cost, keypoints, first unit's cost, its keypoints), in ms
    let mut measured = vec![Vec::new(); plans.len()];
    for image in images {
        let decoded = features::decode(image, DecodeLimits::default(), c.max_side).unwrap();
        let each = extract_interleaved(&decoded, c, &plans, 3).unwrap();
        for (p, e) in each.iter().enumerate() {
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            let total: f64 = e.tiles.iter().map(|t| ms(t.extract)).sum();
            measured[p].push((
                total,
                e.features.len(),
                ms(e.tiles[0].extract),
                e.tiles[0].features,
            ));
        }
    }
    let whole = &measured[0];
    for (plan, m) in plans.iter().zip(&measured) {
        let ratio = |f: &dyn Fn(usize) -> f64| median_ratio(m.len(), f);
        eprintln!(
            "plan {plan:<14}: full extraction {:.2}× the whole image's CPU time ({:.1} ms), \
             keypoints {:.3}×; first unit {:.2}× of the whole image's time for {:.2} of the plan's keypoints \
             (medians over {} images)",
            ratio(&|i| m[i].0 / whole[i].0),
            median(&m.iter().map(|x| x.0).collect::<Vec<_>>()),
            ratio(&|i| m[i].1 as f64 / whole[i].1.max(1) as f64),
            ratio(&|i| m[i].2 / whole[i].0),
            ratio(&|i| m[i].3 as f64 / m[i].1.max(1) as f64),
            m.len()
        );
    }
}

/// Extraction of `images` by `requests` concurrent callers, each over every
/// image, with `threads` OpenCV threads: (median latency in ms, images/s).
fn layout(images: &[Vec<u8>], c: &ExtractConfig, requests: usize, threads: usize) -> (f64, f64) {
    features::set_opencv_threads(threads);
    let start = Instant::now();
    let latencies: Vec<f64> = std::thread::scope(|s| {
        let callers: Vec<_> = (0..requests)
            .map(|_| {
                s.spawn(move || {
                    images
                        .iter()
                        .map(|i| extract_ms(i, c).0)
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        callers
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let throughput = latencies.len() as f64 / start.elapsed().as_secs_f64();
    (median(&latencies), throughput)
}

/// OpenCV's own threads versus request-level parallelism on two cores: the
/// service's choice between one request on two threads and two requests on
/// one thread each (or both).
fn thread_layouts(images: &[Vec<u8>], c: &ExtractConfig) {
    layout(images, c, 1, 1); // warm-up: OpenCV's first calls allocate
    let layouts = [(1, 1), (1, 2), (2, 1), (2, 2)];
    let measured: Vec<(f64, f64)> = layouts
        .iter()
        .map(|&(requests, threads)| layout(images, c, requests, threads))
        .collect();
    let (base_latency, base_throughput) = measured[0];
    for ((requests, threads), (latency, throughput)) in layouts.into_iter().zip(measured) {
        eprintln!(
            "max_side 640: {requests} request(s) at once × {threads} OpenCV thread(s): \
             median latency {latency:.1} ms ({:.2}× of 1×1), throughput {throughput:.2} images/s ({:.2}× of 1×1)",
            latency / base_latency,
            throughput / base_throughput
        );
    }
    features::set_opencv_threads(1);
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
    let cfg = config(640);
    let decoded = features::decode(&images[0], DecodeLimits::default(), cfg.max_side).unwrap();
    let mut group = c.benchmark_group("tile-order/gardens-point");
    group.sample_size(20);
    for order in [TileOrder::Random, TileOrder::Richest] {
        group.bench_with_input(BenchmarkId::new("prepare", order), &order, |b, &order| {
            b.iter(|| Tiles::new(&decoded, &cfg, TileGrid::DEFAULT, Some((order, 1))).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, extract);
criterion_main!(benches);

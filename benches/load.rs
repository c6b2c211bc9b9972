//! Loading a 1 000 000-image map file (synthetic Zipf map, K = 5 000, 200
//! features per image), with and without recomputing the checksums. The file
//! is built once into `target/bench-data/` and reused.

use bowloc::index::MapIndex;
use bowloc::index::synthetic::zipf_map;
use criterion::{Criterion, criterion_group, criterion_main};
use std::path::PathBuf;

fn map_file(images: usize) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/bench-data");
    let path = dir.join(format!("zipf-{images}.bowmap"));
    if MapIndex::open(&path, true).is_err() {
        eprintln!("building {}", path.display());
        zipf_map(images, 5_000, 200, 1).save(&path).unwrap();
    }
    let bytes = std::fs::metadata(&path).unwrap().len();
    eprintln!(
        "{}: {:.1} MiB",
        path.display(),
        bytes as f64 / (1 << 20) as f64
    );
    path
}

fn load(c: &mut Criterion) {
    let images: usize = std::env::var("BOWLOC_BENCH_LOAD_IMAGES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let path = map_file(images);
    let mut group = c.benchmark_group(format!("load/{images}-images"));
    group.sample_size(10);
    group.bench_function("mmap+structure", |b| {
        b.iter(|| MapIndex::open(&path, false).unwrap())
    });
    group.bench_function("mmap+structure+checksums", |b| {
        b.iter(|| MapIndex::open(&path, true).unwrap())
    });
    group.finish();
}

criterion_group!(benches, load);
criterion_main!(benches);

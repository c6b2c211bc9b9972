//! Nearest-word quantization per descriptor: one at a time versus blocks, for
//! several vocabulary sizes and every kernel this CPU runs. Throughput is set
//! in FLOP (K·128·2 per descriptor), so criterion's "elem/s" reads as FLOP/s.
//! `BOWLOC_BENCH_K=5000,20000` limits the vocabulary sizes.

use bowloc::quantize::{ExactQuantizer, Kernel, Quantizer};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use std::hint::black_box;

const DIM: usize = 128;

fn random(rows: usize, seed: u64) -> Array2<f32> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    Array2::from_shape_fn((rows, DIM), |_| rng.random::<f32>())
}

fn quantize(c: &mut Criterion) {
    let ks: Vec<usize> = std::env::var("BOWLOC_BENCH_K")
        .map(|v| v.split(',').filter_map(|k| k.parse().ok()).collect())
        .unwrap_or_else(|_| vec![5_000, 20_000, 100_000]);
    for k in ks {
        let centroids = random(k, 1);
        for kernel in Kernel::ALL.into_iter().filter(|k| k.available()) {
            let q = ExactQuantizer::with_kernel(centroids.as_slice().unwrap(), DIM, kernel);
            let mut group = c.benchmark_group(format!("quantize/K={k}/{}", kernel.name()));
            group.sample_size(10);
            for block in [1usize, 8, 32, 64, 256] {
                let x = random(block, 2);
                let mut out = vec![0u32; block];
                group.throughput(Throughput::Elements((k * DIM * 2 * block) as u64));
                group.bench_with_input(BenchmarkId::new("block", block), &block, |b, _| {
                    b.iter(|| q.quantize(black_box(x.view()), &mut out))
                });
            }
            group.finish();
        }
    }
}

criterion_group!(benches, quantize);
criterion_main!(benches);

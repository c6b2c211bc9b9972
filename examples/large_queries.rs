//! What decoding a large JPEG at a fraction of its size buys. Every query of
//! a dataset is scaled up 4× (bicubic) and encoded as a JPEG (quality 92),
//! the size of a 4K camera frame for gardens-point's 960×540 images. Each is
//! then decoded whole, as before, and shrunk while decoding
//! (`features::decode` with the frame's side), and extracted at the
//! vocabulary's 640 px on one OpenCV thread. Prints the median decode and
//! extraction times of both, the median per-image ratio of their sums, and
//! for vocabulary seeds 1 to 3 the full search's recall@1 and recall@5 (whole
//! images, Hamming weights) with the queries as they are, decoded whole from
//! the large JPEG, and shrunk while decoding (docs/performance.md, "Large
//! photos").
//!
//! ```sh
//! cargo run --release --example large_queries -- ../shared/datasets/gardens-point 5000
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::eval::timing::median;
use bowloc::features::{self, DecodeLimits, ExtractConfig, TileGrid};
use ndarray::{Array2, ArrayView2};
use opencv::core::{Mat, Size, Vector};
use opencv::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

const SCALE: i32 = 4;

/// The image at `path` scaled up [`SCALE`]× and encoded as a JPEG.
fn large_jpeg(path: &std::path::Path) -> anyhow::Result<Vec<u8>> {
    let small = opencv::imgcodecs::imread(
        path.to_str().unwrap_or_default(),
        opencv::imgcodecs::IMREAD_COLOR,
    )?;
    let mut large = Mat::default();
    let size = Size::new(small.cols() * SCALE, small.rows() * SCALE);
    opencv::imgproc::resize(
        &small,
        &mut large,
        size,
        0.0,
        0.0,
        opencv::imgproc::INTER_CUBIC,
    )?;
    let mut jpeg = Vector::<u8>::new();
    let quality = Vector::<i32>::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, 92]);
    opencv::imgcodecs::imencode(".jpg", &large, &mut jpeg, &quality)?;
    Ok(jpeg.to_vec())
}

/// Decode (`frame_side` as `features::decode` takes it) and extract one
/// image: its descriptors and the milliseconds of each step.
fn extract(
    jpeg: &[u8],
    frame_side: u32,
    config: &ExtractConfig,
) -> anyhow::Result<(Array2<f32>, f64, f64)> {
    let started = Instant::now();
    let image = features::decode(jpeg, DecodeLimits::default(), frame_side)?;
    let decoded = started.elapsed().as_secs_f64() * 1e3;
    let f = features::extract(&image, config)?;
    let extracted = started.elapsed().as_secs_f64() * 1e3 - decoded;
    Ok((f.descriptors, decoded, extracted))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = PathBuf::from(
        args.get(1)
            .map_or("../shared/datasets/gardens-point", |s| s),
    );
    let words: usize = args.get(2).map_or(Ok(5000), |s| s.parse())?;
    features::set_opencv_threads(1);
    let config = ExtractConfig::default();
    let dataset = bowloc::dataset::Dataset::open(&root)?;

    // (descriptors, decode ms, extract ms) per query, decoded whole and shrunk
    let mut whole = Vec::new();
    let mut shrunk = Vec::new();
    for q in &dataset.queries {
        let jpeg = large_jpeg(&q.path)?;
        whole.push(extract(&jpeg, 0, &config)?);
        shrunk.push(extract(&jpeg, config.max_side, &config)?);
    }
    let ms = |set: &[(Array2<f32>, f64, f64)], step: fn(&(Array2<f32>, f64, f64)) -> f64| {
        median(&set.iter().map(step).collect::<Vec<_>>())
    };
    for (name, set) in [
        ("decoded whole", &whole),
        ("shrunk while decoding", &shrunk),
    ] {
        println!(
            "{} queries ×{SCALE}, {name}: median decode {:.1} ms, extract {:.1} ms",
            dataset.name,
            ms(set, |r| r.1),
            ms(set, |r| r.2)
        );
    }
    let ratios = whole
        .iter()
        .zip(&shrunk)
        .map(|(w, s)| (s.1 + s.2) / (w.1 + w.2));
    println!(
        "decode + extract, shrunk against whole: median ratio {:.3} per image",
        median(&ratios.collect::<Vec<_>>())
    );

    for seed in 1..=3 {
        let p = cache::prepare(&root, words, seed, TileGrid::WHOLE)?;
        let recall = |images: Vec<Option<ArrayView2<'_, f32>>>| {
            let (r1, r5) = p.full_search_recall(&images);
            format!("recall@1 {r1:.1}, recall@5 {r5:.1}")
        };
        println!(
            "seed {seed}: as they are {} | ×{SCALE} decoded whole {} | ×{SCALE} shrunk while decoding {}",
            recall((0..p.queries.len()).map(|q| p.queries.image(q)).collect()),
            recall(whole.iter().map(|r| Some(r.0.view())).collect()),
            recall(shrunk.iter().map(|r| Some(r.0.view())).collect()),
        );
    }
    Ok(())
}

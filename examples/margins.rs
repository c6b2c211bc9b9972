//! What a tile grid's margins cost: every query of a dataset goes through
//! the whole image and each plan given, in turn (three rounds, the cheapest
//! kept, the extracting thread's CPU time, one OpenCV thread), with the image
//! buffers kept mapped as the binary keeps them (`BOWLOC_KEEP_BUFFERS=0`:
//! glibc's defaults). Prints, per plan, the median of the per-image ratio of
//! its full extraction to the whole image's, and of its keypoints.
//!
//! ```sh
//! cargo run --release --example margins -- ../shared/datasets/rtabmap-loop 2x2+24 2x2+16
//! ```

use bowloc::dataset::Dataset;
use bowloc::features::{self, DecodeLimits, ExtractConfig, TileGrid};
use bowloc::pipeline::extract_tiled;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    features::keep_image_buffers();
    features::set_opencv_threads(1);
    let data = Dataset::open(std::path::Path::new(&args[1]))?;
    let mut plans: Vec<TileGrid> = vec!["1x1+0".parse().map_err(anyhow::Error::msg)?];
    for p in &args[2..] {
        plans.push(p.parse().map_err(anyhow::Error::msg)?);
    }
    let c = ExtractConfig::default();
    let mut cost = vec![Vec::new(); plans.len()];
    let mut points = vec![Vec::new(); plans.len()];
    for q in &data.queries {
        let bytes = std::fs::read(&q.path)?;
        let decoded = features::decode(&bytes, DecodeLimits::default(), c.max_side)?;
        let mut best = vec![(f64::INFINITY, 0usize); plans.len()];
        for _round in 0..3 {
            for (p, plan) in plans.iter().enumerate() {
                let (f, units) = extract_tiled(&decoded, &c, *plan)?;
                let ms: f64 = units.iter().map(|u| u.extract.as_secs_f64() * 1e3).sum();
                if ms < best[p].0 {
                    best[p] = (ms, f.len());
                }
            }
        }
        for (p, b) in best.iter().enumerate() {
            cost[p].push(b.0 / best[0].0);
            points[p].push(b.1 as f64 / best[0].1.max(1) as f64);
        }
    }
    for (p, plan) in plans.iter().enumerate() {
        println!(
            "{plan}: extraction {:.3}× the whole image's, keypoints {:.3}× (medians over {} images)",
            median(cost[p].clone()),
            median(points[p].clone()),
            cost[p].len()
        );
    }
    Ok(())
}

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
use bowloc::eval::timing::median;
use bowloc::features::{self, DecodeLimits, ExtractConfig, TileGrid};
use bowloc::pipeline::extract_interleaved;

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
        let each = extract_interleaved(&decoded, &c, &plans, 3)?;
        let ms = |p: usize| -> f64 { each[p].tiles.iter().map(|t| t.extract.as_secs_f64()).sum() };
        for p in 0..plans.len() {
            cost[p].push(ms(p) / ms(0));
            points[p].push(each[p].features.len() as f64 / each[0].features.len().max(1) as f64);
        }
    }
    for (p, plan) in plans.iter().enumerate() {
        println!(
            "{plan}: extraction {:.3}× the whole image's, keypoints {:.3}× (medians over {} images)",
            median(&cost[p]),
            median(&points[p]),
            cost[p].len()
        );
    }
    Ok(())
}

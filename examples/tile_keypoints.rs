//! How many of the whole image's SIFT keypoints a tile grid finds as they
//! are: every tenth query of a dataset extracted whole and in the grid
//! (`pipeline::extract_tiled`, the eval's and the service's extraction),
//! and each whole-image keypoint looked up among the tiles' (the same
//! centre and size within 0.01 px, within 1 px, or not at all), by size.
//! The small keypoints come out the same; the large ones, whose blur in the
//! upper octaves reaches past a tile's margin, do not (docs/results.md,
//! "Streaming extraction and the verified stop", "Tiling itself").
//!
//! ```sh
//! cargo run --release --example tile_keypoints -- ../shared/datasets/gardens-point 2x2+24
//! ```

use bowloc::dataset::Dataset;
use bowloc::features::{DecodeLimits, ExtractConfig, TileGrid, decode_file};
use bowloc::pipeline::extract_tiled;

/// Size classes: [2^b, 2^(b+1)) px for b = 0..5, the last open.
const CLASSES: usize = 6;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, dataset, grid] = &args[..] else {
        anyhow::bail!("usage: tile_keypoints DATASET GRID (e.g. 2x2+24)");
    };
    let dataset = Dataset::open(std::path::Path::new(dataset))?;
    let grid: TileGrid = grid.parse().map_err(anyhow::Error::msg)?;
    let config = ExtractConfig::default();
    // per size class: whole-image keypoints, found exactly, within 1 px
    let mut classes = [[0usize; 3]; CLASSES];
    let mut tiled = 0;
    for query in dataset.queries.iter().step_by(10) {
        let image = decode_file(&query.path, DecodeLimits::default(), config.max_side)?;
        let (whole, _) = extract_tiled(&image, &config, TileGrid::WHOLE)?;
        let (tiles, _) = extract_tiled(&image, &config, grid)?;
        tiled += tiles.keypoints.len();
        for k in &whole.keypoints {
            let off = tiles
                .keypoints
                .iter()
                .map(|o| (o.x - k.x).hypot(o.y - k.y) + (o.size - k.size).abs())
                .fold(f32::INFINITY, f32::min);
            let class = &mut classes[(k.size.max(1.0).log2() as usize).min(CLASSES - 1)];
            class[0] += 1;
            class[1] += usize::from(off < 0.01);
            class[2] += usize::from(off < 1.0);
        }
    }
    let all: usize = classes.iter().map(|c| c[0]).sum();
    let exact: usize = classes.iter().map(|c| c[1]).sum();
    println!(
        "{} queries: {all} keypoints whole, {tiled} in {grid}; {:.1} % of the whole image's found exactly",
        dataset.queries.len().div_ceil(10),
        100.0 * exact as f64 / all.max(1) as f64
    );
    for (b, c) in classes.iter().enumerate() {
        let pct = |n: usize| 100.0 * n as f64 / c[0].max(1) as f64;
        let upper = if b + 1 == CLASSES {
            "up".to_owned()
        } else {
            format!("{}", 1 << (b + 1))
        };
        println!(
            "size {}–{upper} px: {} keypoints, {:.1} % found exactly, {:.1} % within 1 px",
            1 << b,
            c[0],
            pct(c[1]),
            pct(c[2])
        );
    }
    Ok(())
}

//! Features of images: one decoded image extracted tile by tile with each
//! tile's cost, and whole image lists in parallel, with unreadable images
//! named and skipped.

use super::progress_bar;
use crate::dataset::ImageRef;
use crate::features::{self, DecodeLimits, ExtractConfig, FeatureError, Features, TileGrid, Tiles};
use anyhow::bail;
use cpu_time::ThreadTime;
use ndarray::{Array2, ArrayView2, Axis};
use rayon::prelude::*;
use std::time::Duration;

/// One image's features and what reading them cost.
#[derive(Debug, Clone)]
pub struct Extracted {
    /// Keypoints and descriptor rows tile by tile, in grid order.
    pub features: Features,
    /// Reading and decoding the file (thread CPU time).
    pub decode: Duration,
    /// Feature extraction on the decoded image, all tiles (thread CPU time).
    pub extract: Duration,
    /// Each tile in grid order: its features, its share of the image's area
    /// and its extraction time (one tile when extracted whole).
    pub tiles: Vec<TileCost>,
}

/// What one tile of an image held and cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileCost {
    pub features: usize,
    pub area: f64,
    pub extract: Duration,
    /// FAST corners counted in the tile before extraction (0 for a whole
    /// image), what the tile orders `spread` and `richest` read.
    pub corners: f32,
    /// Its cell (column, row) in the grid ([0, 0] for the coarse pass).
    pub cell: [u32; 2],
}

/// Extract a decoded image tile by tile in grid order, timing each tile by
/// the thread's CPU time (OpenCV runs on the calling thread here), with
/// each tile's corner count (counted first, its time in no tile's).
pub fn extract_tiled(
    image: &features::GrayImage,
    config: &ExtractConfig,
    grid: TileGrid,
) -> Result<(Features, Vec<TileCost>), FeatureError> {
    let mut tiles = Tiles::new(image, config, grid, None)?;
    let corners = tiles.corners()?;
    let cells = tiles.cells();
    let coarse = usize::from(grid.coarse);
    let mut parts = Vec::with_capacity(tiles.total());
    let mut costs = Vec::with_capacity(tiles.total());
    loop {
        let started = ThreadTime::now();
        let Some(tile) = tiles.next_tile() else { break };
        let tile = tile?;
        let unit = costs.len();
        costs.push(TileCost {
            features: tile.len(),
            area: tiles.share_of_last(),
            extract: started.elapsed(),
            corners: unit
                .checked_sub(coarse)
                .and_then(|t| corners.get(t).copied())
                .unwrap_or(0.0),
            cell: unit
                .checked_sub(coarse)
                .and_then(|t| cells.get(t).copied())
                .unwrap_or_default(),
        });
        parts.push(tile);
    }
    let refs: Vec<&Features> = parts.iter().collect();
    let features = Features {
        descriptors: stack(&refs),
        keypoints: parts
            .iter()
            .flat_map(|p| p.keypoints.iter().copied())
            .collect(),
    };
    Ok((features, costs))
}

/// A decoded image extracted with each grid of `grids` in turn, `rounds`
/// times over, keeping for each grid its cheapest round (by the thread's CPU
/// time for the whole extraction, corner counting included). The grids are
/// timed back to back under the same load, so their ratios hold even when
/// the machine's speed drifts between minutes. Each result's `decode` is
/// zero: the caller decoded the image.
pub fn extract_interleaved(
    image: &features::GrayImage,
    config: &ExtractConfig,
    grids: &[TileGrid],
    rounds: usize,
) -> Result<Vec<Extracted>, FeatureError> {
    let mut best: Vec<Option<Extracted>> = vec![None; grids.len()];
    for _round in 0..rounds.max(1) {
        for (kept, &grid) in best.iter_mut().zip(grids) {
            let started = ThreadTime::now();
            let (features, tiles) = extract_tiled(image, config, grid)?;
            let extract = started.elapsed();
            if kept.as_ref().is_none_or(|k| extract < k.extract) {
                *kept = Some(Extracted {
                    features,
                    decode: Duration::ZERO,
                    extract,
                    tiles,
                });
            }
        }
    }
    Ok(best.into_iter().flatten().collect())
}

/// Features (keypoints and descriptors) of every image, in parallel, one
/// image per core. Images that
/// cannot be read or decoded are `None`, each named in a warning, with a count
/// at the end; with `strict` the first one is an error.
pub fn extract_all(
    images: &[ImageRef],
    config: &ExtractConfig,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Features>>> {
    let timed = extract_all_timed(images, config, TileGrid::WHOLE, limits, strict, what)?;
    Ok(timed.into_iter().map(|e| e.map(|e| e.features)).collect())
}

/// [`extract_all`], tile by tile with `grid`, keeping how long each image
/// took to decode and each tile to extract. The times are CPU time of the
/// thread doing the work (one image per thread, OpenCV on one thread), so
/// they price the work as a quiet machine would even when other processes
/// share the cores: wall time there would charge for the waiting too.
pub fn extract_all_timed(
    images: &[ImageRef],
    config: &ExtractConfig,
    grid: TileGrid,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Extracted>>> {
    let together = extract_all_together(images, config, &[grid], 1, limits, strict, what)?;
    Ok(together
        .into_iter()
        .map(|e| e.and_then(|e| e.into_iter().next()))
        .collect())
}

/// [`extract_all_timed`] with several grids at once: each image is decoded
/// once and extracted with every grid back to back, `rounds` times over
/// ([`extract_interleaved`]), so that the grids' times compare image by
/// image. Per image, one [`Extracted`] per grid, in the order of `grids`.
pub fn extract_all_together(
    images: &[ImageRef],
    config: &ExtractConfig,
    grids: &[TileGrid],
    rounds: usize,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Vec<Extracted>>>> {
    features::set_opencv_threads(1);
    let bar = progress_bar(images.len() as u64, what);
    let results: Vec<Result<Vec<Extracted>, FeatureError>> = images
        .par_iter()
        .map(|image| {
            let started = ThreadTime::now();
            let r =
                features::decode_file(&image.path, limits, config.max_side).and_then(|decoded| {
                    let read = started.elapsed();
                    let mut each = extract_interleaved(&decoded, config, grids, rounds)?;
                    for e in &mut each {
                        e.decode = read;
                    }
                    Ok(each)
                });
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let mut out = Vec::with_capacity(images.len());
    let mut failed = 0;
    for (image, result) in images.iter().zip(results) {
        match result {
            Ok(e) => {
                if e.first().is_some_and(|e| e.features.is_empty()) {
                    tracing::warn!(image = %image.name, "no features found");
                }
                out.push(Some(e));
            }
            Err(e) => {
                if strict {
                    bail!("{}: {e}", image.path.display());
                }
                tracing::warn!(image = %image.path.display(), "skipped: {e}");
                failed += 1;
                out.push(None);
            }
        }
    }
    if failed > 0 {
        tracing::warn!(
            "{failed} of {} images could not be read and were skipped",
            images.len()
        );
    }
    if out.iter().all(Option::is_none) {
        bail!("none of the {} images could be read", images.len());
    }
    Ok(out)
}

/// Stack the descriptor rows of several images.
pub fn stack(parts: &[&Features]) -> Array2<f32> {
    let views: Vec<ArrayView2<'_, f32>> = parts.iter().map(|f| f.descriptors.view()).collect();
    if views.is_empty() {
        return Array2::zeros((0, 128));
    }
    ndarray::concatenate(Axis(0), &views).expect("same width")
}

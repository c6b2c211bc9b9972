//! Grayscale image → SIFT (or RootSIFT) descriptors as an `n × 128` matrix.

use super::{DecodeLimits, ExtractConfig, FeatureError, GrayImage, decode_file};
use ndarray::Array2;
use opencv::core::{KeyPoint, Mat, Size, Vector, no_array};
use opencv::prelude::*;

/// One row per keypoint, 128 columns.
pub type Descriptors = Array2<f32>;

/// Extract descriptors from a decoded image.
pub fn extract(image: &GrayImage, config: &ExtractConfig) -> Result<Descriptors, FeatureError> {
    let scaled;
    let mat = match downscale_size(image, config.max_side) {
        Some(size) => {
            let mut out = Mat::default();
            opencv::imgproc::resize(
                &image.0,
                &mut out,
                size,
                0.0,
                0.0,
                opencv::imgproc::INTER_AREA,
            )?;
            scaled = out;
            &scaled
        }
        None => &image.0,
    };
    let p = &config.sift;
    let mut sift = opencv::features2d::SIFT::create(
        p.max_features as i32,
        p.octave_layers as i32,
        p.contrast_threshold,
        p.edge_threshold,
        p.sigma,
    )?;
    let mut keypoints = Vector::<KeyPoint>::new();
    let mut raw = Mat::default();
    sift.detect_and_compute(mat, &no_array(), &mut keypoints, &mut raw, false)?;
    let mut rows = raw.rows().max(0) as usize;
    if p.max_features > 0 {
        // OpenCV keeps ties with the weakest kept response: cap exactly.
        rows = rows.min(p.max_features as usize);
    }
    if rows == 0 {
        return Ok(Array2::zeros((0, 128)));
    }
    let cols = raw.cols() as usize;
    let data: &[f32] = raw.data_typed()?;
    let mut out = Array2::from_shape_vec((rows, cols), data[..rows * cols].to_vec())
        .map_err(|e| FeatureError::OpenCv(e.to_string()))?;
    if config.rootsift {
        rootsift(&mut out);
    }
    Ok(out)
}

/// Decode a file and extract its descriptors.
pub fn extract_file(
    path: &std::path::Path,
    config: &ExtractConfig,
    limits: DecodeLimits,
) -> Result<Descriptors, FeatureError> {
    extract(&decode_file(path, limits)?, config)
}

fn downscale_size(image: &GrayImage, max_side: u32) -> Option<Size> {
    let (w, h) = (image.width(), image.height());
    let longest = w.max(h);
    if max_side == 0 || longest <= max_side {
        return None;
    }
    let scale = max_side as f64 / longest as f64;
    Some(Size::new(
        ((w as f64 * scale).round() as i32).max(1),
        ((h as f64 * scale).round() as i32).max(1),
    ))
}

/// RootSIFT (Arandjelović & Zisserman 2012): L1-normalise, then square root,
/// so Euclidean distance between descriptors compares like the Hellinger kernel.
fn rootsift(descriptors: &mut Descriptors) {
    for mut row in descriptors.rows_mut() {
        let l1: f32 = row.iter().map(|v| v.abs()).sum();
        if l1 > 0.0 {
            row.mapv_inplace(|v| (v.abs() / l1).sqrt());
        }
    }
}

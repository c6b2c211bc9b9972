//! Bytes → 8-bit grayscale image, with the pixel count checked from the file
//! header before any pixel is decoded.

use super::FeatureError;
use opencv::core::{Mat, Vector};
use opencv::prelude::*;

/// Limits applied before decoding.
#[derive(Debug, Clone, Copy)]
pub struct DecodeLimits {
    /// Largest width × height accepted.
    pub max_pixels: u64,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        Self {
            max_pixels: 40_000_000,
        }
    }
}

/// A decoded single-channel 8-bit image.
pub struct GrayImage(pub(super) Mat);

impl GrayImage {
    pub fn width(&self) -> u32 {
        self.0.cols() as u32
    }
    pub fn height(&self) -> u32 {
        self.0.rows() as u32
    }
}

/// Decode an in-memory image (any format OpenCV reads) to grayscale.
pub fn decode(bytes: &[u8], limits: DecodeLimits) -> Result<GrayImage, FeatureError> {
    if bytes.is_empty() {
        return Err(FeatureError::Empty);
    }
    // Formats the header parser knows are size-checked before decoding; for the
    // others only OpenCV's built-in limit (2^30 pixels) applies, which is why
    // the service refuses images whose size it cannot read from the header.
    if let Ok(size) = imagesize::blob_size(bytes) {
        let (width, height) = (size.width as u64, size.height as u64);
        if width.saturating_mul(height) > limits.max_pixels {
            return Err(FeatureError::TooLarge {
                width,
                height,
                limit: limits.max_pixels,
            });
        }
    }
    let buf = Vector::<u8>::from_slice(bytes);
    let mat = opencv::imgcodecs::imdecode(&buf, opencv::imgcodecs::IMREAD_GRAYSCALE)
        .map_err(|e| FeatureError::Undecodable(e.message))?;
    if mat.empty() || mat.rows() == 0 || mat.cols() == 0 {
        return Err(FeatureError::Undecodable(
            "unknown format or damaged data".into(),
        ));
    }
    Ok(GrayImage(mat))
}

/// Read and decode an image file.
pub fn decode_file(
    path: &std::path::Path,
    limits: DecodeLimits,
) -> Result<GrayImage, FeatureError> {
    let bytes = std::fs::read(path).map_err(|source| FeatureError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    decode(&bytes, limits)
}

//! Warming a thread up for extraction. The first image a thread extracts
//! pays for mapping its scale space (tens of MB, which malloc then keeps:
//! [`super::keep_image_buffers`]) and for OpenCV's first calls (decoding,
//! fitting); so does the first second thread of a tile pair
//! ([`super::Frame::detect_two`]). A service answers the synthetic query of
//! [`warm_up_image`] on each worker before it says it is ready, so that its
//! first requests do not pay (docs/performance.md, "Warm workers").

use super::{ExtractConfig, FeatureError};
use opencv::core::{CV_8UC1, Mat, Scalar, Vector};
use opencv::prelude::*;

/// A synthetic query as JPEG bytes, of a common query's frame size (16:9
/// at the configured longer side, 640 px when images keep their size; a
/// larger frame's first request maps only what it needs beyond), made
/// smaller if need be to hold at most `max_pixels` (the largest a request
/// may send), for a thread's first extraction
/// ([`crate::pipeline::Localizer::warm_up`]).
pub fn warm_up_image(config: &ExtractConfig, max_pixels: u64) -> Result<Vec<u8>, FeatureError> {
    let side = match config.max_side {
        0 => ExtractConfig::default().max_side,
        side => side,
    };
    let (w, h) = (f64::from(side), f64::from(side * 9 / 16));
    let shrink = (max_pixels as f64 / (w * h)).sqrt().min(1.0);
    let (w, h) = ((w * shrink) as u32, (h * shrink) as u32);
    let image = textured(w.max(2), h.max(2))?;
    let mut jpeg = Vector::<u8>::new();
    opencv::imgcodecs::imencode(".jpg", &image, &mut jpeg, &Vector::new())?;
    Ok(jpeg.to_vec())
}

/// A `width` × `height` image of squares of random grey in two sizes (64
/// and 256 pixels) laid over one another, the same every time: SIFT builds
/// its whole scale space for it, as for any image of that size, and finds
/// some keypoints, far fewer than a photograph's thousands (which would
/// only make the warm-up longer).
fn textured(width: u32, height: u32) -> Result<Mat, FeatureError> {
    let mut pixels =
        Mat::new_rows_cols_with_default(height as i32, width as i32, CV_8UC1, Scalar::all(0.0))?;
    let grey = |cell: u32, x: u32, y: u32| {
        // a hash of the cell (splitmix64's finaliser)
        let mut z = (u64::from(x / cell) << 32 | u64::from(y / cell)) ^ u64::from(cell) << 56;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)) as u32 % 86
    };
    let data = pixels.data_bytes_mut()?;
    for (i, p) in data.iter_mut().enumerate() {
        let (x, y) = (i as u32 % width, i as u32 / width);
        *p = (grey(64, x, y) + grey(256, x, y)) as u8;
    }
    Ok(pixels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::DecodeLimits;

    #[test]
    fn the_synthetic_query_decodes_to_the_frame_size_and_has_keypoints() {
        let config = ExtractConfig::default();
        let limits = DecodeLimits::default();
        let jpeg = warm_up_image(&config, limits.max_pixels).unwrap();
        let image = super::super::decode(&jpeg, limits, config.max_side).unwrap();
        assert_eq!(
            [image.width(), image.height()],
            [config.max_side, config.max_side * 9 / 16]
        );
        assert!(!super::super::extract(&image, &config).unwrap().is_empty());
    }

    #[test]
    fn a_tiny_frame_makes_a_query_too() {
        let config = ExtractConfig {
            max_side: 3,
            ..ExtractConfig::default()
        };
        let jpeg = warm_up_image(&config, 1_000_000).unwrap();
        super::super::decode(&jpeg, DecodeLimits::default(), 3).unwrap();
    }

    #[test]
    fn the_synthetic_query_fits_the_pixel_limit() {
        let config = ExtractConfig::default();
        let limits = DecodeLimits { max_pixels: 10_000 };
        let jpeg = warm_up_image(&config, limits.max_pixels).unwrap();
        let image = super::super::decode(&jpeg, limits, config.max_side).unwrap();
        let pixels = image.width() * image.height();
        assert!((9_000..=10_000).contains(&pixels), "{pixels} pixels");
    }
}

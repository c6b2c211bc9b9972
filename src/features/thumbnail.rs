//! Small JPEG previews of images (the service's page shows map images with
//! them): decode in colour, downscale so the longer side is at most a given
//! size, encode as JPEG.

use super::FeatureError;
use super::decode::{Colour, DecodeLimits, decode_as};
use super::extract::downscale;
use opencv::core::Vector;
use opencv::prelude::*;

/// JPEG quality of thumbnails (0–100).
const QUALITY: i32 = 82;

/// A JPEG of the image in `bytes` whose longer side is at most `max_side`
/// pixels (an image already smaller keeps its size). The header is checked
/// against `limits` before any pixel is decoded.
pub fn thumbnail(
    bytes: &[u8],
    max_side: u32,
    limits: DecodeLimits,
) -> Result<Vec<u8>, FeatureError> {
    let side = max_side.max(1);
    let (image, size) = decode_as(bytes, limits, Colour::Bgr, side)?;
    let small = downscale(&image, size, side)?;
    let mut jpeg = Vector::<u8>::new();
    let params = Vector::<i32>::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, QUALITY]);
    opencv::imgcodecs::imencode(".jpg", &small, &mut jpeg, &params)?;
    Ok(jpeg.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thumbnails_are_jpegs_within_the_size() {
        let png = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/rgba.png"
        ))
        .unwrap();
        let limits = DecodeLimits::default();
        let source = imagesize::blob_size(&png).unwrap();
        for side in [1u32, 16, 40, 4000] {
            let jpeg = thumbnail(&png, side, limits).unwrap();
            assert!(jpeg.starts_with(&[0xFF, 0xD8]), "JPEG magic");
            let size = imagesize::blob_size(&jpeg).unwrap();
            let longest = size.width.max(size.height);
            assert_eq!(
                longest,
                (side as usize).min(source.width.max(source.height)),
                "{side}"
            );
        }
        assert!(matches!(
            thumbnail(b"not an image", 16, limits),
            Err(FeatureError::Undecodable(_))
        ));
    }
}

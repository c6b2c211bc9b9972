//! Bytes → 8-bit grayscale image, with the format and pixel count checked
//! from the file header before any pixel is decoded, and a JPEG's end checked
//! (OpenCV would decode a truncated JPEG, grey below the cut, without a
//! word).

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

/// The formats [`decode`] accepts: OpenCV decodes them and the header parser
/// reads their size.
pub const SUPPORTED_FORMATS: &str = "JPEG, PNG, BMP, TIFF, WebP or PNM";

/// Read the format and size from the header alone, and check them: a format
/// of [`SUPPORTED_FORMATS`] and at most `limits.max_pixels` pixels. Other
/// recognised formats (GIF, ...) are [`FeatureError::Unsupported`]; bytes in
/// no known format, or with a damaged header, or a JPEG cut short
/// (`jpeg_is_complete`), [`FeatureError::Undecodable`].
pub fn probe(bytes: &[u8], limits: DecodeLimits) -> Result<(), FeatureError> {
    use imagesize::ImageType;
    if bytes.is_empty() {
        return Err(FeatureError::Empty);
    }
    let undecodable = || {
        FeatureError::Undecodable(format!(
            "not an image in a known format ({SUPPORTED_FORMATS}), or its header is damaged"
        ))
    };
    match imagesize::image_type(bytes).map_err(|_| undecodable())? {
        ImageType::Jpeg if !jpeg_is_complete(bytes) => {
            return Err(FeatureError::Undecodable(
                "the JPEG ends before its end-of-image marker: it is truncated \
                 (an upload cut short?)"
                    .into(),
            ));
        }
        ImageType::Jpeg
        | ImageType::Png
        | ImageType::Bmp
        | ImageType::Tiff
        | ImageType::Webp
        | ImageType::Pnm => {}
        ImageType::Gif => return Err(FeatureError::Unsupported("GIF".into())),
        other => return Err(FeatureError::Unsupported(format!("{other:?}"))),
    }
    let size = imagesize::blob_size(bytes).map_err(|_| undecodable())?;
    let (width, height) = (size.width as u64, size.height as u64);
    if width.saturating_mul(height) > limits.max_pixels {
        return Err(FeatureError::TooLarge {
            width,
            height,
            limit: limits.max_pixels,
        });
    }
    Ok(())
}

/// Whether a JPEG's last scan is followed by the end-of-image marker (FF D9).
/// Inside entropy-coded data an FF byte is always followed by 00 or a restart
/// marker, so the last start-of-scan (FF DA) is the last scan's and an FF D9
/// after it is the image's end; bytes after that end are allowed.
pub fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let last = |marker: u8| bytes.windows(2).rposition(|w| w == [0xFF, marker]);
    match (last(0xDA), last(0xD9)) {
        (Some(scan), Some(end)) => end > scan,
        // no scan at all: OpenCV reports the damage itself
        (None, _) => true,
        (Some(_), None) => false,
    }
}

/// Decode an in-memory image to 8-bit grayscale (colour, alpha and 16-bit
/// samples are converted), after [`probe`] has checked its header.
pub fn decode(bytes: &[u8], limits: DecodeLimits) -> Result<GrayImage, FeatureError> {
    decode_as(bytes, limits, opencv::imgcodecs::IMREAD_GRAYSCALE).map(GrayImage)
}

/// [`probe`], then decode with OpenCV's `imread` `flags` (grayscale, colour).
pub(super) fn decode_as(
    bytes: &[u8],
    limits: DecodeLimits,
    flags: i32,
) -> Result<Mat, FeatureError> {
    probe(bytes, limits)?;
    let buf = Vector::<u8>::from_slice(bytes);
    let mat = opencv::imgcodecs::imdecode(&buf, flags)
        .map_err(|e| FeatureError::Undecodable(e.message))?;
    if mat.empty() || mat.rows() == 0 || mat.cols() == 0 {
        return Err(FeatureError::Undecodable("damaged image data".into()));
    }
    Ok(mat)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn probed(bytes: &[u8]) -> String {
        match probe(bytes, DecodeLimits::default()) {
            Ok(()) => "ok".into(),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn probe_checks_format_and_size_from_the_header() {
        let png = |w: u32, h: u32| {
            let mut b = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
            b.extend_from_slice(&w.to_be_bytes());
            b.extend_from_slice(&h.to_be_bytes());
            b.extend_from_slice(&[8, 0, 0, 0, 0, 0, 0, 0, 0]);
            b
        };
        assert_eq!(probed(&png(640, 480)), "ok");
        assert!(probed(&png(50_000, 50_000)).contains("50000×50000"));
        let gif = b"GIF89a\x10\x00\x10\x00\x00\x00\x00";
        assert!(probed(gif).starts_with("GIF images are not supported"));
        assert!(probed(b"not an image at all").contains("known format"));
        assert!(probed(b"").contains("empty"));
    }

    #[test]
    fn a_truncated_jpeg_is_refused_and_a_whole_one_decodes() {
        let jpeg = std::fs::read("tests/fixtures/uniform.jpg").unwrap();
        assert!(decode(&jpeg, DecodeLimits::default()).is_ok());
        // trailing bytes after the end marker are allowed
        let mut padded = jpeg.clone();
        padded.extend_from_slice(b"\0\0trailer");
        assert!(decode(&padded, DecodeLimits::default()).is_ok());
        let scan = jpeg.windows(2).rposition(|w| w == [0xFF, 0xDA]).unwrap();
        for cut in [scan + 2, scan + (jpeg.len() - scan) / 2, jpeg.len() - 1] {
            match decode(&jpeg[..cut], DecodeLimits::default()) {
                Err(FeatureError::Undecodable(m)) => assert!(m.contains("truncated"), "{m}"),
                Err(e) => panic!("cut at {cut}: {e}"),
                Ok(_) => panic!("cut at {cut} of {} decoded", jpeg.len()),
            }
        }
    }

    #[test]
    fn jpeg_end_is_the_marker_after_the_last_scan() {
        let soi = [0xFF, 0xD8];
        let scan = [0xFF, 0xDA, 0x12, 0xFF, 0x00, 0x34];
        let eoi = [0xFF, 0xD9];
        // an embedded thumbnail's scan and end come before the image's
        let thumb = [&soi[..], &scan, &eoi].concat();
        assert!(jpeg_is_complete(&[&soi[..], &thumb, &scan, &eoi].concat()));
        assert!(!jpeg_is_complete(&[&soi[..], &thumb, &scan].concat()));
        assert!(!jpeg_is_complete(&[&soi[..], &scan].concat()));
        assert!(jpeg_is_complete(&soi));
    }
}

//! Bytes → 8-bit grayscale image, with the format and pixel count checked
//! from the file header before any pixel is decoded, and a JPEG's end checked
//! (OpenCV would decode a truncated JPEG, grey below the cut, without a
//! word). A JPEG at least twice the frame SIFT will see is decoded at a
//! fraction of its size (libjpeg's scaled decoding), which saves part of its
//! decoding and most of the downscaling (docs/performance.md, "Large photos").

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
pub struct GrayImage {
    /// The pixels: the image at its size, or a JPEG decoded at 1/2, 1/4 or
    /// 1/8 of it ([`decode`]).
    pub(super) pixels: Mat,
    /// Width and height of the image as sent (its EXIF orientation applied).
    size: [u32; 2],
}

impl GrayImage {
    /// Width of the image as sent, whatever size it was decoded at.
    pub fn width(&self) -> u32 {
        self.size[0]
    }
    /// Height of the image as sent.
    pub fn height(&self) -> u32 {
        self.size[1]
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
    header(bytes, limits).map(|_| ())
}

/// [`probe`]'s checks; on success, whether the image is a JPEG and its
/// width and height as the header gives them (before EXIF orientation).
fn header(bytes: &[u8], limits: DecodeLimits) -> Result<(bool, [u32; 2]), FeatureError> {
    use imagesize::ImageType;
    if bytes.is_empty() {
        return Err(FeatureError::Empty);
    }
    let undecodable = || {
        FeatureError::Undecodable(format!(
            "not an image in a known format ({SUPPORTED_FORMATS}), or its header is damaged"
        ))
    };
    let kind = imagesize::image_type(bytes).map_err(|_| undecodable())?;
    match kind {
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
    Ok((kind == ImageType::Jpeg, [width as u32, height as u32]))
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
/// samples are converted), after [`probe`] has checked its header. With a
/// `frame_side` (0: none), the longer side SIFT will see, a JPEG at least
/// twice that size is decoded at the smallest of 1/2, 1/4 and 1/8 of its size
/// whose longer side still reaches `frame_side`; the frame is then
/// downscaled from those pixels to the size it has from the whole image.
pub fn decode(
    bytes: &[u8],
    limits: DecodeLimits,
    frame_side: u32,
) -> Result<GrayImage, FeatureError> {
    let (pixels, size) = decode_as(bytes, limits, Colour::Gray, frame_side)?;
    Ok(GrayImage { pixels, size })
}

/// Grey or colour pixels out of [`decode_as`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Colour {
    Gray,
    Bgr,
}

/// The factor a JPEG of `size` is shrunk by while decoding for a frame whose
/// longer side is `frame_side`: the largest of 8, 4 and 2 that leaves the
/// longer side at least `frame_side`, else 1 (also for other formats, which
/// OpenCV would decode whole and then shrink without smoothing).
fn shrink_factor(jpeg: bool, size: [u32; 2], frame_side: u32) -> u32 {
    let longer = size[0].max(size[1]);
    match jpeg && frame_side > 0 {
        true => [8, 4, 2]
            .into_iter()
            .find(|f| longer / f >= frame_side)
            .unwrap_or(1),
        false => 1,
    }
}

/// [`probe`], then decode (see [`decode`] for `frame_side`). Returns the
/// pixels and the width and height of the image as sent.
pub(super) fn decode_as(
    bytes: &[u8],
    limits: DecodeLimits,
    colour: Colour,
    frame_side: u32,
) -> Result<(Mat, [u32; 2]), FeatureError> {
    use opencv::imgcodecs::*;
    let (jpeg, header_size) = header(bytes, limits)?;
    let factor = shrink_factor(jpeg, header_size, frame_side);
    let flags = match (colour, factor) {
        (Colour::Gray, 8) => IMREAD_REDUCED_GRAYSCALE_8,
        (Colour::Gray, 4) => IMREAD_REDUCED_GRAYSCALE_4,
        (Colour::Gray, 2) => IMREAD_REDUCED_GRAYSCALE_2,
        (Colour::Gray, _) => IMREAD_GRAYSCALE,
        (Colour::Bgr, 8) => IMREAD_REDUCED_COLOR_8,
        (Colour::Bgr, 4) => IMREAD_REDUCED_COLOR_4,
        (Colour::Bgr, 2) => IMREAD_REDUCED_COLOR_2,
        (Colour::Bgr, _) => IMREAD_COLOR,
    };
    let buf = Vector::<u8>::from_slice(bytes);
    let mat = imdecode(&buf, flags).map_err(|e| FeatureError::Undecodable(e.message))?;
    if mat.empty() || mat.rows() == 0 || mat.cols() == 0 {
        return Err(FeatureError::Undecodable("damaged image data".into()));
    }
    let decoded = [mat.cols() as u32, mat.rows() as u32];
    let size = match factor {
        1 => decoded,
        _ => oriented(header_size, decoded),
    };
    Ok((mat, size))
}

/// The header's `size` turned as the decoded pixels are: EXIF orientation
/// may have swapped width and height, which the shape of `decoded` shows.
fn oriented(size: [u32; 2], decoded: [u32; 2]) -> [u32; 2] {
    let [w, h] = size.map(|v| v as u64);
    let [dw, dh] = decoded.map(|v| v as u64);
    // compare the aspect ratios w:h and h:w with dw:dh, without division
    let kept = (w * dh).abs_diff(h * dw);
    let turned = (h * dh).abs_diff(w * dw);
    match turned < kept {
        true => [size[1], size[0]],
        false => size,
    }
}

/// Read and decode an image file.
pub fn decode_file(
    path: &std::path::Path,
    limits: DecodeLimits,
    frame_side: u32,
) -> Result<GrayImage, FeatureError> {
    let bytes = std::fs::read(path).map_err(|cause| FeatureError::Read {
        path: path.to_path_buf(),
        cause,
    })?;
    decode(&bytes, limits, frame_side)
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
        assert!(decode(&jpeg, DecodeLimits::default(), 0).is_ok());
        // trailing bytes after the end marker are allowed
        let mut padded = jpeg.clone();
        padded.extend_from_slice(b"\0\0trailer");
        assert!(decode(&padded, DecodeLimits::default(), 0).is_ok());
        let scan = jpeg.windows(2).rposition(|w| w == [0xFF, 0xDA]).unwrap();
        for cut in [scan + 2, scan + (jpeg.len() - scan) / 2, jpeg.len() - 1] {
            match decode(&jpeg[..cut], DecodeLimits::default(), 0) {
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

    #[test]
    fn a_jpeg_shrinks_while_decoding_only_when_twice_the_frame() {
        assert_eq!(shrink_factor(true, [4032, 3024], 640), 4); // 1008 px
        assert_eq!(shrink_factor(true, [3024, 4032], 640), 4);
        assert_eq!(shrink_factor(true, [5120, 2880], 640), 8);
        assert_eq!(shrink_factor(true, [1280, 720], 640), 2);
        assert_eq!(shrink_factor(true, [1279, 720], 640), 1);
        assert_eq!(shrink_factor(true, [960, 540], 640), 1);
        assert_eq!(shrink_factor(true, [4032, 3024], 0), 1);
        assert_eq!(shrink_factor(false, [4032, 3024], 640), 1);
    }

    #[test]
    fn the_size_turns_with_the_decoded_pixels() {
        assert_eq!(oriented([4032, 3024], [1008, 756]), [4032, 3024]);
        assert_eq!(oriented([4032, 3024], [756, 1008]), [3024, 4032]);
        assert_eq!(oriented([3001, 3000], [376, 375]), [3001, 3000]);
    }

    /// A gardens-point query scaled up 4× to a 3840×2160 JPEG: decoded at a
    /// quarter of its size for a 640 px frame, it reports its own size and
    /// gives about the frame (and the features) of the whole decode.
    #[test]
    fn a_large_jpeg_decoded_small_gives_the_same_frame() {
        use crate::features::{ExtractConfig, extract};
        use opencv::core::{Size, absdiff, mean, no_array};
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../shared/datasets/gardens-point/day_right/Image100.jpg"
        );
        let small = opencv::imgcodecs::imread(path, opencv::imgcodecs::IMREAD_COLOR).unwrap();
        let mut large = Mat::default();
        opencv::imgproc::resize(
            &small,
            &mut large,
            Size::new(3840, 2160),
            0.0,
            0.0,
            opencv::imgproc::INTER_CUBIC,
        )
        .unwrap();
        let mut jpeg = Vector::<u8>::new();
        let quality = Vector::<i32>::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, 92]);
        opencv::imgcodecs::imencode(".jpg", &large, &mut jpeg, &quality).unwrap();
        let jpeg = jpeg.to_vec();

        let config = ExtractConfig::default();
        let whole = decode(&jpeg, DecodeLimits::default(), 0).unwrap();
        let shrunk = decode(&jpeg, DecodeLimits::default(), config.max_side).unwrap();
        assert_eq!((shrunk.pixels.cols(), shrunk.pixels.rows()), (960, 540));
        assert_eq!((shrunk.width(), shrunk.height()), (3840, 2160));
        assert_eq!((whole.width(), whole.height()), (3840, 2160));

        let frame = |g: &GrayImage| {
            super::super::extract::downscale(&g.pixels, [g.width(), g.height()], config.max_side)
                .unwrap()
        };
        let (a, b) = (frame(&whole), frame(&shrunk));
        assert_eq!(a.size().unwrap(), Size::new(640, 360));
        assert_eq!(b.size().unwrap(), Size::new(640, 360));
        let mut diff = Mat::default();
        absdiff(&a, &b, &mut diff).unwrap();
        let mean_diff = mean(&diff, &no_array()).unwrap()[0];
        assert!(mean_diff < 2.0, "mean difference {mean_diff} grey levels");

        let (fa, fb) = (
            extract(&whole, &config).unwrap(),
            extract(&shrunk, &config).unwrap(),
        );
        let ratio = fb.len() as f64 / fa.len() as f64;
        assert!(
            fa.len() > 300 && (0.9..1.1).contains(&ratio),
            "{} against {}",
            fb.len(),
            fa.len()
        );
    }
}

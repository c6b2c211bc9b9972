//! Grayscale image → SIFT (or RootSIFT) features: keypoints and an `n × 128`
//! descriptor matrix. [`extract`] takes the whole image at once; the tiled,
//! streaming form in [`super::tiles`] uses the same [`Frame`] and detector.

use super::{DecodeLimits, ExtractConfig, FeatureError, GrayImage, decode_file};
use crate::geometry::Keypoint;
use ndarray::Array2;
use opencv::core::{KeyPoint, Mat, Ptr, Rect, Size, Vector, no_array};
use opencv::features2d::SIFT;
use opencv::prelude::*;
use std::time::{Duration, Instant};

/// One row per keypoint, 128 columns.
pub type Descriptors = Array2<f32>;

/// An image's features: keypoint i is described by descriptor row i.
#[derive(Debug, Clone)]
pub struct Features {
    pub keypoints: Vec<Keypoint>,
    pub descriptors: Descriptors,
}

impl Features {
    pub fn empty() -> Self {
        Self {
            keypoints: Vec::new(),
            descriptors: Array2::zeros((0, 128)),
        }
    }

    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}

/// The image as SIFT sees it: downscaled so its longer side is at most
/// `max_side`, with a SIFT detector built from the configuration.
pub struct Frame {
    mat: Mat,
    sift: Ptr<SIFT>,
    /// A second detector, for a region extracted on a second thread
    /// ([`Frame::detect_two`]); made on first use.
    second: Option<Ptr<SIFT>>,
    sift_config: super::SiftParams,
    rootsift: bool,
}

impl Frame {
    /// Downscale `image` and prepare the detector. `max_features` overrides
    /// the configured cap (a tile keeps its share of the image's cap).
    pub fn new(image: &GrayImage, config: &ExtractConfig) -> Result<Self, FeatureError> {
        let mat = downscale(
            &image.pixels,
            [image.width(), image.height()],
            config.max_side,
        )?;
        Ok(Self {
            mat,
            sift: detector(&config.sift)?,
            second: None,
            sift_config: config.sift.clone(),
            rootsift: config.rootsift,
        })
    }

    /// FAST corners counted in each of `cores` (frame coordinates), a guess
    /// of where the keypoints are (`src/features/corners.rs`).
    pub fn corners_per_core(
        &self,
        cores: &[(u32, u32, u32, u32)],
    ) -> Result<Vec<f32>, FeatureError> {
        super::corners::corners_per_core(&self.mat, cores)
    }

    /// The extraction frame's pixels and the configured detector, for
    /// measuring OpenCV's SIFT itself (`examples/sift_split.rs`).
    pub fn parts(&mut self) -> (&Mat, &mut Ptr<SIFT>) {
        (&self.mat, &mut self.sift)
    }

    /// The extraction frame's pixels.
    pub(super) fn pixels(&self) -> &Mat {
        &self.mat
    }

    /// Keypoints the whole frame may keep (0 = all).
    pub(super) fn max_features(&self) -> usize {
        self.sift_config.max_features as usize
    }

    /// Width and height of the extraction frame.
    pub fn size(&self) -> (u32, u32) {
        frame_size(&self.mat)
    }

    /// Detect and describe inside `r.region` (x, y, width, height, clipped
    /// to the frame), keeping only keypoints whose centre lies in `r.core`
    /// (frame coordinates, half-open). Keypoints come back in frame
    /// coordinates, strongest first, at most `r.cap` of them (0 = all).
    pub fn detect(&mut self, r: Region) -> Result<Features, FeatureError> {
        detect_in(&self.mat, &mut self.sift, self.rootsift, r)
    }

    /// [`Frame::detect`] of two regions at once, `b`'s on a second thread
    /// with a detector of its own: the same features as one after the
    /// other, each with the time its own extraction took, or its own error.
    pub fn detect_two(&mut self, a: Region, b: Region) -> [Result<Timed, FeatureError>; 2] {
        if self.second.is_none() {
            match detector(&self.sift_config) {
                Ok(d) => self.second = Some(d),
                Err(e) => return [self.detect_timed(a), Err(e)],
            }
        }
        let Self {
            mat,
            sift,
            second: Some(second),
            rootsift,
            ..
        } = self
        else {
            unreachable!("made above")
        };
        let (mat, rootsift) = (&*mat, *rootsift);
        let timed = |sift: &mut Ptr<SIFT>, r: Region| {
            let t = Instant::now();
            detect_in(mat, sift, rootsift, r).map(|f| (f, t.elapsed()))
        };
        let (first, other) = std::thread::scope(|s| {
            let other = s.spawn(|| timed(second, b));
            (timed(sift, a), other.join())
        });
        let other = other.unwrap_or_else(|_| {
            Err(FeatureError::OpenCv(
                "the second extraction thread failed".into(),
            ))
        });
        [first, other]
    }

    /// [`Frame::detect`] of one region, with the time it took.
    fn detect_timed(&mut self, r: Region) -> Result<Timed, FeatureError> {
        let t = Instant::now();
        self.detect(r).map(|f| (f, t.elapsed()))
    }

    /// Detect and describe on the whole frame downscaled to half its size:
    /// the keypoints of the coarser scales at about a quarter of the cost,
    /// returned in frame coordinates.
    pub fn detect_halved(&mut self, cap: usize) -> Result<Features, FeatureError> {
        let (fw, fh) = self.size();
        let (hw, hh) = (fw.div_ceil(2), fh.div_ceil(2));
        if hw < 2 || hh < 2 {
            return Ok(Features::empty());
        }
        let mut half = Mat::default();
        opencv::imgproc::resize(
            &self.mat,
            &mut half,
            Size::new(hw as i32, hh as i32),
            0.0,
            0.0,
            opencv::imgproc::INTER_AREA,
        )?;
        let (sx, sy) = (fw as f32 / hw as f32, fh as f32 / hh as f32);
        let place = |k: &KeyPoint| {
            let p = k.pt();
            Some(Keypoint {
                x: (p.x + 0.5) * sx - 0.5,
                y: (p.y + 0.5) * sy - 0.5,
                size: k.size() * sx,
                angle: k.angle(),
                response: k.response(),
            })
        };
        describe(&mut self.sift, &half, place, cap, self.rootsift)
    }
}

/// Features with the time their extraction took.
pub type Timed = (Features, Duration);

/// One region to extract: the pixels SIFT sees, the core whose keypoints
/// are kept, and how many of them at most.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    pub region: (u32, u32, u32, u32),
    pub core: (u32, u32, u32, u32),
    pub cap: usize,
}

/// A SIFT detector with the configured parameters.
fn detector(p: &super::SiftParams) -> Result<Ptr<SIFT>, FeatureError> {
    Ok(SIFT::create(
        0,
        p.octave_layers as i32,
        p.contrast_threshold,
        p.edge_threshold,
        p.sigma,
    )?)
}

/// Width and height of a frame.
fn frame_size(mat: &Mat) -> (u32, u32) {
    (mat.cols().max(0) as u32, mat.rows().max(0) as u32)
}

/// [`Frame::detect`] on `mat` with the detector `sift`.
fn detect_in(
    mat: &Mat,
    sift: &mut Ptr<SIFT>,
    rootsift: bool,
    Region { region, core, cap }: Region,
) -> Result<Features, FeatureError> {
    let (fw, fh) = frame_size(mat);
    let x0 = region.0.min(fw);
    let y0 = region.1.min(fh);
    let w = region.2.min(fw - x0);
    let h = region.3.min(fh - y0);
    if w < 2 || h < 2 {
        return Ok(Features::empty());
    }
    let whole = (x0, y0, w, h) == (0, 0, fw, fh);
    let roi = match whole {
        true => None,
        false => {
            Some(Mat::roi(mat, Rect::new(x0 as i32, y0 as i32, w as i32, h as i32))?.try_clone()?)
        }
    };
    let (cx0, cy0) = (core.0 as f32, core.1 as f32);
    let (cx1, cy1) = (cx0 + core.2 as f32, cy0 + core.3 as f32);
    let place = |k: &KeyPoint| {
        let p = k.pt();
        let kp = Keypoint {
            x: p.x + x0 as f32,
            y: p.y + y0 as f32,
            size: k.size(),
            angle: k.angle(),
            response: k.response(),
        };
        let inside = kp.x >= cx0 && kp.x < cx1 && kp.y >= cy0 && kp.y < cy1;
        inside.then_some(kp)
    };
    let input = roi.as_ref().unwrap_or(mat);
    describe(sift, input, place, cap, rootsift)
}

/// Run the detector on `input`, map each keypoint into the frame with
/// `place` (`None` drops it), keep the `cap` strongest (0 = all) and return
/// them with their descriptors (RootSIFT if asked).
fn describe(
    sift: &mut Ptr<SIFT>,
    input: &Mat,
    place: impl Fn(&KeyPoint) -> Option<Keypoint>,
    cap: usize,
    rootsift: bool,
) -> Result<Features, FeatureError> {
    let mut keypoints = Vector::<KeyPoint>::new();
    let mut raw = Mat::default();
    sift.detect_and_compute(input, &no_array(), &mut keypoints, &mut raw, false)?;
    let rows = raw.rows().max(0) as usize;
    if rows == 0 {
        return Ok(Features::empty());
    }
    let cols = raw.cols() as usize;
    let data: &[f32] = raw.data_typed()?;
    let mut kept: Vec<(Keypoint, usize)> = keypoints
        .iter()
        .take(rows)
        .enumerate()
        .filter_map(|(i, k)| place(&k).map(|kp| (kp, i)))
        .collect();
    // Strongest first (stable, so equal responses keep OpenCV's order),
    // then cap exactly: OpenCV's own cap keeps ties with the weakest.
    kept.sort_by(|a, b| b.0.response.total_cmp(&a.0.response));
    if cap > 0 {
        kept.truncate(cap);
    }
    let mut descriptors = Array2::<f32>::zeros((kept.len(), cols));
    for (mut row, (_, i)) in descriptors.rows_mut().into_iter().zip(&kept) {
        row.assign(&ndarray::ArrayView1::from(&data[i * cols..(i + 1) * cols]));
    }
    if rootsift {
        self::rootsift(&mut descriptors);
    }
    Ok(Features {
        keypoints: kept.into_iter().map(|(k, _)| k).collect(),
        descriptors,
    })
}

/// Extract the features of a whole decoded image.
pub fn extract(image: &GrayImage, config: &ExtractConfig) -> Result<Features, FeatureError> {
    let mut frame = Frame::new(image, config)?;
    let (w, h) = frame.size();
    let all = (0, 0, w, h);
    frame.detect(Region {
        region: all,
        core: all,
        cap: config.sift.max_features as usize,
    })
}

/// Decode a file and extract its features.
pub fn extract_file(
    path: &std::path::Path,
    config: &ExtractConfig,
    limits: DecodeLimits,
) -> Result<Features, FeatureError> {
    extract(&decode_file(path, limits, config.max_side)?, config)
}

/// The frame of an image of `size` (width, height) whose longer side is at
/// most `max_side` (0: unchanged), area-interpolated from `mat`: the image's
/// pixels at that size or decoded smaller ([`super::decode`]). The frame SIFT
/// sees, and the one thumbnails of that size show.
pub(super) fn downscale(mat: &Mat, size: [u32; 2], max_side: u32) -> Result<Mat, FeatureError> {
    let frame = downscale_size(size[0], size[1], max_side)
        .unwrap_or(Size::new(size[0] as i32, size[1] as i32));
    if mat.size()? == frame {
        return Ok(mat.clone());
    }
    let mut out = Mat::default();
    opencv::imgproc::resize(mat, &mut out, frame, 0.0, 0.0, opencv::imgproc::INTER_AREA)?;
    Ok(out)
}

fn downscale_size(w: u32, h: u32, max_side: u32) -> Option<Size> {
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

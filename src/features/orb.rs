//! ORB at the extraction edge, for the ORB pass ([`crate::orb_pass`]):
//! keypoint centres and 256-bit descriptors of the extraction frame, either
//! ORB's own strongest corners or corners spread over a grid of cells.

use super::{FeatureError, Frame};
use crate::orb_pass::OrbImage;
use crate::orb_pass::params::check_keypoints;
use crate::vocabulary::binary::from_rows;
use opencv::core::{KeyPoint, Mat, Ptr, Vector, no_array};
use opencv::features2d::{ORB, ORB_ScoreType};
use opencv::prelude::*;

/// Pixels along the border where ORB finds no keypoints (its edge
/// threshold, and the patch its descriptor reads).
const EDGE: i32 = 31;

/// An ORB detector: the keypoints it keeps, and the cells they are spread
/// over (`None`: ORB's own strongest corners, wherever they are).
pub struct OrbDetector {
    orb: Ptr<ORB>,
    keypoints: usize,
    grid: Option<(usize, usize)>,
}

impl OrbDetector {
    /// At most `keypoints` corners. With a grid of `cols`×`rows` cells, ORB
    /// detects four times as many and the strongest of each cell are kept,
    /// an equal share each, so the keypoints cover the frame.
    pub fn new(keypoints: usize, grid: Option<(usize, usize)>) -> Result<Self, FeatureError> {
        check_keypoints(keypoints, grid).map_err(FeatureError::OpenCv)?;
        let features = keypoints * if grid.is_some() { 4 } else { 1 };
        let orb = ORB::create(
            features as i32,
            1.2,
            8,
            EDGE,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            20,
        )?;
        Ok(Self {
            orb,
            keypoints,
            grid,
        })
    }

    /// ORB of the extraction frame.
    pub fn detect(&mut self, frame: &Frame) -> Result<OrbImage, FeatureError> {
        let mat = frame.pixels();
        // no keypoint lies within EDGE pixels of the border, and OpenCV's
        // ORB fails on a frame too small to scale down (one pixel)
        if mat.cols().min(mat.rows()) <= 2 * EDGE {
            return Ok(OrbImage::default());
        }
        let (mut keys, mut raw) = (Vector::<KeyPoint>::new(), Mat::default());
        match self.grid {
            None => self
                .orb
                .detect_and_compute(mat, &no_array(), &mut keys, &mut raw, false)?,
            Some((cols, rows)) => {
                let mut all = Vector::<KeyPoint>::new();
                self.orb.detect(mat, &mut all, &no_array())?;
                let share = self.keypoints / (cols * rows);
                keys = spread(
                    &all,
                    cols,
                    rows,
                    share,
                    mat.cols() as f32,
                    mat.rows() as f32,
                );
                self.orb.compute(mat, &mut keys, &mut raw)?;
            }
        }
        let descriptors = if raw.empty() {
            Vec::new()
        } else {
            from_rows(raw.data_bytes()?)
        };
        Ok(OrbImage {
            centres: keys.iter().map(|k| [k.pt().x, k.pt().y]).collect(),
            descriptors,
        })
    }
}

/// The `share` strongest keypoints of each of `cols`×`rows` cells of a
/// `w`×`h` frame.
fn spread(
    all: &Vector<KeyPoint>,
    cols: usize,
    rows: usize,
    share: usize,
    w: f32,
    h: f32,
) -> Vector<KeyPoint> {
    let mut cells: Vec<Vec<KeyPoint>> = vec![Vec::new(); cols * rows];
    for k in all.iter() {
        let c = ((k.pt().x / w * cols as f32) as usize).min(cols - 1);
        let r = ((k.pt().y / h * rows as f32) as usize).min(rows - 1);
        cells[r * cols + c].push(k);
    }
    let mut kept = Vector::<KeyPoint>::new();
    for mut cell in cells {
        cell.sort_by(|a, b| b.response().total_cmp(&a.response()));
        cell.into_iter().take(share).for_each(|k| kept.push(k));
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{DecodeLimits, ExtractConfig, decode, warm_up_image};

    #[test]
    fn keypoints_and_descriptors_come_in_pairs_inside_the_frame() {
        let config = ExtractConfig::default();
        let bytes = warm_up_image(&config, DecodeLimits::default().max_pixels).unwrap();
        let image = decode(&bytes, DecodeLimits::default(), config.max_side).unwrap();
        for (keypoints, grid) in [
            (1000, None),
            (1000, Some((4, 3))),
            (300, None),
            (300, Some((4, 3))),
        ] {
            let frame = Frame::new(&image, &config).unwrap();
            let (w, h) = frame.size();
            let orb = OrbDetector::new(keypoints, grid)
                .unwrap()
                .detect(&frame)
                .unwrap();
            assert!(!orb.centres.is_empty(), "{grid:?}: no ORB keypoints");
            assert!(orb.centres.len() <= keypoints, "{keypoints} {grid:?}");
            assert_eq!(orb.centres.len(), orb.descriptors.len());
            assert!(
                orb.centres
                    .iter()
                    .all(|&[x, y]| (0.0..w as f32).contains(&x) && (0.0..h as f32).contains(&y))
            );
        }
        assert!(OrbDetector::new(1000, Some((0, 3))).is_err());
        assert!(OrbDetector::new(10, Some((4, 3))).is_err());
        assert!(OrbDetector::new(0, None).is_err());
    }

    /// The frame of a `w`×`h` image, uniform grey or noise.
    fn frame_of(w: i32, h: i32, noise: bool) -> Frame {
        let config = ExtractConfig::default();
        let mut m = Mat::new_rows_cols_with_default(
            h,
            w,
            opencv::core::CV_8UC1,
            opencv::core::Scalar::all(128.0),
        )
        .unwrap();
        if noise {
            let (lo, hi) = (
                Mat::from_slice(&[0.0]).unwrap(),
                Mat::from_slice(&[255.0]).unwrap(),
            );
            opencv::core::randu(&mut m, &lo, &hi).unwrap();
        }
        let mut png = Vector::<u8>::new();
        opencv::imgcodecs::imencode(".png", &m, &mut png, &Vector::new()).unwrap();
        let image = decode(png.as_slice(), DecodeLimits::default(), config.max_side).unwrap();
        Frame::new(&image, &config).unwrap()
    }

    #[test]
    fn a_blank_frame_has_no_keypoints() {
        let orb = OrbDetector::new(1000, None)
            .unwrap()
            .detect(&frame_of(64, 48, false))
            .unwrap();
        assert_eq!(orb, OrbImage::default());
    }

    #[test]
    fn a_frame_too_small_for_orb_has_no_keypoints_not_an_error() {
        for (w, h) in [(1, 1), (8, 8), (200, 62), (62, 200)] {
            for grid in [None, Some((4, 3))] {
                let orb = OrbDetector::new(1000, grid)
                    .unwrap()
                    .detect(&frame_of(w, h, true))
                    .unwrap();
                assert_eq!(orb, OrbImage::default(), "{w}x{h} {grid:?}");
            }
        }
        // just past the border's width, noise has corners
        let orb = OrbDetector::new(1000, None)
            .unwrap()
            .detect(&frame_of(96, 96, true))
            .unwrap();
        assert!(!orb.centres.is_empty());
    }
}

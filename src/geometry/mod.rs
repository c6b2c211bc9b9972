//! Image geometry as plain numbers: where a feature sits in its image. The
//! extraction edge fills these from OpenCV's keypoints; the map stores them
//! per image feature ([`packed`]), and verification matches them between a
//! query and a candidate ([`matches`](mod@matches), [`verify`]); [`ratio_matches`] is the
//! descriptor-matching alternative the examples measure; [`relative_scale`] reads from
//! the matched points how much larger a map image sees the scene. No OpenCV types here: the
//! robust model fit is the trait [`verify::ModelFit`], implemented in
//! `features::fit`.

pub mod matches;
pub mod packed;
pub mod ratio_matches;
pub mod relative_scale;
pub mod verify;

/// A feature's keypoint in the extraction frame (the downscaled image the
/// descriptors were computed on): centre, size and orientation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Keypoint {
    /// Centre, in pixels of the extraction frame.
    pub x: f32,
    pub y: f32,
    /// Diameter of the described region, in pixels.
    pub size: f32,
    /// Orientation in degrees, [0, 360).
    pub angle: f32,
    /// Detector response (contrast): larger is stronger.
    pub response: f32,
}

//! The image edge of the pipeline (decode → extract): bytes in, SIFT
//! keypoints and descriptors out (an `ndarray` matrix), and ORB's for the
//! ORB pass ([`orb`]). This is the only module that touches OpenCV; everything downstream works on plain arrays.

mod buffers;
mod coarse_choice;
mod config;
mod corners;
mod decode;
mod extract;
pub mod fit;
pub mod orb;
mod thumbnail;
mod tiles;
mod warm;

pub use buffers::{Buffers, KEEP_BUFFERS_VAR, keep_image_buffers};
pub use coarse_choice::{CoarseChoice, Learned};
pub use config::{ExtractConfig, SiftParams};
pub use decode::{DecodeLimits, GrayImage, SUPPORTED_FORMATS, decode, decode_file, probe};
pub use extract::{Descriptors, Features, Frame, Region, Timed, extract, extract_file};
pub use thumbnail::thumbnail;
pub use tiles::{TileGrid, TilePlan, Tiles, TilesAhead};
pub use warm::warm_up_image;

/// Why an image yielded no descriptors.
#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    #[error("the image is empty (0 bytes)")]
    Empty,
    #[error("not a decodable image ({0})")]
    Undecodable(String),
    #[error("{0} images are not supported; send {SUPPORTED_FORMATS}")]
    Unsupported(String),
    #[error("image of {width}×{height} pixels exceeds the limit of {limit} pixels")]
    TooLarge { width: u64, height: u64, limit: u64 },
    /// (The I/O error is in the message only, as in [`crate::store::StoreError::Io`].)
    #[error("{path}: {cause}")]
    Read {
        path: std::path::PathBuf,
        cause: std::io::Error,
    },
    #[error("feature extraction failed: {0}")]
    OpenCv(String),
}

impl From<opencv::Error> for FeatureError {
    fn from(e: opencv::Error) -> Self {
        Self::OpenCv(e.message)
    }
}

/// Number of threads OpenCV may use inside one call. Batch jobs that already
/// run one image per core set this to 1 to avoid oversubscription.
pub fn set_opencv_threads(threads: usize) {
    // Failure only means OpenCV was built without a thread pool.
    let _ = opencv::core::set_num_threads(threads as i32);
}

//! The ORB pass: a cheap first look at a query before SIFT. ORB's binary
//! descriptors (made at the extraction edge, `features::orb`) are turned
//! into binary words ([`crate::vocabulary::binary`]) and voted over the map
//! images by tf-idf ([`index`]); the best-voted candidates are verified by a
//! similarity on word pairs ([`index::OrbIndex::check`]); and a [`Setting`]
//! says from what that check found whether the pass answers, and with which
//! candidate ([`pick`]). A query the pass does not answer goes on to the
//! SIFT search. The map's ORB side is kept beside the map ([`file`](mod@file)); the
//! service's settings are [`params`](mod@params). Plain arrays only: the
//! model fit is the trait [`crate::geometry::verify::ModelFit`].
//!
//! Measured in `examples/orb_pass.rs` (docs/performance.md, "An ORB pass
//! before SIFT").

pub mod file;
pub mod index;
pub mod params;
pub mod pick;

pub use file::{OrbSide, OrbSideMeta};
pub use index::{Checked, OrbImage, OrbIndex};
pub use params::{FIT, OrbPassParams};
pub use pick::{PLACE_APART, Pick, Setting, answer};

/// ORB keypoints a query or map image keeps by default
/// (`orb_pass.keypoints`).
pub const ORB_KEYPOINTS: usize = 2000;

/// The most ORB keypoints `orb_pass.keypoints` may ask for.
pub const MAX_ORB_KEYPOINTS: usize = 20_000;

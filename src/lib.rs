//! bowloc: visual place recognition by bag-of-words search with early stopping.
//!
//! A query image runs through the pipeline
//! **decode → extract → permute → quantize → vote → stop → rank**, and the
//! crate's layout follows it:
//!
//! - [`features`] — decode and extract: image bytes to SIFT/RootSIFT
//!   descriptors. The only module that touches OpenCV.
//! - [`search`] — permute, vote, stop and rank: the early-stopping search over
//!   plain arrays, with the stopping rules in [`search::stop`]; the same
//!   search over a map split into shards in [`search::shard`].
//! - [`quantize`] — descriptor → nearest visual word, batched through a
//!   matrix multiply.
//! - [`vocabulary`] — the visual words (k-means centroids) and their training,
//!   the Hamming embedding that signs each feature within its word, and
//!   binary words for binary (ORB) descriptors.
//! - [`geometry`] — keypoints as plain numbers (position, size, angle), the
//!   word pairs between a query and a map image, and the verification that
//!   re-ranks candidates by inliers (its model fit is OpenCV's, behind a
//!   trait implemented in [`features`]).
//! - [`index`] — the map: a tf-idf inverted index over the map's images, and
//!   each map feature's word, keypoint and signature.
//! - [`orb_pass`] — a cheap first look before SIFT: ORB's binary words voted
//!   over the map's ORB side, the best candidates verified by a similarity,
//!   and the setting that says whether that answers the query; the map's
//!   ORB side on disk. Run by the service when `[orb_pass]` enables it
//!   ([`pipeline::orb_pass`]), measured in `examples/orb_pass.rs`.
//! - [`live`] — live maps: images added and removed while serving, a
//!   durable change log beside the map file, compaction into a new file.
//! - [`store`] — the memory-mapped, checksummed file format both are kept in.
//! - [`dataset`] — the shared dataset layout (image lists, ground truth).
//! - [`pipeline`] — glue used by every front end: extraction over image lists
//!   ([`pipeline::extract`]), building vocabularies and maps
//!   ([`pipeline::build`]), answering one query ([`pipeline::localizer`]).
//! - [`sequence`] — frames of one moving camera localized together: the
//!   map's topology, the motion model and the Bayes filter over map images
//!   whose prediction is each frame's prior.
//! - [`calibrate`] — choosing a rule's parameter for a map without ground
//!   truth, from pseudo-queries made of the map's own images.
//! - [`report`] — the answer to a query as users see it (JSON).
//! - [`eval`] — the paper's evaluation on a dataset: descriptor cache, sweep
//!   of rules × parameters × random orders, metrics (precision/recall
//!   definitions), tables and plots. Drives the search on pre-quantized words.
//! - [`server`] — the HTTP service (`bowloc serve`): routes, configuration,
//!   bounded worker pool, metrics, OpenAPI document, protobuf answers.
//!
//! The algorithmic core (`quantize`, `vocabulary`, `index`, `search`,
//! `geometry`, `orb_pass`, `sequence`) has no OpenCV or HTTP types; front ends (`cli`,
//! `server`) live at the edges.

/// A setting chosen by name from a fixed list (a tile order, a
/// verification model, …): the list, each entry's name and a line of help
/// are the type's own, and every front end (configuration, CLI, HTTP
/// parameters, error messages) reads them from here.
pub trait Choice: Copy + Send + Sync + 'static {
    /// Every choice, the default first.
    const ALL: &'static [Self];
    /// Its name in files, flags and answers.
    fn name(self) -> &'static str;
    /// What it does, in a line (help texts).
    fn about(self) -> &'static str;
    /// The choice of that name.
    fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|c| c.name() == name)
    }
}

/// [`Choice`] from a type's own `ALL`, `name` and `about`, and `Display` and
/// `FromStr` by those names, so the accepted names and the error listing
/// them come from one place.
macro_rules! named_choice {
    ($t:ty, $what:literal) => {
        impl $crate::Choice for $t {
            const ALL: &'static [Self] = &<$t>::ALL;
            fn name(self) -> &'static str {
                <$t>::name(self)
            }
            fn about(self) -> &'static str {
                <$t>::about(self)
            }
        }

        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                <Self as $crate::Choice>::from_name(s).ok_or_else(|| {
                    let names: Vec<&str> = Self::ALL.iter().map(|c| c.name()).collect();
                    format!("unknown {} `{s}`; use one of {}", $what, names.join(", "))
                })
            }
        }
    };
}

pub mod calibrate;
pub mod dataset;
pub mod eval;
pub mod features;
pub mod geometry;
pub mod index;
pub mod live;
pub mod orb_pass;
pub mod pipeline;
pub mod quantize;
pub mod report;
pub mod search;
pub mod sequence;
pub mod server;
pub mod store;
pub mod vocabulary;

//! The glue every front end shares, one step of the pipeline per file:
//! [`extract`] reads image lists into features (timed tile by tile),
//! [`build`] trains vocabularies and indexes maps from them, and
//! [`localizer`] answers one query (decode → extract → search → verify →
//! report), after the ORB pass's first look when the map has its ORB side
//! ([`orb_pass`](mod@orb_pass)).

pub mod build;
pub mod extract;
pub mod localizer;
pub mod orb_pass;

pub use build::{
    build_map, build_vocabulary, code, index_descriptors, map_image_words, quantize_all,
    train_vocabulary, words_per_image,
};
pub use extract::{
    Extracted, TileCost, extract_all, extract_all_timed, extract_all_together, extract_interleaved,
    extract_tiled, stack,
};
pub use localizer::{Localizer, Plan, TRACE_POINTS, Tracing};
pub use orb_pass::{OrbPass, build_orb_side, orb_side_of};

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:>24} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_owned());
    bar
}

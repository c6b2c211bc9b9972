//! Compaction: fold a snapshot (map file plus changes) into a new map built
//! from scratch over the images then in the map, in id order — the file's
//! remaining images, then the added ones. idf and every image's weights are
//! recomputed, so the folded map equals a map built directly from the same
//! images ([`MapBuilder`]).
//!
//! The file's images are rebuilt from their stored features (word and
//! keypoint). A map file without stored features (a synthetic one) gives
//! its images' words recovered from the postings
//! ([`MapIndex::image_words`]): words present in every one of its images
//! are lost there, as they weigh nothing.

use super::snapshot::Snapshot;
use crate::index::{ImageWords, MapBuilder, MapIndex, MapRead, Places};

/// The images of `snapshot`, in id order, as a builder would take them, with
/// their places and poses.
pub fn images_of(snapshot: &Snapshot) -> (Vec<ImageWords>, Places) {
    let base = snapshot.base();
    let meta = snapshot.meta();
    let with_geometry = base.view().geometry.len() as u64 == base.meta().features;
    let recovered = (!with_geometry).then(|| base.image_words());
    let mut places = Places {
        pose_fields: meta.pose_fields.clone(),
        ..Places::default()
    };
    let fields = meta.pose_fields.len();
    let mut images = Vec::with_capacity(snapshot.len());
    for id in snapshot.ids() {
        let info = snapshot.image(id);
        let image = match (snapshot.added(id), &recovered) {
            (Some(a), _) => a.image.clone(),
            (None, Some(words)) => ImageWords::from_words(info.name, &words[id as usize]),
            (None, None) => {
                let geometry = base.geometry(id).to_vec();
                let words: Vec<u32> = geometry.iter().map(|f| f.word).collect();
                ImageWords {
                    geometry,
                    ..ImageWords::from_words(info.name, &words)
                }
            }
        };
        let pose: Vec<f64> = meta
            .pose_fields
            .iter()
            .map(|f| {
                info.pose
                    .as_ref()
                    .and_then(|p| p.get(f.as_str()).copied())
                    .unwrap_or(f64::NAN)
            })
            .collect();
        debug_assert_eq!(pose.len(), fields);
        places.rows.insert(
            info.name.to_owned(),
            (info.place.unwrap_or("").to_owned(), pose),
        );
        images.push(image);
    }
    (images, places)
}

/// The map of `snapshot`'s images built from scratch, at its generation.
pub fn fold(snapshot: &Snapshot) -> MapIndex {
    let (images, places) = images_of(snapshot);
    let meta = snapshot.meta();
    let mut builder = MapBuilder::new(meta.words);
    for image in images {
        builder.add(image);
    }
    builder
        .build(&meta.name, &meta.vocab_hash, Some(&places))
        .with_generation(snapshot.generation())
}

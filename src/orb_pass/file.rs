//! The map's ORB side on disk (`MAP.orbpass` beside the map): its binary
//! vocabulary and each map image's ORB keypoint centres and descriptors, in
//! the checksummed, memory-mapped container ([`crate::store`]), with the
//! identity of the map it was built for. The inverted index is rebuilt on
//! open ([`super::OrbIndex::build`]: a few milliseconds per thousand images).

use super::OrbImage;
use crate::index::MapMeta;
use crate::store::{Store, StoreError, StoreWriter};
use crate::vocabulary::binary::{BinaryDescriptor, BinaryVocabulary, from_rows};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const MAGIC: [u8; 8] = *b"BOWLOCOR";
const VERSION: u32 = 1;

/// Where a map's ORB side is kept by default: `MAP.orbpass` beside it.
pub fn path_beside(map: &Path) -> PathBuf {
    map.with_extension("orbpass")
}

/// Which map an ORB side was built for, and how.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OrbSideMeta {
    /// The map's name, images, features, vocabulary and generation
    /// ([`MapMeta`]): the side answers for that map only.
    pub map_name: String,
    pub map_images: usize,
    pub map_features: u64,
    pub map_vocabulary: String,
    pub map_generation: u64,
    /// Binary words of its vocabulary, and the seed they were drawn with.
    pub words: usize,
    pub seed: u64,
    /// ORB keypoints kept per image (a side written before it was recorded
    /// kept 1000), and the cells they were spread over (`None`: ORB's own
    /// strongest corners); queries are detected the same way.
    #[serde(default = "keypoints_before_recorded")]
    pub keypoints: usize,
    pub grid: Option<(usize, usize)>,
}

/// The ORB keypoints every side kept before the side recorded how many.
fn keypoints_before_recorded() -> usize {
    1000
}

impl OrbSideMeta {
    /// The identity of `map` with how the side was built.
    pub fn for_map(
        map: &MapMeta,
        words: usize,
        seed: u64,
        keypoints: usize,
        grid: Option<(usize, usize)>,
    ) -> Self {
        Self {
            map_name: map.name.clone(),
            map_images: map.images,
            map_features: map.features,
            map_vocabulary: map.vocab_hash.clone(),
            map_generation: map.generation,
            words,
            seed,
            keypoints,
            grid,
        }
    }

    /// Whether the side was built for `map` (as loaded, before changes).
    pub fn matches(&self, map: &MapMeta) -> bool {
        self.map_name == map.name
            && self.map_images == map.images
            && self.map_features == map.features
            && self.map_vocabulary == map.vocab_hash
            && self.map_generation == map.generation
    }
}

/// A map's ORB side: its vocabulary and every map image's ORB, in map
/// order.
#[derive(Debug, Clone, PartialEq)]
pub struct OrbSide {
    pub meta: OrbSideMeta,
    pub vocabulary: BinaryVocabulary,
    pub images: Vec<OrbImage>,
}

fn as_bytes(ds: &[BinaryDescriptor]) -> Vec<u8> {
    ds.iter().flatten().flat_map(|w| w.to_le_bytes()).collect()
}

impl OrbSide {
    /// Write the side to `path` (atomically).
    pub fn save(&self, path: &Path) -> Result<(), StoreError> {
        let mut offsets = vec![0u64];
        for m in &self.images {
            offsets.push(offsets.last().copied().unwrap_or(0) + m.centres.len() as u64);
        }
        let centres: Vec<f32> = self
            .images
            .iter()
            .flat_map(|m| m.centres.iter().flatten().copied())
            .collect();
        let descriptors: Vec<BinaryDescriptor> = self
            .images
            .iter()
            .flat_map(|m| m.descriptors.iter().copied())
            .collect();
        StoreWriter::new(MAGIC, VERSION)
            .json("meta", &self.meta)
            .owned_bytes("words", as_bytes(self.vocabulary.words()))
            .u64s("offsets", &offsets)
            .f32s("centres", &centres)
            .owned_bytes("descriptors", as_bytes(&descriptors))
            .write_atomic(path)?;
        Ok(())
    }

    /// Read a side written by [`OrbSide::save`], checking its arrays agree
    /// (and its checksums).
    pub fn open(path: &Path) -> Result<Self, StoreError> {
        let store = Store::open(path, MAGIC, "ORB side", VERSION, true)?;
        let meta: OrbSideMeta = store.json("meta")?;
        let words = from_rows(store.bytes("words")?);
        let offsets = store.u64s("offsets")?;
        let centres = store.f32s("centres")?;
        let descriptors = from_rows(store.bytes("descriptors")?);
        let features = descriptors.len();
        if words.len() != meta.words
            || offsets.len() != meta.map_images + 1
            || offsets.first() != Some(&0)
            || offsets.last() != Some(&(features as u64))
            || offsets.windows(2).any(|w| w[0] > w[1])
            || centres.len() != 2 * features
        {
            return Err(store.invalid(format!(
                "{} words, {} offsets, {} centres and {features} descriptors do not make {} words and {} images",
                words.len(),
                offsets.len(),
                centres.len(),
                meta.words,
                meta.map_images
            )));
        }
        let images = offsets
            .windows(2)
            .map(|w| {
                let (a, b) = (w[0] as usize, w[1] as usize);
                OrbImage {
                    centres: centres[2 * a..2 * b]
                        .chunks_exact(2)
                        .map(|p| [p[0], p[1]])
                        .collect(),
                    descriptors: descriptors[a..b].to_vec(),
                }
            })
            .collect();
        Ok(Self {
            meta,
            vocabulary: BinaryVocabulary::from_words(words),
            images,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn side() -> OrbSide {
        let d = |x: u64| [x, !x, x.rotate_left(9), 7];
        let map = MapMeta {
            name: "corridor".into(),
            images: 3,
            features: 120,
            vocab_hash: "abc".into(),
            ..MapMeta::default()
        };
        OrbSide {
            meta: OrbSideMeta::for_map(&map, 2, 5, 40, None),
            vocabulary: BinaryVocabulary::from_words(vec![d(1), d(2)]),
            images: vec![
                OrbImage {
                    centres: vec![[1.0, 2.0], [3.5, 4.0]],
                    descriptors: vec![d(10), d(11)],
                },
                OrbImage::default(),
                OrbImage {
                    centres: vec![[9.0, 8.0]],
                    descriptors: vec![d(u64::MAX)],
                },
            ],
        }
    }

    #[test]
    fn a_side_reads_back_as_written_and_knows_its_map() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.orbpass");
        let side = side();
        side.save(&path).unwrap();
        let read = OrbSide::open(&path).unwrap();
        assert_eq!(read, side);
        let mut map = MapMeta {
            name: "corridor".into(),
            images: 3,
            features: 120,
            vocab_hash: "abc".into(),
            ..MapMeta::default()
        };
        assert!(read.meta.matches(&map));
        map.generation = 1;
        assert!(!read.meta.matches(&map));
        assert_eq!(
            path_beside(Path::new("data/x/map.bowmap")),
            Path::new("data/x/map.orbpass")
        );
    }

    #[test]
    fn a_side_written_before_it_recorded_its_keypoints_kept_1000() {
        let mut meta = serde_json::to_value(side().meta).unwrap();
        meta.as_object_mut().unwrap().remove("keypoints");
        let read: OrbSideMeta = serde_json::from_value(meta).unwrap();
        assert_eq!(read.keypoints, 1000);
        assert_eq!(read.grid, None);
    }

    #[test]
    fn a_damaged_or_foreign_file_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.orbpass");
        side().save(&path).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        std::fs::write(&path, &bytes).unwrap();
        assert!(OrbSide::open(&path).is_err());
        std::fs::write(&path, b"not a bowloc file at all, not at all").unwrap();
        let e = OrbSide::open(&path).unwrap_err().to_string();
        assert!(e.contains("not a bowloc ORB side file"), "{e}");
    }
}

//! The map file: JSON `meta` plus the arrays of [`MapArrays`] as sections.
//! Structure is checked on open (sizes, offsets, string tables); contents are
//! covered by the section checksums.

use super::{Backing, MapIndex, MapView, Postings, metadata::StrTable};
use crate::store::{Store, StoreError, StoreWriter};
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: [u8; 8] = *b"BOWLOCMA";
/// 2: per-image geometry (`geometry.offsets`, `geometry.features`).
/// 3: each stored feature carries its Hamming signature (20 bytes).
const VERSION: u32 = 3;

/// What a map is.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MapMeta {
    pub name: String,
    pub images: usize,
    pub words: usize,
    /// Total (word, image) entries.
    pub postings: usize,
    /// `hash_hex()` of the vocabulary the map was built with.
    pub vocab_hash: String,
    /// Names of the pose columns (may be empty).
    pub pose_fields: Vec<String>,
    /// Features over all map images.
    pub features: u64,
    pub images_without_features: usize,
    /// The change log's generation this file includes: 0 for a map built
    /// from images, the generation it was folded at for a compacted one
    /// (`crate::live`).
    #[serde(default)]
    pub generation: u64,
    /// When a compaction wrote this file, in milliseconds since the Unix
    /// epoch (`None` for a map built from images).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compacted_at_ms: Option<u64>,
}

pub(super) fn save(map: &MapIndex, path: &Path) -> Result<(), StoreError> {
    let v = map.view();
    let (offsets, images, weights) = v.postings.raw();
    StoreWriter::new(MAGIC, VERSION)
        .json("meta", &map.meta)
        .f32s("idf", v.idf)
        .u64s("postings.offsets", offsets)
        .u32s("postings.images", images)
        .f32s("postings.weights", weights)
        .f32s("image_max", v.image_max)
        .u64s("names.offsets", v.names.offsets)
        .bytes("names.bytes", v.names.bytes)
        .u64s("places.offsets", v.places.offsets)
        .bytes("places.bytes", v.places.bytes)
        .f64s("poses", v.poses)
        .u64s("geometry.offsets", v.geometry_offsets)
        .u32s("geometry.features", bytemuck::cast_slice(v.geometry))
        .write_atomic(path)?;
    Ok(())
}

pub(super) fn view(store: &Store) -> Result<MapView<'_>, StoreError> {
    Ok(MapView {
        idf: store.f32s("idf")?,
        postings: Postings::new(
            store.u64s("postings.offsets")?,
            store.u32s("postings.images")?,
            store.f32s("postings.weights")?,
        ),
        image_max: store.f32s("image_max")?,
        names: StrTable {
            offsets: store.u64s("names.offsets")?,
            bytes: store.bytes("names.bytes")?,
        },
        places: StrTable {
            offsets: store.u64s("places.offsets")?,
            bytes: store.bytes("places.bytes")?,
        },
        poses: store.f64s("poses")?,
        geometry_offsets: store.u64s("geometry.offsets")?,
        geometry: bytemuck::try_cast_slice(store.u32s("geometry.features")?)
            .map_err(|_| store.invalid("geometry.features is not whole features"))?,
        feature_runs: &[],
        overlay: None,
    })
}

pub(super) fn open(path: &Path, verify: bool) -> Result<MapIndex, StoreError> {
    let store = match Store::open(path, MAGIC, "map", VERSION, verify) {
        Err(StoreError::WrongVersion { found, .. }) if found < VERSION => {
            return Err(StoreError::Invalid {
                path: path.to_path_buf(),
                detail: format!(
                    "map format version {found} is older than this build's version {VERSION} \
                     (which stores each feature's keypoint and Hamming signature, for \
                     verification and vote weighing); rebuild the map with \
                     `bowloc map build --vocab VOCAB --images IMAGES --out MAP`"
                ),
            });
        }
        other => other?,
    };
    let meta: MapMeta = store.json("meta")?;
    {
        let v = view(&store)?;
        let (offsets, images, weights) = v.postings.raw();
        let bad = |what: String| Err(store.invalid(what));
        if v.idf.len() != meta.words || offsets.len() != meta.words + 1 {
            return bad(format!(
                "{} idf values and {} offsets for {} words",
                v.idf.len(),
                offsets.len(),
                meta.words
            ));
        }
        if images.len() != weights.len()
            || images.len() != meta.postings
            || offsets.last().copied() != Some(meta.postings as u64)
            || offsets.first().copied() != Some(0)
            || offsets.windows(2).any(|w| w[0] > w[1])
        {
            return bad("postings arrays disagree in length".into());
        }
        if v.image_max.len() != meta.images
            || v.names.len() != meta.images
            || v.places.len() != meta.images
            || v.poses.len() != meta.images * meta.pose_fields.len()
        {
            return bad(format!(
                "per-image arrays do not hold {} images",
                meta.images
            ));
        }
        let g = v.geometry_offsets;
        if g.len() != meta.images + 1
            || g.first().copied() != Some(0)
            || g.last().copied() != Some(v.geometry.len() as u64)
            || g.windows(2).any(|w| w[0] > w[1])
        {
            return bad("geometry offsets disagree with the features stored".into());
        }
        v.names
            .validate()
            .map_err(|e| store.invalid(format!("names: {e}")))?;
        v.places
            .validate()
            .map_err(|e| store.invalid(format!("places: {e}")))?;
    }
    Ok(MapIndex {
        backing: Backing::Mapped(store),
        meta,
        runs: Default::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Keypoint;
    use crate::index::{ImageWords, MapBuilder};

    fn kp(x: f32, y: f32) -> Keypoint {
        Keypoint {
            x,
            y,
            size: 3.0,
            angle: 45.0,
            response: 0.1,
        }
    }

    #[test]
    fn geometry_survives_save_and_open() {
        let mut b = MapBuilder::new(4);
        b.add(ImageWords::with_geometry(
            "a",
            &[3, 1, 1],
            &[],
            &[kp(1.0, 2.0), kp(3.0, 4.0), kp(5.0, 6.0)],
        ));
        b.add(ImageWords::from_words("no features", &[]));
        b.add(ImageWords::with_geometry("c", &[2], &[], &[kp(7.0, 8.0)]));
        let built = b.build("t", "0", None);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.bowmap");
        built.save(&path).unwrap();
        let map = MapIndex::open(&path, true).unwrap();
        let a = map.geometry(0);
        assert_eq!(a.iter().map(|f| f.word).collect::<Vec<_>>(), vec![1, 1, 3]);
        assert_eq!(a[2].point(), [1.0, 2.0]);
        assert!(map.geometry(1).is_empty());
        assert_eq!(map.geometry(2)[0].point(), [7.0, 8.0]);
        assert!(map.geometry(99).is_empty());
    }

    #[test]
    fn an_older_map_is_refused_with_how_to_rebuild_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("old.bowmap");
        StoreWriter::new(MAGIC, 1)
            .json("meta", &MapMeta::default())
            .write_atomic(&path)
            .unwrap();
        let e = MapIndex::open(&path, true).err().unwrap().to_string();
        assert!(e.contains("bowloc map build"), "{e}");
        assert!(e.contains("version 1"), "{e}");
    }
}

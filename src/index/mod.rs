//! The map index: a tf-idf inverted index over the map's images.
//!
//! For map image j with word counts count_j(w) over n_j features:
//! tf_j(w) = count_j(w)/n_j, idf(w) = ln(N_map/df(w)), d_j = tf_j·idf and
//! d̂_j = d_j/‖d_j‖. The postings of word w list (j, d̂_j(w)) for every image
//! holding w, in a flat CSR layout. Per-image metadata (name, place label,
//! pose) rides along, and so does each image's geometry: every feature's word,
//! keypoint and Hamming signature, packed ([`crate::geometry::packed`]), for
//! weighing votes and for verification. Built by [`build`], stored and memory-mapped by `file`.

pub mod build;
mod file;
pub mod metadata;
pub mod overlay;
mod postings;
pub mod synthetic;

pub use build::{ImageWords, MapBuilder};
pub use file::MapMeta;
pub use metadata::{ImageInfo, Places, StringTable};
pub use overlay::Overlay;
pub use postings::Postings;

use crate::geometry::packed::PackedFeature;
use crate::store::{Store, StoreError};

/// A map, memory-mapped from a file or held in memory.
pub struct MapIndex {
    backing: Backing,
    meta: MapMeta,
    /// Built on first use: see [`MapView::feature_runs`].
    runs: std::sync::OnceLock<Vec<[u32; 2]>>,
}

/// The arrays of an in-memory map.
pub struct MapArrays {
    pub idf: Vec<f32>,
    pub offsets: Vec<u64>,
    pub images: Vec<u32>,
    pub weights: Vec<f32>,
    /// max over w of idf(w)·d̂_j(w): the largest share of one feature's vote
    /// image j can receive (times 1/N).
    pub image_max: Vec<f32>,
    pub names: StringTable,
    pub places: StringTable,
    /// `images × pose_fields.len()`, NaN where unknown.
    pub poses: Vec<f64>,
    /// Image j's features are `geometry[geometry_offsets[j]..geometry_offsets[j + 1]]`.
    pub geometry_offsets: Vec<u64>,
    pub geometry: Vec<PackedFeature>,
}

enum Backing {
    Mapped(Store),
    Owned(Box<MapArrays>),
}

/// Borrowed view of every array of a map.
#[derive(Clone, Copy)]
pub struct MapView<'a> {
    pub idf: &'a [f32],
    pub postings: Postings<'a>,
    pub image_max: &'a [f32],
    pub names: metadata::StrTable<'a>,
    pub places: metadata::StrTable<'a>,
    pub poses: &'a [f64],
    pub geometry_offsets: &'a [u64],
    pub geometry: &'a [PackedFeature],
    /// For postings entry e (word w, image j): j's features of word w are
    /// `geometry[start..start + len]`, `[start, len] = feature_runs[e]`. What
    /// a vote weighed by signatures reads; empty where not built (the voter
    /// then searches the image's features).
    pub feature_runs: &'a [[u32; 2]],
    /// Images added and removed since the file was written (none for a
    /// map file on its own).
    pub overlay: Option<&'a Overlay>,
}

/// What a search reads of a map: a map file on its own ([`MapIndex`]) or a
/// map file with changes on top (`crate::live::Snapshot`). Ids are those of
/// [`MapView`]: the file's images, then the added ones.
pub trait MapRead: Send + Sync {
    /// All arrays, borrowed (take it once per query).
    fn view(&self) -> MapView<'_>;
    /// What the map is (for a map with changes: its images now).
    fn meta(&self) -> &MapMeta;
    /// Name, place label and pose of image `id`.
    fn image(&self, id: u32) -> ImageInfo<'_>;
    /// The stored features of image `id`, sorted by word.
    fn geometry(&self, id: u32) -> &[PackedFeature];
    /// Image ids run from 0 to this (a live map's removed ids included: ids
    /// are not reused until a compaction renumbers the images).
    fn id_range(&self) -> usize {
        self.meta().images
    }
    /// Calls `f` with each image's id and position (pose fields `x` and
    /// `y`; NaN where unknown), in id order, without collecting them; false,
    /// and no call, when the map lacks either field.
    fn each_position(&self, f: &mut dyn FnMut(u32, [f64; 2])) -> bool {
        let Some([x, y]) = xy_fields(self.meta()) else {
            return false;
        };
        let poses = self.view().poses;
        let n = self.meta().pose_fields.len();
        for i in 0..self.meta().images {
            let at = |k: usize| poses.get(i * n + k).copied().unwrap_or(f64::NAN);
            f(i as u32, [at(x), at(y)]);
        }
        true
    }
    /// Each image's position by id, as [`each_position`](Self::each_position)
    /// gives them, when the map has both fields.
    fn positions(&self) -> Option<Vec<[f64; 2]>> {
        let mut out = Vec::with_capacity(self.id_range());
        self.each_position(&mut |_, p| out.push(p)).then_some(out)
    }
}

/// Where pose fields `x` and `y` stand among a map's pose fields, when it
/// has both.
pub fn xy_fields(meta: &MapMeta) -> Option<[usize; 2]> {
    let at = |name: &str| meta.pose_fields.iter().position(|f| f == name);
    Some([at("x")?, at("y")?])
}

impl MapRead for MapIndex {
    fn view(&self) -> MapView<'_> {
        MapIndex::view(self)
    }
    fn meta(&self) -> &MapMeta {
        MapIndex::meta(self)
    }
    fn image(&self, id: u32) -> ImageInfo<'_> {
        MapIndex::image(self, id)
    }
    fn geometry(&self, id: u32) -> &[PackedFeature] {
        MapIndex::geometry(self, id)
    }
}

impl MapIndex {
    pub fn from_arrays(arrays: MapArrays, meta: MapMeta) -> Self {
        Self {
            backing: Backing::Owned(Box::new(arrays)),
            meta,
            runs: Default::default(),
        }
    }

    pub fn meta(&self) -> &MapMeta {
        &self.meta
    }

    /// The same map, recorded as including the change log up to `generation`.
    pub fn with_generation(mut self, generation: u64) -> Self {
        self.meta.generation = generation;
        self
    }

    /// The same map, recorded as written by a compaction at `at_ms`
    /// (milliseconds since the Unix epoch).
    pub fn compacted_at(mut self, at_ms: u64) -> Self {
        self.meta.compacted_at_ms = Some(at_ms);
        self
    }

    /// What identifies this map's content: the file's section-table checksum
    /// (which covers every section's checksum), or for a map held in memory
    /// a hash of its metadata.
    pub fn fingerprint(&self) -> u64 {
        match &self.backing {
            Backing::Mapped(store) => store.table_checksum(),
            Backing::Owned(_) => crate::store::checksum(
                serde_json::to_string(&self.meta)
                    .unwrap_or_default()
                    .as_bytes(),
            ),
        }
    }

    /// Number of map images.
    pub fn images(&self) -> usize {
        self.meta.images
    }

    /// Number of visual words.
    pub fn words(&self) -> usize {
        self.meta.words
    }

    /// All arrays, borrowed (a handful of lookups: take it once per query).
    /// The first call also indexes the features' runs by postings entry
    /// (time and 8 bytes per entry, once).
    pub fn view(&self) -> MapView<'_> {
        let mut view = self.arrays();
        view.feature_runs = self.runs.get_or_init(|| feature_runs(&view));
        view
    }

    fn arrays(&self) -> MapView<'_> {
        match &self.backing {
            Backing::Owned(a) => MapView {
                idf: &a.idf,
                postings: Postings::new(&a.offsets, &a.images, &a.weights),
                image_max: &a.image_max,
                names: a.names.as_view(),
                places: a.places.as_view(),
                poses: &a.poses,
                geometry_offsets: &a.geometry_offsets,
                geometry: &a.geometry,
                feature_runs: &[],
                overlay: None,
            },
            Backing::Mapped(store) => file::view(store).expect("validated on load"),
        }
    }

    /// Name, place label and pose of map image `id`.
    pub fn image(&self, id: u32) -> ImageInfo<'_> {
        let view = self.arrays();
        metadata::image_info(&view, &self.meta.pose_fields, id)
    }

    /// The stored features of map image `id`, sorted by word (empty for an
    /// image without features or an unknown id).
    pub fn geometry(&self, id: u32) -> &[PackedFeature] {
        let v = self.arrays();
        let j = id as usize;
        match (v.geometry_offsets.get(j), v.geometry_offsets.get(j + 1)) {
            (Some(&a), Some(&b)) => &v.geometry[a as usize..b as usize],
            _ => &[],
        }
    }

    /// Each image's words, recovered from the postings: d̂_j(w) ∝ count_j(w)·idf(w),
    /// so count_j(w) ∝ d̂_j(w)/idf(w), scaled so the rarest word counts once.
    /// Words of idf 0 (present in every image) leave no posting and are
    /// missing, as they cast no vote anyway.
    pub fn image_words(&self) -> Vec<Vec<u32>> {
        let v = self.view();
        let mut ratios: Vec<Vec<(u32, f32)>> = vec![Vec::new(); self.images()];
        for w in 0..self.words() as u32 {
            let idf = v.idf[w as usize];
            let (ids, weights) = v.postings.list(w);
            for (&j, &d) in ids.iter().zip(weights) {
                if let Some(r) = ratios.get_mut(j as usize)
                    && idf > 0.0
                {
                    r.push((w, d / idf));
                }
            }
        }
        ratios
            .into_iter()
            .map(|r| {
                let unit = r.iter().map(|e| e.1).fold(f32::INFINITY, f32::min);
                r.iter()
                    .flat_map(|&(w, x)| {
                        let count = (x / unit).round().max(1.0) as usize;
                        std::iter::repeat_n(w, count)
                    })
                    .collect()
            })
            .collect()
    }

    /// Open a map file. With `verify`, every checksum is recomputed.
    pub fn open(path: &std::path::Path, verify: bool) -> Result<Self, StoreError> {
        file::open(path, verify)
    }

    /// Open a map file and check it was built with `vocab`.
    pub fn open_for(
        path: &std::path::Path,
        vocab: &crate::vocabulary::Vocabulary,
        verify: bool,
    ) -> Result<Self, StoreError> {
        let map = Self::open(path, verify)?;
        if map.meta.vocab_hash != vocab.hash_hex() || map.words() != vocab.words() {
            return Err(StoreError::Invalid {
                path: path.to_path_buf(),
                detail: format!(
                    "map was built with vocabulary {} ({} words), but the loaded vocabulary is {} ({} words)",
                    map.meta.vocab_hash,
                    map.words(),
                    vocab.hash_hex(),
                    vocab.words()
                ),
            });
        }
        Ok(map)
    }

    /// Write atomically to `path`.
    pub fn save(&self, path: &std::path::Path) -> Result<(), StoreError> {
        file::save(self, path)
    }
}

/// [`MapView::feature_runs`] of `view`'s postings and geometry. Each image's
/// features are sorted by word and each word's postings list images in
/// ascending order, so one pass over the images in order fills every entry.
/// An entry whose image stores no features of its word gets an empty run.
fn feature_runs(view: &MapView<'_>) -> Vec<[u32; 2]> {
    let (offsets, images, _) = view.postings.raw();
    if view.geometry.is_empty() || view.geometry.len() > u32::MAX as usize {
        return Vec::new();
    }
    let mut runs = vec![[0u32; 2]; images.len()];
    let mut cursor: Vec<u64> = offsets
        .iter()
        .take(offsets.len().saturating_sub(1))
        .copied()
        .collect();
    for (j, bounds) in view.geometry_offsets.windows(2).enumerate() {
        let (mut at, end) = (bounds[0] as usize, bounds[1] as usize);
        while at < end {
            let word = view.geometry[at].word;
            let len = view.geometry[at..end]
                .iter()
                .take_while(|f| f.word == word)
                .count();
            let list_end = offsets.get(word as usize + 1).copied().unwrap_or(0);
            if let Some(c) = cursor.get_mut(word as usize) {
                let e = *c as usize;
                if *c < list_end && images.get(e) == Some(&(j as u32)) {
                    runs[e] = [at as u32, len as u32];
                    *c += 1;
                }
            }
            at += len;
        }
    }
    runs
}

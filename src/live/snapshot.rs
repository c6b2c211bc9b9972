//! One consistent state of a live map: the map file (memory-mapped, read
//! only) plus the changes since it was written, as persistent structures.
//! A query takes one snapshot and searches it through [`MapRead`] like a map
//! file; a writer clones the current snapshot (cheap: everything is shared),
//! applies one change and publishes the result.
//!
//! Scoring between compactions: idf stays frozen at the map file's values;
//! an added image is weighted (tf·idf, L2-normalised) under that frozen idf,
//! and a removed image simply gets no votes. Words the file's images never
//! hold have idf 0 until the next compaction recomputes idf over the images
//! then in the map ([`super::compact`]).

use super::log::{Change, NewImage, Record};
use crate::calibrate::auto_warmup;
use crate::geometry::packed::PackedFeature;
use crate::index::build::weigh;
use crate::index::metadata::pose_of;
use crate::index::{ImageInfo, ImageWords, MapIndex, MapMeta, MapRead, MapView, Overlay};
use std::sync::{Arc, OnceLock};

/// An image added since the map file was written.
#[derive(Debug)]
pub struct Added {
    pub place: String,
    /// One value per pose field (NaN: unknown), or empty.
    pub pose: Vec<f64>,
    /// Its words and features (name included).
    pub image: ImageWords,
    pub added_at_ms: u64,
}

impl Added {
    fn new(i: &NewImage) -> Self {
        let words: Vec<u32> = i.features.iter().map(|f| f.word).collect();
        Self {
            place: i.place.clone(),
            pose: i.pose.clone(),
            image: ImageWords {
                geometry: i.features.clone(),
                ..ImageWords::from_words(i.name.clone(), &words)
            },
            added_at_ms: i.added_at_ms,
        }
    }
}

/// A change that cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    #[error("no image named `{0}` in the map")]
    NotFound(String),
    #[error("the map holds {0} images, its limit")]
    Full(usize),
    #[error("{0}")]
    Invalid(String),
}

/// What applying a change did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Applied {
    /// The image's id in this snapshot (an add) or the id it had (a removal).
    pub id: u32,
    /// An add replaced an image of the same name.
    pub replaced: bool,
}

/// One state of the map: file plus changes.
#[derive(Clone)]
pub struct Snapshot {
    base: Arc<MapIndex>,
    overlay: Overlay,
    /// Added images; `added[k]` has id `overlay.first() + k`.
    added: imbl::Vector<Arc<Added>>,
    /// The map file's ids ordered by (name, id), to find a file image by
    /// name; built on the first lookup by name (queries never need it) and
    /// shared by every snapshot of the same file.
    file_names: Arc<OnceLock<Vec<u32>>>,
    /// Name → id of the images added since the map file (not removed).
    added_names: imbl::HashMap<Arc<str>, u32>,
    /// The base's meta, counting the images now in the map.
    meta: MapMeta,
    generation: u64,
    /// [`Self::auto_warmup`], computed on first use (a change clears it).
    auto_warmup: OnceLock<usize>,
}

impl Snapshot {
    /// The map file with no changes, at its own generation.
    pub fn new(base: Arc<MapIndex>) -> Self {
        let meta = base.meta().clone();
        Self {
            overlay: Overlay::new(base.images() as u32, base.words()),
            generation: meta.generation,
            added: imbl::Vector::new(),
            file_names: Arc::default(),
            added_names: imbl::HashMap::new(),
            meta,
            base,
            auto_warmup: OnceLock::new(),
        }
    }

    pub fn base(&self) -> &Arc<MapIndex> {
        &self.base
    }

    pub fn overlay(&self) -> &Overlay {
        &self.overlay
    }

    /// Changes applied so far, counting from 0 at the first map file.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Images in the map now.
    pub fn len(&self) -> usize {
        self.meta.images
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Id of the image named `name` (of two file images of one name, the
    /// later).
    pub fn id_of(&self, name: &str) -> Option<u32> {
        if let Some(&id) = self.added_names.get(name) {
            return Some(id);
        }
        let names = self.base.view().names;
        let sorted = self.file_names.get_or_init(|| {
            let all: Vec<&str> = (0..self.base.images()).map(|j| names.get(j)).collect();
            let mut ids: Vec<u32> = (0..all.len() as u32).collect();
            ids.sort_unstable_by_key(|&j| (all[j as usize], j));
            ids
        });
        let after = sorted.partition_point(|&j| names.get(j as usize) <= name);
        let id = *sorted.get(after.checked_sub(1)?)?;
        (names.get(id as usize) == name && !self.overlay.is_removed(id)).then_some(id)
    }

    /// Whether image `id` is in the map (exists and is not removed).
    pub fn contains(&self, id: u32) -> bool {
        id < self.overlay.ids() && !self.overlay.is_removed(id)
    }

    /// Every id in the map, ascending (the file's images first).
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.overlay.ids()).filter(|&j| !self.overlay.is_removed(j))
    }

    /// The added image of id `id`, if it is one.
    pub fn added(&self, id: u32) -> Option<&Added> {
        let k = id.checked_sub(self.overlay.first())?;
        self.added.get(k as usize).map(|a| &**a)
    }

    /// Features of image `id`: its stored features, or, for a file without
    /// geometry, none known (0).
    pub fn features_of(&self, id: u32) -> usize {
        match self.added(id) {
            Some(a) => a.image.features as usize,
            None => self.base.geometry(id).len(),
        }
    }

    /// The warm-up `auto` means on this map: [`auto_warmup`] of its images'
    /// feature counts (a map of small frames gets a short one).
    pub fn auto_warmup(&self) -> usize {
        *self.auto_warmup.get_or_init(|| {
            let counts: Vec<usize> = self.ids().map(|j| self.features_of(j)).collect();
            auto_warmup(&counts)
        })
    }

    /// Apply one change (not yet durable: the caller logs it first or is
    /// replaying the log), at the record's generation. `max_images` caps the
    /// map's size. On error nothing changes.
    pub fn apply(&mut self, record: &Record, max_images: usize) -> Result<Applied, ApplyError> {
        let applied = match &record.change {
            Change::Add(i) => self.add(i, max_images)?,
            Change::Remove { name } => self.remove(name)?,
        };
        self.generation = record.generation;
        self.meta.generation = record.generation;
        self.auto_warmup = OnceLock::new();
        Ok(applied)
    }

    fn add(&mut self, i: &NewImage, max_images: usize) -> Result<Applied, ApplyError> {
        let fields = self.meta.pose_fields.len();
        if !i.pose.is_empty() && i.pose.len() != fields {
            return Err(ApplyError::Invalid(format!(
                "{} pose values for the map's {fields} pose fields",
                i.pose.len()
            )));
        }
        let old = self.id_of(&i.name);
        if old.is_none() && self.len() >= max_images {
            return Err(ApplyError::Full(max_images));
        }
        if let Some(old) = old {
            self.drop_image(old);
        }
        let added = Added::new(i);
        let (entries, image_max) = weigh(&added.image, self.base.view().idf);
        let id = self.overlay.add(&entries, image_max);
        self.meta.images += 1;
        self.meta.postings += entries.len();
        self.meta.features += added.image.features as u64;
        self.meta.images_without_features += (added.image.features == 0) as usize;
        self.added_names.insert(Arc::from(i.name.as_str()), id);
        self.added.push_back(Arc::new(added));
        Ok(Applied {
            id,
            replaced: old.is_some(),
        })
    }

    fn remove(&mut self, name: &str) -> Result<Applied, ApplyError> {
        let id = self
            .id_of(name)
            .ok_or_else(|| ApplyError::NotFound(name.to_owned()))?;
        self.added_names.remove(name);
        self.drop_image(id);
        Ok(Applied {
            id,
            replaced: false,
        })
    }

    /// Mark `id` removed and take it out of the counts.
    fn drop_image(&mut self, id: u32) {
        let features = self.features_of(id);
        if self.overlay.remove(id) {
            self.meta.images -= 1;
            self.meta.features = self.meta.features.saturating_sub(features as u64);
            if features == 0 {
                self.meta.images_without_features =
                    self.meta.images_without_features.saturating_sub(1);
            }
        }
    }
}

impl MapRead for Snapshot {
    fn view(&self) -> MapView<'_> {
        MapView {
            overlay: (!self.overlay.is_empty()).then_some(&self.overlay),
            ..self.base.view()
        }
    }

    fn meta(&self) -> &MapMeta {
        &self.meta
    }

    fn image(&self, id: u32) -> ImageInfo<'_> {
        match self.added(id) {
            None => self.base.image(id),
            Some(a) => ImageInfo {
                id,
                name: &a.image.name,
                place: Some(a.place.as_str()).filter(|p| !p.is_empty()),
                pose: pose_of(&self.meta.pose_fields, &a.pose),
            },
        }
    }

    fn geometry(&self, id: u32) -> &[PackedFeature] {
        match self.added(id) {
            None => self.base.geometry(id),
            Some(a) => &a.image.geometry,
        }
    }

    fn id_range(&self) -> usize {
        self.overlay.ids() as usize
    }

    /// The file's positions, then the added images' (NaN where unknown).
    fn each_position(&self, f: &mut dyn FnMut(u32, [f64; 2])) -> bool {
        let Some([x, y]) = crate::index::xy_fields(&self.meta) else {
            return false;
        };
        if !self.base.each_position(f) {
            return false;
        }
        for (k, a) in self.added.iter().enumerate() {
            let at = |k: usize| a.pose.get(k).copied().unwrap_or(f64::NAN);
            f(self.overlay.first() + k as u32, [at(x), at(y)]);
        }
        true
    }
}

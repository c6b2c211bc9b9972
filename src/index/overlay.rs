//! The changes on top of a map file, in the form the voter reads: the
//! postings of the images added since the file was written and the set of
//! images removed. Added images take the ids after the file's, in the order
//! they were added; a removed image keeps its id but gets no votes.
//!
//! Everything here is persistent (structurally shared): cloning an overlay is
//! O(1), and adding an image copies only the few chunks of the per-word lists
//! it touches, so the cost of a change does not grow with the number of
//! changes before it. The removed set is a plain bitset (copied on a removal:
//! one bit per image), so a vote tests it with one load.
//!
//! Walking a persistent list costs more per entry than a flat array, so the
//! voter reads the added postings from a flat copy ([`Flat`], CSR like the
//! file's), built by the first query of a snapshot and shared by every
//! later query of it: writes never build it, and a query builds it at most
//! once per write (in time linear in the added postings).

use imbl::Vector;
use std::sync::{Arc, OnceLock};

/// The added postings in CSR layout: word w's entries are
/// `entries[offsets[w]..offsets[w + 1]]`, (image id, d̂_j(w)), ids ascending.
#[derive(Debug, Default)]
pub struct Flat {
    offsets: Vec<u32>,
    entries: Vec<(u32, f32)>,
}

impl Flat {
    /// Word `w`'s entries (empty for an unknown word).
    #[inline]
    pub fn list(&self, w: u32) -> &[(u32, f32)] {
        let w = w as usize;
        match (self.offsets.get(w), self.offsets.get(w + 1)) {
            (Some(&a), Some(&b)) => self.entries.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }
}

/// Added postings and removed ids over a map of `first` images.
#[derive(Clone, Default)]
pub struct Overlay {
    /// Id of the first added image: the images of the map file.
    first: u32,
    /// By word: (image id, d̂_j(w)) of the added images holding w, ids ascending.
    postings: Vector<Vector<(u32, f32)>>,
    /// Per added image: max over w of idf(w)·d̂_j(w).
    image_max: Vector<f32>,
    /// Bit j set: image j is removed. Ids beyond it are not removed.
    removed: Arc<Vec<u64>>,
    removed_count: usize,
    /// Largest image_max of any image added (an upper bound when some of
    /// them are removed).
    vote_cap: f32,
    /// Postings entries of added images.
    entries: usize,
    /// The flat copy of `postings`, once a query asked for it.
    flat: Arc<OnceLock<Flat>>,
}

impl Overlay {
    /// No changes yet over a map of `images` images and `words` words.
    pub fn new(images: u32, words: usize) -> Self {
        Self {
            first: images,
            postings: std::iter::repeat_n(Vector::new(), words).collect(),
            ..Self::default()
        }
    }

    /// Whether nothing was added or removed.
    pub fn is_empty(&self) -> bool {
        self.image_max.is_empty() && self.removed_count == 0
    }

    /// Id of the first added image (the images of the map file).
    pub fn first(&self) -> u32 {
        self.first
    }

    /// All ids: the map file's images and every image added (removed or not).
    pub fn ids(&self) -> u32 {
        self.first + self.image_max.len() as u32
    }

    /// Images added (removed ones included).
    pub fn added(&self) -> usize {
        self.image_max.len()
    }

    /// Images removed (of the file's and of the added).
    pub fn removed(&self) -> usize {
        self.removed_count
    }

    pub fn vote_cap(&self) -> f32 {
        self.vote_cap
    }

    /// Add an image by its normalised tf-idf entries (word ascending, as
    /// [`crate::index::build::weigh`] makes them) and its largest vote;
    /// returns its id.
    pub fn add(&mut self, entries: &[(u32, f32)], image_max: f32) -> u32 {
        let id = self.ids();
        for &(w, v) in entries {
            if let Some(list) = self.postings.get_mut(w as usize) {
                list.push_back((id, v));
                self.entries += 1;
            }
        }
        self.image_max.push_back(image_max);
        self.vote_cap = self.vote_cap.max(image_max);
        self.flat = Arc::default();
        id
    }

    /// Remove image `id` (of the file or added); false when it already was
    /// or does not exist.
    pub fn remove(&mut self, id: u32) -> bool {
        if id >= self.ids() || self.is_removed(id) {
            return false;
        }
        let (word, bit) = (id as usize / 64, id % 64);
        let bits = Arc::make_mut(&mut self.removed);
        if bits.len() <= word {
            bits.resize(word + 1, 0);
        }
        bits[word] |= 1 << bit;
        self.removed_count += 1;
        true
    }

    #[inline]
    pub fn is_removed(&self, id: u32) -> bool {
        is_set(&self.removed, id)
    }

    /// The removed bitset (bit j of word j/64).
    pub fn removed_bits(&self) -> &[u64] {
        &self.removed
    }

    /// The added postings as flat arrays: built on first use, then shared
    /// by every clone until the next add.
    pub fn flat(&self) -> &Flat {
        self.flat.get_or_init(|| {
            let mut offsets = Vec::with_capacity(self.postings.len() + 1);
            let mut entries = Vec::with_capacity(self.entries);
            offsets.push(0);
            for list in &self.postings {
                for chunk in list.leaves() {
                    entries.extend_from_slice(chunk);
                }
                offsets.push(entries.len() as u32);
            }
            Flat { offsets, entries }
        })
    }

    /// Largest vote image `id` can get from one feature, for an added image.
    pub fn image_max(&self, id: u32) -> Option<f32> {
        let k = id.checked_sub(self.first)?;
        self.image_max.get(k as usize).copied()
    }
}

/// Whether bit `id` of `bits` is set (ids beyond it are not).
#[inline]
pub fn is_set(bits: &[u64], id: u32) -> bool {
    bits.get(id as usize / 64)
        .is_some_and(|b| b & (1 << (id % 64)) != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adds_take_the_next_ids_and_share_with_clones() {
        let mut o = Overlay::new(3, 4);
        let before = o.clone();
        assert_eq!(o.add(&[(1, 0.6), (3, 0.8)], 0.5), 3);
        assert_eq!(o.add(&[(1, 1.0)], 0.9), 4);
        assert_eq!(o.flat().list(1), &[(3, 0.6), (4, 1.0)]);
        assert_eq!(o.flat().list(3), &[(3, 0.8)]);
        assert!(o.flat().list(0).is_empty() && o.flat().list(99).is_empty());
        o.add(&[(1, 0.5)], 0.5);
        assert_eq!(o.flat().list(1).len(), 3, "an add makes a new flat copy");
        // the clone taken before is unchanged
        assert!(before.flat().list(1).is_empty());
        assert_eq!(before.ids(), 3);
        assert_eq!((o.ids(), o.added()), (6, 3));
        assert_eq!(o.image_max(4), Some(0.9));
        assert_eq!(o.image_max(2), None);
        assert_eq!(o.vote_cap(), 0.9);
    }

    #[test]
    fn removals_are_bits() {
        let mut o = Overlay::new(130, 2);
        let snapshot = o.clone();
        assert!(o.remove(129));
        assert!(!o.remove(129));
        assert!(!o.remove(130), "no such id");
        assert!(o.is_removed(129) && !o.is_removed(128) && !o.is_removed(5000));
        assert!(!snapshot.is_removed(129));
        assert_eq!(o.removed(), 1);
    }
}

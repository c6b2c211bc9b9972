//! The inverted lists in CSR layout: `offsets[w]..offsets[w+1]` indexes the
//! parallel arrays `images` (map image ids, ascending) and `weights` (d̂_j(w)).

/// Borrowed postings of all words.
#[derive(Clone, Copy)]
pub struct Postings<'a> {
    offsets: &'a [u64],
    images: &'a [u32],
    weights: &'a [f32],
}

impl<'a> Postings<'a> {
    pub fn new(offsets: &'a [u64], images: &'a [u32], weights: &'a [f32]) -> Self {
        Self {
            offsets,
            images,
            weights,
        }
    }

    /// Number of words.
    pub fn words(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Total number of (word, image) entries.
    pub fn len(&self) -> usize {
        self.images.len()
    }

    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// The postings of word `w`: image ids and their weights. Out-of-range
    /// words and inconsistent offsets give an empty list, never a panic.
    #[inline]
    pub fn list(&self, w: u32) -> (&'a [u32], &'a [f32]) {
        let w = w as usize;
        let (Some(&a), Some(&b)) = (self.offsets.get(w), self.offsets.get(w + 1)) else {
            return (&[], &[]);
        };
        match (
            self.images.get(a as usize..b as usize),
            self.weights.get(a as usize..b as usize),
        ) {
            (Some(i), Some(v)) => (i, v),
            _ => (&[], &[]),
        }
    }

    /// Where word `w`'s entries start among all entries (0 for an unknown
    /// word).
    #[inline]
    pub fn start(&self, w: u32) -> usize {
        self.offsets.get(w as usize).map_or(0, |&a| a as usize)
    }

    pub(crate) fn raw(&self) -> (&'a [u64], &'a [u32], &'a [f32]) {
        (self.offsets, self.images, self.weights)
    }
}

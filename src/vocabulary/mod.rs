//! The visual vocabulary: K centroids of descriptor space (the visual words),
//! their precomputed squared norms, and the extraction settings they were
//! trained with. Loaded by memory-mapping a store file; trained by `kmeans`.

mod file;
pub mod kmeans;

pub use file::VocabularyMeta;

use crate::quantize::{ExactQuantizer, squared_norms};
use crate::store::{Store, StoreError};
use ndarray::{Array2, ArrayView2};

/// A vocabulary, either memory-mapped from a file or held in memory.
pub struct Vocabulary {
    backing: Backing,
    meta: VocabularyMeta,
    hash: u64,
}

enum Backing {
    Mapped(Store),
    Owned { centroids: Vec<f32>, norms: Vec<f32> },
}

impl Vocabulary {
    /// A vocabulary from a `K × D` centroid matrix (norms computed here).
    pub fn from_centroids(centroids: Array2<f32>, mut meta: VocabularyMeta) -> Self {
        let (k, dim) = centroids.dim();
        meta.words = k;
        meta.dim = dim;
        let centroids = centroids.into_raw_vec_and_offset().0;
        let norms = squared_norms(&centroids, dim);
        let hash = crate::store::checksum(bytemuck::cast_slice(&centroids));
        Self {
            backing: Backing::Owned { centroids, norms },
            meta,
            hash,
        }
    }

    pub fn words(&self) -> usize {
        self.meta.words
    }

    pub fn dim(&self) -> usize {
        self.meta.dim
    }

    pub fn meta(&self) -> &VocabularyMeta {
        &self.meta
    }

    /// Identity of the centroids: the xxh3 of their bytes. Maps record it.
    pub fn hash(&self) -> u64 {
        self.hash
    }

    /// `hash()` as the 16 hex digits shown to users.
    pub fn hash_hex(&self) -> String {
        format!("{:016x}", self.hash)
    }

    pub fn centroids(&self) -> ArrayView2<'_, f32> {
        ArrayView2::from_shape((self.words(), self.dim()), self.centroid_slice())
            .expect("validated on load")
    }

    fn centroid_slice(&self) -> &[f32] {
        match &self.backing {
            Backing::Mapped(store) => store.f32s("centroids").expect("validated on load"),
            Backing::Owned { centroids, .. } => centroids,
        }
    }

    fn norm_slice(&self) -> &[f32] {
        match &self.backing {
            Backing::Mapped(store) => store.f32s("norms").expect("validated on load"),
            Backing::Owned { norms, .. } => norms,
        }
    }

    /// The exact batched quantizer over these centroids.
    pub fn exact_quantizer(&self) -> ExactQuantizer<'_> {
        ExactQuantizer::new(self.centroid_slice(), self.norm_slice(), self.dim())
    }

    /// Open a vocabulary file; `verify` recomputes every checksum.
    pub fn open(path: &std::path::Path, verify: bool) -> Result<Self, StoreError> {
        file::open(path, verify)
    }

    /// Write atomically to `path`.
    pub fn save(&self, path: &std::path::Path) -> Result<(), StoreError> {
        file::save(self, path)
    }
}

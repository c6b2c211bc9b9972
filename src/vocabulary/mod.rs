//! The visual vocabulary: K centroids of descriptor space (the visual words),
//! their precomputed squared norms, the extraction settings they were
//! trained with, and the Hamming embedding that signs each feature within
//! its word (`hamming`). Loaded by memory-mapping a store file; trained by
//! `kmeans`. Binary words for binary descriptors (ORB's) are `binary`.

pub mod binary;
mod file;
pub mod hamming;
pub mod kmeans;

pub use hamming::HammingEmbedding;

pub use file::VocabularyMeta;

use crate::quantize::{ExactQuantizer, Quantizer, QuantizerKind, TreeQuantizer};
use crate::store::{Store, StoreError};
use ndarray::{Array2, ArrayView2};

/// A vocabulary, either memory-mapped from a file or held in memory.
pub struct Vocabulary {
    backing: Backing,
    meta: VocabularyMeta,
    hash: u64,
    /// Packed on first use.
    exact: std::sync::OnceLock<ExactQuantizer>,
    /// Built on first use.
    tree: std::sync::OnceLock<TreeQuantizer>,
    /// Signs features within their words; `None` signs every feature 0.
    hamming: Option<HammingEmbedding>,
}

enum Backing {
    Mapped(Store),
    Owned(Vec<f32>),
}

impl Vocabulary {
    /// A vocabulary from a `K × D` centroid matrix (norms computed here).
    pub fn from_centroids(centroids: Array2<f32>, mut meta: VocabularyMeta) -> Self {
        let (k, dim) = centroids.dim();
        meta.words = k;
        meta.dim = dim;
        let centroids = centroids.as_standard_layout().to_owned();
        let centroids = centroids.into_raw_vec_and_offset().0;
        let hash = crate::store::checksum(bytemuck::cast_slice(&centroids));
        Self {
            backing: Backing::Owned(centroids),
            meta,
            hash,
            exact: std::sync::OnceLock::new(),
            tree: std::sync::OnceLock::new(),
            hamming: None,
        }
    }

    /// A vocabulary from trained centroids, with its Hamming embedding
    /// learned from (at most 200,000 rows of) the training descriptors.
    pub fn trained(
        centroids: Array2<f32>,
        meta: VocabularyMeta,
        descriptors: ArrayView2<'_, f32>,
    ) -> Self {
        let vocab = Self::from_centroids(centroids, meta);
        let step = descriptors.nrows().div_ceil(200_000).max(1);
        let sample = descriptors.slice(ndarray::s![..;step, ..]);
        let mut words = vec![0u32; sample.nrows()];
        vocab.exact_quantizer().quantize(sample, &mut words);
        let he = HammingEmbedding::train(sample, &words, vocab.words(), vocab.meta.seed);
        vocab.with_hamming(he)
    }

    /// This vocabulary with `he` as its embedding.
    pub fn with_hamming(mut self, he: HammingEmbedding) -> Self {
        self.hamming = Some(he);
        self
    }

    /// The Hamming embedding, when the vocabulary has one.
    pub fn hamming(&self) -> Option<&HammingEmbedding> {
        self.hamming.as_ref()
    }

    /// Signatures of `descriptors` quantized to `words` (all 0 without an
    /// embedding).
    pub fn sign(&self, descriptors: ArrayView2<'_, f32>, words: &[u32], out: &mut [u64]) {
        hamming::sign_or_zero(self.hamming.as_ref(), descriptors, words, out);
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
            Backing::Owned(centroids) => centroids,
        }
    }

    /// The exact batched quantizer over these centroids (packed once, on
    /// first use).
    pub fn exact_quantizer(&self) -> &ExactQuantizer {
        self.exact
            .get_or_init(|| ExactQuantizer::new(self.centroid_slice(), self.dim()))
    }

    /// The two-level tree over these words (built on first use: k-means of
    /// the K words into ⌈√K⌉ groups).
    pub fn tree_quantizer(&self) -> &TreeQuantizer {
        self.tree.get_or_init(|| {
            let groups = (self.words() as f64).sqrt().ceil() as usize;
            let config = kmeans::KmeansConfig {
                k: groups,
                seed: self.meta.seed,
                max_iter: 15,
                train_sample: 0,
                ..Default::default()
            };
            let (centres, report) =
                kmeans::kmeans(self.centroids(), &config, &indicatif::ProgressBar::hidden())
                    .expect("⌈√K⌉ ≤ K groups");
            let mut group_of = vec![0u32; self.words()];
            let exact = ExactQuantizer::new(centres.as_slice().expect("standard"), self.dim());
            for (rows, out) in self
                .centroid_slice()
                .chunks(256 * self.dim())
                .zip(group_of.chunks_mut(256))
            {
                let block = ArrayView2::from_shape((out.len(), self.dim()), rows).expect("rows");
                exact.quantize(block, out);
            }
            tracing::debug!(
                groups,
                iterations = report.iterations,
                "quantization tree built"
            );
            TreeQuantizer::new(
                self.centroid_slice(),
                self.dim(),
                centres.into_raw_vec_and_offset().0,
                &group_of,
            )
        })
    }

    /// The quantizer of the given kind.
    pub fn quantizer(&self, kind: QuantizerKind) -> Box<dyn Quantizer + '_> {
        match kind {
            QuantizerKind::Exact => Box::new(self.exact_quantizer()),
            QuantizerKind::Tree { probes } => Box::new(self.tree_quantizer().with_probes(probes)),
        }
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

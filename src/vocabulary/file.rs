//! The vocabulary file: sections `meta` (JSON), `centroids` (f32, K × D)
//! and, when it has one, the Hamming embedding (`hamming.projection`, 64 × D,
//! and `hamming.thresholds`, K × 64). A file without the embedding (written
//! before it existed) still loads and signs every feature 0.

use super::{Backing, HammingEmbedding, Vocabulary};
use crate::features::ExtractConfig;
use crate::store::{Store, StoreError, StoreWriter};
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: [u8; 8] = *b"BOWLOCVO";
const VERSION: u32 = 1;

/// What a vocabulary is and how it was made.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct VocabularyMeta {
    pub words: usize,
    pub dim: usize,
    /// Settings every map and query using this vocabulary must extract with.
    pub extract: ExtractConfig,
    /// k-means seed.
    pub seed: u64,
    /// Descriptors the centroids were trained on.
    pub trained_on: usize,
    /// Lloyd iterations run.
    pub iterations: usize,
}

pub(super) fn save(vocab: &Vocabulary, path: &Path) -> Result<(), StoreError> {
    let mut writer = StoreWriter::new(MAGIC, VERSION);
    writer
        .json("meta", &vocab.meta)
        .f32s("centroids", vocab.centroid_slice());
    if let Some(he) = &vocab.hamming {
        writer
            .f32s("hamming.projection", he.projection())
            .f32s("hamming.thresholds", he.thresholds());
    }
    writer.write_atomic(path)?;
    Ok(())
}

pub(super) fn open(path: &Path, verify: bool) -> Result<Vocabulary, StoreError> {
    let store = Store::open(path, MAGIC, "vocabulary", VERSION, verify)?;
    let meta: VocabularyMeta = store.json("meta")?;
    let centroids = store.f32s("centroids")?;
    if meta.words == 0 || meta.dim == 0 {
        return Err(store.invalid("vocabulary has no words"));
    }
    if Some(centroids.len()) != meta.words.checked_mul(meta.dim) {
        return Err(store.invalid(format!(
            "meta says {} words of {} dimensions but the file holds {} centroid values",
            meta.words,
            meta.dim,
            centroids.len()
        )));
    }
    if centroids.iter().any(|v| !v.is_finite()) {
        return Err(store.invalid("centroids hold NaN or infinite values"));
    }
    let hash = store.section("centroids")?.checksum;
    let hamming = match (
        store.f32s("hamming.projection"),
        store.f32s("hamming.thresholds"),
    ) {
        (Ok(p), Ok(t)) => Some(
            HammingEmbedding::from_parts(p, t, meta.dim, meta.words)
                .map_err(|e| store.invalid(e))?,
        ),
        _ => {
            tracing::warn!(
                path = %path.display(),
                "the vocabulary has no Hamming embedding: votes are plain tf-idf; \
                 retrain it (`bowloc vocab`) for better recall"
            );
            None
        }
    };
    Ok(Vocabulary {
        hamming,
        backing: Backing::Mapped(store),
        meta,
        hash,
        exact: Default::default(),
        tree: Default::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn save_and_open_round_trip_keeps_hash() {
        let c = Array2::from_shape_fn((10, 4), |(i, j)| (i * 4 + j) as f32);
        let v = Vocabulary::from_centroids(c.clone(), VocabularyMeta::default());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.bowvoc");
        v.save(&path).unwrap();
        let w = Vocabulary::open(&path, true).unwrap();
        assert_eq!(w.hash(), v.hash());
        assert_eq!(w.centroids(), c.view());
        assert_eq!(w.words(), 10);
        assert_eq!(w.dim(), 4);
    }
}

//! Building a map: per-image word counts → tf-idf weights → CSR postings,
//! plus each image's packed features (word and keypoint) for verification.

use super::{MapArrays, MapIndex, MapMeta, Places, StringTable};
use crate::geometry::Keypoint;
use crate::geometry::packed::{PackedFeature, pack_image};
use rayon::prelude::*;

/// One map image as the words its features quantized to.
#[derive(Debug, Clone)]
pub struct ImageWords {
    pub name: String,
    /// Distinct words, ascending, with their counts.
    pub counts: Vec<(u32, u32)>,
    /// Number of features (sum of counts).
    pub features: u32,
    /// Each feature's word and keypoint, sorted by word (empty: the image
    /// has no stored geometry).
    pub geometry: Vec<PackedFeature>,
}

impl ImageWords {
    pub fn from_words(name: impl Into<String>, words: &[u32]) -> Self {
        let mut sorted = words.to_vec();
        sorted.sort_unstable();
        let mut counts: Vec<(u32, u32)> = Vec::new();
        for w in sorted {
            match counts.last_mut() {
                Some((last, c)) if *last == w => *c += 1,
                _ => counts.push((w, 1)),
            }
        }
        Self {
            name: name.into(),
            counts,
            features: words.len() as u32,
            geometry: Vec::new(),
        }
    }

    /// Words, their signatures (or none: all 0) and the keypoints they came
    /// from (`keypoints[i]` is the feature of `words[i]`), so the map can
    /// weigh votes and verify geometry.
    pub fn with_geometry(
        name: impl Into<String>,
        words: &[u32],
        signatures: &[u64],
        keypoints: &[Keypoint],
    ) -> Self {
        debug_assert_eq!(words.len(), keypoints.len());
        Self {
            geometry: pack_image(words, signatures, keypoints),
            ..Self::from_words(name, words)
        }
    }
}

/// Collects images, then computes the index.
pub struct MapBuilder {
    words: usize,
    images: Vec<ImageWords>,
}

impl MapBuilder {
    pub fn new(words: usize) -> Self {
        Self {
            words,
            images: Vec::new(),
        }
    }

    pub fn add(&mut self, image: ImageWords) {
        self.images.push(image);
    }

    /// Compute idf, the normalised tf-idf vectors and the postings.
    /// `name` names the map; `vocab_hash` is the vocabulary's `hash_hex()`.
    pub fn build(self, name: &str, vocab_hash: &str, places: Option<&Places>) -> MapIndex {
        let idf = self.idf();
        self.build_with_idf(idf, name, vocab_hash, places)
    }

    /// idf(w) = ln(N/df(w)) over the images collected (0 for a word in no image).
    pub fn idf(&self) -> Vec<f32> {
        let n_images = self.images.len();
        let mut df = vec![0u32; self.words];
        for image in &self.images {
            for &(w, _) in &image.counts {
                if let Some(d) = df.get_mut(w as usize) {
                    *d += 1;
                }
            }
        }
        df.iter()
            .map(|&d| {
                if d == 0 {
                    0.0
                } else {
                    (n_images as f64 / d as f64).ln() as f32
                }
            })
            .collect()
    }

    /// [`build`](Self::build) under a given idf (one per word), e.g. the
    /// idf a live map froze at its last compaction.
    pub fn build_with_idf(
        self,
        idf: Vec<f32>,
        name: &str,
        vocab_hash: &str,
        places: Option<&Places>,
    ) -> MapIndex {
        let n_images = self.images.len();
        let k = self.words;
        // d̂_j(w) for each image's words, in parallel.
        let (weighted, image_max): (Vec<Vec<(u32, f32)>>, Vec<f32>) = self
            .images
            .par_iter()
            .map(|image| weigh(image, &idf))
            .unzip();

        // CSR by word: counting sort keeps image ids ascending in each list.
        let mut offsets = vec![0u64; k + 1];
        for entries in &weighted {
            for &(w, _) in entries {
                offsets[w as usize + 1] += 1;
            }
        }
        for w in 0..k {
            offsets[w + 1] += offsets[w];
        }
        let total = offsets[k] as usize;
        let mut images = vec![0u32; total];
        let mut weights = vec![0f32; total];
        let mut fill: Vec<u64> = offsets[..k].to_vec();
        for (j, entries) in weighted.iter().enumerate() {
            for &(w, v) in entries {
                let at = fill[w as usize] as usize;
                images[at] = j as u32;
                weights[at] = v;
                fill[w as usize] += 1;
            }
        }

        let mut geometry_offsets = Vec::with_capacity(n_images + 1);
        geometry_offsets.push(0u64);
        let mut geometry = Vec::new();
        for image in &self.images {
            geometry.extend_from_slice(&image.geometry);
            geometry_offsets.push(geometry.len() as u64);
        }

        let pose_fields = places.map(|p| p.pose_fields.clone()).unwrap_or_default();
        let mut place_labels = Vec::with_capacity(n_images);
        let mut poses = Vec::with_capacity(n_images * pose_fields.len());
        for (j, image) in self.images.iter().enumerate() {
            match places.and_then(|p| p.lookup(&image.name, j)) {
                Some((place, pose)) => {
                    place_labels.push(place.as_str());
                    poses.extend_from_slice(pose);
                }
                None => {
                    place_labels.push("");
                    poses.extend(std::iter::repeat_n(f64::NAN, pose_fields.len()));
                }
            }
        }
        let meta = MapMeta {
            name: name.to_owned(),
            images: n_images,
            words: k,
            postings: total,
            vocab_hash: vocab_hash.to_owned(),
            pose_fields,
            features: self.images.iter().map(|i| i.features as u64).sum(),
            images_without_features: self.images.iter().filter(|i| i.features == 0).count(),
            generation: 0,
            compacted_at_ms: None,
        };
        let arrays = MapArrays {
            idf,
            offsets,
            images,
            weights,
            image_max,
            names: StringTable::from_strings(self.images.iter().map(|i| i.name.as_str())),
            places: StringTable::from_strings(place_labels),
            poses,
            geometry_offsets,
            geometry,
        };
        MapIndex::from_arrays(arrays, meta)
    }
}

/// tf·idf of one image, L2-normalised, under `idf`: its postings entries
/// (word ascending; words of zero weight are dropped) and its largest vote
/// max_w idf(w)·d̂(w). Words beyond `idf` weigh 0.
pub fn weigh(image: &ImageWords, idf: &[f32]) -> (Vec<(u32, f32)>, f32) {
    let n = image.features.max(1) as f32;
    let mut entries: Vec<(u32, f32)> = image
        .counts
        .iter()
        .map(|&(w, c)| {
            (
                w,
                c as f32 / n * idf.get(w as usize).copied().unwrap_or(0.0),
            )
        })
        .filter(|&(_, v)| v > 0.0)
        .collect();
    let norm = entries.iter().map(|&(_, v)| v * v).sum::<f32>().sqrt();
    if norm > 0.0 {
        for e in &mut entries {
            e.1 /= norm;
        }
    }
    let max = entries
        .iter()
        .map(|&(w, v)| idf[w as usize] * v)
        .fold(0.0, f32::max);
    (entries, max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_words_are_recovered_from_the_postings() {
        let mut b = MapBuilder::new(5);
        b.add(ImageWords::from_words("a", &[0, 0, 1, 2, 2, 2]));
        b.add(ImageWords::from_words("b", &[1, 3]));
        b.add(ImageWords::from_words("c", &[3, 4, 4]));
        let map = b.build("t", "0", None);
        let mut got = map.image_words();
        for g in &mut got {
            g.sort_unstable();
        }
        assert_eq!(got, vec![vec![0, 0, 1, 2, 2, 2], vec![1, 3], vec![3, 4, 4]]);
    }

    #[test]
    fn counts_are_run_lengths() {
        let iw = ImageWords::from_words("a", &[3, 1, 3, 3, 0]);
        assert_eq!(iw.counts, vec![(0, 1), (1, 1), (3, 3)]);
        assert_eq!(iw.features, 5);
    }

    #[test]
    fn tfidf_postings_by_hand() {
        // 3 images over 4 words.
        let mut b = MapBuilder::new(4);
        b.add(ImageWords::from_words("a", &[0, 0, 1]));
        b.add(ImageWords::from_words("b", &[1, 2]));
        b.add(ImageWords::from_words("c", &[2, 2, 2]));
        let map = b.build("t", "0", None);
        let v = map.view();
        let ln = |x: f64| x.ln() as f32;
        assert_eq!(v.idf, &[ln(3.0), ln(1.5), ln(1.5), 0.0]);
        // image a: tf = (2/3, 1/3), d = (2/3·ln3, 1/3·ln1.5)
        let (da0, da1) = (2.0 / 3.0 * ln(3.0), 1.0 / 3.0 * ln(1.5));
        let na = (da0 * da0 + da1 * da1).sqrt();
        let (ids, w) = v.postings.list(0);
        assert_eq!(ids, &[0]);
        assert!((w[0] - da0 / na).abs() < 1e-6);
        let (ids, w) = v.postings.list(1);
        assert_eq!(ids, &[0, 1]);
        assert!((w[0] - da1 / na).abs() < 1e-6);
        assert!((w[1] - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
        let (ids, w) = v.postings.list(2);
        assert_eq!(ids, &[1, 2]);
        assert!((w[1] - 1.0).abs() < 1e-6);
        assert_eq!(v.postings.list(3).0.len(), 0);
        assert_eq!(v.postings.list(99).0.len(), 0);
        assert_eq!(map.image(1).name, "b");
    }
}

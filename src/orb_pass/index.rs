//! The map's ORB side: each map image's ORB keypoint centres, descriptors
//! and binary words, an inverted tf-idf index over the words (weighed as
//! the SIFT map weighs its images, [`crate::index::build::weigh`]), and the
//! check of a query against the best-voted images: word pairs verified by a
//! similarity, with the relative scale of the inliers.

use crate::geometry::matches::Correspondences;
use crate::geometry::relative_scale::relative_scale;
use crate::geometry::verify::{ModelFit, fit_inliers};
use crate::index::build::{ImageWords, MapBuilder, weigh};
#[cfg(target_arch = "x86_64")]
use crate::vocabulary::binary::has_popcnt;
use crate::vocabulary::binary::{BinaryDescriptor, BinaryVocabulary, hamming};
use rayon::prelude::*;

/// A word pair's descriptors may differ in at most this many bits.
pub const MAX_PAIR_HAMMING: u32 = 64;

/// One image's ORB keypoint centres (pixels of the extraction frame) and
/// descriptors, in the same order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OrbImage {
    pub centres: Vec<[f32; 2]>,
    pub descriptors: Vec<BinaryDescriptor>,
}

/// What verifying one candidate found: its inliers and the scale the map
/// image sees the scene at against the query ([`relative_scale`] of the
/// inliers; `None` without any).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checked {
    pub image: u32,
    pub inliers: usize,
    pub scale: Option<f32>,
}

/// One map image's features sorted by word, for word pairs.
#[derive(Debug, Clone, Default)]
struct ByWord {
    /// (word, feature), sorted.
    features: Vec<(u32, u32)>,
}

impl ByWord {
    fn new(words: &[u32]) -> Self {
        let mut features: Vec<(u32, u32)> = words
            .iter()
            .enumerate()
            .map(|(i, &w)| (w, i as u32))
            .collect();
        features.sort_unstable();
        Self { features }
    }

    /// The image's features of word `w`.
    fn of(&self, w: u32) -> impl Iterator<Item = usize> + '_ {
        let start = self.features.partition_point(|&(v, _)| v < w);
        self.features[start..]
            .iter()
            .take_while(move |&&(v, _)| v == w)
            .map(|&(_, i)| i as usize)
    }
}

/// The map's ORB images, their words and the inverted index over them.
#[derive(Debug, Clone)]
pub struct OrbIndex {
    images: Vec<OrbImage>,
    by_word: Vec<ByWord>,
    /// Per word: (map image, tf-idf weight).
    postings: Vec<Vec<(u32, f32)>>,
    idf: Vec<f32>,
}

impl OrbIndex {
    /// Index the map's ORB images (in map order) with `vocabulary`'s words.
    pub fn build(images: Vec<OrbImage>, vocabulary: &BinaryVocabulary) -> Self {
        let words_of: Vec<Vec<u32>> = images
            .par_iter()
            .map(|m| vocabulary.words_of(&m.descriptors))
            .collect();
        let mut builder = MapBuilder::new(vocabulary.len());
        for ws in &words_of {
            builder.add(ImageWords::from_words("", ws));
        }
        let idf = builder.idf();
        let mut postings = vec![Vec::new(); vocabulary.len()];
        for (image, ws) in words_of.iter().enumerate() {
            for (w, x) in weigh(&ImageWords::from_words("", ws), &idf).0 {
                postings[w as usize].push((image as u32, x));
            }
        }
        Self {
            images,
            by_word: words_of.iter().map(|ws| ByWord::new(ws)).collect(),
            postings,
            idf,
        }
    }

    /// Map images indexed.
    pub fn len(&self) -> usize {
        self.images.len()
    }

    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// The `n` map images of the highest cosine score of their tf-idf with
    /// the query's `words`, best first (equal scores in map order).
    pub fn top(&self, words: &[u32], n: usize) -> Vec<u32> {
        let mut score = vec![0f32; self.images.len()];
        for (w, x) in weigh(&ImageWords::from_words("", words), &self.idf).0 {
            for &(image, y) in self.postings.get(w as usize).into_iter().flatten() {
                score[image as usize] += x * y;
            }
        }
        let mut order: Vec<u32> = (0..score.len() as u32).collect();
        order.sort_by(|&a, &b| score[b as usize].total_cmp(&score[a as usize]));
        order.truncate(n);
        order
    }

    /// Word pairs from the query (its features and their `words`) to map
    /// image `m`: each query feature with the map feature of its word whose
    /// descriptor is nearest, if at most [`MAX_PAIR_HAMMING`] bits away.
    pub fn pairs(&self, query: &OrbImage, words: &[u32], m: u32) -> Correspondences {
        #[cfg(target_arch = "x86_64")]
        if has_popcnt() {
            // SAFETY: the CPU has POPCNT
            return unsafe { self.pairs_popcnt(query, words, m) };
        }
        self.pairs_of(query, words, m)
    }

    /// [`OrbIndex::pairs`] compiled with POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "popcnt")]
    fn pairs_popcnt(&self, query: &OrbImage, words: &[u32], m: u32) -> Correspondences {
        self.pairs_of(query, words, m)
    }

    #[inline(always)]
    fn pairs_of(&self, query: &OrbImage, words: &[u32], m: u32) -> Correspondences {
        let (map, by_word) = (&self.images[m as usize], &self.by_word[m as usize]);
        let mut c = Correspondences::default();
        for ((&w, d), &centre) in words.iter().zip(&query.descriptors).zip(&query.centres) {
            let nearest = by_word
                .of(w)
                .map(|j| (hamming(d, &map.descriptors[j]), j))
                .min();
            if let Some((h, j)) = nearest
                && h <= MAX_PAIR_HAMMING
            {
                c.query.push(centre);
                c.map.push(map.centres[j]);
            }
        }
        c
    }

    /// Verify the query against its `top` best-voted map images (`words`:
    /// the query's binary words): each one's inliers and scale, in vote
    /// order.
    pub fn check(
        &self,
        query: &OrbImage,
        words: &[u32],
        top: usize,
        fit: &dyn ModelFit,
    ) -> Vec<Checked> {
        self.top(words, top)
            .into_iter()
            .map(|m| {
                let (v, inliers) = fit_inliers(&self.pairs(query, words, m), fit, 0);
                Checked {
                    image: m,
                    inliers: v.inliers,
                    scale: relative_scale(&inliers).filter(|_| v.inliers > 0),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::verify::{Estimator, FitError, FitParams, Model};

    /// A fit that takes every pair within 1 px of `q · 2` as an inlier (a
    /// known scale of 2, no rotation or shift).
    struct Doubling(FitParams);

    impl ModelFit for Doubling {
        fn params(&self) -> &FitParams {
            &self.0
        }
        fn inliers(&self, query: &[[f32; 2]], map: &[[f32; 2]]) -> Result<Vec<bool>, FitError> {
            Ok(query
                .iter()
                .zip(map)
                .map(|(q, m)| (q[0] * 2.0 - m[0]).hypot(q[1] * 2.0 - m[1]) < 1.0)
                .collect())
        }
    }

    fn descriptor(seed: u64) -> BinaryDescriptor {
        let x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        [x, x.rotate_left(17), x.rotate_left(31), x.rotate_left(47)]
    }

    #[test]
    fn the_map_image_sharing_the_querys_words_verifies_at_its_scale() {
        // 40 distinct descriptors, each its own word
        let ds: Vec<BinaryDescriptor> = (0..40).map(descriptor).collect();
        let vocabulary = BinaryVocabulary::train(&ds, 40, 1, 1);
        let grid = |i: usize| [(i % 8) as f32 * 20.0 + 5.0, (i / 8) as f32 * 15.0 + 3.0];
        let query = OrbImage {
            centres: (0..30).map(grid).collect(),
            descriptors: ds[..30].to_vec(),
        };
        // image 1 sees the query's scene twice as large, with 5 pairs moved
        let seen = OrbImage {
            centres: (0..30)
                .map(|i| {
                    let [x, y] = grid(i);
                    if i % 6 == 0 {
                        [y, x + 50.0]
                    } else {
                        [2.0 * x, 2.0 * y]
                    }
                })
                .collect(),
            descriptors: ds[..30].to_vec(),
        };
        // image 0 shares no word with the query
        let other = OrbImage {
            centres: (0..10).map(grid).collect(),
            descriptors: ds[30..].to_vec(),
        };
        let index = OrbIndex::build(vec![other, seen], &vocabulary);
        let words = vocabulary.words_of(&query.descriptors);
        assert_eq!(index.top(&words, 2), vec![1, 0]);
        let fit = Doubling(FitParams {
            model: Model::Similarity,
            estimator: Estimator::Ransac,
            threshold_px: 1.0,
            confidence: 0.99,
            max_iters: 10,
        });
        let checked = index.check(&query, &words, 2, &fit);
        assert_eq!(checked[0].image, 1);
        assert_eq!(checked[0].inliers, 25);
        assert!((checked[0].scale.unwrap() - 2.0).abs() < 1e-4);
        assert_eq!(
            (checked[1].image, checked[1].inliers, checked[1].scale),
            (0, 0, None)
        );
        // the pairs are the same with POPCNT (where the CPU has it) as without
        for m in 0..2 {
            let (fast, portable) = (
                index.pairs(&query, &words, m),
                index.pairs_of(&query, &words, m),
            );
            assert_eq!((fast.query, fast.map), (portable.query, portable.map));
        }
    }
}

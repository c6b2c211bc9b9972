//! Tentative correspondences between a query and one map image: every pair of
//! features that quantized to the same visual word and whose Hamming
//! signatures differ in at most `max_distance` bits. A word frequent in either
//! image (a repeated texture) would add many pairs of which at most one can
//! be right, so words giving more than `max_word_pairs` such pairs are
//! skipped.

use super::Keypoint;
use super::packed::PackedFeature;
use crate::vocabulary::hamming::distance;

/// One query feature as verification sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueryFeature {
    pub word: u32,
    /// Its Hamming signature (0 without an embedding).
    pub signature: u64,
    pub keypoint: Keypoint,
}

impl From<(u32, Keypoint)> for QueryFeature {
    /// A feature without a signature.
    fn from((word, keypoint): (u32, Keypoint)) -> Self {
        Self {
            word,
            signature: 0,
            keypoint,
        }
    }
}

/// A query's features by word, ready to be matched against many map images.
#[derive(Debug, Clone, Default)]
pub struct QueryFeatures {
    /// (word, signature, position), sorted by word.
    sorted: Vec<(u32, u64, [f32; 2])>,
}

impl QueryFeatures {
    pub fn new<F: Into<QueryFeature> + Copy>(features: &[F]) -> Self {
        let mut sorted: Vec<(u32, u64, [f32; 2])> = features
            .iter()
            .map(|&f| {
                let f: QueryFeature = f.into();
                (f.word, f.signature, [f.keypoint.x, f.keypoint.y])
            })
            .collect();
        // by word, then position: the pairs, hence the fit, do not depend on
        // the order the features came in
        sorted.sort_by(|a, b| {
            (a.0, a.2[0], a.2[1], a.1)
                .partial_cmp(&(b.0, b.2[0], b.2[1], b.1))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        Self { sorted }
    }

    pub fn len(&self) -> usize {
        self.sorted.len()
    }

    pub fn is_empty(&self) -> bool {
        self.sorted.is_empty()
    }
}

/// Matched positions: `query[i]` ↔ `map[i]`. Identical pairs (a keypoint
/// SIFT reports twice, once per orientation) appear once.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Correspondences {
    pub query: Vec<[f32; 2]>,
    pub map: Vec<[f32; 2]>,
}

impl Correspondences {
    pub fn len(&self) -> usize {
        self.query.len()
    }

    pub fn is_empty(&self) -> bool {
        self.query.is_empty()
    }
}

/// Pairs of features sharing a word with signatures at most `max_distance`
/// bits apart (a merge of the two word-sorted lists). `map` must be sorted by
/// word, as [`super::packed::pack_image`] stores it.
pub fn tentative(
    query: &QueryFeatures,
    map: &[PackedFeature],
    max_word_pairs: usize,
    max_distance: u32,
) -> Correspondences {
    let q = &query.sorted;
    let mut out = Correspondences::default();
    let mut seen: Vec<([u32; 2], [u32; 2])> = Vec::new();
    let mut pairs: Vec<([f32; 2], [f32; 2])> = Vec::new();
    let (mut i, mut j) = (0, 0);
    while i < q.len() && j < map.len() {
        let (wq, wm) = (q[i].0, map[j].word);
        if wq < wm {
            i += 1;
        } else if wm < wq {
            j += 1;
        } else {
            let qe = i + q[i..].iter().take_while(|f| f.0 == wq).count();
            let me = j + map[j..].iter().take_while(|f| f.word == wq).count();
            for qf in &q[i..qe] {
                for mf in &map[j..me] {
                    if distance(qf.1, mf.signature()) > max_distance {
                        continue;
                    }
                    let m = mf.point();
                    let key = (qf.2.map(f32::to_bits), m.map(f32::to_bits));
                    if !seen.contains(&key) {
                        seen.push(key);
                        pairs.push((qf.2, m));
                    }
                }
            }
            if pairs.len() <= max_word_pairs {
                for &(a, b) in &pairs {
                    out.query.push(a);
                    out.map.push(b);
                }
            }
            seen.clear();
            pairs.clear();
            i = qe;
            j = me;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::packed::pack_image;
    use super::*;

    fn kp(x: f32, y: f32) -> Keypoint {
        Keypoint {
            x,
            y,
            size: 2.0,
            angle: 0.0,
            response: 0.0,
        }
    }

    fn map(features: &[(u32, f32, f32)]) -> Vec<PackedFeature> {
        let words: Vec<u32> = features.iter().map(|f| f.0).collect();
        let kps: Vec<Keypoint> = features.iter().map(|f| kp(f.1, f.2)).collect();
        pack_image(&words, &[], &kps)
    }

    #[test]
    fn shared_words_pair_up_and_frequent_words_are_skipped() {
        let query = QueryFeatures::new(&[
            (7, kp(1.0, 1.0)),
            (3, kp(2.0, 2.0)),
            (9, kp(3.0, 3.0)),
            (9, kp(4.0, 4.0)),
            (5, kp(6.0, 6.0)),
        ]);
        let m = map(&[
            (3, 10.0, 10.0),
            (9, 30.0, 30.0),
            (9, 40.0, 40.0),
            (9, 50.0, 50.0),
            (7, 70.0, 70.0),
            (8, 80.0, 80.0),
        ]);
        let c = tentative(&query, &m, 4, 64);
        // word 9 gives 2 × 3 = 6 pairs > 4: skipped; words 5 and 8 are unshared.
        assert_eq!(c.query, vec![[2.0, 2.0], [1.0, 1.0]]);
        assert_eq!(c.map, vec![[10.0, 10.0], [70.0, 70.0]]);
        assert_eq!(tentative(&query, &m, 6, 64).len(), 8);
        assert!(tentative(&query, &[], 4, 64).is_empty());
        assert!(tentative(&QueryFeatures::default(), &m, 4, 64).is_empty());
    }

    #[test]
    fn pairs_do_not_depend_on_the_order_of_the_query_features() {
        let features = [
            (2, kp(9.0, 1.0)),
            (2, kp(3.0, 4.0)),
            (1, kp(5.0, 5.0)),
            (2, kp(3.0, 2.0)),
        ];
        let mut reversed = features;
        reversed.reverse();
        let m = map(&[(1, 1.0, 1.0), (2, 2.0, 2.0)]);
        assert_eq!(
            tentative(&QueryFeatures::new(&features), &m, 4, 64),
            tentative(&QueryFeatures::new(&reversed), &m, 4, 64)
        );
    }

    #[test]
    fn pairs_with_distant_signatures_are_dropped_before_the_cap() {
        let k = kp(1.0, 1.0);
        let query = QueryFeatures::new(&[
            QueryFeature {
                word: 9,
                signature: 0,
                keypoint: k,
            },
            QueryFeature {
                word: 9,
                signature: u64::MAX,
                keypoint: kp(2.0, 2.0),
            },
        ]);
        let m = pack_image(&[9, 9], &[0b111, u64::MAX], &[kp(5.0, 5.0), kp(6.0, 6.0)]);
        // all 4 pairs without a distance limit: over a cap of 3
        assert!(tentative(&query, &m, 3, 64).is_empty());
        // within 3 bits: (0, 0b111) and (MAX, MAX)
        let c = tentative(&query, &m, 3, 3);
        assert_eq!(c.query, vec![[1.0, 1.0], [2.0, 2.0]]);
        assert_eq!(c.map, vec![[5.0, 5.0], [6.0, 6.0]]);
    }

    #[test]
    fn repeated_keypoints_give_one_pair() {
        let query = QueryFeatures::new(&[(1, kp(5.0, 5.0)), (1, kp(5.0, 5.0))]);
        let c = tentative(&query, &map(&[(1, 8.0, 8.0)]), 4, 64);
        assert_eq!(c.len(), 1);
    }
}

//! Binary visual words: K 256-bit centroids of binary descriptors (ORB's),
//! trained by k-majority (k-means under the Hamming distance, each centroid
//! the bitwise majority of the descriptors nearest it) and searched
//! exhaustively with popcounts. Plain arrays only: OpenCV, which makes the
//! descriptors, stays at the extraction edge (`features::orb`); the ORB pass
//! ([`crate::orb_pass`]) votes with these words.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A 256-bit binary descriptor, as four little-endian words.
pub type BinaryDescriptor = [u64; 4];

/// Bits that differ between two descriptors.
#[inline(always)]
pub fn hamming(a: &BinaryDescriptor, b: &BinaryDescriptor) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// Whether this CPU counts bits in one instruction (x86-64's POPCNT, which
/// the baseline target leaves out): the loops over many descriptors are
/// compiled twice, with and without it, and the CPU runs the one it can.
#[inline]
pub fn has_popcnt() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Descriptors from OpenCV-style rows of 32 bytes (the bytes of a row in
/// order, bit 0 of byte 0 first). A trailing partial row is dropped.
pub fn from_rows(bytes: &[u8]) -> Vec<BinaryDescriptor> {
    bytes
        .chunks_exact(32)
        .map(|row| {
            std::array::from_fn(|i| {
                u64::from_le_bytes(row[i * 8..i * 8 + 8].try_into().expect("8 bytes"))
            })
        })
        .collect()
}

/// K binary words.
#[derive(Debug, Clone, PartialEq)]
pub struct BinaryVocabulary {
    words: Vec<BinaryDescriptor>,
}

impl BinaryVocabulary {
    /// Train `k` words on `data` by k-majority: start from `k` descriptors
    /// drawn with `seed` as k-means++ draws them (each next one with a
    /// chance growing with the square of its distance to the nearest drawn
    /// so far), then `iterations` rounds of assigning every
    /// descriptor to its nearest word and setting each word to the bitwise
    /// majority of its descriptors (a word left without any is drawn
    /// again). Fewer descriptors than `k` give one word per descriptor.
    pub fn train(data: &[BinaryDescriptor], k: usize, iterations: usize, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        if data.len() <= k {
            return Self {
                words: data.to_vec(),
            };
        }
        let mut words = spread_seeds(data, k, &mut rng);
        for _ in 0..iterations {
            let assigned: Vec<u32> = data.par_iter().map(|d| nearest(&words, d)).collect();
            let mut ones = vec![[0u32; 256]; k];
            let mut sizes = vec![0u32; k];
            for (d, &w) in data.iter().zip(&assigned) {
                let w = w as usize;
                sizes[w] += 1;
                for (bit, count) in ones[w].iter_mut().enumerate() {
                    *count += ((d[bit / 64] >> (bit % 64)) & 1) as u32;
                }
            }
            for (w, word) in words.iter_mut().enumerate() {
                *word = if sizes[w] == 0 {
                    data[rng.random_range(0..data.len())]
                } else {
                    majority(&ones[w], sizes[w])
                };
            }
        }
        Self { words }
    }

    /// Words as given (as read from a file).
    pub fn from_words(words: Vec<BinaryDescriptor>) -> Self {
        Self { words }
    }

    /// The words as trained.
    pub fn words(&self) -> &[BinaryDescriptor] {
        &self.words
    }

    /// How many words.
    pub fn len(&self) -> usize {
        self.words.len()
    }

    /// No words at all.
    pub fn is_empty(&self) -> bool {
        self.words.is_empty()
    }

    /// The nearest word's index (the lowest on ties); 0 for an empty
    /// vocabulary.
    pub fn word(&self, d: &BinaryDescriptor) -> u32 {
        nearest(&self.words, d)
    }

    /// The word of each descriptor, in order.
    pub fn words_of(&self, ds: &[BinaryDescriptor]) -> Vec<u32> {
        #[cfg(target_arch = "x86_64")]
        if has_popcnt() {
            // SAFETY: the CPU has POPCNT
            return unsafe { words_popcnt(&self.words, ds) };
        }
        ds.iter().map(|d| nearest(&self.words, d)).collect()
    }
}

/// [`BinaryVocabulary::words_of`] compiled with POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "popcnt")]
fn words_popcnt(words: &[BinaryDescriptor], ds: &[BinaryDescriptor]) -> Vec<u32> {
    ds.iter().map(|d| nearest(words, d)).collect()
}

/// The index of the word nearest `d` (the lowest on ties; 0 when there are
/// none).
#[inline(always)]
fn nearest(words: &[BinaryDescriptor], d: &BinaryDescriptor) -> u32 {
    let mut best = (u32::MAX, 0u32);
    for (w, c) in words.iter().enumerate() {
        let h = hamming(c, d);
        if h < best.0 {
            best = (h, w as u32);
        }
    }
    best.1
}

/// `k` of `data`, the first uniformly, each next with a chance
/// proportional to its squared distance to the nearest one drawn so far.
fn spread_seeds(
    data: &[BinaryDescriptor],
    k: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<BinaryDescriptor> {
    let mut words = vec![data[rng.random_range(0..data.len())]];
    let mut nearest: Vec<u32> = data.par_iter().map(|d| hamming(d, &words[0])).collect();
    while words.len() < k {
        let total: u64 = nearest.iter().map(|&d| u64::from(d * d)).sum();
        let next = if total == 0 {
            // every descriptor is a word already: any will do
            data[rng.random_range(0..data.len())]
        } else {
            let mut at = rng.random_range(0..total);
            let i = nearest
                .iter()
                .position(|&d| {
                    let w = u64::from(d * d);
                    if at < w {
                        return true;
                    }
                    at -= w;
                    false
                })
                .expect("a draw below the total");
            data[i]
        };
        nearest
            .par_iter_mut()
            .zip(data)
            .for_each(|(n, d)| *n = (*n).min(hamming(d, &next)));
        words.push(next);
    }
    words
}

/// The descriptor whose bit is set where more than half of `size`
/// descriptors had it set.
fn majority(ones: &[u32; 256], size: u32) -> BinaryDescriptor {
    let mut word = [0u64; 4];
    for (bit, &count) in ones.iter().enumerate() {
        if 2 * count > size {
            word[bit / 64] |= 1 << (bit % 64);
        }
    }
    word
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` descriptors around each of `centres`, each with `flips` random
    /// bits flipped.
    fn clusters(centres: &[BinaryDescriptor], n: usize, flips: usize) -> Vec<BinaryDescriptor> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut out = Vec::new();
        for c in centres {
            for _ in 0..n {
                let mut d = *c;
                for _ in 0..flips {
                    let bit = rng.random_range(0..256usize);
                    d[bit / 64] ^= 1 << (bit % 64);
                }
                out.push(d);
            }
        }
        out
    }

    fn random_descriptors(n: usize, seed: u64) -> Vec<BinaryDescriptor> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.random()))
            .collect()
    }

    #[test]
    fn hamming_counts_differing_bits() {
        let a = [0, 0, 0, 0];
        let b = [0b1011, 0, 1 << 63, u64::MAX];
        assert_eq!(hamming(&a, &b), 3 + 1 + 64);
        assert_eq!(hamming(&b, &b), 0);
    }

    #[test]
    fn rows_are_read_little_endian_and_partial_rows_dropped() {
        let mut bytes = vec![0u8; 32 + 5];
        bytes[0] = 1;
        bytes[9] = 0x80;
        let d = from_rows(&bytes);
        assert_eq!(d, vec![[1, 1 << 15, 0, 0]]);
    }

    #[test]
    fn k_majority_recovers_separated_clusters() {
        let centres = random_descriptors(4, 1);
        let data = clusters(&centres, 50, 20);
        let vocabulary = BinaryVocabulary::train(&data, 4, 10, 3);
        // every centre has a word within a few bits of it, and every
        // descriptor's word is its own centre's
        for c in &centres {
            let w = vocabulary.word(c) as usize;
            assert!(hamming(&vocabulary.words()[w], c) <= 4, "{c:?}");
        }
        for (i, d) in data.iter().enumerate() {
            let centre = &centres[i / 50];
            assert_eq!(vocabulary.word(d), vocabulary.word(centre));
        }
    }

    #[test]
    fn the_nearest_word_is_the_exhaustive_minimum() {
        let vocabulary = BinaryVocabulary::train(&random_descriptors(500, 2), 16, 3, 1);
        for d in random_descriptors(100, 3) {
            let w = vocabulary.word(&d) as usize;
            let min = vocabulary.words().iter().map(|c| hamming(c, &d)).min();
            assert_eq!(Some(hamming(&vocabulary.words()[w], &d)), min);
        }
        // all at once (with POPCNT where the CPU has it), the same words
        let ds = random_descriptors(100, 3);
        let one_by_one: Vec<u32> = ds.iter().map(|d| vocabulary.word(d)).collect();
        assert_eq!(vocabulary.words_of(&ds), one_by_one);
    }

    #[test]
    fn training_is_deterministic_by_seed_and_small_sets_keep_every_descriptor() {
        let data = random_descriptors(300, 4);
        let a = BinaryVocabulary::train(&data, 8, 4, 11);
        assert_eq!(a, BinaryVocabulary::train(&data, 8, 4, 11));
        assert_ne!(a, BinaryVocabulary::train(&data, 8, 4, 12));
        assert_eq!(a.len(), 8);
        let few = BinaryVocabulary::train(&data[..5], 8, 4, 11);
        assert_eq!(few.words(), &data[..5]);
        assert_eq!(BinaryVocabulary::train(&[], 8, 4, 1).word(&data[0]), 0);
    }
}

//! Synthetic maps for benchmarks: images whose words follow a Zipf law, as
//! visual words do in real image collections (a few words are everywhere,
//! most are rare), so posting-list lengths are realistic at any map size.

use super::{ImageWords, MapBuilder, MapIndex};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Draws word ids with P(w) ∝ 1/(w + 1)^exponent by inverting the CDF.
pub struct Zipf {
    cdf: Vec<f64>,
}

impl Zipf {
    pub fn new(words: usize, exponent: f64) -> Self {
        let mut cdf: Vec<f64> = (0..words)
            .map(|w| 1.0 / ((w + 1) as f64).powf(exponent))
            .collect();
        let mut acc = 0.0;
        for p in &mut cdf {
            acc += *p;
            *p = acc;
        }
        for p in &mut cdf {
            *p /= acc;
        }
        Self { cdf }
    }

    pub fn sample(&self, rng: &mut ChaCha8Rng) -> u32 {
        let u: f64 = rng.random();
        self.cdf.partition_point(|&c| c < u).min(self.cdf.len() - 1) as u32
    }
}

/// A map of `images` images, each with `features` features drawn from a
/// Zipf(1) law over `words` words (word ids shuffled so frequency does not
/// follow id order).
pub fn zipf_map(images: usize, words: usize, features: usize, seed: u64) -> MapIndex {
    let zipf = Zipf::new(words, 1.0);
    let all: Vec<ImageWords> = (0..images)
        .into_par_iter()
        .map(|j| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (j as u64).wrapping_mul(0x9E37_79B9));
            let ws: Vec<u32> = (0..features)
                .map(|_| scramble(zipf.sample(&mut rng), words))
                .collect();
            ImageWords::from_words(format!("synthetic/{j}"), &ws)
        })
        .collect();
    let mut builder = MapBuilder::new(words);
    for image in all {
        builder.add(image);
    }
    builder.build(&format!("zipf-{images}"), "synthetic", None)
}

/// Query words drawn from the same law as [`zipf_map`].
pub fn zipf_query(words: usize, features: usize, seed: u64) -> Vec<u32> {
    let zipf = Zipf::new(words, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..features)
        .map(|_| scramble(zipf.sample(&mut rng), words))
        .collect()
}

/// A fixed bijection of 0..words (multiplication by a unit modulo words).
fn scramble(w: u32, words: usize) -> u32 {
    let n = words as u64;
    let mut a = 2_654_435_761u64 % n;
    while gcd(a, n) != 1 {
        a += 1;
    }
    ((w as u64 * a) % n) as u32
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zipf_frequencies_fall_with_rank() {
        let z = Zipf::new(1000, 1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut counts = vec![0u32; 1000];
        for _ in 0..100_000 {
            counts[z.sample(&mut rng) as usize] += 1;
        }
        assert!(counts[0] > 5 * counts[9] && counts[9] > 5 * counts[99]);
    }

    #[test]
    fn scramble_is_a_bijection() {
        let mut seen: Vec<u32> = (0..5000).map(|w| scramble(w, 5000)).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..5000).collect::<Vec<u32>>());
    }

    #[test]
    fn synthetic_map_has_the_requested_shape() {
        let m = zipf_map(100, 500, 40, 3);
        assert_eq!(m.images(), 100);
        assert_eq!(m.words(), 500);
        assert!(m.meta().postings > 100 * 10);
    }
}

//! The random order features are streamed in: a Fisher–Yates shuffle driven by
//! ChaCha8, so a seed gives the same order on every platform.

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// A permutation of `0..n` determined by `seed`.
pub fn permutation(n: usize, seed: u64) -> Vec<u32> {
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    order
}

/// Salt of the tile order's seed, so the order of the tiles and the order of
/// the features inside the first tile are not drawn from the same stream.
const TILE_ORDER_SALT: u64 = 0x7469_6c65_6f72_6465;

/// The order in which an image's `n` tiles are extracted, determined by the
/// search's seed.
pub fn tile_order(n: usize, seed: u64) -> Vec<u32> {
    permutation(n, seed ^ TILE_ORDER_SALT)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_a_permutation_fixed_by_its_seed() {
        let a = permutation(1000, 42);
        let mut sorted = a.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..1000).collect::<Vec<u32>>());
        assert_eq!(a, permutation(1000, 42));
        assert_ne!(a, permutation(1000, 43));
        assert_ne!(a, sorted);
    }
}

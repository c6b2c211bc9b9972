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

/// The order in which an image's `n` extraction units are extracted,
/// determined by the search's seed: the tiles in a random order, after the
/// coarse pass (unit 0) when there is one.
pub fn tile_order(n: usize, coarse_first: bool, seed: u64) -> Vec<u32> {
    match coarse_first {
        true if n > 0 => std::iter::once(0)
            .chain(
                permutation(n - 1, seed ^ TILE_ORDER_SALT)
                    .into_iter()
                    .map(|t| t + 1),
            )
            .collect(),
        _ => permutation(n, seed ^ TILE_ORDER_SALT),
    }
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

    #[test]
    fn a_coarse_pass_comes_first() {
        let fine = tile_order(4, false, 9);
        let coarse = tile_order(5, true, 9);
        assert_eq!(coarse[0], 0);
        let shifted: Vec<u32> = fine.iter().map(|t| t + 1).collect();
        assert_eq!(coarse[1..], shifted[..]);
    }
}

//! The order features and tiles are streamed in. Features: a Fisher–Yates
//! shuffle driven by ChaCha8, so a seed gives the same order on every
//! platform. Tiles ([`TileOrder`]): richest first, by a count of corners
//! taken before extraction, or at random; and, for the feature-count
//! estimate, the share of the image's keypoints each tile is expected to hold.

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

/// In which order a query's tiles are extracted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TileOrder {
    /// Most corners first (FAST corners counted on the half-size frame
    /// before any tile is extracted); ties in a random order from the seed.
    /// The tiles richest in keypoints come first, so a search that stops
    /// early has seen more features for its time (docs/results.md, "Tile
    /// order").
    #[default]
    Richest,
    /// The tile with most corners first, then each next tile the one
    /// farthest from those already extracted, more corners first among
    /// equally far ones: the rich part of the image first, then the rest of
    /// it spread out.
    Spread,
    /// A random order drawn from the search's seed.
    Random,
}

impl TileOrder {
    /// Every order, the default first.
    pub const ALL: [TileOrder; 3] = [TileOrder::Richest, TileOrder::Spread, TileOrder::Random];

    pub fn name(self) -> &'static str {
        match self {
            TileOrder::Richest => "richest",
            TileOrder::Spread => "spread",
            TileOrder::Random => "random",
        }
    }

    /// What the order does, in a line (for help texts).
    pub fn about(self) -> &'static str {
        match self {
            TileOrder::Richest => "most FAST corners first",
            TileOrder::Spread => "the richest tile, then each next the farthest from those taken",
            TileOrder::Random => "a random order drawn from the seed",
        }
    }

    /// Whether the order reads the tiles' corner counts.
    pub fn counts_corners(self) -> bool {
        self != TileOrder::Random
    }
}

named_choice!(TileOrder, "tile order");

/// What is known of a query's tiles before any is extracted, one entry per
/// tile in grid order: its FAST corners and its cell (column, row) in the grid.
#[derive(Debug, Clone, Copy)]
pub struct TileGuide<'a> {
    pub corners: &'a [f32],
    pub cells: &'a [[u32; 2]],
}

/// The order in which an image's `n` extraction units are extracted: the
/// coarse pass (unit 0) first when there is one, then the tiles in `order`.
/// Ties, and every tile in the random order or without a `guide` that fits
/// the tiles, follow a random order drawn from the search's seed.
pub fn tile_order(
    n: usize,
    coarse_first: bool,
    seed: u64,
    order: TileOrder,
    guide: Option<TileGuide<'_>>,
) -> Vec<u32> {
    let coarse = usize::from(coarse_first && n > 0);
    let mut tiles = permutation(n - coarse, seed ^ TILE_ORDER_SALT);
    let fits = |g: &TileGuide<'_>| g.corners.len() == tiles.len() && g.cells.len() == tiles.len();
    if let Some(g) = guide.filter(fits).filter(|_| order.counts_corners()) {
        let count = |t: u32| g.corners[t as usize].max(0.0);
        // stable: equal counts keep the random order
        tiles.sort_by(|&a, &b| count(b).total_cmp(&count(a)));
        if order == TileOrder::Spread {
            tiles = farthest_first(&tiles, g.cells);
        }
    }
    (0..coarse as u32)
        .chain(tiles.into_iter().map(|t| t + coarse as u32))
        .collect()
}

/// `ranked` (tiles, best first) reordered so that after the first, each
/// tile is the one whose nearest already chosen tile is farthest away (in
/// grid cells); among equally far ones the earlier in `ranked`.
fn farthest_first(ranked: &[u32], cells: &[[u32; 2]]) -> Vec<u32> {
    let distance = |a: u32, b: u32| {
        let ([ax, ay], [bx, by]) = (cells[a as usize], cells[b as usize]);
        ax.abs_diff(bx).pow(2) + ay.abs_diff(by).pow(2)
    };
    let mut left: Vec<u32> = ranked.to_vec();
    let mut out = Vec::with_capacity(left.len());
    while !left.is_empty() {
        let gap = |t: u32| out.iter().map(|&c| distance(t, c)).min().unwrap_or(0);
        // max_by_key keeps the last of equal keys: search the reversed list
        let at = (0..left.len())
            .rev()
            .max_by_key(|&i| gap(left[i]))
            .unwrap_or(0);
        out.push(left.remove(at));
    }
    out
}

/// The share of the image's keypoints each unit is expected to hold, before
/// they are counted: `area` gives each unit's share by area (the coarse
/// pass's assumed share first, when `coarse_first`); with `corners` (one count
/// per tile, grid order) the tiles' part is shared out by their corners
/// instead, when they counted any.
pub fn expected_shares(area: &[f64], coarse_first: bool, corners: Option<&[f32]>) -> Vec<f64> {
    let coarse = usize::from(coarse_first && !area.is_empty());
    let mut shares = area.to_vec();
    let tiles = &mut shares[coarse..];
    if let Some(corners) = corners.filter(|c| c.len() == tiles.len()) {
        let total: f64 = corners.iter().map(|&c| c.max(0.0) as f64).sum();
        let fine: f64 = tiles.iter().sum();
        if total > 0.0 {
            for (s, &c) in tiles.iter_mut().zip(corners) {
                *s = fine * c.max(0.0) as f64 / total;
            }
        }
    }
    shares
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_order_is_listed_first() {
        assert_eq!(TileOrder::ALL[0], TileOrder::default());
    }

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
        let fine = tile_order(4, false, 9, TileOrder::Random, None);
        let coarse = tile_order(5, true, 9, TileOrder::Random, None);
        assert_eq!(coarse[0], 0);
        let shifted: Vec<u32> = fine.iter().map(|t| t + 1).collect();
        assert_eq!(coarse[1..], shifted[..]);
    }

    /// A 2 × 2 grid, row by row.
    const CELLS: [[u32; 2]; 4] = [[0, 0], [1, 0], [0, 1], [1, 1]];

    fn guide(corners: &[f32]) -> Option<TileGuide<'_>> {
        Some(TileGuide {
            corners,
            cells: &CELLS[..corners.len()],
        })
    }

    #[test]
    fn the_richest_tiles_come_first_ties_at_random() {
        let corners = [3.0, 40.0, 3.0, 12.0];
        let richest = |seed, coarse: bool| {
            tile_order(
                4 + coarse as usize,
                coarse,
                seed,
                TileOrder::Richest,
                guide(&corners),
            )
        };
        for seed in 0..20 {
            let order = richest(seed, false);
            assert_eq!(order[..2], [1, 3]);
            let mut rest = order[2..].to_vec();
            rest.sort_unstable();
            assert_eq!(rest, [0, 2]);
            // after a coarse pass, the same tiles shifted by one
            assert_eq!(richest(seed, true)[..3], [0, 2, 4]);
        }
        // ties: both orders of tiles 0 and 2 occur
        let thirds: std::collections::HashSet<u32> =
            (0..40).map(|seed| richest(seed, false)[2]).collect();
        assert_eq!(thirds.len(), 2);
        // a guide of the wrong length, or the random order, ignores the counts
        let random = tile_order(4, false, 9, TileOrder::Random, None);
        assert_eq!(
            tile_order(4, false, 9, TileOrder::Richest, guide(&[1.0])),
            random
        );
        assert_eq!(
            tile_order(4, false, 9, TileOrder::Random, guide(&corners)),
            random
        );
    }

    #[test]
    fn spread_takes_the_richest_then_the_farthest() {
        // tile 1 (top right) is richest; the farthest from it is tile 2
        // (bottom left), whatever its corners; then tile 3 before tile 0
        let corners = [30.0, 40.0, 1.0, 35.0];
        for seed in 0..20 {
            assert_eq!(
                tile_order(4, false, seed, TileOrder::Spread, guide(&corners)),
                [1, 2, 3, 0]
            );
            assert_eq!(
                tile_order(5, true, seed, TileOrder::Spread, guide(&corners)),
                [0, 2, 3, 4, 1]
            );
        }
        // a 3 × 3 grid from a corner: the far corner, then the two others
        let cells: Vec<[u32; 2]> = (0..9).map(|t| [t % 3, t / 3]).collect();
        let mut corners = [1.0f32; 9];
        corners[0] = 9.0;
        let g = Some(TileGuide {
            corners: &corners,
            cells: &cells,
        });
        let order = tile_order(9, false, 3, TileOrder::Spread, g);
        assert_eq!(order[..2], [0, 8]);
        let mut next = order[2..4].to_vec();
        next.sort_unstable();
        assert_eq!(next, [2, 6]);
    }

    #[test]
    fn shares_follow_the_corners_and_keep_their_total() {
        let area = [0.3, 0.175, 0.175, 0.175, 0.175];
        let shares = expected_shares(&area, true, Some(&[1.0, 0.0, 2.0, 1.0]));
        let want = [0.3, 0.175, 0.0, 0.35, 0.175];
        for (s, w) in shares.iter().zip(want) {
            assert!((s - w).abs() < 1e-12, "{shares:?}");
        }
        // no corners anywhere, or none asked: by area
        assert_eq!(expected_shares(&area, true, Some(&[0.0; 4])), area);
        assert_eq!(expected_shares(&area[1..], false, None), area[1..]);
    }
}

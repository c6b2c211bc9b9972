//! Streaming extraction replayed. The cache keeps each query's features
//! grouped by tile (in grid order) with what each tile cost to extract, so
//! the sweep can feed tiles in the order the service would draw for the same
//! seed, stop extracting where the service would, and charge a setting only
//! for the tiles it extracted.

use crate::index::MapIndex;
use crate::search::{self, SearchOptions, SearchOutcome, permute};
use serde::{Deserialize, Serialize};

/// One tile of a cached query, in grid order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tile {
    /// Features the tile kept.
    pub features: u32,
    /// Share of the image's area its core covers.
    pub area: f32,
    /// Extraction time, in milliseconds.
    pub ms: f32,
}

/// A query as the sweep sees it: its words in grid order (tile 0's first),
/// its tiles, and the extraction cost that does not depend on the tiles
/// extracted (decoding and downscaling).
#[derive(Debug, Clone, Default)]
pub struct Query {
    pub words: Vec<u32>,
    /// Empty: the whole image as one tile that cost nothing to extract.
    pub tiles: Vec<Tile>,
    pub fixed_ms: f32,
}

impl Query {
    /// A query of known words extracted whole, with no extraction cost.
    pub fn whole(words: Vec<u32>) -> Self {
        Self {
            words,
            ..Self::default()
        }
    }

    /// Extraction time of the whole image (every tile).
    pub fn full_extract_ms(&self) -> f64 {
        self.fixed_ms as f64 + self.tiles.iter().map(|t| t.ms as f64).sum::<f64>()
    }

    /// Search as the service does with streaming extraction: tiles in the
    /// order drawn from the options' seed, each tile's words fed in a random
    /// order, no tile extracted after the search stops. Returns the outcome,
    /// the tiles extracted and their extraction time (with the fixed cost).
    pub fn search(&self, map: &MapIndex, options: &SearchOptions) -> (SearchOutcome, usize, f64) {
        if self.tiles.is_empty() {
            let o = search::search_words(map, &self.words, options);
            return (o, 1, self.fixed_ms as f64);
        }
        let mut starts = Vec::with_capacity(self.tiles.len() + 1);
        starts.push(0usize);
        for t in &self.tiles {
            starts.push(starts.last().unwrap() + t.features as usize);
        }
        let order = permute::tile_order(self.tiles.len(), options.seed);
        let batches: Vec<(&[u32], f64)> = order
            .iter()
            .map(|&t| {
                let t = t as usize;
                (
                    &self.words[starts[t]..starts[t + 1]],
                    self.tiles[t].area as f64,
                )
            })
            .collect();
        let (outcome, used) = search::search_tiles(map, &batches, options);
        let ms = self.fixed_ms as f64
            + order[..used]
                .iter()
                .map(|&t| self.tiles[t as usize].ms as f64)
                .sum::<f64>();
        (outcome, used, ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::{ImageWords, MapBuilder};
    use crate::search::RuleSpec;

    #[test]
    fn replay_charges_only_the_tiles_extracted() {
        let mut b = MapBuilder::new(4);
        for j in 0..4u32 {
            b.add(ImageWords::from_words(format!("{j}"), &[j]));
        }
        let map = b.build("t", "0", None);
        // four tiles of 10 features each, all voting for image 0
        let tile = Tile {
            features: 10,
            area: 0.25,
            ms: 5.0,
        };
        let q = Query {
            words: vec![0; 40],
            tiles: vec![tile; 4],
            fixed_ms: 2.0,
        };
        assert_eq!(q.full_extract_ms(), 22.0);
        let none = SearchOptions::default();
        let (o, tiles, ms) = q.search(&map, &none);
        assert_eq!((o.features_used, tiles, ms), (40, 4, 22.0));
        // stable-peak 15 stops in the second tile: two tiles extracted
        let early = SearchOptions {
            rule: RuleSpec::new("stable-peak", Some(15.0)).unwrap(),
            ..SearchOptions::default()
        };
        let (o, tiles, ms) = q.search(&map, &early);
        assert_eq!(
            (o.features_used, o.features_total, tiles, ms),
            (16, 20, 2, 12.0)
        );
        // a whole-image query is one batch
        let (o, tiles, ms) = Query::whole(vec![0; 40]).search(&map, &early);
        assert_eq!(
            (o.features_used, o.features_total, tiles, ms),
            (16, 40, 1, 0.0)
        );
    }
}

//! Streaming extraction replayed. The cache keeps each query's features
//! grouped by tile (in grid order) with what each tile cost to extract, so
//! the sweep can feed tiles in the order the service would draw for the same
//! seed, stop extracting where the service would, and charge a setting only
//! for the tiles it extracted.

use crate::geometry::Keypoint;
use crate::geometry::verify::{
    LeaderVerifier, ModelFit, Reranked, VerifyParams, rerank, with_keypoints,
};
use crate::index::MapIndex;
use crate::search::{self, Ranked, SearchOptions, SearchOutcome, permute};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

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
#[derive(Clone, Default)]
pub struct Query {
    pub words: Vec<u32>,
    /// Keypoint of each word (empty: the query cannot be verified).
    pub keypoints: Vec<Keypoint>,
    /// Empty: the whole image as one tile that cost nothing to extract.
    pub tiles: Vec<Tile>,
    pub fixed_ms: f32,
    /// Tile 0 is a coarse pass, extracted first ([`crate::features::TileGrid::coarse`]).
    pub coarse_first: bool,
    /// How to verify it geometrically (the `verified` stop and re-ranking).
    pub geometry: Option<Arc<Geometry>>,
}

/// Geometric verification as the service does it.
pub struct Geometry {
    pub fit: Box<dyn ModelFit>,
    pub params: VerifyParams,
}

/// What replaying one search gave.
pub struct Replay {
    pub outcome: SearchOutcome,
    /// Tiles extracted.
    pub tiles: usize,
    /// Decoding and extracting them, in milliseconds.
    pub extract_ms: f64,
    /// Checking the leader during the search and verifying the candidates
    /// after it, in milliseconds.
    pub verify_ms: f64,
    /// The best candidate is geometrically verified.
    pub verified: bool,
}

impl Query {
    /// A query of known words extracted whole, with no extraction cost.
    pub fn whole(words: Vec<u32>) -> Self {
        Self {
            words,
            ..Self::default()
        }
    }

    /// Search as the service does with streaming extraction: tiles in the
    /// order drawn from the options' seed, each tile's words fed in a random
    /// order, no tile extracted after the search stops; with `verify`, the
    /// candidates re-ranked by geometric verification afterwards. A rule
    /// that verifies its leader (`verified`) does so with [`Query::geometry`].
    pub fn search(&self, map: &MapIndex, options: &SearchOptions, verify: bool) -> Replay {
        let whole = [Tile {
            features: self.words.len() as u32,
            area: 1.0,
            ms: 0.0,
        }];
        let tiles: &[Tile] = if self.tiles.is_empty() {
            &whole
        } else {
            &self.tiles
        };
        let mut starts = Vec::with_capacity(tiles.len() + 1);
        starts.push(0usize);
        for t in tiles {
            starts.push(starts.last().unwrap() + t.features as usize);
        }
        let order: Vec<usize> = if tiles.len() == 1 {
            vec![0]
        } else {
            permute::tile_order(tiles.len(), self.coarse_first, options.seed)
                .into_iter()
                .map(|t| t as usize)
                .collect()
        };
        let batches: Vec<(&[u32], f64)> = order
            .iter()
            .map(|&t| (&self.words[starts[t]..starts[t + 1]], tiles[t].area as f64))
            .collect();
        // keypoints in the order the features are given to the search
        let fed_keypoints: Vec<Keypoint> = if self.keypoints.len() == self.words.len() {
            order
                .iter()
                .flat_map(|&t| self.keypoints[starts[t]..starts[t + 1]].iter().copied())
                .collect()
        } else {
            Vec::new()
        };
        let mut check = self.geometry.as_ref().map(|g| LeaderVerifier {
            map,
            fit: &*g.fit,
            params: &g.params,
            keypoints: &fed_keypoints,
        });
        let (mut outcome, voted, used) = search::search_tiles(
            map,
            &batches,
            options,
            check.as_mut().map(|c| c as &mut dyn search::LeaderCheck),
        );
        let mut verify_ms = outcome.timings.verify.as_secs_f64() * 1e3;
        let mut verified = false;
        if verify && let Some(g) = &self.geometry {
            let started = Instant::now();
            let votes: Vec<(u32, f32)> =
                outcome.candidates.iter().map(|r| (r.id, r.score)).collect();
            let reranked: Vec<Reranked> = rerank(
                map,
                &votes,
                &with_keypoints(&voted, &fed_keypoints),
                &*g.fit,
                &g.params,
            );
            verified = reranked
                .first()
                .and_then(|r| r.verification)
                .is_some_and(|v| v.verified);
            outcome.candidates = reranked
                .iter()
                .map(|r| Ranked {
                    id: r.id,
                    score: r.score(),
                })
                .collect();
            verify_ms += started.elapsed().as_secs_f64() * 1e3;
        }
        let extract_ms = self.fixed_ms as f64
            + order[..used]
                .iter()
                .map(|&t| tiles[t].ms as f64)
                .sum::<f64>();
        Replay {
            outcome,
            tiles: used,
            extract_ms,
            verify_ms,
            verified,
        }
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
            ..Query::default()
        };
        let none = SearchOptions::default();
        let r = q.search(&map, &none, false);
        assert_eq!(
            (r.outcome.features_used, r.tiles, r.extract_ms),
            (40, 4, 22.0)
        );
        // stable-peak 15 stops in the second tile: two tiles extracted
        let early = SearchOptions {
            rule: RuleSpec::new("stable-peak", Some(15.0)).unwrap(),
            ..SearchOptions::default()
        };
        let r = q.search(&map, &early, false);
        let o = &r.outcome;
        assert_eq!(
            (o.features_used, o.features_total, r.tiles, r.extract_ms),
            (16, 20, 2, 12.0)
        );
        // a whole-image query is one batch
        let r = Query::whole(vec![0; 40]).search(&map, &early, false);
        let o = &r.outcome;
        assert_eq!(
            (o.features_used, o.features_total, r.tiles, r.extract_ms),
            (16, 40, 1, 0.0)
        );
    }
}

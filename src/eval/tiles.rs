//! Streaming extraction replayed. The cache keeps each query's features
//! grouped by tile (in grid order) with what each tile cost to extract, so
//! the sweep can feed tiles in the order the service would draw for the same
//! seed, stop extracting where the service would, and charge a setting only
//! for the tiles it extracted. Inside a tile the features are voted in the
//! service's random order or, to measure another, strongest first
//! ([`FeatureOrder`]).

use crate::geometry::Keypoint;
use crate::geometry::verify::{
    LeaderVerifier, ModelFit, Reranked, VerifyParams, rerank, with_keypoints,
};
use crate::index::MapIndex;
use crate::search::permute::TileGuide;
use crate::search::{self, Ranked, SearchOptions, SearchOutcome, TileOrder, permute};
use cpu_time::ThreadTime;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Duration;

/// One tile of a cached query, in grid order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tile {
    /// Features the tile kept.
    pub features: u32,
    /// Share of the image's area its core covers.
    pub area: f32,
    /// Extraction time, in milliseconds.
    pub ms: f32,
    /// FAST corners counted in it before extraction (what the tile orders
    /// `spread` and `richest` read; 0 for the coarse pass).
    pub corners: f32,
    /// Its cell (column, row) in the grid.
    pub cell: [u32; 2],
}

/// A query as the sweep sees it: its words in grid order (tile 0's first),
/// its tiles, and the extraction cost that does not depend on the tiles
/// extracted (decoding and downscaling).
#[derive(Clone, Default)]
pub struct Query {
    pub words: Vec<u32>,
    /// Hamming signature of each word (empty: all 0).
    pub signatures: Vec<u64>,
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

/// The order a replayed query's features are voted in, inside each tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeatureOrder {
    /// A random order drawn from the search's seed, as the service votes.
    #[default]
    Random,
    /// The keypoints with the largest detector response first (the same
    /// order on every run).
    Strongest,
}

impl FeatureOrder {
    pub const ALL: [FeatureOrder; 2] = [FeatureOrder::Random, FeatureOrder::Strongest];

    pub fn name(self) -> &'static str {
        match self {
            FeatureOrder::Random => "random",
            FeatureOrder::Strongest => "strongest",
        }
    }

    pub fn about(self) -> &'static str {
        match self {
            FeatureOrder::Random => "a random order drawn from the seed, as the service votes",
            FeatureOrder::Strongest => "the largest detector response first",
        }
    }
}

named_choice!(FeatureOrder, "feature order");

/// Geometric verification as the service does it.
pub struct Geometry {
    pub fit: Box<dyn ModelFit>,
    pub params: VerifyParams,
}

impl Geometry {
    /// OpenCV's fit with `params`, to be shared by every query.
    pub fn shared(params: &VerifyParams) -> Arc<Self> {
        Arc::new(Self {
            fit: Box::new(crate::features::fit::OpenCvFit::new(params.fit())),
            params: params.clone(),
        })
    }
}

/// What replaying one search gave.
pub struct Replay {
    pub outcome: SearchOutcome,
    /// Tiles extracted.
    pub tiles: usize,
    /// Decoding and extracting them, in milliseconds.
    pub extract_ms: f64,
    /// Checking the leader during the search and verifying the candidates
    /// after it, in milliseconds of the thread's CPU time.
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

    /// Where each tile's features start in [`words`](Self::words), in grid
    /// order, and after the last where they end; a query without tiles is
    /// one, the whole image.
    fn starts(&self) -> Vec<usize> {
        if self.tiles.is_empty() {
            return vec![0, self.words.len()];
        }
        let mut starts = Vec::with_capacity(self.tiles.len() + 1);
        starts.push(0usize);
        for t in &self.tiles {
            starts.push(starts.last().unwrap() + t.features as usize);
        }
        starts
    }

    /// Sort the features of each tile by their keypoint's response, the
    /// strongest first (a search told [`SearchOptions::given_order`] then
    /// votes them so). A query without keypoints is left as it is.
    pub fn strongest_first(&mut self) {
        if self.keypoints.len() != self.words.len() {
            return;
        }
        let response = |i: usize| self.keypoints[i].response;
        let mut order: Vec<usize> = Vec::with_capacity(self.words.len());
        for span in self.starts().windows(2) {
            let mut tile: Vec<usize> = (span[0]..span[1]).collect();
            tile.sort_by(|&a, &b| response(b).total_cmp(&response(a)));
            order.extend(tile);
        }
        fn take<T: Copy>(values: &[T], order: &[usize]) -> Vec<T> {
            order.iter().map(|&i| values[i]).collect()
        }
        self.words = take(&self.words, &order);
        self.keypoints = take(&self.keypoints, &order);
        if self.signatures.len() == order.len() {
            self.signatures = take(&self.signatures, &order);
        }
    }

    /// The tiles in the order the service extracts them in `tile_order` for
    /// `seed`: their numbers in grid order, and each one's features as a
    /// span of [`words`](Self::words) with the share of the image's keypoints
    /// the service expects it to hold. A query without tiles is one tile, the
    /// whole image.
    pub fn tile_order(
        &self,
        seed: u64,
        tile_order: TileOrder,
    ) -> (Vec<usize>, Vec<(usize, usize, f64)>) {
        if self.tiles.is_empty() {
            return (vec![0], vec![(0, self.words.len(), 1.0)]);
        }
        let starts = self.starts();
        let coarse = usize::from(self.coarse_first);
        let corners: Vec<f32> = self.tiles.iter().skip(coarse).map(|t| t.corners).collect();
        let cells: Vec<[u32; 2]> = self.tiles.iter().skip(coarse).map(|t| t.cell).collect();
        let corners = (tile_order.counts_corners() && corners.len() > 1).then_some(&corners[..]);
        let guide = corners.map(|corners| TileGuide {
            corners,
            cells: &cells,
        });
        let order: Vec<usize> = if self.tiles.len() == 1 {
            vec![0]
        } else {
            permute::tile_order(self.tiles.len(), self.coarse_first, seed, tile_order, guide)
                .into_iter()
                .map(|t| t as usize)
                .collect()
        };
        let area: Vec<f64> = self.tiles.iter().map(|t| t.area as f64).collect();
        let shares = permute::expected_shares(&area, self.coarse_first, corners);
        let spans = order
            .iter()
            .map(|&t| (starts[t], starts[t + 1], shares[t]))
            .collect();
        (order, spans)
    }

    /// The features of each span of [`tile_order`](Self::tile_order), with its share of the image.
    pub fn batches(&self, spans: &[(usize, usize, f64)]) -> Vec<(search::KnownFeatures<'_>, f64)> {
        spans
            .iter()
            .map(|&(a, b, area)| {
                let features = search::KnownFeatures {
                    words: &self.words[a..b],
                    signatures: self.signatures.get(a..b).unwrap_or(&[]),
                };
                (features, area)
            })
            .collect()
    }

    /// The query's features N, as the search counts them: those of its
    /// tiles, without a coarse pass's (a search the pass does not end
    /// starts over on the tiles, which hold every scale).
    pub fn feature_count(&self) -> usize {
        match (self.coarse_first, &self.tiles[..]) {
            (true, [probe, _, ..]) => self.words.len() - probe.features as usize,
            _ => self.words.len(),
        }
    }

    /// All its features, in grid order.
    pub fn features(&self) -> search::KnownFeatures<'_> {
        search::KnownFeatures {
            words: &self.words,
            signatures: &self.signatures,
        }
    }

    /// Search as the service does with streaming extraction: tiles in the
    /// query's tile order (ties drawn from the options' seed), each tile's words fed in a random
    /// order, no tile extracted after the search stops; with `verify`, the
    /// candidates re-ranked by geometric verification afterwards. A rule
    /// that verifies its leader (`verified`) does so with [`Query::geometry`].
    pub fn search(&self, map: &MapIndex, options: &SearchOptions, verify: bool) -> Replay {
        let (order, spans) = self.tile_order(options.seed, options.tile_order);
        let batches = self.batches(&spans);
        // keypoints in the order the features are given to the search
        let fed_keypoints: Vec<Keypoint> = if self.keypoints.len() == self.words.len() {
            spans
                .iter()
                .flat_map(|&(a, b, _)| self.keypoints[a..b].iter().copied())
                .collect()
        } else {
            Vec::new()
        };
        let mut check = self.geometry.as_ref().map(|g| CpuTimed {
            inner: LeaderVerifier {
                map,
                fit: &*g.fit,
                params: &g.params,
                keypoints: &fed_keypoints,
                place_window: options.place_window,
            },
            spent: Duration::ZERO,
        });
        let (mut outcome, voted, used) = search::search_tiles(
            map,
            &batches,
            options,
            self.coarse_first,
            check.as_mut().map(|c| c as &mut dyn search::LeaderCheck),
        );
        let mut verify_ms = check.map_or(0.0, |c| c.spent.as_secs_f64() * 1e3);
        let mut verified = false;
        if verify && let Some(g) = &self.geometry {
            let started = ThreadTime::now();
            let votes: Vec<(u32, f32)> =
                outcome.candidates.iter().map(|r| (r.id, r.score)).collect();
            let reranked: Vec<Reranked> = rerank(
                map,
                &votes,
                &with_keypoints(&voted, &fed_keypoints),
                &*g.fit,
                &g.params,
                options.place_window,
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
                    distinct: search::rank::distinct_of(&outcome.candidates, r.distinct_from),
                })
                .collect();
            verify_ms += started.elapsed().as_secs_f64() * 1e3;
        }
        let extract_ms = self.fixed_ms as f64
            + order[..used]
                .iter()
                .map(|&t| self.tiles.get(t).map_or(0.0, |t| t.ms as f64))
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

/// A leader check timed by the thread's CPU time, as the cache times
/// extraction (the search's own clock is the wall clock, which on a busy
/// machine charges for waiting too).
struct CpuTimed<C> {
    inner: C,
    spent: Duration,
}

impl<C: search::LeaderCheck> search::LeaderCheck for CpuTimed<C> {
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[search::Voted],
        min_inliers: usize,
    ) -> Option<search::stop::CheckedAnswer> {
        let started = ThreadTime::now();
        let answer = self.inner.answer(candidates, voted, min_inliers);
        self.spent += started.elapsed();
        answer
    }

    fn max_log_scale(&self) -> f32 {
        self.inner.max_log_scale()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::{ImageWords, MapBuilder};
    use crate::search::RuleSpec;

    /// A map of four images, image j holding word j alone.
    fn four_images() -> MapIndex {
        let mut b = MapBuilder::new(4);
        for j in 0..4u32 {
            b.add(ImageWords::from_words(format!("{j}"), &[j]));
        }
        b.build("t", "0", None)
    }

    /// A tile of `features` features, a quarter of the image, 5 ms to
    /// extract, no corners, in the grid's first cell.
    fn tile(features: u32) -> Tile {
        Tile {
            features,
            area: 0.25,
            ms: 5.0,
            corners: 0.0,
            cell: [0, 0],
        }
    }

    #[test]
    fn replay_charges_only_the_tiles_extracted() {
        let map = four_images();
        // four tiles of 10 features each, all voting for image 0
        let q = Query {
            words: vec![0; 40],
            tiles: vec![tile(10); 4],
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

    #[test]
    fn strongest_first_sorts_inside_each_tile_and_the_search_votes_in_that_order() {
        let map = four_images();
        let keypoint = |response| Keypoint {
            response,
            ..Keypoint::default()
        };
        // tile 0: words 0, 1, 2 (responses 1, 3, 2); tile 1: words 3, 0
        let mut q = Query {
            words: vec![0, 1, 2, 3, 0],
            signatures: vec![10, 11, 12, 13, 14],
            keypoints: [1.0, 3.0, 2.0, 0.5, 9.0].map(keypoint).to_vec(),
            tiles: vec![tile(3), tile(2)],
            ..Query::default()
        };
        q.strongest_first();
        assert_eq!(q.words, [1, 2, 0, 0, 3]);
        assert_eq!(q.signatures, [11, 12, 10, 14, 13]);
        let responses: Vec<f32> = q.keypoints.iter().map(|k| k.response).collect();
        assert_eq!(responses, [3.0, 2.0, 1.0, 9.0, 0.5]);
        // one feature voted (the image as one batch): told to keep the
        // order given, the search votes the strongest, word 1, every time
        let whole = Query {
            tiles: Vec::new(),
            ..q.clone()
        };
        let first = |seed, given_order| {
            let options = SearchOptions {
                rule: RuleSpec::new("fixed", Some(0.2)).unwrap(),
                seed,
                given_order,
                ..SearchOptions::default()
            };
            let r = whole.search(&map, &options, false);
            assert_eq!(r.outcome.features_used, 1);
            r.outcome.candidates[0].id
        };
        let firsts = |given_order| -> std::collections::HashSet<u32> {
            (0..32).map(|seed| first(seed, given_order)).collect()
        };
        assert_eq!(firsts(true), [1].into());
        assert!(
            firsts(false).len() > 1,
            "a random order starts elsewhere too"
        );
    }

    #[test]
    fn the_richest_tile_is_replayed_first_and_its_corners_set_the_estimate() {
        let map = four_images();
        // tile t's 10 features all vote for image t; tile 2 has most corners
        let corners = [1.0, 0.0, 6.0, 3.0];
        let q = Query {
            words: (0..4u32).flat_map(|t| [t; 10]).collect(),
            tiles: corners
                .iter()
                .enumerate()
                .map(|(t, &c)| Tile {
                    corners: c,
                    cell: [t as u32 % 2, t as u32 / 2],
                    ..tile(10)
                })
                .collect(),
            ..Query::default()
        };
        let first_tiles = |order: TileOrder| -> std::collections::HashSet<usize> {
            (0..32).map(|seed| q.tile_order(seed, order).0[0]).collect()
        };
        assert_eq!(first_tiles(TileOrder::Richest), [2].into());
        let (order, spans) = q.tile_order(7, TileOrder::Richest);
        assert_eq!(order, [2, 3, 0, 1]);
        let shares: Vec<f64> = spans.iter().map(|s| s.2).collect();
        assert_eq!(shares, [0.6, 0.3, 0.1, 0.0]);
        // spread: after tile 2 (bottom left), the farthest, tile 1 (top right)
        let (order, spans) = q.tile_order(7, TileOrder::Spread);
        assert_eq!(order, [2, 1, 3, 0]);
        let shares: Vec<f64> = spans.iter().map(|s| s.2).collect();
        assert_eq!(shares, [0.6, 0.0, 0.3, 0.1]);
        // the search replays the options' order: richest by default, where
        // stable-peak 5 stops inside the first tile, on image 2
        assert_eq!(TileOrder::default(), TileOrder::Richest);
        let early = SearchOptions {
            rule: RuleSpec::new("stable-peak", Some(5.0)).unwrap(),
            ..SearchOptions::default()
        };
        let r = q.search(&map, &early, false);
        assert_eq!((r.tiles, r.outcome.candidates[0].id), (1, 2));
        // at random, other tiles come first too, and the search follows
        assert!(first_tiles(TileOrder::Random).len() > 1);
        let firsts: std::collections::HashSet<u32> = (0..32)
            .map(|seed| {
                let random = SearchOptions {
                    seed,
                    tile_order: TileOrder::Random,
                    ..early.clone()
                };
                q.search(&map, &random, false).outcome.candidates[0].id
            })
            .collect();
        assert!(firsts.len() > 1, "{firsts:?}");
    }
}

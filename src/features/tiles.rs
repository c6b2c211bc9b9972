//! Streaming extraction: the extraction frame cut into a grid of tiles, each
//! extracted on demand, so a search that stops early never pays for the tiles
//! it did not need. A tile is detected on its core rectangle grown by a margin
//! (so a keypoint near a border sees its neighbourhood) and keeps only the
//! keypoints whose centre lies in its core: every keypoint is found once.
//!
//! A grid may also be *coarse first*: before any tile, the whole frame is
//! extracted at half size (about a quarter of the cost), which finds the
//! keypoints of the coarser scales, a probe that may end the search when
//! its answer verifies. When it does not, the tiles that follow are the
//! plain grid's, every scale, and the search starts over on them
//! ([`crate::search::Search::feed_tile`]): an answer not taken on the
//! coarse pass is the tiles alone's.
//!
//! A core that would otherwise idle may extract the tile after the next one
//! at the same time ([`Tiles::extract_ahead`]); it is handed out in its turn,
//! so the search sees the same features in the same order either way.

use super::{ExtractConfig, FeatureError, Features, Frame, GrayImage, Region, Timed};
use crate::search::permute::{self, TileGuide, TileOrder};
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// How a query is cut into tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileGrid {
    /// Tiles across and down (1 × 1: the whole image as one batch).
    pub cols: u32,
    pub rows: u32,
    /// Pixels of context around each tile's core, in the extraction frame.
    pub margin: u32,
    /// Extract the whole frame at half size before the tiles: a probe that
    /// only the verified stop may end; when it does not, the search starts
    /// over on the tiles (every scale).
    #[serde(default)]
    pub coarse: bool,
}

impl TileGrid {
    /// The streaming grid front ends use unless told otherwise: 2 × 2 tiles
    /// with 24 px of context.
    pub const DEFAULT: Self = Self {
        cols: 2,
        rows: 2,
        margin: 24,
        coarse: false,
    };

    /// The whole image in one piece.
    pub const WHOLE: Self = Self {
        cols: 1,
        rows: 1,
        margin: 0,
        coarse: false,
    };

    /// Share of an image's keypoints the coarse pass finds, before it has
    /// run: what the feature-count estimate assumes until the tiles say more.
    /// SIFT's first octave (on the frame upsampled twice) holds most of an
    /// image's keypoints; `bowloc eval --tiles 2x2+24,coarse` prints the
    /// measured share on a dataset.
    pub const COARSE_SHARE: f64 = 0.3;

    /// Smallest tile side: a grid is coarsened so no core is narrower.
    pub const MIN_CORE: u32 = 64;

    /// Extraction units: the tiles, plus the coarse pass.
    pub fn count(&self) -> usize {
        (self.cols.max(1) * self.rows.max(1)) as usize + usize::from(self.coarse)
    }

    /// Check the grid's numbers.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=16).contains(&self.cols) || !(1..=16).contains(&self.rows) {
            return Err(format!(
                "tile grid {}×{}: columns and rows must each lie in 1..=16",
                self.cols, self.rows
            ));
        }
        if self.margin > 256 {
            return Err(format!("tile margin {} px exceeds 256", self.margin));
        }
        Ok(())
    }

    /// The core rectangles (x, y, width, height) of a `width × height`
    /// frame, row by row. A small frame gets fewer, larger tiles (no core
    /// under [`Self::MIN_CORE`] pixels), down to one.
    pub fn cores(&self, width: u32, height: u32) -> Vec<(u32, u32, u32, u32)> {
        let cols = self.cols.max(1).min((width / Self::MIN_CORE).max(1));
        let rows = self.rows.max(1).min((height / Self::MIN_CORE).max(1));
        let edges = |n: u32, len: u32| -> Vec<u32> {
            (0..=n)
                .map(|i| (i as u64 * len as u64 / n as u64) as u32)
                .collect()
        };
        let (xs, ys) = (edges(cols, width), edges(rows, height));
        let mut out = Vec::with_capacity((cols * rows) as usize);
        for r in 0..rows as usize {
            for c in 0..cols as usize {
                out.push((xs[c], ys[r], xs[c + 1] - xs[c], ys[r + 1] - ys[r]));
            }
        }
        out
    }
}

impl std::fmt::Display for TileGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}+{}", self.cols, self.rows, self.margin)?;
        if self.coarse {
            write!(f, ",coarse")?;
        }
        Ok(())
    }
}

impl std::str::FromStr for TileGrid {
    type Err = String;

    /// `COLSxROWS` or `COLSxROWS+MARGIN` (margin in pixels, default 24),
    /// optionally followed by `,coarse`.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("tile grid `{s}`: expected COLSxROWS[+MARGIN][,coarse], e.g. 2x2+24");
        let (spec, coarse) = match s.split_once(',') {
            Some((g, "coarse")) => (g, true),
            Some(_) => return Err(bad()),
            None => (s, false),
        };
        let (grid, margin) = match spec.split_once('+') {
            Some((g, m)) => (g, m.trim().parse().map_err(|_| bad())?),
            None => (spec, 24),
        };
        let (c, r) = grid.split_once(['x', 'X', '×']).ok_or_else(bad)?;
        let t = Self {
            cols: c.trim().parse().map_err(|_| bad())?,
            rows: r.trim().parse().map_err(|_| bad())?,
            margin,
            coarse,
        };
        t.validate()?;
        Ok(t)
    }
}

/// How the service cuts queries: a grid, and whether its coarse pass is
/// learned for the map ([`super::CoarseChoice`]) rather than fixed by the
/// grid. Written as a grid (`2x2+24`, `2x2+24,coarse`) or a grid followed by
/// `,auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TilePlan {
    pub grid: TileGrid,
    pub learn_coarse: bool,
}

impl TilePlan {
    /// The grids its queries may be cut in: the grid alone, or (learned) the
    /// grid without and with the coarse pass.
    pub fn grids(&self) -> Vec<TileGrid> {
        if self.learn_coarse {
            vec![
                TileGrid {
                    coarse: false,
                    ..self.grid
                },
                TileGrid {
                    coarse: true,
                    ..self.grid
                },
            ]
        } else {
            vec![self.grid]
        }
    }
}

impl From<TileGrid> for TilePlan {
    fn from(grid: TileGrid) -> Self {
        Self {
            grid,
            learn_coarse: false,
        }
    }
}

impl std::str::FromStr for TilePlan {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.strip_suffix(",auto") {
            Some(grid) => Ok(Self {
                grid: grid
                    .parse()
                    .map_err(|e: String| format!("{e}, or ending in ,auto"))?,
                learn_coarse: true,
            }),
            None => Ok(Self {
                grid: s
                    .parse()
                    .map_err(|e: String| format!("{e}, or ending in ,auto"))?,
                learn_coarse: false,
            }),
        }
    }
}

impl std::fmt::Display for TilePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.grid)?;
        if self.learn_coarse {
            write!(f, ",auto")?;
        }
        Ok(())
    }
}

/// One piece of streaming extraction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unit {
    /// The whole frame at half size.
    Coarse,
    /// A tile of the grid, by number (row by row).
    Tile(usize),
}

/// The cell (column, row) of each of `cores` (row by row, as
/// [`TileGrid::cores`] gives them).
fn cells(cores: &[(u32, u32, u32, u32)]) -> Vec<[u32; 2]> {
    let cols = cores
        .iter()
        .take_while(|c| c.1 == cores[0].1)
        .count()
        .max(1);
    (0..cores.len())
        .map(|t| [(t % cols) as u32, (t / cols) as u32])
        .collect()
}

/// The tiles of one image extracted ahead of their turn
/// ([`Tiles::extract_ahead`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TilesAhead {
    /// Tiles extracted ahead.
    pub extracted: usize,
    /// One of them was never handed out: the search stopped before it
    /// (or has not asked for it yet).
    pub unused: bool,
}

/// The tiles of one image, extracted one at a time in a given order.
pub struct Tiles {
    frame: Frame,
    cores: Vec<(u32, u32, u32, u32)>,
    margin: u32,
    /// The units in extraction order: the coarse pass (if any) first.
    order: Vec<Unit>,
    /// Each unit's expected share of the image's keypoints, in extraction
    /// order.
    shares: Vec<f64>,
    /// FAST corners per tile (grid order), once counted.
    corners: Option<Vec<f32>>,
    next: usize,
    /// Keypoints the image may keep (0 = all), shared out over the units.
    cap: usize,
    /// Extract two tiles at a time ([`Tiles::extract_ahead`]).
    two_at_a_time: bool,
    /// A unit extracted ahead, by its place in the order, with the time it
    /// took (or its error), waiting its turn.
    ahead: Option<(usize, Result<Timed, FeatureError>)>,
    /// What the unit handed out last took to extract, on its own thread.
    last_time: Duration,
    /// Tiles extracted ahead so far.
    extracted_ahead: usize,
}

impl Tiles {
    /// Prepare `image` for tiled extraction: in grid order (the coarse pass
    /// first) when `order` is `None`, else in the search's [`TileOrder`]
    /// drawn from its seed ([`permute::tile_order`]). Ordering by corners
    /// counts them first, and then also shares the expected keypoints out by
    /// them ([`permute::expected_shares`]). The grid may have been coarsened
    /// for a small image, so the number of units is known only here.
    pub fn new(
        image: &GrayImage,
        config: &ExtractConfig,
        grid: TileGrid,
        order: Option<(TileOrder, u64)>,
    ) -> Result<Self, FeatureError> {
        Self::of_frame(Frame::new(image, config)?, grid, order)
    }

    /// [`Tiles::new`] of an image already in its extraction frame (one an
    /// earlier look at the query made).
    pub fn of_frame(
        frame: Frame,
        grid: TileGrid,
        order: Option<(TileOrder, u64)>,
    ) -> Result<Self, FeatureError> {
        let (w, h) = frame.size();
        let cores = grid.cores(w, h);
        let n = cores.len() + usize::from(grid.coarse);
        let all = (w as f64 * h as f64).max(1.0);
        // the coarse pass's expected share of the image's keypoints, then
        // the tiles' among themselves: the search starts over on them
        let area: Vec<f64> = grid
            .coarse
            .then_some(TileGrid::COARSE_SHARE)
            .into_iter()
            .chain(cores.iter().map(|c| c.2 as f64 * c.3 as f64 / all))
            .collect();
        let corners = match order {
            Some((o, _)) if o.counts_corners() && cores.len() > 1 => {
                Some(frame.corners_per_core(&cores)?)
            }
            _ => None,
        };
        let shares = permute::expected_shares(&area, grid.coarse, corners.as_deref());
        let cells = cells(&cores);
        let order: Vec<Unit> = match order {
            Some((o, seed)) => {
                let guide = corners.as_deref().map(|corners| TileGuide {
                    corners,
                    cells: &cells,
                });
                permute::tile_order(n, grid.coarse, seed, o, guide)
            }
            None => (0..n as u32).collect(),
        }
        .into_iter()
        .map(|u| match (grid.coarse, u as usize) {
            (true, 0) => Unit::Coarse,
            (true, u) => Unit::Tile(u - 1),
            (false, u) => Unit::Tile(u),
        })
        .collect();
        let coarse = usize::from(grid.coarse);
        let shares = order
            .iter()
            .map(|u| match *u {
                Unit::Coarse => shares[0],
                Unit::Tile(i) => shares[i + coarse],
            })
            .collect();
        let cap = frame.max_features();
        Ok(Self {
            margin: if cores.len() == 1 { 0 } else { grid.margin },
            frame,
            cores,
            order,
            shares,
            corners,
            next: 0,
            cap,
            two_at_a_time: false,
            ahead: None,
            last_time: Duration::ZERO,
            extracted_ahead: 0,
        })
    }

    /// Units (tiles and the coarse pass) in all.
    pub fn total(&self) -> usize {
        self.order.len()
    }

    /// Units extracted so far.
    pub fn extracted(&self) -> usize {
        self.next
    }

    /// Each tile's cell (column, row) in the grid, grid order.
    pub fn cells(&self) -> Vec<[u32; 2]> {
        cells(&self.cores)
    }

    /// FAST corners per tile, grid order (`src/features/corners.rs`): counted now
    /// unless the tile order already did; none for an image in one tile,
    /// which has nothing to order.
    pub fn corners(&mut self) -> Result<Vec<f32>, FeatureError> {
        if self.corners.is_none() && self.cores.len() > 1 {
            self.corners = Some(self.frame.corners_per_core(&self.cores)?);
        }
        Ok(self.corners.clone().unwrap_or_default())
    }

    /// The share of the image's keypoints extracted so far, as expected
    /// before they are counted: each tile's share of the frame's area, or of
    /// its corners when the tiles are ordered by them. After a coarse pass
    /// (expected to hold [`TileGrid::COARSE_SHARE`]) the tiles count alone,
    /// as the search that starts over on them does.
    pub fn share_extracted(&self) -> f64 {
        let coarse = self.coarse_units();
        match self.next {
            0 => 0.0,
            n if n <= coarse => self.shares[0],
            n => self.shares[coarse..n].iter().sum(),
        }
    }

    /// 1 when a coarse pass comes first, else 0: the units before the tiles.
    fn coarse_units(&self) -> usize {
        usize::from(self.order.first() == Some(&Unit::Coarse))
    }

    /// The expected share of the unit extracted last ([`Tiles::share_extracted`]
    /// counts the tiles after a coarse pass among themselves; this is each
    /// unit's own, the coarse pass's among the image's keypoints).
    pub fn share_of_last(&self) -> f64 {
        self.next.checked_sub(1).map_or(0.0, |k| self.shares[k])
    }

    /// The expected shares of the units not extracted yet, in the order
    /// they would come, as [`Tiles::share_of_last`] counts them.
    pub fn shares_left(&self) -> &[f64] {
        &self.shares[self.next.min(self.shares.len())..]
    }

    /// From now on (`true`) extract the next tile together with the one
    /// after it, on a second thread, keeping that one for the next call; or
    /// (`false`) one tile at a time. The features are the same either way:
    /// two at a time only uses a core that would otherwise idle, and a tile
    /// extracted ahead of a stop is never handed out. A coarse pass is
    /// always extracted alone.
    pub fn extract_ahead(&mut self, two_at_a_time: bool) {
        self.two_at_a_time = two_at_a_time;
    }

    /// The tiles extracted ahead so far.
    pub fn ahead(&self) -> TilesAhead {
        TilesAhead {
            extracted: self.extracted_ahead,
            unused: self.ahead.is_some(),
        }
    }

    /// The keypoints of the next unit when it is already extracted, ahead
    /// of its turn ([`Tiles::extract_ahead`]): only its votes are left to
    /// wait for.
    pub fn waiting_keypoints(&self) -> Option<usize> {
        match &self.ahead {
            Some((at, Ok((features, _)))) if *at == self.next => Some(features.len()),
            _ => None,
        }
    }

    /// What the unit handed out last took to extract on its own thread
    /// (zero before any): with two at a time, not the wait for it.
    pub fn last_time(&self) -> Duration {
        self.last_time
    }

    /// Extract the next unit: its features in frame coordinates.
    pub fn next_tile(&mut self) -> Option<Result<Features, FeatureError>> {
        let k = self.next;
        let &unit = self.order.get(k)?;
        self.next += 1;
        if let Some((at, extracted)) = self.ahead.take()
            && at == k
        {
            return Some(self.handed_out(extracted));
        }
        let started = Instant::now();
        let cap = self.tile_cap(k);
        let features = match (unit, self.order.get(k + 1)) {
            (Unit::Coarse, _) => self.frame.detect_halved(cap),
            (Unit::Tile(tile), Some(&Unit::Tile(after))) if self.two_at_a_time => {
                let (a, b) = (
                    self.region(tile, cap),
                    self.region(after, self.tile_cap(k + 1)),
                );
                let [first, next] = self.frame.detect_two(a, b);
                self.ahead = Some((k + 1, next));
                self.extracted_ahead += 1;
                return Some(self.handed_out(first));
            }
            (Unit::Tile(tile), _) => self.frame.detect(self.region(tile, cap)),
        };
        self.last_time = started.elapsed();
        Some(features)
    }

    /// Hand out a unit extracted with its time.
    fn handed_out(
        &mut self,
        extracted: Result<Timed, FeatureError>,
    ) -> Result<Features, FeatureError> {
        extracted.map(|(features, took)| {
            self.last_time = took;
            features
        })
    }

    /// Tile `tile`'s region: its core grown by the margin (clipped at the
    /// frame's top and left; [`Frame::detect`] clips the rest), keeping at
    /// most `cap` keypoints.
    fn region(&self, tile: usize, cap: usize) -> Region {
        let core = self.cores[tile];
        let m = self.margin;
        let region = (
            core.0.saturating_sub(m),
            core.1.saturating_sub(m),
            core.2 + m + core.0.min(m),
            core.3 + m + core.1.min(m),
        );
        Region { region, core, cap }
    }

    /// The cap of the k-th unit extracted: a coarse pass, the image's whole;
    /// the tiles, the image's cap split evenly, the remainder to the first
    /// ones, so the tiles' caps add up to the image's (as without the pass).
    fn tile_cap(&self, k: usize) -> usize {
        let coarse = self.coarse_units();
        if self.cap == 0 || k < coarse {
            return self.cap;
        }
        let (n, k) = (self.cores.len(), k - coarse);
        (self.cap / n + usize::from(k < self.cap % n)).max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cores_partition_the_frame() {
        let g: TileGrid = "3x2+24".parse().unwrap();
        let cores = g.cores(640, 360);
        assert_eq!(cores.len(), 6);
        let area: u32 = cores.iter().map(|c| c.2 * c.3).sum();
        assert_eq!(area, 640 * 360);
        assert_eq!(cores[0], (0, 0, 213, 180));
        assert_eq!(cores[5], (426, 180, 214, 180));
    }

    #[test]
    fn small_frames_get_fewer_tiles() {
        let g: TileGrid = "4x4".parse().unwrap();
        assert_eq!(g.cores(160, 120).len(), 2);
        assert_eq!(g.cores(40, 30), vec![(0, 0, 40, 30)]);
    }

    #[test]
    fn grids_parse_and_are_checked() {
        assert_eq!(
            "2x2".parse::<TileGrid>().unwrap(),
            TileGrid {
                cols: 2,
                rows: 2,
                margin: 24,
                coarse: false,
            }
        );
        assert_eq!("1x1+0".parse::<TileGrid>().unwrap(), TileGrid::WHOLE);
        let coarse: TileGrid = "2x2+24,coarse".parse().unwrap();
        assert!(coarse.coarse);
        assert_eq!(
            (coarse.count(), coarse.to_string()),
            (5, "2x2+24,coarse".into())
        );
        for bad in [
            "", "2", "0x2", "2x17", "2x2+x", "2x2+999", "axb", "2x2,fine",
        ] {
            assert!(bad.parse::<TileGrid>().is_err(), "{bad}");
        }
    }
}

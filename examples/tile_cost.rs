//! How well does a time budget foresee the next tile's cost? After `k`
//! tiles of a `2x2+24` query (richest first, as the service orders them),
//! the budget ([`bowloc::search::budget`]) predicts the next tile's
//! extraction time. This replays the eval cache's per-tile timings, FAST
//! corner counts and keypoints, and prints, for each way of predicting, the
//! ratio of the predicted to the actual time (median, 10th and 90th
//! percentiles over queries and tile ends) and how often the prediction was
//! more than 10 % over or under:
//!
//! - `mean of the tiles so far`: the tiles' mean time;
//! - `keypoints, q ms each`: the tiles' mean time apart from their
//!   keypoints, plus `q` for each keypoint the next tile is expected to hold
//!   (the keypoints so far shared out by corners), as
//!   [`bowloc::search::budget::next_tile_time`] does; `q` first as fitted
//!   here (the slope of a tile's time against its keypoints among the tiles
//!   of each query, what the service learns), then at set values;
//! - `own line`: `q` fitted to the query's own tiles alone (from two on);
//! - `corners, a = x`: the mean scaled by `a + (1 - a) * c / c̄` (`c` the
//!   next tile's corners, `c̄` the mean of the tiles so far).
//!
//! First it prints the mean time of the tiles at each place in the order
//! (what the budget's plan prices the first tiles at). Then the
//! predictions, and then the same for all the tiles left after `k` (what a stop after `k`
//! tiles saved, as the answer's `tiles.saved_ms` prices it): the mean of the
//! tiles so far times the tiles left, against each tile left priced by its
//! keypoints ([`bowloc::search::budget::tiles_left_time`]).
//!
//! ```sh
//! cargo run --release --example tile_cost -- ../shared/datasets/gardens-point 5000 1
//! ```
//!
//! It reads (or fills) the eval's caches in `data/eval-cache/<dataset>`.

use bowloc::eval::cache;
use bowloc::features::TileGrid;
use bowloc::search::budget::{TILES_TO_BEAT_THE_PASS, UnitCost, slope_sums, tiles_left_time};
use std::time::Duration;

/// One tile as the cache timed it.
#[derive(Clone, Copy)]
struct TileRow {
    ms: f64,
    corners: f64,
    keypoints: f64,
}

impl TileRow {
    fn unit(&self) -> UnitCost {
        UnitCost {
            time: Duration::from_secs_f64(self.ms / 1e3),
            keypoints: self.keypoints as usize,
        }
    }
}

/// [`slope_sums`] of `tiles`, in ms.
fn slope(tiles: &[TileRow]) -> (f64, f64) {
    let units: Vec<UnitCost> = tiles.iter().map(TileRow::unit).collect();
    let (xy, xx) = slope_sums(&units);
    (xy * 1e3, xx)
}

/// The ratios of `predict(done, next)` to the next tile's time, over every
/// query and tile end from `first` tiles on, printed as one line.
fn report(
    name: &str,
    tiles: &[Vec<TileRow>],
    first: usize,
    predict: &dyn Fn(&[TileRow], &TileRow) -> f64,
) {
    report_ahead(name, tiles, first, &|done, left| predict(done, &left[0]), 1);
}

/// The ratios of `predict(done, ahead)` to the time of the `ahead` tiles
/// after `done` (all those left when `ahead` is `usize::MAX`), over every
/// query and tile end from `first` tiles on, printed as one line.
fn report_ahead(
    name: &str,
    tiles: &[Vec<TileRow>],
    first: usize,
    predict: &dyn Fn(&[TileRow], &[TileRow]) -> f64,
    ahead: usize,
) {
    let mut ratios: Vec<f64> = tiles
        .iter()
        .flat_map(|t| (first..t.len()).map(move |k| (t, k)))
        .map(|(t, k)| (&t[..k], &t[k..(k.saturating_add(ahead)).min(t.len())]))
        .filter(|(_, left)| left.iter().map(|t| t.ms).sum::<f64>() > 0.0)
        .map(|(done, left)| predict(done, left) / left.iter().map(|t| t.ms).sum::<f64>())
        .collect();
    ratios.sort_by(f64::total_cmp);
    let at = |q: f64| ratios[((ratios.len() - 1) as f64 * q).round() as usize];
    let share = |f: &dyn Fn(f64) -> bool| {
        100.0 * ratios.iter().filter(|&&r| f(r)).count() as f64 / ratios.len() as f64
    };
    println!(
        "{name:<28} median {:.3}  p10 {:.3}  p90 {:.3}  over by >10 %: {:4.1} %  under by >10 %: {:4.1} %",
        at(0.5),
        at(0.1),
        at(0.9),
        share(&|r| r > 1.1),
        share(&|r| r < 1.0 / 1.1),
    );
}

/// [`tiles_left_time`] of the tiles `left` at `q` ms a keypoint, in ms,
/// their keypoints expected from the corners.
fn priced(done: &[TileRow], left: &[TileRow], q: f64) -> f64 {
    let costs: Vec<UnitCost> = done.iter().map(TileRow::unit).collect();
    let corners = done.iter().map(|t| t.corners).sum();
    let shares: Vec<f64> = left.iter().map(|t| t.corners).collect();
    let q = Duration::from_secs_f64(q / 1e3);
    tiles_left_time(&costs, corners, &shares, q).as_secs_f64() * 1e3
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let prepared = cache::prepare_from_args(&args, TileGrid::DEFAULT)?;
    // per query: its tiles, richest first
    let tiles: Vec<Vec<TileRow>> = prepared
        .queries
        .meta()
        .tiles
        .iter()
        .filter(|t| t.len() > 1)
        .map(|t| {
            let mut t: Vec<TileRow> = t
                .iter()
                .map(|t| TileRow {
                    ms: t.ms as f64,
                    corners: t.corners as f64,
                    keypoints: t.features as f64,
                })
                .collect();
            t.sort_by(|a, b| b.corners.total_cmp(&a.corners));
            t
        })
        .collect();
    println!(
        "{}: {} queries of {} tiles; predicted / actual time of the next tile, richest first",
        prepared.dataset.name,
        tiles.len(),
        tiles.first().map_or(0, Vec::len)
    );
    let mean = |done: &[TileRow]| done.iter().map(|t| t.ms).sum::<f64>() / done.len() as f64;
    let width = tiles.iter().map(Vec::len).max().unwrap_or(0);
    let at: Vec<f64> = (0..width)
        .map(|k| {
            let times: Vec<f64> = tiles
                .iter()
                .filter_map(|t| t.get(k))
                .map(|t| t.ms)
                .collect();
            times.iter().sum::<f64>() / times.len().max(1) as f64
        })
        .collect();
    let all: Vec<TileRow> = tiles.iter().flatten().copied().collect();
    let first = TILES_TO_BEAT_THE_PASS as usize;
    println!(
        "mean ms of the 1st, 2nd, … tile: {}; of any tile: {:.2}; the first {first} together: {:.2}, {first} at the mean of any: {:.2}",
        at.iter()
            .map(|ms| format!("{ms:.2}"))
            .collect::<Vec<_>>()
            .join(", "),
        mean(&all),
        at.iter().take(first).sum::<f64>(),
        first as f64 * mean(&all)
    );
    report("mean of the tiles so far", &tiles, 1, &|d, _| mean(d));
    let (xy, xx) = tiles
        .iter()
        .map(|t| slope(t))
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let fitted = xy / xx;
    for q in [fitted, 0.02, 0.025, 0.03] {
        let name = format!("keypoints, {q:.4} ms each");
        report(&name, &tiles, 1, &|d, n| {
            priced(d, std::slice::from_ref(n), q)
        });
    }
    report("own line (from 2 tiles)", &tiles, 2, &|d, n| {
        let (xy, xx) = slope(d);
        let q = if xx > 0.0 { (xy / xx).max(0.0) } else { 0.0 };
        priced(d, std::slice::from_ref(n), q)
    });
    for a in [0.9, 0.8, 0.67, 0.5] {
        report(&format!("corners, a = {a}"), &tiles, 1, &|d, n| {
            let c = d.iter().map(|t| t.corners).sum::<f64>() / d.len() as f64;
            match c > 0.0 {
                true => mean(d) * (a + (1.0 - a) * n.corners / c),
                false => mean(d),
            }
        });
    }
    println!("predicted / actual time of all the tiles left, richest first");
    report_ahead(
        "mean so far × tiles left",
        &tiles,
        1,
        &|d, left| mean(d) * left.len() as f64,
        usize::MAX,
    );
    let name = format!("keypoints, {fitted:.4} ms each");
    report_ahead(
        &name,
        &tiles,
        1,
        &|d, left| priced(d, left, fitted),
        usize::MAX,
    );
    Ok(())
}

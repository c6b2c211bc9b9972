//! A request's time budget: whether streaming extraction may extract one
//! more tile. A caller that must have an answer within a time (a robot's
//! control loop) gives the budget; after each tile the next one is taken
//! only if it is expected to end within it. The first tile (or the coarse
//! pass) is always taken, so every answer has votes behind it. Plain arithmetic on durations: the
//! pipeline measures, this decides.
//!
//! What a tile costs (its extraction, quantization, votes and checks) is a
//! part that comes with its area, about the same for every tile of a grid,
//! and a part per keypoint; tiles are extracted richest first, so the next
//! one usually holds fewer keypoints than those before it, and their mean
//! time overestimates it (by a median of 32.5 % on gardens-point, on a
//! 2-vCPU Intel Xeon; docs/service.md, "A time budget"). [`next_tile_time`] prices the next tile's
//! expected keypoints instead, at what a keypoint costs on this machine,
//! which [`TileCostModel`] learns from the requests served.
//!
//! While a core would idle, tiles are extracted two at a time (the second
//! on that core, [`crate::features::Tiles::extract_ahead`]): a pair waits
//! for its longer tile, and the second, already extracted when its turn
//! comes, costs only its votes ([`waiting_tile_time`]).
//!
//! A tight budget also changes the plan: one that holds fewer than
//! [`TILES_TO_BEAT_THE_PASS`] tiles starts with the coarse pass
//! ([`pass_first`]), and after a pass the search starts over on the tiles
//! only when that many fit.

use serde::{Deserialize, Serialize};
use std::sync::Mutex;
use std::time::Duration;

/// The longest budget accepted: ten minutes, far past any deadline.
pub const MAX_BUDGET: Duration = Duration::from_secs(600);

/// `ms` if it is an accepted budget in milliseconds (a finite number > 0,
/// at most [`MAX_BUDGET`]), else why not: the one check behind the
/// configuration, the API and `--budget-ms`.
pub fn check_ms(ms: f64) -> Result<Duration, String> {
    if ms.is_finite() && ms > 0.0 && ms <= MAX_BUDGET.as_millis() as f64 {
        Ok(Duration::from_secs_f64(ms / 1000.0))
    } else {
        Err(format!(
            "must be a number of milliseconds in (0, {}], got {ms}",
            MAX_BUDGET.as_millis()
        ))
    }
}

/// What one extracted unit (a tile or the coarse pass) cost a request: the
/// time from asking for it to its votes counted and checked, and the
/// keypoints it gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitCost {
    pub time: Duration,
    pub keypoints: usize,
}

/// The expected time of the next tile, after the tiles `done` (at least
/// one), when it is expected to hold `next_keypoints`: the tiles' mean time
/// apart from their keypoints, plus `per_keypoint` for each of the next
/// one's.
pub fn next_tile_time(done: &[UnitCost], next_keypoints: f64, per_keypoint: Duration) -> Duration {
    let n = done.len().max(1) as f64;
    let q = per_keypoint.as_secs_f64();
    let apart = done
        .iter()
        .map(|u| u.time.as_secs_f64() - q * u.keypoints as f64)
        .sum::<f64>()
        / n;
    Duration::from_secs_f64(apart.max(0.0) + q * next_keypoints.max(0.0))
}

/// The keypoints a tile is expected to hold: the `seen` keypoints of the
/// `done` tiles so far shared out by expected shares (`share_done` of the
/// image's, `share` the tile's; by corners, or area), or their mean per
/// tile when the tiles done were expected to hold none.
pub fn expected_keypoints(seen: usize, done: usize, share_done: f64, share: f64) -> f64 {
    match share_done > 0.0 {
        true => seen as f64 * share / share_done,
        false => seen as f64 / done.max(1) as f64,
    }
}

/// The expected time of the tiles `left` (each one's expected share of the
/// image's keypoints, as [`expected_keypoints`] reads it) after the tiles
/// `done` (at least one), which held `share_done` of them: each priced as
/// [`next_tile_time`] prices the next one. For the next tile alone, pass its
/// share; for all the tiles a stop skipped, theirs (what the stop saved).
pub fn tiles_left_time(
    done: &[UnitCost],
    share_done: f64,
    left: &[f64],
    per_keypoint: Duration,
) -> Duration {
    let seen = done.iter().map(|c| c.keypoints).sum();
    left.iter()
        .map(|&share| {
            let keypoints = expected_keypoints(seen, done.len(), share_done, share);
            next_tile_time(done, keypoints, per_keypoint)
        })
        .sum()
}

/// The sums of a least-squares slope of time (seconds) against keypoints
/// among `tiles`, through the origin of their centred values:
/// (Σ Δkeypoints · Δseconds, Σ Δkeypoints²).
pub fn slope_sums(tiles: &[UnitCost]) -> (f64, f64) {
    let n = tiles.len().max(1) as f64;
    let mean_k = tiles.iter().map(|u| u.keypoints as f64).sum::<f64>() / n;
    let mean_t = tiles.iter().map(|u| u.time.as_secs_f64()).sum::<f64>() / n;
    tiles.iter().fold((0.0, 0.0), |(xy, xx), u| {
        let dk = u.keypoints as f64 - mean_k;
        (xy + dk * (u.time.as_secs_f64() - mean_t), xx + dk * dk)
    })
}

/// The time a tile extracted ahead of its turn (on a spare core, while the
/// tile before it was extracted) still takes: its extraction is done, its
/// `keypoints` are known, and only their quantization, votes and checks are
/// left, at what those took a keypoint in this request so far (`voting`
/// over the `voted` keypoints of the tiles before it).
pub fn waiting_tile_time(voting: Duration, voted: usize, keypoints: usize) -> Duration {
    match voted {
        0 => Duration::ZERO,
        n => voting.mul_f64(keypoints as f64 / n as f64),
    }
}

/// The tiles extracted together, in one wait: one, or with two at a time
/// (the second on a spare core, [`crate::features::Tiles::extract_ahead`])
/// a pair.
pub fn tiles_a_wait(two_at_a_time: bool) -> usize {
    match two_at_a_time {
        true => 2,
        false => 1,
    }
}

/// How many waits `tiles` tiles in a row take ([`tiles_a_wait`]).
pub fn waits(tiles: u32, two_at_a_time: bool) -> u32 {
    tiles.div_ceil(tiles_a_wait(two_at_a_time) as u32)
}

/// Whether the next wait extracts two tiles: with `two_at_a_time`, when
/// the next two fit together (`fits(true)`), else one, when it fits alone
/// (`fits(false)`, and it is then extracted alone); `Err`: not even one
/// fits, and why.
pub fn next_wait(
    two_at_a_time: bool,
    fits: impl Fn(bool) -> Result<(), String>,
) -> Result<bool, String> {
    match two_at_a_time && fits(true).is_ok() {
        true => Ok(true),
        false => fits(false).map(|()| false),
    }
}

/// The tiles whose answer beats the coarse pass's: the pass sees the whole
/// image at half size, one or two richest tiles of four (a quarter or half
/// of it at full size) answered worse on gardens-point, three better
/// (docs/service.md, "A time budget"). A budget expected to hold fewer
/// tiles (at what the first tiles of a request have taken lately) starts
/// with the pass, whatever the plan ([`pass_first`]); after a pass that did
/// not end the search, the search starts over on the tiles only when this
/// many are expected to fit (each priced at what the pass took).
pub const TILES_TO_BEAT_THE_PASS: u32 = 3;

/// Whether a search under `budget` should start with the coarse pass, when
/// the first [`TILES_TO_BEAT_THE_PASS`] tiles are expected to take
/// `first_tiles` together (`None`: nothing known yet, no).
pub fn pass_first(budget: Duration, first_tiles: Option<Duration>) -> bool {
    first_tiles.is_some_and(|t| t > budget)
}

/// `Ok` when the next `tiles` tiles, expected to take `next` together, fit
/// in `budget`, else why they do not (the stop's detail). `spent`: the time
/// since the request's work began (decoding included).
pub fn next_tiles_fit(
    budget: Duration,
    spent: Duration,
    next: Duration,
    tiles: u32,
) -> Result<(), String> {
    if spent + next <= budget {
        return Ok(());
    }
    let ms = |d: Duration| d.as_secs_f64() * 1000.0;
    let what = match tiles {
        1 => "the next tile".to_string(),
        n => format!("the next {n} tiles"),
    };
    Err(format!(
        "time budget {:.1} ms: {:.1} ms spent, {what} would take about {:.1} ms",
        ms(budget),
        ms(spent),
        ms(next)
    ))
}

/// What tiles cost on this machine, learnt from the requests served (not
/// [`crate::pipeline::TileCost`], one tile's measured cost in the eval): what
/// a keypoint adds to a tile, the slope of a tile's time against its
/// keypoints among the tiles of one request (same grid, same image: they
/// differ in little else), and what the first, second, … tile of a request
/// takes (tiles come richest first, so each place in the order has its own
/// mean: on gardens-point 18.0, 14.8, 12.5 and 10.7 ms of extraction on a
/// 2-vCPU Intel Xeon, docs/service.md).
/// Both are summed over the recent requests (each request's weight fades by
/// [`TileCostModel::FADE`] with every one after it, so the figures follow the
/// machine's speed); the slope starts from [`TileCostModel::PRIOR`]. What
/// it has learnt ([`TileCosts`]) can be kept and resumed, so a restart
/// prices its first requests as the last run did.
pub struct TileCostModel {
    sums: Mutex<TileCosts>,
}

/// What a [`TileCostModel`] has learnt: its sums, as kept across restarts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileCosts {
    /// Σ (keypoints − mean) · (seconds − mean), over the tiles of each request
    xy: f64,
    /// Σ (keypoints − mean)²
    xx: f64,
    /// per place in a request's order: Σ seconds of the tiles there and how
    /// many, faded alike
    at: Vec<(f64, f64)>,
}

impl TileCostModel {
    /// Before any request: 0.03 ms a keypoint (SIFT describes one in about
    /// 0.024 ms on the 2-vCPU Xeon and EPYC machines of docs/performance.md,
    /// "Where SIFT's time goes", and quantizing and voting it add a little).
    pub const PRIOR: Duration = Duration::from_micros(30);
    /// The prior weighs as much as this Σ (keypoints − mean)² of requests
    /// (the spread of the tiles of a few queries).
    const PRIOR_WEIGHT: f64 = 20_000.0;
    /// Each request's share fades by this factor with every later one.
    pub const FADE: f64 = 0.99;

    /// The most places in a request's order a model keeps (a grid of 64 × 64
    /// tiles).
    const MAX_PLACES: usize = 4096;

    pub fn new() -> Self {
        Self {
            sums: Mutex::new(TileCosts {
                xy: Self::PRIOR.as_secs_f64() * Self::PRIOR_WEIGHT,
                xx: Self::PRIOR_WEIGHT,
                at: Vec::new(),
            }),
        }
    }

    fn sums(&self) -> std::sync::MutexGuard<'_, TileCosts> {
        self.sums.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What it has learnt so far.
    pub fn learnt(&self) -> TileCosts {
        self.sums().clone()
    }

    /// Whether it has learnt from any request.
    pub fn has_learnt(&self) -> bool {
        !self.sums().at.is_empty()
    }

    /// Go on from `costs` (learnt by an earlier run), unless they are not
    /// what a model could have learnt: then why, and nothing changes.
    pub fn resume(&self, costs: TileCosts) -> Result<(), String> {
        let sums_ok =
            costs.xy.is_finite() && costs.xx.is_finite() && costs.xx >= Self::PRIOR_WEIGHT;
        let places_ok = costs.at.len() <= Self::MAX_PLACES
            && costs
                .at
                .iter()
                .all(|&(s, n)| s.is_finite() && n.is_finite() && s >= 0.0 && n >= 0.0);
        if !(sums_ok && places_ok) {
            return Err("its tile costs are not ones a server learns".into());
        }
        *self.sums() = costs;
        Ok(())
    }

    /// What a keypoint adds to a tile (never negative).
    pub fn per_keypoint(&self) -> Duration {
        let s = self.sums();
        Duration::from_secs_f64((s.xy / s.xx).max(0.0))
    }

    /// How long a request waits for its first `n` tiles, each at the mean
    /// of the recent requests' tiles at its place in the order (a place no
    /// request has reached lately at the mean of the one before; `None`
    /// before the first request): their sum, or with two at a time
    /// ([`waits`]) the longer of each pair's.
    pub fn first_tiles(&self, n: usize, two_at_a_time: bool) -> Option<Duration> {
        let s = self.sums();
        let mut last = None;
        let mut each = Vec::with_capacity(n);
        for k in 0..n {
            if let Some(&(seconds, count)) = s.at.get(k).filter(|a| a.1 > 0.0) {
                last = Some(seconds / count);
            }
            each.push(last?);
        }
        let waits = each.chunks(tiles_a_wait(two_at_a_time));
        Some(Duration::from_secs_f64(
            waits.map(|w| w.iter().copied().fold(0.0, f64::max)).sum(),
        ))
    }

    /// How long a request waits for the first [`TILES_TO_BEAT_THE_PASS`]
    /// tiles ([`TileCostModel::first_tiles`]): what a budget is held
    /// against to start with the coarse pass ([`pass_first`]).
    pub fn tiles_to_beat_the_pass(&self, two_at_a_time: bool) -> Option<Duration> {
        self.first_tiles(TILES_TO_BEAT_THE_PASS as usize, two_at_a_time)
    }

    /// Learn from the tiles of one request in the grid whose tiles this
    /// prices, in the order they were extracted (a coarse pass left out: its
    /// area is not a tile's); the slope from two tiles on.
    pub fn record(&self, tiles: &[UnitCost]) {
        if tiles.is_empty() {
            return;
        }
        let (xy, xx) = slope_sums(tiles);
        let mut s = self.sums();
        if s.at.len() < tiles.len() {
            s.at.resize(tiles.len().min(Self::MAX_PLACES), (0.0, 0.0));
        }
        for (k, at) in s.at.iter_mut().enumerate() {
            *at = (at.0 * Self::FADE, at.1 * Self::FADE);
            if let Some(tile) = tiles.get(k) {
                *at = (at.0 + tile.time.as_secs_f64(), at.1 + 1.0);
            }
        }
        if tiles.len() < 2 {
            return;
        }
        s.xy = s.xy * Self::FADE + xy;
        s.xx = s.xx * Self::FADE + xx;
        // the prior fades too, but never below its own weight
        if s.xx < Self::PRIOR_WEIGHT {
            s.xy += Self::PRIOR.as_secs_f64() * (Self::PRIOR_WEIGHT - s.xx);
            s.xx = Self::PRIOR_WEIGHT;
        }
    }
}

impl Default for TileCostModel {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    fn unit(ms: u64, keypoints: usize) -> UnitCost {
        UnitCost {
            time: MS * ms as u32,
            keypoints,
        }
    }

    #[test]
    fn a_tile_is_taken_while_it_fits() {
        assert!(next_tiles_fit(35 * MS, 25 * MS, 10 * MS, 1).is_ok());
        let why = next_tiles_fit(34 * MS, 25 * MS, 10 * MS, 1).unwrap_err();
        assert!(why.contains("34.0 ms"), "{why}");
        assert!(
            why.contains("the next tile would take about 10.0 ms"),
            "{why}"
        );
        let why = next_tiles_fit(34 * MS, 25 * MS, 20 * MS, 2).unwrap_err();
        assert!(
            why.contains("the next 2 tiles would take about 20.0 ms"),
            "{why}"
        );
        // already past the budget
        assert!(next_tiles_fit(20 * MS, 25 * MS, Duration::ZERO, 1).is_err());
    }

    #[test]
    fn the_next_tile_is_priced_by_its_keypoints() {
        // 6 ms apart from keypoints, 0.02 ms a keypoint
        let q = Duration::from_micros(20);
        let done = [unit(12, 300), unit(10, 200)];
        let next = next_tile_time(&done, 100.0, q);
        assert!((next.as_secs_f64() * 1e3 - 8.0).abs() < 1e-9, "{next:?}");
        // at no cost a keypoint, the mean of the tiles so far
        assert_eq!(next_tile_time(&done, 100.0, Duration::ZERO), 11 * MS);
        // a per-keypoint cost above a tile's own leaves no negative part
        let next = next_tile_time(&[unit(2, 200)], 0.0, q);
        assert_eq!(next, Duration::ZERO);
    }

    #[test]
    fn the_tiles_left_are_priced_each_by_its_share() {
        // 6 ms apart from keypoints, 0.02 ms a keypoint; the two tiles done
        // held 500 keypoints, half the image's expected
        let q = Duration::from_micros(20);
        let done = [unit(12, 300), unit(10, 200)];
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        // the next alone: 0.1 of the image, 100 keypoints, 8 ms
        let next = tiles_left_time(&done, 0.5, &[0.1], q);
        assert!((ms(next) - 8.0).abs() < 1e-9, "{next:?}");
        // both left: 100 and 400 keypoints, 8 + 14 ms
        let both = tiles_left_time(&done, 0.5, &[0.1, 0.4], q);
        assert!((ms(both) - 22.0).abs() < 1e-9, "{both:?}");
        assert_eq!(tiles_left_time(&done, 0.5, &[], q), Duration::ZERO);
    }

    #[test]
    fn what_tiles_cost_is_learnt_from_the_requests() {
        let cost = TileCostModel::new();
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        assert_eq!(cost.per_keypoint(), TileCostModel::PRIOR);
        assert_eq!(cost.first_tiles(3, false), None);
        // one tile, or tiles alike in keypoints, tell nothing of keypoints
        cost.record(&[unit(10, 100)]);
        cost.record(&[unit(10, 100), unit(12, 100)]);
        assert!((ms(cost.per_keypoint()) - ms(TileCostModel::PRIOR)).abs() < 1e-9);
        // the first tiles took 10 ms, the one second 12; a third place, not
        // reached yet, at the second's
        assert!((ms(cost.first_tiles(1, false).unwrap()) - 10.0).abs() < 1e-9);
        assert!((ms(cost.first_tiles(3, false).unwrap()) - 34.0).abs() < 1e-9);
        assert_eq!(cost.first_tiles(0, false), Some(Duration::ZERO));
        // two at a time: the first pair waits for its longer tile (12 ms),
        // the third alone (12 ms)
        assert!((ms(cost.first_tiles(3, true).unwrap()) - 24.0).abs() < 1e-9);
        // a machine where a keypoint costs 0.05 ms: tiles of 5 ms + 0.05 ms each
        for _ in 0..200 {
            let tiles: Vec<UnitCost> = [400u64, 250, 150, 50]
                .iter()
                .map(|&k| UnitCost {
                    time: Duration::from_micros(5000 + 50 * k),
                    keypoints: k as usize,
                })
                .collect();
            cost.record(&tiles);
        }
        let learnt = ms(cost.per_keypoint());
        assert!((learnt - 0.05).abs() < 0.002, "{learnt}");
        // each place in the order at its own: 25 + 17.5 + 12.5 ms for the
        // first three (the two requests before faded to under 3 % of them)
        let three = ms(cost.first_tiles(3, false).unwrap());
        assert!((three - 55.0).abs() < 0.1, "{three}");
        // two at a time: 25 + 12.5 ms
        let paired = ms(cost.first_tiles(3, true).unwrap());
        assert!((paired - 37.5).abs() < 0.1, "{paired}");
    }

    #[test]
    fn a_tile_extracted_ahead_is_priced_at_its_votes() {
        // 2 ms of votes for the 400 keypoints before: 0.005 ms each
        let left = waiting_tile_time(2 * MS, 400, 100);
        assert_eq!(left, MS / 2);
        assert_eq!(waiting_tile_time(2 * MS, 0, 100), Duration::ZERO);
        assert_eq!(waits(3, false), 3);
        assert_eq!(waits(3, true), 2);
        assert_eq!(waits(4, true), 2);
        assert_eq!(waits(0, true), 0);
    }

    #[test]
    fn two_tiles_that_do_not_fit_together_may_fit_one_at_a_time() {
        // the pair takes 30 ms, the next tile alone 20, 25 ms are left
        let asked = std::cell::RefCell::new(Vec::new());
        let fits = |left: Duration| {
            let asked = &asked;
            move |two: bool| {
                asked.borrow_mut().push(two);
                let next = if two { 30 * MS } else { 20 * MS };
                next_tiles_fit(left, Duration::ZERO, next, 1 + two as u32)
            }
        };
        assert_eq!(next_wait(true, fits(25 * MS)), Ok(false));
        assert_eq!(asked.take(), [true, false]);
        assert_eq!(next_wait(true, fits(30 * MS)), Ok(true));
        assert_eq!(asked.take(), [true]);
        // one at a time: a pair is never asked about
        assert_eq!(next_wait(false, fits(30 * MS)), Ok(false));
        assert_eq!(asked.take(), [false]);
        // not even one: why, from the tile alone
        let why = next_wait(true, fits(10 * MS)).unwrap_err();
        assert!(
            why.contains("the next tile would take about 20.0 ms"),
            "{why}"
        );
        assert_eq!(asked.take(), [true, false]);
    }

    #[test]
    fn what_tiles_cost_is_resumed_as_it_was_learnt() {
        let first = TileCostModel::new();
        assert!(!first.has_learnt());
        first.record(&[unit(25, 500), unit(15, 300), unit(10, 100)]);
        assert!(first.has_learnt());
        let kept: TileCosts =
            serde_json::from_str(&serde_json::to_string(&first.learnt()).unwrap()).unwrap();
        let next = TileCostModel::new();
        assert_eq!(next.first_tiles(3, false), None);
        next.resume(kept.clone()).unwrap();
        assert_eq!(next.per_keypoint(), first.per_keypoint());
        assert_eq!(next.first_tiles(3, false), first.first_tiles(3, false));
        // sums no model could have learnt are refused, and change nothing
        let fresh = TileCostModel::new();
        for bad in [
            TileCosts {
                xx: 0.0,
                ..kept.clone()
            },
            TileCosts {
                xy: f64::INFINITY,
                ..kept.clone()
            },
            TileCosts {
                at: vec![(-1.0, 1.0)],
                ..kept.clone()
            },
            TileCosts {
                at: vec![(0.01, 1.0); 5000],
                ..kept.clone()
            },
        ] {
            assert!(fresh.resume(bad).is_err());
        }
        assert!(!fresh.has_learnt());
        assert_eq!(fresh.per_keypoint(), TileCostModel::PRIOR);
    }

    #[test]
    fn a_budget_of_less_than_three_tiles_starts_with_the_pass() {
        assert!(!pass_first(MS, None));
        assert!(pass_first(38 * MS, Some(39 * MS)));
        assert!(!pass_first(39 * MS, Some(39 * MS)));
    }

    #[test]
    fn budgets_are_checked() {
        assert_eq!(check_ms(30.0), Ok(30 * MS));
        assert_eq!(check_ms(0.5), Ok(MS / 2));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 600_001.0] {
            assert!(check_ms(bad).is_err(), "{bad}");
        }
        assert!(check_ms(600_000.0).is_ok());
    }
}

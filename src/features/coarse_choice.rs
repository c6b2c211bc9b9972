//! Learning, for one map, whether streaming extraction should start with the
//! coarse pass (`TileGrid::coarse`). The coarse pass costs about a quarter of
//! the whole image's extraction and pays off when the search often stops on
//! its keypoints (small images, distinctive places); when it seldom does, it
//! is paid on top of the tiles. Which holds depends on the map and its
//! queries, so the service measures it: both plans are tried on the first
//! requests, then each request takes the plan it draws as the cheaper one
//! from what each has cost (Thompson sampling: a typical time drawn for each
//! plan from its mean and standard error, the smaller wins), so a plan whose
//! trials were unlucky by chance is tried again until its costs say so, and
//! a plan clearly slower is left alone. The one not preferred is still tried
//! on one request in [`CoarseChoice::EXPLORE_EVERY`], so a change of queries
//! is noticed. The coarse pass is taken only while
//! most of its requests end on it ([`CoarseChoice::MIN_ENDED_ON_COARSE`]):
//! a pass that seldom ends a search is paid for nothing by most requests,
//! which then start over on the tiles (when the tiles after it kept only the
//! finest scale and the search went on from the pass's votes, the coarse
//! plan lost up to 2.8 points of recall@1 on gardens-point; docs/performance.md,
//! "The learned plan, verified on the coarse pass"). A request's time is its extraction,
//! quantization, voting and verification (decoding is the same either way);
//! the typical time is the geometric mean, not the arithmetic one: the coarse
//! plan's times are bimodal (most requests end after the coarse pass, the
//! rest pay for it on top of the tiles), and a mean would weigh the few slow
//! requests as much as the many fast ones.
//! What a choice has learned ([`Learned`]) can be taken out and put back
//! ([`CoarseChoice::learned`], [`CoarseChoice::resume`]), so a server
//! restarted on the same map skips the trials (the service keeps it in a
//! file: `server::plan_memory`).
//! No OpenCV here: the policy is plain arithmetic over reported times, and
//! `bowloc eval --tiles …,auto` replays it over cached queries
//! (`eval::sweep::run_learned`; `--plan-orders` over random query orders,
//! fresh and resumed).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::sync::Mutex;

/// The running choice between a grid without and with the coarse pass.
#[derive(Debug, Default)]
pub struct CoarseChoice {
    state: Mutex<State>,
}

#[derive(Debug, Clone)]
struct State {
    learned: Learned,
    /// The draws, from a fixed seed: a replay of the same requests makes
    /// the same choices.
    rng: ChaCha8Rng,
}

impl Default for State {
    fn default() -> Self {
        Self {
            learned: Learned::default(),
            rng: ChaCha8Rng::seed_from_u64(0x636f_6172_7365),
        }
    }
}

/// What a choice has learned: its requests and what each plan has cost.
#[derive(Debug, Default, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Learned {
    /// Requests the choice has been asked about.
    pub requests: u64,
    /// Without (`tiles`) and with (`coarse`) the coarse pass.
    pub tiles: Arm,
    pub coarse: Arm,
}

impl Learned {
    /// Each plan's name (in `/metrics` and `/map`) with what it has cost:
    /// the tiles alone, then the coarse pass first.
    pub fn plans(&self) -> [(&'static str, Arm); 2] {
        [
            (CoarseChoice::plan_name(false), self.tiles),
            (CoarseChoice::plan_name(true), self.coarse),
        ]
    }

    fn arm_mut(&mut self, coarse: bool) -> &mut Arm {
        if coarse {
            &mut self.coarse
        } else {
            &mut self.tiles
        }
    }

    /// Why these figures cannot be what a choice learned (`None`: they can):
    /// every mean finite, a mean square at least the square of its mean,
    /// a share within [0, 1].
    pub fn invalid(&self) -> Option<String> {
        [("tiles", &self.tiles), ("coarse", &self.coarse)]
            .into_iter()
            .find_map(|(name, a)| {
                let finite = [a.mean_ln_ms, a.mean_sq_ln_ms, a.ended_first]
                    .iter()
                    .all(|v| v.is_finite());
                let square = a.mean_sq_ln_ms >= a.mean_ln_ms * a.mean_ln_ms * (1.0 - 1e-9) - 1e-9;
                let share = (0.0..=1.0).contains(&a.ended_first);
                (!(finite && square && share))
                    .then(|| format!("the {name} plan's figures are not a plan's: {a:?}"))
            })
    }
}

/// What one plan has cost.
#[derive(Debug, Default, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Arm {
    /// Requests answered with it.
    pub samples: u64,
    /// Mean of ln(request time in ms): a plain mean over the first
    /// [`CoarseChoice::MEMORY`] samples, then a moving average that weighs
    /// the last one by 1/MEMORY.
    pub mean_ln_ms: f64,
    /// Mean of ln(request time in ms)², averaged as `mean_ln_ms` is.
    pub mean_sq_ln_ms: f64,
    /// Share of its requests that ended on their first unit (the coarse
    /// pass, or the first tile), averaged as `mean_ln_ms` is.
    pub ended_first: f64,
}

impl Arm {
    /// The typical request time (ms): the geometric mean.
    pub fn typical_ms(&self) -> f64 {
        self.mean_ln_ms.exp()
    }

    /// The sum of the squared weights the average gives its samples: the
    /// variance of the mean is the samples' times this. 1/n for the plain
    /// mean of the first n ≤ MEMORY; then each sample scales the old
    /// weights by 1 − w and adds w (w = 1/MEMORY), so the sum moves from
    /// 1/MEMORY towards its fixed point w²/(1 − (1 − w)²) = 1/(2·MEMORY − 1)
    /// by (1 − w)² a sample.
    pub fn sum_sq_weights(&self) -> f64 {
        let memory = CoarseChoice::MEMORY;
        let n = self.samples as f64;
        if n <= memory {
            return 1.0 / n.max(1.0);
        }
        let shrink = (1.0 - 1.0 / memory).powi(2);
        let steady = 1.0 / (2.0 * memory - 1.0);
        steady + (1.0 / memory - steady) * shrink.powf(n - memory)
    }

    /// The squared standard error of `mean_ln_ms`: the variance of
    /// ln(ms) times the sum of the squared weights of the average.
    fn squared_error(&self) -> f64 {
        let variance = (self.mean_sq_ln_ms - self.mean_ln_ms * self.mean_ln_ms).max(0.0);
        variance * self.sum_sq_weights()
    }

    /// A typical ln(ms) drawn from what the arm has cost: normal about its
    /// mean with its standard error.
    fn draw(&self, rng: &mut ChaCha8Rng) -> f64 {
        let z: f64 = rng.sample(StandardNormal);
        self.mean_ln_ms + z * self.squared_error().sqrt()
    }
}

impl CoarseChoice {
    /// Requests each plan answers before either is preferred: 8 let
    /// rtabmap-loop's vocabulary seed 2 settle on the tiles alone after a
    /// stretch of easy queries, where the coarse pass answers in a median
    /// 0.300 of the whole-image full search against 0.381 (docs/performance.md,
    /// "Longer trials for the learned plan").
    pub const TRIAL: u64 = 16;
    /// Once a plan is preferred, one request in this many tries the other.
    pub const EXPLORE_EVERY: u64 = 32;
    /// Samples the moving average remembers.
    pub const MEMORY: f64 = 32.0;
    /// The coarse pass is preferred only when more than this share of its
    /// requests ended on it.
    pub const MIN_ENDED_ON_COARSE: f64 = 0.5;
    /// The plans' names (in `/metrics` and `/map`), without and with the
    /// coarse pass.
    pub const PLANS: [&'static str; 2] = ["tiles", "coarse"];

    /// The name of the plan with (`coarse`) or without the coarse pass.
    pub fn plan_name(coarse: bool) -> &'static str {
        Self::PLANS[usize::from(coarse)]
    }

    /// Whether the next request should start with the coarse pass.
    pub fn choose(&self) -> bool {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        s.learned.requests += 1;
        let Learned {
            requests,
            tiles: plain,
            coarse,
        } = s.learned;
        if plain.samples < Self::TRIAL || coarse.samples < Self::TRIAL {
            // trials: the plan tried less, alternating on a tie
            return match plain.samples.cmp(&coarse.samples) {
                std::cmp::Ordering::Less => false,
                std::cmp::Ordering::Greater => true,
                std::cmp::Ordering::Equal => requests.is_multiple_of(2),
            };
        }
        if requests.is_multiple_of(Self::EXPLORE_EVERY) {
            return !Self::coarse_wins(plain, coarse);
        }
        coarse.ended_first > Self::MIN_ENDED_ON_COARSE
            && coarse.draw(&mut s.rng) < plain.draw(&mut s.rng)
    }

    /// Whether the coarse pass is the better plan: its typical request is
    /// shorter and most of its requests end on it.
    fn coarse_wins(plain: Arm, coarse: Arm) -> bool {
        coarse.mean_ln_ms < plain.mean_ln_ms && coarse.ended_first > Self::MIN_ENDED_ON_COARSE
    }

    /// A request answered with (`coarse`) or without the coarse pass took
    /// `ms` (not counting its decoding; at least a microsecond is counted)
    /// and ended on its first unit or not (`ended_first`). Non-finite or
    /// negative times are ignored.
    pub fn record(&self, coarse: bool, ms: f64, ended_first: bool) {
        if !ms.is_finite() || ms < 0.0 {
            return;
        }
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let arm = s.learned.arm_mut(coarse);
        arm.samples += 1;
        let weight = (1.0 / arm.samples as f64).max(1.0 / Self::MEMORY);
        let ln_ms = ms.max(1e-3).ln();
        arm.mean_ln_ms += weight * (ln_ms - arm.mean_ln_ms);
        arm.mean_sq_ln_ms += weight * (ln_ms * ln_ms - arm.mean_sq_ln_ms);
        arm.ended_first += weight * (f64::from(u8::from(ended_first)) - arm.ended_first);
    }

    /// What each plan has cost so far: (without, with) the coarse pass.
    pub fn arms(&self) -> (Arm, Arm) {
        let learned = self.learned();
        (learned.tiles, learned.coarse)
    }

    /// What the choice has learned so far.
    pub fn learned(&self) -> Learned {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).learned
    }

    /// Go on from what an earlier choice learned (a plan that ran its trials
    /// goes on without them), unless its figures are not a plan's. The draws
    /// start again from the fixed seed, as in a new choice.
    pub fn resume(&self, learned: Learned) -> Result<(), String> {
        if let Some(why) = learned.invalid() {
            return Err(why);
        }
        *self.state.lock().unwrap_or_else(|e| e.into_inner()) = State {
            learned,
            ..State::default()
        };
        Ok(())
    }

    /// The plan preferred now (`None` while the trials run).
    pub fn preferred(&self) -> Option<bool> {
        let (plain, coarse) = self.arms();
        (plain.samples >= Self::TRIAL && coarse.samples >= Self::TRIAL)
            .then_some(Self::coarse_wins(plain, coarse))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Answer `n` requests whose cost is `plain_ms` without the coarse pass
    /// and `coarse_ms` with it, every coarse request ending on the coarse
    /// pass; returns how many started with it.
    fn run(choice: &CoarseChoice, n: usize, plain_ms: f64, coarse_ms: f64) -> usize {
        let mut coarse_used = 0;
        for _ in 0..n {
            let coarse = choice.choose();
            coarse_used += coarse as usize;
            choice.record(coarse, if coarse { coarse_ms } else { plain_ms }, coarse);
        }
        coarse_used
    }

    #[test]
    fn both_plans_are_tried_before_one_is_preferred() {
        let c = CoarseChoice::default();
        let used = run(&c, 2 * CoarseChoice::TRIAL as usize, 10.0, 50.0);
        assert_eq!(used, CoarseChoice::TRIAL as usize);
        assert_eq!(c.preferred(), Some(false));
        let (plain, coarse) = c.arms();
        assert!((plain.typical_ms() - 10.0).abs() < 1e-9);
        assert!((coarse.typical_ms() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn the_cheaper_plan_wins_and_the_other_is_still_sampled() {
        let c = CoarseChoice::default();
        run(&c, 2 * CoarseChoice::TRIAL as usize, 60.0, 20.0);
        let used = run(&c, 320, 60.0, 20.0);
        // all but one request in EXPLORE_EVERY start with the coarse pass
        assert_eq!(used, 320 - 320 / CoarseChoice::EXPLORE_EVERY as usize);
        assert_eq!(c.preferred(), Some(true));
    }

    #[test]
    fn the_typical_request_decides_not_the_mean() {
        // coarse: 3 of 4 requests take 10 ms, 1 takes 130 (mean 40, typical
        // 10·13^¼ ≈ 19); tiles: every request 35 ms
        let c = CoarseChoice::default();
        let mut n = 0;
        for _ in 0..400 {
            let coarse = c.choose();
            let ms = if coarse {
                n += 1;
                if n % 4 == 0 { 130.0 } else { 10.0 }
            } else {
                35.0
            };
            c.record(coarse, ms, ms < 100.0);
        }
        assert_eq!(c.preferred(), Some(true));
    }

    #[test]
    fn a_coarse_pass_few_requests_end_on_is_not_preferred_even_when_faster() {
        // coarse: 1 request in 4 ends on it (10 ms), the others take 30 ms
        // (typical ≈ 23); tiles: every request 35 ms
        let c = CoarseChoice::default();
        let mut n = 0;
        let mut coarse_used = 0;
        for _ in 0..400 {
            let coarse = c.choose();
            coarse_used += coarse as usize;
            let (ms, ended) = if coarse {
                n += 1;
                if n % 4 == 0 {
                    (10.0, true)
                } else {
                    (30.0, false)
                }
            } else {
                (35.0, false)
            };
            c.record(coarse, ms, ended);
        }
        let (plain, coarse) = c.arms();
        assert!(coarse.typical_ms() < plain.typical_ms());
        assert!(
            (coarse.ended_first - 0.25).abs() < 0.1,
            "{}",
            coarse.ended_first
        );
        assert_eq!(c.preferred(), Some(false));
        // the trials, then one request in EXPLORE_EVERY
        assert!(
            coarse_used
                <= CoarseChoice::TRIAL as usize + 400 / CoarseChoice::EXPLORE_EVERY as usize
        );
    }

    #[test]
    fn a_change_in_costs_changes_the_choice() {
        let c = CoarseChoice::default();
        run(&c, 200, 60.0, 20.0);
        assert_eq!(c.preferred(), Some(true));
        // the queries change: the coarse pass no longer pays
        run(&c, 2000, 60.0, 90.0);
        assert_eq!(c.preferred(), Some(false));
    }

    #[test]
    fn the_standard_error_is_that_of_the_moving_average() {
        let c = CoarseChoice::default();
        for k in 0..10 {
            c.record(false, 10.0 + k as f64, false);
        }
        let (plain, _) = c.arms();
        assert!((plain.sum_sq_weights() - 0.1).abs() < 1e-12);
        // against the weights themselves, sample by sample: 1/n, then each
        // old weight times 1 − w and the new one w
        let w = 1.0 / CoarseChoice::MEMORY;
        let mut weights = vec![0.1; 10];
        for k in 0..2000 {
            c.record(false, 10.0 + (k % 7) as f64, false);
            let n = 11 + k;
            let new = (1.0 / n as f64).max(w);
            weights.iter_mut().for_each(|x| *x *= 1.0 - new);
            weights.push(new);
            if k % 97 == 0 || k == 1999 {
                let (plain, _) = c.arms();
                let sum: f64 = weights.iter().map(|x| x * x).sum();
                assert!(
                    (plain.sum_sq_weights() - sum).abs() < 1e-12,
                    "{k}: {plain:?}"
                );
            }
        }
        let (plain, _) = c.arms();
        let steady = 1.0 / (2.0 * CoarseChoice::MEMORY - 1.0);
        assert!((plain.sum_sq_weights() - steady).abs() < 1e-9, "{plain:?}");
    }

    #[test]
    fn a_plan_unlucky_in_its_trials_is_tried_again_until_its_costs_say_so() {
        // the coarse pass's trials come out slower (8 or 24 ms, typical
        // 13.9) than the tiles' (10 or 14, typical 11.8), though it costs 6
        // or 14 ms afterwards (typical 9.2): one exploration in 32 would not
        // overturn its trials within 200 requests, the draws do
        let c = CoarseChoice::default();
        let mut seen = [0usize; 2];
        let mut used_after_trials = 0;
        for _ in 0..2 * CoarseChoice::TRIAL + 200 {
            let coarse = c.choose();
            let k = seen[coarse as usize];
            seen[coarse as usize] += 1;
            let ms = match (coarse, k < CoarseChoice::TRIAL as usize, k % 2 == 0) {
                (false, _, even) => [14.0, 10.0][even as usize],
                (true, true, even) => [24.0, 8.0][even as usize],
                (true, false, even) => [14.0, 6.0][even as usize],
            };
            c.record(coarse, ms, coarse);
            used_after_trials += usize::from(coarse && k >= CoarseChoice::TRIAL as usize);
        }
        assert_eq!(c.preferred(), Some(true), "{:?}", c.arms());
        assert!(used_after_trials > 200 / 2, "{used_after_trials}");
    }

    #[test]
    fn a_resumed_choice_goes_on_where_the_other_stopped() {
        let c = CoarseChoice::default();
        run(&c, 100, 60.0, 20.0);
        let learned = c.learned();
        assert_eq!(learned.requests, 100);
        assert_eq!(learned.tiles.samples + learned.coarse.samples, 100);
        let text = serde_json::to_string(&learned).unwrap();
        let back: Learned = serde_json::from_str(&text).unwrap();
        assert_eq!(back, learned);
        let resumed = CoarseChoice::default();
        resumed.resume(back).unwrap();
        assert_eq!(resumed.learned(), learned);
        assert_eq!(resumed.preferred(), Some(true));
        // no trials: the first requests already take the coarse pass
        let used = run(&resumed, 16, 60.0, 20.0);
        assert!(used >= 15, "{used}");
        // a new choice alternates
        assert_eq!(run(&CoarseChoice::default(), 16, 60.0, 20.0), 8);
    }

    #[test]
    fn figures_that_no_choice_learns_are_refused() {
        let c = CoarseChoice::default();
        run(&c, 40, 60.0, 20.0);
        let good = c.learned();
        let bad = [
            Learned {
                coarse: Arm {
                    mean_ln_ms: f64::NAN,
                    ..good.coarse
                },
                ..good
            },
            Learned {
                tiles: Arm {
                    ended_first: 1.5,
                    ..good.tiles
                },
                ..good
            },
            Learned {
                tiles: Arm {
                    mean_sq_ln_ms: 0.0,
                    ..good.tiles
                },
                ..good
            },
        ];
        for learned in bad {
            let fresh = CoarseChoice::default();
            assert!(fresh.resume(learned).is_err(), "{learned:?}");
            assert_eq!(fresh.learned(), Learned::default());
        }
    }

    #[test]
    fn times_that_are_not_times_are_ignored() {
        let c = CoarseChoice::default();
        c.record(true, f64::NAN, true);
        c.record(false, -1.0, true);
        c.record(false, f64::INFINITY, false);
        assert_eq!(c.arms(), (Arm::default(), Arm::default()));
    }
}

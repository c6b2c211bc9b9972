//! Rule `confident` (δ): stop when the leader beats every other image with
//! confidence 1 − δ, by an anytime-valid confidence bound for sampling
//! without replacement.
//!
//! The features are a uniformly random permutation of a finite set of N, so
//! after t features the per-feature vote differences x_i = v_i(L) − v_i(j)
//! between the leader L and a challenger j are t draws without replacement
//! from N fixed values. L wins under full bag-of-words iff their population
//! mean is positive. The empirical Bernstein–Serfling inequality (Bardenet &
//! Maillard 2015, Theorem 3) bounds the gap between sample and population
//! means:
//!
//! μ ≥ x̄_t − σ̂_t·√(2·ρ_t·ln(5/δ')/t) − κ·(b − a)·ln(5/δ')/t, with
//! κ = 7/3 + 3/√2, ρ_t = 1 − (t−1)/N for t ≤ N/2, else (1 − t/N)(1 + 1/t).
//!
//! It is made anytime-valid by spending δ' = δ / ((M − 1)·t·(t + 1)) at step t
//! on each of the M − 1 challengers (Σ_t 1/(t(t+1)) = 1), so with probability
//! at least 1 − δ the rule never stops on a leader that full bag-of-words
//! would not rank first. While N is unknown (tiles left to extract) the
//! finite-population factor is dropped (ρ = 1, the with-replacement bound,
//! which is valid for sampling without replacement too). With tiled
//! extraction the order is random within a tile and between tiles, not over
//! the whole image, so the guarantee is exact only for whole-image extraction.
//! The check is made conservative in O(1): x̄ uses the
//! strongest challenger, σ̂² ≤ (Σv_L² + max_j Σv_j²)/t (votes are
//! non-negative, so the cross term only lowers it), and the range b − a uses
//! cap_L plus the largest cap of the map.
//!
//! The rule also stops when the lead is certain: when h(L) − h(j) exceeds what
//! the features left could add to any challenger (the `lossless` bound for
//! the top 1), so it never needs more features than `lossless` at n = 1.
//! Per-feature votes are sparse and heavy-tailed (a feature gives nothing to
//! most images and a large vote to a few), so the probabilistic bound is
//! often the weaker of the two: `docs/results.md` measures both.

use super::{Grid, Parameter, Range, RuleInfo, StopRule};
use crate::search::vote::{Needs, VoteStats};

pub const INFO: RuleInfo = RuleInfo {
    name: "confident",
    parameter: Some(Parameter {
        name: "delta",
        meaning: "δ, the chance of stopping on a leader that would lose",
        range: Range::Open01,
        example: 0.05,
    }),
    grid: Grid::Values(&[0.1, 0.05, 0.01]),
    about: "stop when the leader wins with probability ≥ 1 − δ (Bernstein–Serfling, anytime)",
    stops_early: true,
    geometric: false,
    whole_histogram: false,
    make: |d, _| Ok(Box::new(Confident(d))),
};

const KAPPA: f64 = 7.0 / 3.0 + 2.121_320_343_559_643; // 7/3 + 3/√2

struct Confident(f64);

/// Lower confidence bound on the population mean of N values in a range of
/// width `range`, from t draws without replacement with mean `mean` and
/// standard deviation at most `sd`, at level δ (N unknown: `None`).
pub fn serfling_lower_bound(
    mean: f64,
    sd: f64,
    range: f64,
    t: usize,
    n: Option<usize>,
    delta: f64,
) -> f64 {
    let t_f = t as f64;
    let rho = match n {
        None => 1.0,
        Some(n) if 2 * t <= n => 1.0 - (t_f - 1.0) / n as f64,
        Some(n) => (1.0 - t_f / n as f64) * (1.0 + 1.0 / t_f),
    };
    let log = (5.0 / delta).ln();
    mean - sd * (2.0 * rho * log / t_f).sqrt() - KAPPA * range * log / t_f
}

impl StopRule for Confident {
    fn needs(&self) -> Needs {
        Needs {
            top: 2,
            squares: true,
            ..Needs::default()
        }
    }

    fn check(&mut self, voter: &dyn VoteStats) -> Option<String> {
        let tally = voter.tally();
        let (t, images) = (tally.features, tally.images);
        let leader = tally.leader?;
        if t < 2 || images < 2 || tally.max <= tally.second {
            return None;
        }
        if let Some(left) = tally.remaining()
            && tally.max - tally.second > left as f32 * tally.vote_cap * (1.0 + 1e-5)
        {
            return Some(format!(
                "leader certain: lead exceeds what {left} features left can add"
            ));
        }
        let tf = t as f64;
        let mean = (tally.max - tally.second) as f64 / tf;
        let second_moment =
            (voter.squares_of(leader) as f64 + voter.max_squares_except(leader) as f64) / tf;
        let sd = second_moment.sqrt();
        let range = (voter.image_vote_cap(leader) + tally.vote_cap) as f64;
        let step_delta = self.0 / ((images - 1) as f64 * tf * (tf + 1.0));
        let lower = serfling_lower_bound(mean, sd, range, t, tally.total, step_delta);
        (lower > 0.0).then(|| {
            format!(
                "leader wins with confidence 1 − {}: lower bound {:.3e} > 0",
                self.0, lower
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bound_tightens_with_samples_and_without_replacement() {
        let b = |t| serfling_lower_bound(0.1, 0.2, 1.0, t, Some(10_000), 0.05);
        assert!(b(10) < b(100) && b(100) < b(1000));
        // the finite-population factor helps once most of the set is seen
        let near_end = serfling_lower_bound(0.1, 0.2, 1.0, 9_990, Some(10_000), 0.05);
        let infinite = 0.1
            - 0.2 * (2.0 * (5.0f64 / 0.05).ln() / 9_990.0).sqrt()
            - KAPPA * (5.0f64 / 0.05).ln() / 9_990.0;
        assert!(near_end > infinite);
        // a smaller δ gives a lower bound
        assert!(
            serfling_lower_bound(0.1, 0.2, 1.0, 100, Some(1000), 0.001)
                < serfling_lower_bound(0.1, 0.2, 1.0, 100, Some(1000), 0.1)
        );
    }
}

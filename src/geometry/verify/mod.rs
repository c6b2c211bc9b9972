//! Geometric verification of vote candidates: tentative correspondences by
//! shared word ([`super::matches`]), a robust model fit behind [`ModelFit`]
//! (implemented with OpenCV in `features::fit`), the inliers counted
//! ([`verify_features`]; [`LeaderVerifier`] offers the same check to the
//! geometric stops), and the candidates re-ranked by inliers ([`rerank`]).
//! The score a verified answer reports is the inlier count: the number of
//! query features whose position agrees with one geometric transformation to
//! the candidate, which means the same for every query whatever the stop
//! point. The settings are in [`params`](mod@params).

pub mod params;
pub mod ranking;

pub use params::{Estimator, FitError, FitParams, Model, ModelFit, Order, Rerank, VerifyParams};
pub use ranking::{Reranked, rerank};

use super::Keypoint;
use super::matches::{Correspondences, QueryFeature, QueryFeatures, tentative};
use super::packed::PackedFeature;
use crate::index::MapRead;
use crate::search::stop::CheckedAnswer;
use crate::search::{LeaderCheck, Voted};
use serde::Serialize;

/// What verifying one candidate found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Verification {
    /// Tentative correspondences (shared words).
    pub matches: usize,
    /// Correspondences agreeing with the fitted model (distinct points).
    pub inliers: usize,
    /// `inliers ≥ min_inliers`.
    pub verified: bool,
}

/// Inliers whose points, on either side, spread less than this (standard
/// deviation along the thinnest direction, pixels) lie on a line or a point:
/// no model is determined, so they count as none.
const MIN_SPREAD_PX: f32 = 2.0;

/// Standard deviation of `points` along their thinnest direction.
fn thinnest_spread(points: &[[f32; 2]]) -> f32 {
    let n = points.len() as f32;
    if points.len() < 2 {
        return 0.0;
    }
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p[0] / n, y + p[1] / n));
    let (mut sxx, mut syy, mut sxy) = (0.0f32, 0.0f32, 0.0f32);
    for p in points {
        let (dx, dy) = (p[0] - mx, p[1] - my);
        sxx += dx * dx / n;
        syy += dy * dy / n;
        sxy += dx * dy / n;
    }
    // smaller eigenvalue of [[sxx, sxy], [sxy, syy]]
    let half_trace = (sxx + syy) / 2.0;
    let det = sxx * syy - sxy * sxy;
    let disc = (half_trace * half_trace - det).max(0.0).sqrt();
    (half_trace - disc).max(0.0).sqrt()
}

fn distinct(points: impl Iterator<Item = [f32; 2]>) -> usize {
    let mut keys: Vec<[u32; 2]> = points.map(|p| p.map(f32::to_bits)).collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len()
}

/// Count the inliers of a robust fit to `c`.
pub fn count_inliers(c: &Correspondences, fit: &dyn ModelFit, min_inliers: usize) -> Verification {
    fit_inliers(c, fit, min_inliers).0
}

/// [`count_inliers`], with the inliers as matched positions (empty when
/// none count).
pub fn fit_inliers(
    c: &Correspondences,
    fit: &dyn ModelFit,
    min_inliers: usize,
) -> (Verification, Correspondences) {
    let matches = c.len();
    let none = (
        Verification {
            matches,
            inliers: 0,
            verified: false,
        },
        Correspondences::default(),
    );
    // fewer matches than the model needs, or than a verified candidate has
    // inliers: no fit can verify it, so none is run
    let needed = fit.params().model.min_matches();
    if matches < needed.max(min_inliers)
        || distinct(c.query.iter().copied()) < needed
        || distinct(c.map.iter().copied()) < needed
    {
        return none;
    }
    let mask = match fit.inliers(&c.query, &c.map) {
        Ok(mask) if mask.len() == matches => mask,
        Ok(_) => return none,
        Err(e) => {
            tracing::debug!("{e}");
            return none;
        }
    };
    let pick = |side: &[[f32; 2]]| -> Vec<[f32; 2]> {
        side.iter()
            .zip(&mask)
            .filter(|(_, inlier)| **inlier)
            .map(|(p, _)| *p)
            .collect()
    };
    let (q, m) = (pick(&c.query), pick(&c.map));
    if thinnest_spread(&q) < MIN_SPREAD_PX || thinnest_spread(&m) < MIN_SPREAD_PX {
        return none;
    }
    let inliers = distinct(q.iter().copied()).min(distinct(m.iter().copied()));
    let verification = Verification {
        matches,
        inliers,
        verified: inliers >= min_inliers.max(1),
    };
    (verification, Correspondences { query: q, map: m })
}

/// Verify one map image's stored features against the query's: the
/// verification and the pairs the fit took as inliers.
pub fn verify_features(
    map_features: &[PackedFeature],
    query: &QueryFeatures,
    fit: &dyn ModelFit,
    params: &VerifyParams,
) -> (Verification, Correspondences) {
    let c = tentative(
        query,
        map_features,
        params.max_word_pairs,
        params.max_hamming,
    );
    fit_inliers(&c, fit, params.min_inliers())
}

/// Verify the current leader against the features seen so far: what a
/// search calls mid-way to decide whether it may stop. Cheap enough for
/// every block (one merge and one fit).
pub fn verify_leader(
    map: &dyn MapRead,
    leader: u32,
    query_so_far: &[QueryFeature],
    fit: &dyn ModelFit,
    params: &VerifyParams,
) -> Verification {
    verify_features(
        map.geometry(leader),
        &QueryFeatures::new(query_so_far),
        fit,
        params,
    )
    .0
}

/// The `verified` stop's check (a [`LeaderCheck`]): a map image against
/// the query features voted so far, verified as the final answer is.
/// `keypoints` holds every feature given to the search, by feature number.
pub struct LeaderVerifier<'a> {
    pub map: &'a dyn MapRead,
    pub fit: &'a dyn ModelFit,
    pub params: &'a VerifyParams,
    pub keypoints: &'a [Keypoint],
    /// The search's place window ([`rerank`]).
    pub place_window: u32,
}

impl LeaderCheck for LeaderVerifier<'_> {
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[Voted],
        min_inliers: usize,
    ) -> Option<CheckedAnswer> {
        let query = with_keypoints(voted, self.keypoints);
        let params = self.params.for_stop(min_inliers);
        let reranked = rerank(
            self.map,
            candidates,
            &query,
            self.fit,
            &params,
            self.place_window,
        );
        reranked.first().map(|r| CheckedAnswer {
            id: r.id,
            inliers: r.inliers(),
            scale: r.scale(),
        })
    }

    fn max_log_scale(&self) -> f32 {
        self.params.stop_log_scale
    }

    fn fit_needs(&self) -> usize {
        self.params.model.min_matches()
    }
}

/// The features voted, with their keypoints (`keypoints` holds every
/// feature's keypoint by number).
pub fn with_keypoints(voted: &[Voted], keypoints: &[Keypoint]) -> Vec<QueryFeature> {
    voted
        .iter()
        .filter_map(|v| {
            keypoints.get(v.feature as usize).map(|k| QueryFeature {
                word: v.word,
                signature: v.signature,
                keypoint: *k,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit that calls every pair an inlier.
    pub(super) struct AllInliers(pub(super) FitParams);

    impl ModelFit for AllInliers {
        fn params(&self) -> &FitParams {
            &self.0
        }
        fn inliers(&self, q: &[[f32; 2]], _: &[[f32; 2]]) -> Result<Vec<bool>, FitError> {
            Ok(vec![true; q.len()])
        }
    }

    fn pairs(q: &[[f32; 2]]) -> Correspondences {
        Correspondences {
            query: q.to_vec(),
            map: q.iter().map(|p| [p[0] + 3.0, p[1] * 2.0]).collect(),
        }
    }

    #[test]
    fn degenerate_correspondences_count_no_inliers() {
        let fit = AllInliers(FitParams {
            model: Model::Homography,
            ..VerifyParams::default().fit()
        });
        // fewer than the model needs (4 for a homography)
        let v = count_inliers(&pairs(&[[0.0, 0.0], [5.0, 9.0], [7.0, 1.0]]), &fit, 1);
        assert_eq!((v.matches, v.inliers, v.verified), (3, 0, false));
        // all on a line
        let line: Vec<[f32; 2]> = (0..20).map(|i| [i as f32, 2.0 * i as f32 + 1.0]).collect();
        assert_eq!(count_inliers(&pairs(&line), &fit, 1).inliers, 0);
        // all on one point
        assert_eq!(count_inliers(&pairs(&[[4.0, 4.0]; 20]), &fit, 1).inliers, 0);
        // no pairs at all
        assert_eq!(
            count_inliers(&Correspondences::default(), &fit, 1),
            Verification::default()
        );
        // spread points are counted
        let grid: Vec<[f32; 2]> = (0..16)
            .map(|i| [(i % 4) as f32 * 10.0, (i / 4) as f32 * 10.0])
            .collect();
        let v = count_inliers(&pairs(&grid), &fit, 16);
        assert_eq!((v.inliers, v.verified), (16, true));
        assert!(!count_inliers(&pairs(&grid), &fit, 17).verified);
    }
}

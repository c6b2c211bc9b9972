//! Geometric verification of vote candidates: tentative correspondences by
//! shared word ([`super::matches`]), a robust model fit behind [`ModelFit`]
//! (implemented with OpenCV in `features::fit`), the inliers counted, and
//! the candidates re-ranked by inliers. The score a verified answer reports
//! is the inlier count: the number of query features whose position agrees
//! with one geometric transformation to the candidate, which means the same
//! for every query whatever the stop point.

use super::Keypoint;
use super::matches::{Correspondences, QueryFeature, QueryFeatures, tentative};
use super::packed::PackedFeature;
use super::relative_scale::relative_scale;
use crate::index::MapRead;
use crate::search::stop::CheckedAnswer;
use crate::search::{LeaderCheck, Voted};
use serde::{Deserialize, Serialize};

/// The geometric model fitted to the correspondences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// A plane-to-plane map (4 matches at least).
    Homography,
    /// Epipolar geometry of two views (8 matches at least).
    Fundamental,
    /// Rotation, uniform scale and translation (2 matches at least).
    Similarity,
    /// A 2-D affine map (3 matches at least).
    Affine,
}

/// The robust estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Estimator {
    /// Classic RANSAC.
    Ransac,
    /// USAC with MAGSAC++ scoring.
    Magsac,
}

/// How verification orders the candidates it checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Order {
    /// By inliers, most first (equal counts in vote order).
    Inliers,
    /// The verified candidates (at least `min_inliers`) first, then the
    /// others, each group in vote order: a vote leader that verifies stays
    /// first, and one that does not gives way to the best-voted one that does.
    Verified,
    /// By the inliers of the candidate's place: its own plus those of the
    /// other checked candidates within the place window along the map's
    /// order (most first; equal sums by the candidate's own inliers, then in
    /// vote order). Neighbouring map images
    /// see the same place, so their inliers add up to evidence for it where
    /// one image's inliers are few (docs/results.md, "Place inliers").
    Place,
    /// [`Order::Place`], then the first place answers with its verified
    /// candidate whose inliers show the scene at the scale nearest the
    /// query's ([`super::relative_scale`]): of the map images that see the
    /// place, the one taken nearest the query along the way. It keeps the
    /// place's score.
    PlaceScale,
}

/// Which of the checked candidates verification moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rerank {
    /// The answer only: the order's first candidate leads, and the others
    /// follow in vote order. A wrong candidate with a few inliers can then
    /// take the first place only, never push the right one out of the
    /// top five (docs/results.md, "Re-ranking the answer only").
    Answer,
    /// Every checked candidate takes its place in the order.
    All,
}

impl Rerank {
    /// Every choice, the default first.
    pub const ALL: [Rerank; 2] = [Rerank::Answer, Rerank::All];

    pub fn name(self) -> &'static str {
        match self {
            Self::Answer => "answer",
            Self::All => "all",
        }
    }

    /// What it does, in a line (for help texts).
    pub fn about(self) -> &'static str {
        match self {
            Self::Answer => "the order's first candidate leads; the others follow in vote order",
            Self::All => "every checked candidate in the order",
        }
    }
}

impl Order {
    /// Every order, the default first.
    pub const ALL: [Order; 4] = [
        Order::PlaceScale,
        Order::Place,
        Order::Inliers,
        Order::Verified,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::Inliers => "inliers",
            Self::Verified => "verified",
            Self::Place => "place",
            Self::PlaceScale => "place-scale",
        }
    }

    /// What the order does, in a line (for help texts).
    pub fn about(self) -> &'static str {
        match self {
            Self::Place => {
                "by the inliers of the candidate and of the checked candidates within the \
                 place window of it, most first"
            }
            Self::PlaceScale => {
                "as place, then the first place answers with its verified candidate whose \
                 inliers show the scene at the scale nearest the query's"
            }
            Self::Inliers => "by the candidate's own inliers, most first",
            Self::Verified => {
                "the verified candidates (at least min_inliers) first, each group in vote order"
            }
        }
    }
}

impl Model {
    /// Every model, the default first.
    pub const ALL: [Model; 4] = [
        Model::Similarity,
        Model::Homography,
        Model::Fundamental,
        Model::Affine,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::Homography => "homography",
            Self::Fundamental => "fundamental",
            Self::Similarity => "similarity",
            Self::Affine => "affine",
        }
    }

    /// What the model is, in a line (for help texts).
    pub fn about(self) -> &'static str {
        match self {
            Self::Homography => "a plane-to-plane map (4 pairs at least)",
            Self::Fundamental => "epipolar geometry of two views (8 pairs at least)",
            Self::Similarity => {
                "rotation, one scale and translation (2 pairs at least; fitted by RANSAC)"
            }
            Self::Affine => "a 2-D affine map (3 pairs at least; fitted by RANSAC)",
        }
    }

    /// Fewest correspondences the model can be fitted to.
    pub fn min_matches(self) -> usize {
        match self {
            Self::Homography => 4,
            Self::Fundamental => 8,
            Self::Similarity => 2,
            Self::Affine => 3,
        }
    }

    /// The inliers that verify a candidate unless `verify.min_inliers`
    /// says otherwise: 6 for a similarity, chosen on gardens-point and
    /// checked on rtabmap-loop (docs/results.md, "The verification
    /// floor"); 12, the value before, for the models that floor was not
    /// measured with.
    pub fn default_min_inliers(self) -> usize {
        match self {
            Self::Similarity => 6,
            Self::Homography | Self::Fundamental | Self::Affine => 12,
        }
    }

    /// Every model's default floor, for help texts and the docs:
    /// "similarity 6, homography 12, …".
    pub fn default_floors() -> String {
        Self::ALL
            .iter()
            .map(|m| format!("{} {}", m.name(), m.default_min_inliers()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl Estimator {
    /// Every estimator, the default first.
    pub const ALL: [Estimator; 2] = [Estimator::Magsac, Estimator::Ransac];

    pub fn name(self) -> &'static str {
        match self {
            Self::Ransac => "ransac",
            Self::Magsac => "magsac",
        }
    }

    /// What the estimator is, in a line (for help texts).
    pub fn about(self) -> &'static str {
        match self {
            Self::Ransac => "classic RANSAC",
            Self::Magsac => "USAC with MAGSAC++ scoring (a homography or a fundamental matrix)",
        }
    }
}

named_choice!(Order, "order");
named_choice!(Rerank, "re-ranking");
named_choice!(Model, "model");
named_choice!(Estimator, "estimator");

/// How a model is fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitParams {
    pub model: Model,
    pub estimator: Estimator,
    /// Largest distance of an inlier from the model, in pixels of the
    /// extraction frame (reprojection error for a homography, distance to
    /// the epipolar line for a fundamental matrix).
    pub threshold_px: f64,
    /// Confidence the estimator aims for.
    pub confidence: f64,
    /// Iteration cap of the estimator.
    pub max_iters: u32,
}

impl FitParams {
    /// The estimator the fit runs: the one asked for, except for a
    /// similarity or an affine map, which OpenCV fits by RANSAC only.
    pub fn estimator_used(&self) -> Estimator {
        match self.model {
            Model::Homography | Model::Fundamental => self.estimator,
            Model::Similarity | Model::Affine => Estimator::Ransac,
        }
    }
}

/// Why a fit failed (the candidate then counts no inliers).
#[derive(Debug, thiserror::Error)]
#[error("model fit failed: {0}")]
pub struct FitError(pub String);

/// A robust fit: which of the pairs `query[i]` ↔ `map[i]` agree with the
/// best model found. An empty mask means no model was found.
pub trait ModelFit: Send + Sync {
    fn params(&self) -> &FitParams;
    fn inliers(&self, query: &[[f32; 2]], map: &[[f32; 2]]) -> Result<Vec<bool>, FitError>;
}

/// Verification settings (the service's `[verify]` section).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerifyParams {
    /// Verify when the request does not say.
    pub enabled: bool,
    /// Vote candidates verified (the rest keep their vote order below them).
    pub top_k: usize,
    /// Inliers for a candidate to count as verified, and matches for it to
    /// be fitted at all; `None`: the model's default
    /// ([`Model::default_min_inliers`], read through
    /// [`VerifyParams::min_inliers`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_inliers: Option<usize>,
    /// A word giving more pairs than this between the two images is skipped.
    pub max_word_pairs: usize,
    /// Features whose Hamming signatures differ in more bits than this do
    /// not pair up (64: every pair of a word).
    pub max_hamming: u32,
    /// How the checked candidates are ordered.
    pub order: Order,
    /// Whether that order places every checked candidate or the answer only.
    pub rerank: Rerank,
    pub model: Model,
    pub estimator: Estimator,
    /// See [`FitParams::threshold_px`].
    pub threshold_px: f64,
    pub confidence: f64,
    pub max_iters: u32,
    /// The geometric stops (`verified`, `or_verified`) stop only on an
    /// answer whose inliers show the scene at the query's scale: spread at
    /// most e^this times more or less in the map image than in the query
    /// (docs/results.md, "The verified stop at the query's scale").
    pub stop_log_scale: f32,
}

impl Default for VerifyParams {
    fn default() -> Self {
        // Chosen by measurement on the shared datasets (docs/results.md,
        // "Geometric verification", "The default rule"): a similarity makes
        // the default rule's answers the best to threshold (recall top-1 @90 %
        // precision) and keeps its recall; MAGSAC++ serves the models that
        // take an estimator; on by default because, with the place-scale
        // order, it raises recall@1 on gardens-point's worst seed after the
        // default early stop (docs/results.md, "Place inliers").
        Self {
            enabled: true,
            top_k: 10,
            min_inliers: None,
            max_word_pairs: 4,
            max_hamming: 16,
            order: Order::PlaceScale,
            rerank: Rerank::Answer,
            model: Model::Similarity,
            estimator: Estimator::Magsac,
            threshold_px: 8.0,
            confidence: 0.995,
            max_iters: 500,
            stop_log_scale: crate::search::stop::MAX_LOG_SCALE,
        }
    }
}

impl VerifyParams {
    /// The fit's part of the settings.
    pub fn fit(&self) -> FitParams {
        FitParams {
            model: self.model,
            estimator: self.estimator,
            threshold_px: self.threshold_px,
            confidence: self.confidence,
            max_iters: self.max_iters,
        }
    }

    /// Inliers for a candidate to count as verified: the configured value,
    /// else the model's default.
    pub fn min_inliers(&self) -> usize {
        self.min_inliers
            .unwrap_or_else(|| self.model.default_min_inliers())
    }

    /// The same settings with the floor written out, so that a record of
    /// them (an evaluation's `results.json`) says which floor ran.
    pub fn resolved(self) -> Self {
        Self {
            min_inliers: Some(self.min_inliers()),
            ..self
        }
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.top_k == 0 {
            return Err("top_k must be at least 1".into());
        }
        let needs = self.model.min_matches();
        if self.min_inliers() <= needs {
            return Err(format!(
                "min_inliers must be more than the {needs} pairs a {} fit takes (any {needs} agree with the model fitted to them), got {}",
                self.model.name(),
                self.min_inliers()
            ));
        }
        if self.max_word_pairs == 0 {
            return Err("max_word_pairs must be at least 1".into());
        }
        if !(self.threshold_px.is_finite() && self.threshold_px > 0.0) {
            return Err(format!(
                "threshold_px must be a positive number, got {}",
                self.threshold_px
            ));
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(format!(
                "confidence must lie in (0, 1), got {}",
                self.confidence
            ));
        }
        if self.max_iters == 0 {
            return Err("max_iters must be at least 1".into());
        }
        if !(self.stop_log_scale.is_finite() && self.stop_log_scale >= 0.0) {
            return Err(format!(
                "stop_log_scale must be a number of at least 0, got {}",
                self.stop_log_scale
            ));
        }
        Ok(())
    }
}

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
    fn inliers(&mut self, image: u32, voted: &[Voted]) -> usize {
        let query = with_keypoints(voted, self.keypoints);
        verify_leader(self.map, image, &query, self.fit, self.params).inliers
    }

    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[Voted],
        min_inliers: usize,
    ) -> Option<CheckedAnswer> {
        let query = with_keypoints(voted, self.keypoints);
        // a floor under the stop's m would let `place-scale` answer with a
        // candidate too weak to stop on, and hide a stronger one of its place
        let params = VerifyParams {
            min_inliers: Some(self.params.min_inliers().max(min_inliers)),
            ..self.params.clone()
        };
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
            scale: relative_scale(&r.inlier_pairs),
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

#[derive(Debug, Clone, PartialEq)]
pub struct Reranked {
    pub id: u32,
    /// The vote score it had.
    pub votes: f32,
    /// Its score after verification ([`Reranked::score`]).
    score: f32,
    /// `None` beyond the top k (not verified).
    pub verification: Option<Verification>,
    /// The pairs the fit took as inliers (empty unless it verified some).
    pub inlier_pairs: Correspondences,
    /// The candidate whose vote distinctness this one's answer carries: its
    /// own id, or that of the place's leader it was moved ahead of
    /// ([`Order::PlaceScale`]), as it carries the place's score.
    pub distinct_from: u32,
    /// Its place in the vote order.
    vote_rank: usize,
}

impl Reranked {
    /// The score of a verified answer: the inlier count, or the place's
    /// (0 when not checked).
    pub fn score(&self) -> f32 {
        self.score
    }

    fn inliers(&self) -> usize {
        self.verification.map_or(0, |v| v.inliers)
    }
}

/// Verify the first `params.top_k` of `candidates` (id, vote score; best
/// first) and order them as `params.order` says, ties kept in vote order;
/// candidates beyond the top k follow in vote order. With
/// [`Rerank::Answer`] only the order's first candidate moves: the others
/// stay in vote order behind it. `place_window`: the
/// images on each side of an image, along the map's order, that belong to
/// its place ([`Order::Place`]).
pub fn rerank(
    map: &dyn MapRead,
    candidates: &[(u32, f32)],
    query: &[QueryFeature],
    fit: &dyn ModelFit,
    params: &VerifyParams,
    place_window: u32,
) -> Vec<Reranked> {
    let query = QueryFeatures::new(query);
    let k = params.top_k.min(candidates.len());
    let mut out: Vec<Reranked> = candidates
        .iter()
        .enumerate()
        .map(|(i, &(id, votes))| {
            let (verification, inlier_pairs) = if i < k {
                let (v, pairs) = verify_features(map.geometry(id), &query, fit, params);
                (Some(v), pairs)
            } else {
                (None, Correspondences::default())
            };
            Reranked {
                id,
                votes,
                score: verification.map_or(0.0, |v| v.inliers as f32),
                verification,
                inlier_pairs,
                distinct_from: id,
                vote_rank: i,
            }
        })
        .collect();
    // stable: equal keys keep vote order
    match params.order {
        Order::Inliers => out[..k].sort_by_key(|r| std::cmp::Reverse(r.inliers())),
        Order::Verified => out[..k].sort_by_key(|r| !r.verification.is_some_and(|v| v.verified)),
        Order::Place | Order::PlaceScale => {
            let place: Vec<usize> = out[..k]
                .iter()
                .map(|r| {
                    out[..k]
                        .iter()
                        .filter(|o| o.id.abs_diff(r.id) <= place_window)
                        .map(Reranked::inliers)
                        .sum()
                })
                .collect();
            for (r, &p) in out[..k].iter_mut().zip(&place) {
                r.score = p as f32;
            }
            // neighbours often share a sum: the one with more inliers of
            // its own first
            out[..k].sort_by(|a, b| {
                b.score
                    .total_cmp(&a.score)
                    .then(b.inliers().cmp(&a.inliers()))
            });
            if params.order == Order::PlaceScale {
                nearest_scale_first(&mut out[..k], place_window);
            }
        }
    }
    if params.rerank == Rerank::Answer && !out.is_empty() {
        out[1..].sort_by_key(|r| r.vote_rank);
    }
    out
}

/// Move to the front the verified candidate of the first one's place (within
/// `place_window` of it) whose inliers show the scene at the relative scale
/// nearest 1 (equal ones in their order); it takes the first one's score
/// and distinctness, the place's.
fn nearest_scale_first(ranked: &mut [Reranked], place_window: u32) {
    let Some(first) = ranked.first() else { return };
    let (leader, score, distinct_from) = (first.id, first.score, first.distinct_from);
    let nearest = ranked
        .iter()
        .enumerate()
        .filter(|(_, r)| r.id.abs_diff(leader) <= place_window)
        .filter(|(_, r)| r.verification.is_some_and(|v| v.verified))
        .filter_map(|(i, r)| Some((i, relative_scale(&r.inlier_pairs)?.ln().abs())))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((i, _)) = nearest {
        ranked[..=i].rotate_right(1);
        ranked[0].score = score;
        ranked[0].distinct_from = distinct_from;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit that calls every pair an inlier.
    struct AllInliers(FitParams);

    impl ModelFit for AllInliers {
        fn params(&self) -> &FitParams {
            &self.0
        }
        fn inliers(&self, q: &[[f32; 2]], _: &[[f32; 2]]) -> Result<Vec<bool>, FitError> {
            Ok(vec![true; q.len()])
        }
    }

    #[test]
    fn each_choice_lists_its_default_first() {
        let d = VerifyParams::default();
        assert_eq!(Model::ALL[0], d.model);
        assert_eq!(Order::ALL[0], d.order);
        assert_eq!(Estimator::ALL[0], d.estimator);
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

    /// Keypoint of word `i`, on a grid of 5 columns 17 px apart and rows
    /// 13 px apart.
    fn grid_keypoint(i: u32) -> Keypoint {
        Keypoint {
            x: (i % 5) as f32 * 17.0 + 3.0,
            y: (i / 5) as f32 * 13.0 + 5.0,
            size: 4.0,
            angle: 0.0,
            response: 1.0,
        }
    }

    #[test]
    fn reranked_candidates_carry_the_inliers_their_fit_counted() {
        use crate::index::{ImageWords, MapBuilder};
        // map image 0 shares 20 spread words with the query, image 1 none
        let words: Vec<u32> = (0..20).collect();
        let kps: Vec<Keypoint> = words.iter().map(|&w| grid_keypoint(w)).collect();
        let other: Vec<u32> = (20..40).collect();
        let mut b = MapBuilder::new(40);
        b.add(ImageWords::with_geometry("a", &words, &[], &kps));
        b.add(ImageWords::with_geometry("b", &other, &[], &kps));
        let map = b.build("m", "v", None);
        let query: Vec<QueryFeature> = words
            .iter()
            .map(|&w| (w, grid_keypoint(w)).into())
            .collect();
        let fit = AllInliers(VerifyParams::default().fit());
        let out = rerank(
            &map,
            &[(1, 0.9), (0, 0.5)],
            &query,
            &fit,
            &VerifyParams::default(),
            2,
        );
        assert_eq!(out[0].id, 0, "the image with inliers is ranked first");
        let v = out[0].verification.unwrap();
        assert_eq!(v.inliers, 20);
        assert_eq!(out[0].inlier_pairs.len(), v.inliers);
        assert_eq!(out[1].verification.unwrap().inliers, 0);
        assert!(out[1].inlier_pairs.is_empty());
    }

    /// Default settings with verification `order` placing every checked
    /// candidate.
    fn in_order(order: Order) -> VerifyParams {
        VerifyParams {
            order,
            rerank: Rerank::All,
            ..Default::default()
        }
    }

    /// [`rerank`] with a fit that calls every pair an inlier.
    fn all_inliers(
        map: &dyn MapRead,
        votes: &[(u32, f32)],
        query: &[QueryFeature],
        params: VerifyParams,
        window: u32,
    ) -> Vec<Reranked> {
        rerank(
            map,
            votes,
            query,
            &AllInliers(params.fit()),
            &params,
            window,
        )
    }

    /// (id, score) of each re-ranked candidate.
    fn scores(ranked: &[Reranked]) -> Vec<(u32, f32)> {
        ranked.iter().map(|r| (r.id, r.score())).collect()
    }

    #[test]
    fn the_place_order_adds_up_the_inliers_of_neighbouring_images() {
        use crate::index::{ImageWords, MapBuilder};
        // along the map's order: images 0 and 1 share 14 and 13 words with
        // the query, 2 and 3 none, image 4 shares 20
        let shared: [std::ops::Range<u32>; 5] = [0..14, 14..27, 60..61, 61..62, 27..47];
        let mut b = MapBuilder::new(64);
        for (j, words) in shared.iter().enumerate() {
            let words: Vec<u32> = words.clone().collect();
            let kps: Vec<Keypoint> = words.iter().map(|&w| grid_keypoint(w)).collect();
            b.add(ImageWords::with_geometry(format!("{j}"), &words, &[], &kps));
        }
        let map = b.build("m", "v", None);
        let query: Vec<QueryFeature> = (0..47).map(|w| (w, grid_keypoint(w)).into()).collect();
        let votes = [(4, 0.9), (1, 0.5), (0, 0.4)];
        let ranked = |order: Order, window: u32| {
            scores(&all_inliers(&map, &votes, &query, in_order(order), window))
        };
        assert_eq!(ranked(Order::Inliers, 2), [(4, 20.0), (0, 14.0), (1, 13.0)]);
        // images 0 and 1 are one place: 14 + 13 inliers; of two equal sums
        // the image with more inliers of its own comes first
        assert_eq!(ranked(Order::Place, 2), [(0, 27.0), (1, 27.0), (4, 20.0)]);
        // a window of 0 makes every image its own place
        assert_eq!(ranked(Order::Place, 0), [(4, 20.0), (0, 14.0), (1, 13.0)]);
        // image 4 is 3 images from image 1: their places overlap with a
        // window of 3
        assert_eq!(ranked(Order::Place, 3), [(1, 47.0), (4, 33.0), (0, 27.0)]);
    }

    #[test]
    fn the_place_scale_order_answers_with_the_image_seen_at_the_query_scale() {
        use crate::index::{ImageWords, MapBuilder};
        // one place of three map images, seeing the query's scene at 0.7,
        // 1.05 and 1.5 times its size with 20, 14 and 16 shared words; image
        // 5 is another place, whose 5 shared words lie on a line (no inliers;
        // 3 and 4 share nothing)
        let images: [(std::ops::Range<u32>, f32); 6] = [
            (0..20, 0.7),
            (0..14, 1.05),
            (0..16, 1.5),
            (60..61, 1.0),
            (61..62, 1.0),
            (20..25, 1.0),
        ];
        let mut b = MapBuilder::new(64);
        for (j, (words, scale)) in images.iter().enumerate() {
            let words: Vec<u32> = words.clone().collect();
            let kps: Vec<Keypoint> = words
                .iter()
                .map(|&w| {
                    let k = grid_keypoint(w);
                    Keypoint {
                        x: k.x * scale + 40.0,
                        y: k.y * scale + 10.0,
                        ..k
                    }
                })
                .collect();
            b.add(ImageWords::with_geometry(format!("{j}"), &words, &[], &kps));
        }
        let map = b.build("m", "v", None);
        let query: Vec<QueryFeature> = (0..25).map(|w| (w, grid_keypoint(w)).into()).collect();
        let votes = [(5, 0.9), (0, 0.8), (2, 0.7), (1, 0.6)];
        let ranked = |order: Order, window: u32| {
            scores(&all_inliers(&map, &votes, &query, in_order(order), window))
        };
        // the place order puts image 0 first (the most inliers of its own
        // among equal sums); place-scale answers with image 1, at the place's
        // score
        assert_eq!(
            ranked(Order::Place, 2),
            [(0, 50.0), (2, 50.0), (1, 50.0), (5, 0.0)]
        );
        assert_eq!(
            ranked(Order::PlaceScale, 2),
            [(1, 50.0), (0, 50.0), (2, 50.0), (5, 0.0)]
        );
        // and it answers with the distinctness of the leader it displaced
        let out = all_inliers(&map, &votes, &query, in_order(Order::PlaceScale), 2);
        let from: Vec<(u32, u32)> = out.iter().map(|r| (r.id, r.distinct_from)).collect();
        assert_eq!(from, [(1, 0), (0, 0), (2, 2), (5, 5)]);
        // re-ranking the answer only: image 1 leads, the others keep their
        // vote order (image 5, with no inliers, second) and their scores
        let answer_only = VerifyParams {
            rerank: Rerank::Answer,
            ..in_order(Order::PlaceScale)
        };
        let out = all_inliers(&map, &votes, &query, answer_only, 2);
        assert_eq!(scores(&out), [(1, 50.0), (5, 0.0), (0, 50.0), (2, 50.0)]);
        let from: Vec<(u32, u32)> = out.iter().map(|r| (r.id, r.distinct_from)).collect();
        assert_eq!(from, [(1, 0), (5, 5), (0, 0), (2, 2)]);
        // an unverified candidate is not a choice: with 14 inliers needed
        // image 1 still is, with 15 it is not and image 0 (0.7) stays ahead
        // of image 2 (1.5)
        let with_min = |min_inliers: usize| -> Vec<u32> {
            let params = VerifyParams {
                min_inliers: Some(min_inliers),
                ..in_order(Order::PlaceScale)
            };
            let out = all_inliers(&map, &votes, &query, params, 2);
            out.iter().map(|r| r.id).collect()
        };
        assert_eq!(with_min(14), [1, 0, 2, 5]);
        assert_eq!(with_min(15), [0, 2, 1, 5]);
        // a window of 0: each image its own place, image 0 leads alone
        assert_eq!(ranked(Order::PlaceScale, 0)[0], (0, 20.0));
    }

    #[test]
    fn settings_are_checked() {
        assert!(VerifyParams::default().validate().is_ok());
        // every model's default floor is more than its fit takes
        for model in Model::ALL {
            let p = VerifyParams {
                model,
                ..Default::default()
            };
            assert!(p.validate().is_ok(), "{model:?}");
            assert_eq!(p.min_inliers(), model.default_min_inliers());
        }
        let set = VerifyParams {
            min_inliers: Some(9),
            ..Default::default()
        };
        assert_eq!(set.min_inliers(), 9);
        assert_eq!(set.clone().resolved(), set);
        assert_eq!(VerifyParams::default().resolved().min_inliers, Some(6));
        for bad in [
            VerifyParams {
                top_k: 0,
                ..Default::default()
            },
            VerifyParams {
                threshold_px: f64::NAN,
                ..Default::default()
            },
            VerifyParams {
                confidence: 1.0,
                ..Default::default()
            },
            // a homography fits any 4 pairs, a fundamental matrix any 8
            VerifyParams {
                model: Model::Homography,
                min_inliers: Some(4),
                ..Default::default()
            },
            VerifyParams {
                model: Model::Fundamental,
                min_inliers: Some(8),
                ..Default::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}

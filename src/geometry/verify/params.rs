//! What verification is asked to do: the geometric model and its robust
//! estimator ([`FitParams`], fitted behind [`ModelFit`]), the floor of
//! inliers, how the checked candidates are ordered ([`Order`]) and which of
//! them move ([`Rerank`]); the service's `[verify]` section
//! ([`VerifyParams`]).

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
    /// query's ([`relative_scale`](crate::geometry::relative_scale::relative_scale)): of the map images that see the
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
    /// A word giving more pairs than this between the two images is skipped
    /// (the answer's re-ranking; the geometric stops' is
    /// [`VerifyParams::stop_max_word_pairs`]).
    pub max_word_pairs: usize,
    /// Features whose Hamming signatures differ in more bits than this do
    /// not pair up (64: every pair of a word; the answer's re-ranking, the
    /// geometric stops' is [`VerifyParams::stop_max_hamming`]).
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
    /// [`VerifyParams::max_hamming`] for the geometric stops' checks.
    pub stop_max_hamming: u32,
    /// [`VerifyParams::max_word_pairs`] for the geometric stops' checks.
    pub stop_max_word_pairs: usize,
}

impl Default for VerifyParams {
    fn default() -> Self {
        // Chosen by measurement on the shared datasets (docs/results.md,
        // "Geometric verification", "The default rule"): a similarity makes
        // the default rule's answers the best to threshold (recall top-1 @90 %
        // precision) and keeps its recall; MAGSAC++ serves the models that
        // take an estimator; on by default because, with the place-scale
        // order, it raises recall@1 on gardens-point's worst seed after the
        // default early stop (docs/results.md, "Place inliers"). The answer
        // pairs features more loosely than the stops check (24 bits and 8
        // pairs a word against 16 and 4): more inliers for the right place
        // without stopping more searches on a wrong one (docs/results.md,
        // "Word pairs of the answer and of the stop").
        Self {
            enabled: true,
            top_k: 10,
            min_inliers: None,
            max_word_pairs: 8,
            max_hamming: 24,
            order: Order::PlaceScale,
            rerank: Rerank::Answer,
            model: Model::Similarity,
            estimator: Estimator::Magsac,
            threshold_px: 8.0,
            confidence: 0.995,
            max_iters: 500,
            stop_log_scale: crate::search::stop::MAX_LOG_SCALE,
            stop_max_hamming: 16,
            stop_max_word_pairs: 4,
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

    /// The settings a geometric stop verifies with, asking for `m` inliers:
    /// its own word pairs (`stop_max_hamming`, `stop_max_word_pairs`), and a
    /// floor of at least m, so that the answer it checks cannot be one too
    /// weak to stop on ahead of a stronger one of its place.
    pub fn for_stop(&self, m: usize) -> Self {
        Self {
            min_inliers: Some(self.min_inliers().max(m)),
            max_hamming: self.stop_max_hamming,
            max_word_pairs: self.stop_max_word_pairs,
            ..self.clone()
        }
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
        if self.max_word_pairs == 0 || self.stop_max_word_pairs == 0 {
            return Err("max_word_pairs and stop_max_word_pairs must be at least 1".into());
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_choice_lists_its_default_first() {
        let d = VerifyParams::default();
        assert_eq!(Model::ALL[0], d.model);
        assert_eq!(Order::ALL[0], d.order);
        assert_eq!(Rerank::ALL[0], d.rerank);
        assert_eq!(Estimator::ALL[0], d.estimator);
    }

    #[test]
    fn a_stop_verifies_with_its_own_pairs_and_at_least_its_m_as_floor() {
        let p = VerifyParams {
            max_hamming: 24,
            max_word_pairs: 8,
            stop_max_hamming: 10,
            stop_max_word_pairs: 2,
            ..Default::default()
        };
        let stop = p.for_stop(12);
        assert_eq!((stop.max_hamming, stop.max_word_pairs), (10, 2));
        assert_eq!(stop.min_inliers(), 12);
        // the floor is never lowered below the configured one
        assert_eq!(p.for_stop(0).min_inliers(), p.min_inliers());
        // the rest is the answer's
        assert_eq!(stop.stop_log_scale, p.stop_log_scale);
        assert_eq!(stop.order, p.order);
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
                stop_max_word_pairs: 0,
                ..Default::default()
            },
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

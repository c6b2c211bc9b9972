//! The robust model fit of geometric verification, with OpenCV's calib3d:
//! a homography or a fundamental matrix, by RANSAC or USAC/MAGSAC++. Both
//! are deterministic (OpenCV seeds its samplers with a constant).

use crate::geometry::verify::{Estimator, FitError, FitParams, Model, ModelFit};
use opencv::core::{Mat, Point2f, Vector};
use opencv::prelude::*;

/// [`ModelFit`] by `cv::findHomography` / `cv::findFundamentalMat`.
#[derive(Debug, Clone)]
pub struct OpenCvFit {
    params: FitParams,
}

impl OpenCvFit {
    pub fn new(params: FitParams) -> Self {
        Self { params }
    }
}

fn points(p: &[[f32; 2]]) -> Vector<Point2f> {
    p.iter().map(|&[x, y]| Point2f::new(x, y)).collect()
}

impl ModelFit for OpenCvFit {
    fn params(&self) -> &FitParams {
        &self.params
    }

    fn inliers(&self, query: &[[f32; 2]], map: &[[f32; 2]]) -> Result<Vec<bool>, FitError> {
        let p = &self.params;
        if query.len() != map.len() {
            return Err(FitError(format!(
                "{} query points but {} map points",
                query.len(),
                map.len()
            )));
        }
        if query.len() < p.model.min_matches() {
            return Ok(vec![false; query.len()]);
        }
        let (src, dst) = (points(query), points(map));
        let mut mask = Mat::default();
        let fail = |e: opencv::Error| FitError(e.message);
        // the estimator the model is fitted with (a similarity or an affine
        // map only by RANSAC), as OpenCV names it
        let method = match (p.model, p.estimator_used()) {
            (_, Estimator::Magsac) => opencv::calib3d::USAC_MAGSAC,
            (Model::Fundamental, Estimator::Ransac) => opencv::calib3d::FM_RANSAC,
            (_, Estimator::Ransac) => opencv::calib3d::RANSAC,
        };
        let model = match p.model {
            Model::Homography => opencv::calib3d::find_homography_ext(
                &src,
                &dst,
                method,
                p.threshold_px,
                &mut mask,
                p.max_iters as i32,
                p.confidence,
            ),
            Model::Fundamental => opencv::calib3d::find_fundamental_mat(
                &src,
                &dst,
                method,
                p.threshold_px,
                p.confidence,
                p.max_iters as i32,
                &mut mask,
            ),
            Model::Similarity | Model::Affine => {
                let estimate = match p.model {
                    Model::Similarity => opencv::calib3d::estimate_affine_partial_2d,
                    _ => opencv::calib3d::estimate_affine_2d,
                };
                // then 10 Levenberg–Marquardt refinements on the inliers
                estimate(
                    &src,
                    &dst,
                    &mut mask,
                    method,
                    p.threshold_px,
                    p.max_iters as usize,
                    p.confidence,
                    10,
                )
            }
        }
        .map_err(fail)?;
        if model.empty() || mask.empty() {
            return Ok(vec![false; query.len()]);
        }
        let flags: &[u8] = mask.data_typed().map_err(fail)?;
        if flags.len() != query.len() {
            return Err(FitError(format!(
                "mask of {} values for {} points",
                flags.len(),
                query.len()
            )));
        }
        Ok(flags.iter().map(|&f| f != 0).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::matches::Correspondences;
    use crate::geometry::verify::{VerifyParams, count_inliers};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A known homography: rotation, scale, shear, translation and a
    /// perspective term.
    const H: [[f32; 3]; 3] = [
        [0.9, -0.15, 40.0],
        [0.12, 1.05, -25.0],
        [0.0002, -0.0001, 1.0],
    ];

    fn apply(p: [f32; 2]) -> [f32; 2] {
        let w = H[2][0] * p[0] + H[2][1] * p[1] + H[2][2];
        [
            (H[0][0] * p[0] + H[0][1] * p[1] + H[0][2]) / w,
            (H[1][0] * p[0] + H[1][1] * p[1] + H[1][2]) / w,
        ]
    }

    /// A known similarity: rotation by 0.3 rad, scale 1.1, translation.
    fn similar(p: [f32; 2]) -> [f32; 2] {
        let (c, s) = (1.1 * 0.3f32.cos(), 1.1 * 0.3f32.sin());
        [c * p[0] - s * p[1] + 30.0, s * p[0] + c * p[1] - 20.0]
    }

    /// 60 true pairs under [`H`] (with half-pixel noise) and 140 outliers,
    /// shuffled; returns the pairs and which are true.
    fn synthetic(seed: u64) -> (Correspondences, Vec<bool>) {
        synthetic_under(seed, apply)
    }

    /// [`synthetic`] with the true pairs related by `apply`.
    fn synthetic_under(seed: u64, apply: fn([f32; 2]) -> [f32; 2]) -> (Correspondences, Vec<bool>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut pairs: Vec<([f32; 2], [f32; 2], bool)> = Vec::new();
        for i in 0..200 {
            let q = [rng.random_range(0.0..640.0), rng.random_range(0.0..360.0)];
            if i < 60 {
                let t = apply(q);
                let noise = [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5)];
                pairs.push((q, [t[0] + noise[0], t[1] + noise[1]], true));
            } else {
                let m = [rng.random_range(0.0..640.0), rng.random_range(0.0..360.0)];
                pairs.push((q, m, false));
            }
        }
        for i in (1..pairs.len()).rev() {
            pairs.swap(i, rng.random_range(0..=i));
        }
        let c = Correspondences {
            query: pairs.iter().map(|p| p.0).collect(),
            map: pairs.iter().map(|p| p.1).collect(),
        };
        (c, pairs.iter().map(|p| p.2).collect())
    }

    fn fit(model: Model, estimator: Estimator) -> OpenCvFit {
        OpenCvFit::new(
            VerifyParams {
                model,
                estimator,
                threshold_px: 3.0,
                ..Default::default()
            }
            .fit(),
        )
    }

    #[test]
    fn the_inliers_found_are_the_true_pairs() {
        for estimator in [Estimator::Ransac, Estimator::Magsac] {
            let f = fit(Model::Homography, estimator);
            for seed in 0..3 {
                let (c, truth) = synthetic(seed);
                let mask = f.inliers(&c.query, &c.map).unwrap();
                let found_true = mask.iter().zip(&truth).filter(|(m, t)| **m && **t).count();
                let found_false = mask.iter().zip(&truth).filter(|(m, t)| **m && !**t).count();
                // every true pair, and at most a stray outlier lying near the model by chance
                assert_eq!(found_true, 60, "{estimator:?} seed {seed}");
                assert!(found_false <= 2, "{estimator:?} seed {seed}: {found_false}");
                let v = count_inliers(&c, &f, 30);
                assert!(v.verified && (60..=62).contains(&v.inliers), "{v:?}");
            }
        }
    }

    #[test]
    fn a_fundamental_matrix_also_keeps_the_true_pairs() {
        let f = fit(Model::Fundamental, Estimator::Ransac);
        let (c, truth) = synthetic(7);
        let mask = f.inliers(&c.query, &c.map).unwrap();
        let found_true = mask.iter().zip(&truth).filter(|(m, t)| **m && **t).count();
        assert!(found_true >= 57, "{found_true}");
    }

    #[test]
    fn a_similarity_and_an_affine_map_find_the_true_pairs() {
        // MAGSAC++ asked for, these models are still fitted (by RANSAC)
        for (model, estimator) in [
            (Model::Similarity, Estimator::Ransac),
            (Model::Affine, Estimator::Ransac),
            (Model::Similarity, Estimator::Magsac),
        ] {
            for seed in 0..3 {
                let f = fit(model, estimator);
                let (c, truth) = synthetic_under(seed, similar);
                let mask = f.inliers(&c.query, &c.map).unwrap();
                let found_true = mask.iter().zip(&truth).filter(|(m, t)| **m && **t).count();
                let found_false = mask.iter().zip(&truth).filter(|(m, t)| **m && !**t).count();
                assert_eq!(found_true, 60, "{model:?} seed {seed}");
                assert!(found_false <= 2, "{model:?} seed {seed}: {found_false}");
            }
        }
    }

    #[test]
    fn degenerate_input_answers_cleanly() {
        let models = [
            Model::Homography,
            Model::Fundamental,
            Model::Similarity,
            Model::Affine,
        ];
        for model in models {
            for estimator in [Estimator::Ransac, Estimator::Magsac] {
                let f = fit(model, estimator);
                // too few pairs: one fewer than the model needs
                let points = [[1.0, 2.0], [3.0, 5.0], [9.0, 1.0], [4.0, 8.0], [7.0, 7.0]];
                let n = model.min_matches() - 1;
                let few = Correspondences {
                    query: points.iter().cycle().take(n).copied().collect(),
                    map: points.iter().cycle().take(n).copied().collect(),
                };
                assert_eq!(count_inliers(&few, &f, 1).inliers, 0);
                assert_eq!(f.inliers(&few.query, &few.map).unwrap(), vec![false; n]);
                // collinear
                let line = Correspondences {
                    query: (0..30).map(|i| [i as f32 * 7.0, i as f32 * 3.0]).collect(),
                    map: (0..30).map(|i| [i as f32 * 5.0, 40.0]).collect(),
                };
                let v = count_inliers(&line, &f, 1);
                assert_eq!(
                    (v.inliers, v.verified),
                    (0, false),
                    "{model:?} {estimator:?}"
                );
                // one point
                let point = Correspondences {
                    query: vec![[10.0, 10.0]; 30],
                    map: vec![[20.0, 30.0]; 30],
                };
                assert_eq!(count_inliers(&point, &f, 1).inliers, 0);
                // mismatched lengths are an error, not a panic
                assert!(f.inliers(&[[0.0, 0.0]; 9], &[[0.0, 0.0]; 8]).is_err());
            }
        }
    }
}

//! Nearest-neighbour descriptor matches with Lowe's ratio test: the
//! alternative to word pairs ([`super::matches`]) for a map that kept its
//! descriptors. The service's maps do not; the examples `overlap` and
//! `candidates` measure what the alternative would give (docs/results.md).

use super::Keypoint;
use super::matches::Correspondences;
use ndarray::ArrayView2;

/// Lowe's ratio: a match is kept when its nearest neighbour is closer than
/// this fraction of the second nearest.
pub const RATIO: f32 = 0.8;

/// `(query row, map row)` of every query descriptor whose nearest map
/// descriptor passes the ratio test. Rows are L2-normalised descriptors.
pub fn ratio_matches(
    q: ArrayView2<'_, f32>,
    m: ArrayView2<'_, f32>,
    ratio: f32,
) -> Vec<(usize, usize)> {
    let sim = q.dot(&m.t()); // cosine; squared distance = 2 − 2·cos
    let mut out = Vec::new();
    for (i, row) in sim.outer_iter().enumerate() {
        let (mut best, mut second, mut at) = (f32::MIN, f32::MIN, 0);
        for (j, &s) in row.iter().enumerate() {
            if s > best {
                second = best;
                best = s;
                at = j;
            } else if s > second {
                second = s;
            }
        }
        let d1 = (2.0 - 2.0 * best).max(0.0).sqrt();
        let d2 = (2.0 - 2.0 * second).max(0.0).sqrt();
        if second > f32::MIN && d1 < ratio * d2 {
            out.push((i, at));
        }
    }
    out
}

/// The positions of the [`ratio_matches`] between a query's and a map
/// image's descriptors (rows aligned with their keypoints), ready for the
/// model fit that word pairs go through.
pub fn ratio_correspondences(
    query: (ArrayView2<'_, f32>, &[Keypoint]),
    map: (ArrayView2<'_, f32>, &[Keypoint]),
    ratio: f32,
) -> Correspondences {
    let pairs = ratio_matches(query.0, map.0, ratio);
    let at = |kps: &[Keypoint], i: usize| [kps[i].x, kps[i].y];
    Correspondences {
        query: pairs.iter().map(|&(i, _)| at(query.1, i)).collect(),
        map: pairs.iter().map(|&(_, j)| at(map.1, j)).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn keeps_only_unambiguous_nearest_neighbours() {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        let map = array![[1.0, 0.0], [0.0, 1.0], [s, s]];
        // row 0 sits on map row 0; row 1 halfway between rows 1 and 2
        let c = (std::f32::consts::PI * 3.0 / 8.0).cos();
        let query = array![[1.0, 0.0], [c, (1.0 - c * c).sqrt()]];
        assert_eq!(ratio_matches(query.view(), map.view(), RATIO), [(0, 0)]);
        // a single map descriptor has no second neighbour: no match
        assert!(ratio_matches(query.view(), map.slice(ndarray::s![..1, ..]), RATIO).is_empty());
    }

    #[test]
    fn correspondences_carry_the_matched_keypoints_positions() {
        let map = array![[1.0, 0.0], [0.0, 1.0]];
        let query = array![[0.0, 1.0]];
        let kp = |x: f32, y: f32| Keypoint {
            x,
            y,
            ..Default::default()
        };
        let c = ratio_correspondences(
            (query.view(), &[kp(5.0, 6.0)]),
            (map.view(), &[kp(1.0, 2.0), kp(3.0, 4.0)]),
            RATIO,
        );
        assert_eq!(c.query, [[5.0, 6.0]]);
        assert_eq!(c.map, [[3.0, 4.0]]);
    }
}

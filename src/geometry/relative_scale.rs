//! How much larger a map image sees the scene than the query does, from the
//! positions of their matched points: the spread of the map's points over
//! the spread of the query's. A map image taken further ahead along the way
//! sees what lies ahead larger (a scale above 1), one taken behind sees it
//! smaller, so among map images of one place the scale nearest 1 points to
//! the one taken nearest the query (docs/results.md, "Place inliers").

use super::matches::Correspondences;

/// The map points' root-mean-square distance from their centroid over the
/// query points'. `None` when there are fewer than two pairs or either side's
/// points all coincide.
pub fn relative_scale(c: &Correspondences) -> Option<f32> {
    if c.len() < 2 {
        return None;
    }
    let (map, query) = (spread(&c.map), spread(&c.query));
    (map > 0.0 && query > 0.0).then(|| map / query)
}

/// Root-mean-square distance of `points` from their centroid.
fn spread(points: &[[f32; 2]]) -> f32 {
    let n = points.len() as f32;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p[0] / n, y + p[1] / n));
    let sum: f32 = points
        .iter()
        .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
        .sum();
    (sum / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs(query: &[[f32; 2]], scale: f32, shift: [f32; 2]) -> Correspondences {
        Correspondences {
            query: query.to_vec(),
            map: query
                .iter()
                .map(|p| [p[0] * scale + shift[0], p[1] * scale + shift[1]])
                .collect(),
        }
    }

    #[test]
    fn the_scale_of_a_scaled_and_shifted_copy() {
        let q = [[10.0, 20.0], [200.0, 40.0], [120.0, 300.0], [50.0, 90.0]];
        for scale in [0.5, 1.0, 1.7] {
            let s = relative_scale(&pairs(&q, scale, [33.0, -7.0])).unwrap();
            assert!((s - scale).abs() < 1e-4, "{s} for {scale}");
        }
    }

    #[test]
    fn no_scale_from_too_few_or_coincident_points() {
        assert_eq!(relative_scale(&Correspondences::default()), None);
        assert_eq!(relative_scale(&pairs(&[[1.0, 2.0]], 2.0, [0.0, 0.0])), None);
        assert_eq!(
            relative_scale(&pairs(&[[1.0, 2.0]; 3], 2.0, [0.0, 0.0])),
            None
        );
    }
}

//! Re-ranking the vote candidates after verification: the top k are
//! verified, ordered as [`Order`] says (by their own inliers, their place's,
//! or the place's answered by the image seen at the query's scale), and
//! [`Rerank`] says whether that order places them all or the answer only.

use super::{ModelFit, Order, Rerank, Verification, VerifyParams, verify_features};
use crate::geometry::matches::{Correspondences, QueryFeature, QueryFeatures};
use crate::geometry::relative_scale::relative_scale;
use crate::index::MapRead;

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

    /// Its inliers (0 when not checked).
    pub fn inliers(&self) -> usize {
        self.verification.map_or(0, |v| v.inliers)
    }

    /// How much larger the map image sees the scene than the query, from
    /// its inliers ([`relative_scale`]); `None` with fewer than two.
    pub fn scale(&self) -> Option<f32> {
        relative_scale(&self.inlier_pairs)
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
        .filter_map(|(i, r)| Some((i, r.scale()?.ln().abs())))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((i, _)) = nearest {
        ranked[..=i].rotate_right(1);
        ranked[0].score = score;
        ranked[0].distinct_from = distinct_from;
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::AllInliers;
    use super::*;
    use crate::geometry::Keypoint;

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
}

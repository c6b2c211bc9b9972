//! Ranking: the top-n map images by vote, each score the mean vote per
//! feature so far — an estimate of its full bag-of-words score, so scores
//! compare across queries whatever the stop point and whether or not the
//! query's feature count is known — and each candidate's *distinctness*:
//! its votes against the best image elsewhere on the map, a confidence that
//! means the same for every query.

use super::prior::Prior;
use super::vote::{VoteStats, Voter};

/// One ranked map image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ranked {
    pub id: u32,
    /// h(j)/t, the mean vote per feature: under a uniformly random feature
    /// order an unbiased estimate of the full tf-idf score h_N(j)/N.
    pub score: f32,
    /// h(j) / (h(j) + h(k*)), k* the best-voted image outside j's place
    /// (the images within the place window of j along the map's order):
    /// 1 when nothing elsewhere has a vote, ½ for a tie, towards 0 when
    /// another place leads. Neighbours along a route look alike and share a
    /// query's votes; what says the answer is safe is how far it leads the
    /// rest of the map ([`distinctness`]).
    pub distinct: f32,
}

/// The distinctness of image `j` with `h` votes, given the leading images
/// `leaders` (value descending): h / (h + best outside j's place), the
/// place being the images within `window` ids of j. `leaders` must hold
/// at least 2·window + 2 entries (or every voted image) for the answer to
/// be exact: at most 2·window + 1 of them lie in j's place.
pub fn distinctness(j: u32, h: f32, leaders: &[(f32, u32)], window: u32) -> f32 {
    let elsewhere = elsewhere(j, leaders, window);
    if h + elsewhere > 0.0 {
        h / (h + elsewhere)
    } else {
        0.0
    }
}

/// The votes of the best image outside `j`'s place (the images within
/// `window` ids of j) among `leaders` (value descending), 0 when none of
/// them lies outside. Exact when `leaders` holds at least 2·window + 2
/// entries or every voted image: a place has at most 2·window + 1 images.
pub fn elsewhere(j: u32, leaders: &[(f32, u32)], window: u32) -> f32 {
    best_elsewhere(j, leaders, window).map_or(0.0, |e| e.0)
}

/// The best image outside `j`'s place among `leaders`, (h, id), as for
/// [`elsewhere`]; `None` when none of them lies outside.
pub fn best_elsewhere(j: u32, leaders: &[(f32, u32)], window: u32) -> Option<(f32, u32)> {
    leaders
        .iter()
        .find(|&&(_, k)| k.abs_diff(j) > window)
        .copied()
}

/// The `count` highest (h, id) of `ids` (ties by lower id), best first.
fn leaders(h: &[f32], ids: &[u32], count: usize) -> Vec<(f32, u32)> {
    let mut all: Vec<(f32, u32)> = ids.iter().map(|&j| (h[j as usize], j)).collect();
    let better = |a: &(f32, u32), b: &(f32, u32)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
    if all.len() > count && count > 0 {
        all.select_nth_unstable_by(count - 1, better);
        all.truncate(count);
    }
    all.sort_unstable_by(better);
    all
}

/// The `n` highest-voted images (ties broken by lower id), scores at least
/// `min_score`; with `allowed`, only the images that prior allows. Each
/// candidate's distinctness is against the best image outside its place of
/// `window` images on each side (over every image, allowed or not).
pub fn top_n(
    voter: &Voter<'_>,
    n: usize,
    min_score: f32,
    allowed: Option<&Prior>,
    window: u32,
) -> Vec<Ranked> {
    let t = voter.tally();
    if t.features == 0 || n == 0 {
        return Vec::new();
    }
    let scale = 1.0 / t.features as f32;
    let h = voter.histogram();
    let touched = voter.touched();
    let everywhere = leaders(h, touched, 2 * window as usize + 2);
    let ids: Vec<u32> = match allowed {
        Some(p) => touched.iter().copied().filter(|&j| p.allows(j)).collect(),
        None => touched.to_vec(),
    };
    leaders(h, &ids, n)
        .into_iter()
        .map(|(v, id)| Ranked {
            id,
            score: v * scale,
            distinct: distinctness(id, v, &everywhere, window),
        })
        .filter(|r| r.score >= min_score)
        .collect()
}

/// The distinctness of candidate `id` in `candidates` (0 if absent): for
/// answers re-ordered after the search (geometric verification).
pub fn distinct_of(candidates: &[Ranked], id: u32) -> f32 {
    candidates
        .iter()
        .find(|r| r.id == id)
        .map_or(0.0, |r| r.distinct)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinctness_compares_with_the_best_image_outside_the_place() {
        let leaders = [(10.0, 5), (8.0, 6), (4.0, 20), (3.0, 4)];
        // window 0: image 5 against image 6
        assert!((distinctness(5, 10.0, &leaders, 0) - 10.0 / 18.0).abs() < 1e-6);
        // window 1: image 6 is 5's neighbour; image 20 is the best elsewhere
        assert!((distinctness(5, 10.0, &leaders, 1) - 10.0 / 14.0).abs() < 1e-6);
        // image 6's best elsewhere (window 1: 5 and 7 are its place) is 20
        assert!((distinctness(6, 8.0, &leaders, 1) - 8.0 / 12.0).abs() < 1e-6);
        // image 20 against image 5
        assert!((distinctness(20, 4.0, &leaders, 2) - 4.0 / 14.0).abs() < 1e-6);
        // nothing elsewhere: 1; nothing at all: 0
        assert_eq!(distinctness(5, 10.0, &leaders[..2], 1), 1.0);
        assert_eq!(distinctness(5, 0.0, &[], 1), 0.0);
    }

    #[test]
    fn leaders_are_the_highest_with_ties_by_id() {
        let h = [1.0, 5.0, 3.0, 5.0, 0.5];
        assert_eq!(
            leaders(&h, &[0, 1, 2, 3, 4], 3),
            [(5.0, 1), (5.0, 3), (3.0, 2)]
        );
        assert_eq!(leaders(&h, &[4, 0], 5), [(1.0, 0), (0.5, 4)]);
    }
}

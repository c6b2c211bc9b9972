//! Ranking: the top-n map images by vote, each score the mean vote per
//! feature so far — an estimate of its full bag-of-words score, so scores
//! compare across queries whatever the stop point and whether or not the
//! query's feature count is known.

use super::prior::Prior;
use super::vote::{VoteStats, Voter};

/// One ranked map image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ranked {
    pub id: u32,
    /// h(j)/t, the mean vote per feature: under a uniformly random feature
    /// order an unbiased estimate of the full tf-idf score h_N(j)/N.
    pub score: f32,
}

/// The `n` highest-voted images (ties broken by lower id), scores at least
/// `min_score`; with `allowed`, only the images that prior allows.
pub fn top_n(voter: &Voter<'_>, n: usize, min_score: f32, allowed: Option<&Prior>) -> Vec<Ranked> {
    let t = voter.tally();
    if t.features == 0 || n == 0 {
        return Vec::new();
    }
    let scale = 1.0 / t.features as f32;
    let h = voter.histogram();
    let mut ids: Vec<u32> = match allowed {
        Some(p) => voter
            .touched()
            .iter()
            .copied()
            .filter(|&j| p.allows(j))
            .collect(),
        None => voter.touched().to_vec(),
    };
    let better = |a: &u32, b: &u32| {
        h[*b as usize]
            .total_cmp(&h[*a as usize])
            .then_with(|| a.cmp(b))
    };
    if ids.len() > n {
        ids.select_nth_unstable_by(n - 1, better);
        ids.truncate(n);
    }
    ids.sort_unstable_by(better);
    ids.into_iter()
        .map(|id| Ranked {
            id,
            score: h[id as usize] * scale,
        })
        .filter(|r| r.score >= min_score)
        .collect()
}

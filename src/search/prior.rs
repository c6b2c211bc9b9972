//! A prior over map images for one search, and the posterior its votes give.
//!
//! The evidence model: after t features, image j's vote h(j) (summed tf-idf
//! votes, [`Voter::histogram`](super::Voter::histogram)) is read as a
//! log-likelihood, log p(votes | j) = κ·h(j)/√t + const = κ·√t·s(j) with
//! s(j) = h(j)/t the mean vote per feature, so
//!
//! p(j | votes) ∝ prior(j) · exp(κ·h(j)/√t).
//!
//! Evidence grows like √t, as a difference of mean votes does against its
//! standard error, so the posterior sharpens as the search goes on without
//! the overconfidence of counting every feature as independent evidence
//! (κ·h(j)); κ (the evidence weight) says how much that is worth against
//! the prior. A prior is sparse: a few tracked images with
//! their probabilities and one probability (the floor) shared by every other
//! image, so its size follows the images tracked, not the map. A floor of 0
//! excludes the untracked images: the search then ranks only tracked images
//! (how a pose restriction is expressed).

use std::cmp::Ordering;

/// Evidence weight κ used when none is configured (per unit of summed vote):
/// chosen on gardens-point with Hamming-weighted votes (docs/results.md,
/// "Sequences").
pub const DEFAULT_KAPPA: f64 = 6.0;
/// Images a posterior keeps when none is configured.
pub const DEFAULT_KEEP: usize = 64;

/// A prior over map images.
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    images: usize,
    /// Tracked images, ascending id, with their probabilities.
    tracked: Vec<(u32, f64)>,
    /// Probability of each image not tracked (0: excluded).
    floor: f64,
    /// Evidence weight κ.
    pub kappa: f64,
    /// Images the posterior of a search with this prior keeps.
    pub keep: usize,
    /// Images within this many ids of the leader count as its place when
    /// the leader's probability is read ([`leader`]): neighbours along a
    /// route look alike and share the mass. 0: the image alone.
    pub window: u32,
}

impl Prior {
    /// Every one of `images` equally likely.
    pub fn uniform(images: usize, kappa: f64) -> Self {
        Self {
            images,
            tracked: Vec::new(),
            floor: 1.0 / images.max(1) as f64,
            kappa,
            keep: DEFAULT_KEEP,
            window: 0,
        }
    }

    /// Tracked images with weights (any order, ids below `images`, duplicates
    /// summed, non-finite or negative weights taken as 0) and a weight
    /// `floor` for each other image; normalized to sum to 1. With nothing
    /// left to weigh, uniform.
    pub fn new(images: usize, tracked: Vec<(u32, f64)>, floor: f64, kappa: f64) -> Self {
        let clean = |w: f64| if w.is_finite() && w > 0.0 { w } else { 0.0 };
        let mut t: Vec<(u32, f64)> = tracked
            .into_iter()
            .filter(|&(j, _)| (j as usize) < images)
            .map(|(j, w)| (j, clean(w)))
            .collect();
        t.sort_unstable_by_key(|e| e.0);
        t.dedup_by(|b, a| {
            if a.0 == b.0 {
                a.1 += b.1;
                true
            } else {
                false
            }
        });
        let floor = clean(floor);
        let total: f64 = t.iter().map(|e| e.1).sum::<f64>() + floor * (images - t.len()) as f64;
        if total <= 0.0 || !total.is_finite() {
            return Self::uniform(images, kappa);
        }
        for e in &mut t {
            e.1 /= total;
        }
        Self {
            images,
            tracked: t,
            floor: floor / total,
            kappa,
            keep: DEFAULT_KEEP,
            window: 0,
        }
    }

    /// Only `ids` (equally likely); every other image excluded.
    pub fn only(images: usize, ids: impl IntoIterator<Item = u32>, kappa: f64) -> Self {
        Self::new(
            images,
            ids.into_iter().map(|j| (j, 1.0)).collect(),
            0.0,
            kappa,
        )
    }

    /// The same prior, its searches' posteriors keeping `keep` images.
    pub fn keeping(mut self, keep: usize) -> Self {
        self.keep = keep;
        self
    }

    /// The same prior, the leader's place `window` ids either side.
    pub fn with_window(mut self, window: u32) -> Self {
        self.window = window;
        self
    }

    pub fn images(&self) -> usize {
        self.images
    }

    /// Tracked images, ascending id, with their probabilities.
    pub fn tracked(&self) -> &[(u32, f64)] {
        &self.tracked
    }

    /// Probability of each untracked image.
    pub fn floor(&self) -> f64 {
        self.floor
    }

    /// Prior probability of image `j`.
    pub fn of(&self, j: u32) -> f64 {
        match self.tracked.binary_search_by_key(&j, |e| e.0) {
            Ok(p) => self.tracked[p].1,
            Err(_) if (j as usize) < self.images => self.floor,
            Err(_) => 0.0,
        }
    }

    /// Whether image `j` may be a candidate (non-zero prior).
    pub fn allows(&self, j: u32) -> bool {
        self.of(j) > 0.0
    }

    /// Whether some images are excluded.
    pub fn restricts(&self) -> bool {
        self.floor == 0.0
    }

    /// Whether every image weighs what it does in [`Prior::uniform`] (same
    /// images and κ): a search's posterior under it is then its posterior
    /// under a uniform prior, bit for bit.
    pub fn is_uniform(&self) -> bool {
        self.tracked.is_empty() && self.floor == Self::uniform(self.images, self.kappa).floor
    }
}

/// A posterior (or any belief) over map images, kept sparse: the most
/// probable images best first, and the mass of all the others.
#[derive(Debug, Clone, PartialEq)]
pub struct Posterior {
    /// (image, probability), best first (ties: lower id first).
    pub top: Vec<(u32, f64)>,
    /// Total probability of the images not in `top`.
    pub rest: f64,
    /// Map images.
    pub images: usize,
}

impl Posterior {
    /// The most probable image and its probability.
    pub fn leader(&self) -> Option<(u32, f64)> {
        self.top.first().copied()
    }

    /// Probability of each image outside `top` (spread evenly).
    pub fn floor(&self) -> f64 {
        let others = self.images.saturating_sub(self.top.len());
        if others == 0 {
            0.0
        } else {
            self.rest / others as f64
        }
    }
}

/// The unnormalized log-weights of every image with a non-zero posterior
/// that is tracked or has votes, and of the others (all with the same
/// weight): (listed, log-weight of each other image, how many others).
fn log_weights(
    prior: &Prior,
    hist: &[f32],
    touched: &[u32],
    features: usize,
) -> (Vec<(u32, f64)>, f64, usize) {
    let k = prior.kappa / (features.max(1) as f64).sqrt();
    let h = |j: u32| hist.get(j as usize).copied().unwrap_or(0.0) as f64;
    let mut listed: Vec<(u32, f64)> = prior
        .tracked
        .iter()
        .filter(|e| e.1 > 0.0)
        .map(|&(j, p)| (j, p.ln() + k * h(j)))
        .collect();
    let floor_ln = if prior.floor > 0.0 {
        prior.floor.ln()
    } else {
        f64::NEG_INFINITY
    };
    let mut covered = prior.tracked.len();
    for &j in touched {
        if (j as usize) >= prior.images || prior.tracked.binary_search_by_key(&j, |e| e.0).is_ok() {
            continue;
        }
        covered += 1;
        if prior.floor > 0.0 {
            listed.push((j, floor_ln + k * h(j)));
        }
    }
    let others = if prior.floor > 0.0 {
        prior.images.saturating_sub(covered)
    } else {
        0
    };
    (listed, floor_ln, others)
}

fn by_weight(a: &(u32, f64), b: &(u32, f64)) -> Ordering {
    b.1.total_cmp(&a.1).then(a.0.cmp(&b.0))
}

/// Σ exp(w − m) over the listed weights and `others` copies of `other`,
/// with m the largest weight: (m, the sum).
fn normalizer(listed: &[(u32, f64)], other: f64, others: usize) -> (f64, f64) {
    let mut m = listed.iter().map(|e| e.1).fold(f64::NEG_INFINITY, f64::max);
    if others > 0 {
        m = m.max(other);
    }
    if !m.is_finite() {
        return (m, 0.0);
    }
    let mut z: f64 = listed.iter().map(|e| (e.1 - m).exp()).sum();
    if others > 0 {
        z += others as f64 * (other - m).exp();
    }
    (m, z)
}

/// The posterior given the votes `hist` of `features` features (images with
/// a vote: `touched`), keeping the `keep` most probable images. Cost: the
/// tracked images plus the touched ones, never the whole map.
pub fn posterior(
    prior: &Prior,
    hist: &[f32],
    touched: &[u32],
    features: usize,
    keep: usize,
) -> Posterior {
    let (mut listed, other, others) = log_weights(prior, hist, touched, features);
    let (m, z) = normalizer(&listed, other, others);
    let images = prior.images;
    if z <= 0.0 || !z.is_finite() {
        return Posterior {
            top: Vec::new(),
            rest: 1.0,
            images,
        };
    }
    let keep = keep.min(listed.len());
    if keep > 0 && keep < listed.len() {
        listed.select_nth_unstable_by(keep - 1, by_weight);
    }
    listed.truncate(keep);
    listed.sort_unstable_by(by_weight);
    let mut top: Vec<(u32, f64)> = listed
        .into_iter()
        .map(|(j, w)| (j, (w - m).exp() / z))
        .collect();
    // the collect reuses the buffer of every listed image: keep `keep`
    top.shrink_to_fit();
    let kept: f64 = top.iter().map(|e| e.1).sum();
    Posterior {
        top,
        rest: (1.0 - kept).max(0.0),
        images,
    }
}

/// The most probable image given the votes and the posterior probability of
/// its place: the images within [`Prior::window`] ids of it (`None` before
/// any image has weight). Costs what [`posterior`] does, without sorting.
pub fn leader(prior: &Prior, hist: &[f32], touched: &[u32], features: usize) -> Option<(u32, f64)> {
    let (listed, other, others) = log_weights(prior, hist, touched, features);
    let (m, z) = normalizer(&listed, other, others);
    if z <= 0.0 || !z.is_finite() {
        return None;
    }
    let best = listed.iter().min_by(|a, b| by_weight(a, b))?.0;
    let w = prior.window as i64;
    let near = |j: u32| (j as i64 - best as i64).abs() <= w;
    let (mut mass, mut seen) = (0.0, 0usize);
    for e in listed.iter().filter(|e| near(e.0)) {
        mass += (e.1 - m).exp();
        seen += 1;
    }
    if others > 0 {
        // the window's images not listed share the others' weight
        let lo = (best as i64 - w).max(0);
        let hi = (best as i64 + w).min(prior.images as i64 - 1);
        let unlisted = ((hi - lo + 1) as usize).saturating_sub(seen);
        mass += unlisted.min(others) as f64 * (other - m).exp();
    }
    Some((best, (mass / z).min(1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn prior_is_normalized_and_sparse() {
        let p = Prior::new(10, vec![(3, 2.0), (1, 1.0), (3, 1.0), (12, 5.0)], 0.5, 1.0);
        // 3 + 1 + 8 · 0.5 = 8
        assert_eq!(p.tracked(), &[(1, 1.0 / 8.0), (3, 3.0 / 8.0)]);
        assert!(close(p.floor(), 0.5 / 8.0));
        assert!(close(p.of(7), 0.5 / 8.0));
        assert_eq!(p.of(12), 0.0);
        let total: f64 = (0..10).map(|j| p.of(j)).sum();
        assert!(close(total, 1.0));
        // nothing to weigh: uniform
        assert_eq!(Prior::new(4, vec![], 0.0, 1.0), Prior::uniform(4, 1.0));
        let only = Prior::only(5, [4, 2], 1.0);
        assert!(only.restricts() && only.allows(2) && !only.allows(3));
    }

    #[test]
    fn a_prior_is_uniform_when_no_image_weighs_apart() {
        assert!(
            Prior::uniform(7, 1.0)
                .keeping(3)
                .with_window(2)
                .is_uniform()
        );
        assert!(Prior::new(7, vec![], 2.0, 1.0).is_uniform());
        assert!(
            Prior::new(7, vec![(9, 1.0)], 0.0, 1.0).is_uniform(),
            "nothing to weigh"
        );
        assert!(!Prior::new(7, vec![(1, 2.0)], 1.0, 1.0).is_uniform());
        assert!(!Prior::only(7, [1, 2], 1.0).is_uniform());
    }

    #[test]
    fn posterior_matches_a_dense_computation() {
        let prior = Prior::new(6, vec![(0, 3.0), (4, 1.0)], 0.5, 0.7);
        let hist = [1.0f32, 0.0, 2.5, 0.0, 0.3, 4.0];
        let touched = [5u32, 0, 2, 4];
        let dense: Vec<f64> = (0..6)
            .map(|j| prior.of(j) * (0.7 * hist[j as usize] as f64).exp())
            .collect();
        let z: f64 = dense.iter().sum();
        let post = posterior(&prior, &hist, &touched, 1, 3);
        let mut want: Vec<(u32, f64)> = (0..6u32).map(|j| (j, dense[j as usize] / z)).collect();
        want.sort_by(by_weight);
        for (got, want) in post.top.iter().zip(&want) {
            assert_eq!(got.0, want.0);
            assert!(close(got.1, want.1), "{got:?} {want:?}");
        }
        assert_eq!(post.top.len(), 3);
        let rest: f64 = want[3..].iter().map(|e| e.1).sum();
        assert!(close(post.rest, rest));
        let (j, p) = leader(&prior, &hist, &touched, 1).unwrap();
        assert_eq!((j, p), post.top[0]);
    }

    #[test]
    fn evidence_grows_like_the_root_of_the_features() {
        let prior = Prior::uniform(2, 1.0);
        // the same mean votes after 4 and after 16 features
        let p4 = leader(&prior, &[4.0, 0.0], &[0], 4).unwrap().1;
        let p16 = leader(&prior, &[16.0, 0.0], &[0], 16).unwrap().1;
        assert!((p4 - 1.0 / (1.0 + (-2.0f64).exp())).abs() < 1e-12);
        assert!((p16 - 1.0 / (1.0 + (-4.0f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn the_leaders_place_holds_its_neighbours_mass() {
        let hist = [0.0f32, 5.0, 5.0, 4.9, 0.0, 0.0];
        let alone = Prior::uniform(6, 1.0);
        let place = Prior::uniform(6, 1.0).with_window(1);
        let (j, p) = leader(&alone, &hist, &[1, 2, 3], 1).unwrap();
        let (k, q) = leader(&place, &hist, &[1, 2, 3], 1).unwrap();
        assert_eq!((j, k), (1, 1));
        let post = posterior(&alone, &hist, &[1, 2, 3], 1, 6);
        let mass = |ids: &[u32]| {
            post.top
                .iter()
                .filter(|e| ids.contains(&e.0))
                .map(|e| e.1)
                .sum::<f64>()
        };
        assert!((p - mass(&[1])).abs() < 1e-12);
        // image 0 has no vote: it holds the share of the images not listed
        let unlisted = post.rest / 3.0;
        assert!((q - (mass(&[1, 2]) + unlisted)).abs() < 1e-12);
    }

    #[test]
    fn an_excluding_prior_never_ranks_excluded_images() {
        let prior = Prior::only(4, [1], 1.0);
        let hist = [9.0f32, 1.0, 0.0, 8.0];
        let post = posterior(&prior, &hist, &[0, 1, 3], 1, 4);
        assert_eq!(post.top, vec![(1, 1.0)]);
        assert_eq!(post.rest, 0.0);
    }

    #[test]
    fn large_votes_do_not_overflow() {
        let prior = Prior::uniform(3, 10.0);
        let hist = [1000.0f32, 999.0, 0.0];
        let (j, p) = leader(&prior, &hist, &[0, 1], 1).unwrap();
        assert_eq!(j, 0);
        assert!(p > 0.99 && p.is_finite());
    }
}

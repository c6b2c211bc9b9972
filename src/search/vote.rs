//! The voter: applies one quantized feature at a time to the vote histogram
//! over map images and keeps, incrementally, the statistics the stopping rules
//! read. A feature of word w adds idf(w)·d̂_j(w) to h(j) for every image j in
//! postings(w), so after all N features h(j)/N = q·d̂_j, the tf-idf score.
//! Votes are not divided by N: with streaming extraction N is not known until
//! the last tile, and nothing here needs it. The cost of a vote is the length
//! of w's posting list; nothing scans the whole map.
//!
//! The rules read the statistics through [`VoteStats`], which the voter
//! implements; a search over a map split into shards implements it too, from
//! the statistics each shard reports ([`super::shard`]).
//! A map with changes ([`Overlay`]) is voted the same way: w's list in the
//! file, skipping removed images, then w's list of added images.
//!
//! With Hamming weights ([`HammingWeights`], Jégou et al. 2008), a vote also
//! counts how close the query feature lies to image j's features of word w:
//! idf(w)·d̂_j(w) is scaled by the mean of g(distance) over those features,
//! g(h) = exp(−(h/σ)²) for h ≤ the largest distance and 0 beyond, so a word
//! shared by chance (far corners of its cell) adds little. With every
//! signature 0 the scale is 1: plain tf-idf.

use crate::geometry::packed::{PackedFeature, word_run};
use crate::index::overlay::{Flat, is_set};
use crate::index::{MapRead, MapView, Overlay, Postings};
use crate::vocabulary::hamming::{BITS, distance};

/// How a vote is weighed by the Hamming distance between the query
/// feature's signature and the map features' of the same word.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HammingWeights {
    /// Features further apart than this many bits (of 64) do not vote.
    pub max_distance: u32,
    /// Width of the Gaussian weight, in bits.
    pub sigma: f32,
}

impl HammingWeights {
    /// The weights the service and evaluation default to (docs/results.md,
    /// "Hamming embedding").
    pub const DEFAULT: Self = Self {
        max_distance: 28,
        sigma: 16.0,
    };

    /// g(h) for h = 0..=64.
    pub fn table(&self) -> [f32; BITS + 1] {
        std::array::from_fn(|h| {
            if h as u32 > self.max_distance {
                0.0
            } else if self.sigma.is_finite() && self.sigma > 0.0 {
                (-(h as f32 / self.sigma).powi(2)).exp()
            } else {
                1.0
            }
        })
    }
}

impl Default for HammingWeights {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Running statistics of the histogram after `features` votes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    /// Features voted so far (t).
    pub features: usize,
    /// Features in the query (N), once known: when the whole image has been
    /// extracted. `None` while tiles remain.
    pub total: Option<usize>,
    /// Best estimate of N while it is unknown (features so far scaled by the
    /// share of the image extracted); equal to N once known.
    pub expected_total: Option<f64>,
    /// Map images (size of the histogram).
    pub images: usize,
    /// Image with the highest vote, if any vote was cast.
    pub leader: Option<u32>,
    /// max h.
    pub max: f32,
    /// Highest vote of any image other than the leader.
    pub second: f32,
    /// Σ h, for the mean.
    pub sum: f64,
    /// Largest vote one feature can give one image, idf(w)·d̂_j(w) over all
    /// w and j: per-feature votes scaled by it lie in [0, 1].
    pub vote_cap: f32,
}

impl Tally {
    /// mean(h) over all map images.
    pub fn mean(&self) -> f64 {
        if self.images == 0 {
            0.0
        } else {
            self.sum / self.images as f64
        }
    }

    /// Features not voted yet, when N is known.
    pub fn remaining(&self) -> Option<usize> {
        self.total.map(|n| n.saturating_sub(self.features))
    }

    /// N if known, else its estimate, else the features seen so far.
    pub fn total_or_estimate(&self) -> f64 {
        match (self.total, self.expected_total) {
            (Some(n), _) => n as f64,
            (None, Some(e)) => e.max(self.features as f64),
            (None, None) => self.features as f64,
        }
    }
}

/// What a stopping rule needs the voter to track beyond the basic tally.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Needs {
    /// Leading images to keep in order (at least 2 are always kept).
    pub top: usize,
    /// Per-image sums of squared per-feature votes.
    pub squares: bool,
    /// [`VoteStats::best_outside`] (read only once N is known).
    pub outside: bool,
}

impl Needs {
    /// What two rules read together.
    pub fn and(self, other: Needs) -> Needs {
        Needs {
            top: self.top.max(other.top),
            squares: self.squares || other.squares,
            outside: self.outside || other.outside,
        }
    }
}

/// What a stopping rule may read of the votes so far: the running tally, the
/// leading images, and bounds on what the features left can still change.
/// The [`Voter`] answers from its histogram; a sharded search answers from
/// the statistics its shards report, with the same values.
pub trait VoteStats {
    /// Running statistics of the histogram.
    fn tally(&self) -> &Tally;

    /// The leading images, best first: (h, id). Holds `Needs::top` entries
    /// (fewer while fewer images have votes).
    fn top(&self) -> &[(f32, u32)];

    /// Σ v² of image `j`'s per-feature votes (needs `Needs::squares`; asked
    /// only of the images in [`top`](Self::top)).
    fn squares_of(&self, j: u32) -> f32;

    /// The largest Σ v² of any image other than `j` (needs `Needs::squares`).
    fn max_squares_except(&self, j: u32) -> f32;

    /// Upper bound on what one more feature can add to h(j).
    fn image_vote_cap(&self, j: u32) -> f32;

    /// The most an image outside the first `n` of [`top`](Self::top) can
    /// reach with `left` more features: max of h(j) + left·cap_j over the
    /// images with votes, and left × the map's largest cap when some image
    /// has none (needs `Needs::outside`). Scans the images with votes
    /// ([`Voter::best_outside_each`]).
    fn best_outside(&self, n: usize, left: f32) -> f32;

    /// The whole histogram h and the images with a vote, when this view
    /// holds them (the [`Voter`] does; a sharded search does not).
    fn histogram_and_touched(&self) -> Option<(&[f32], &[u32])> {
        None
    }
}

/// The k highest values of a histogram whose entries only grow, kept in
/// order (value descending, then id ascending). Every image outside the list
/// is never better than the list's last entry, so an update that does not
/// beat the last entry costs one comparison.
#[derive(Debug, Clone)]
pub struct TopK {
    k: usize,
    items: Vec<(f32, u32)>,
}

fn better(a: (f32, u32), b: (f32, u32)) -> bool {
    a.0 > b.0 || (a.0 == b.0 && a.1 < b.1)
}

impl TopK {
    /// Room for `k` entries; the list grows as images get votes, so a `k`
    /// larger than the map (a rule asking for a place wider than it) costs
    /// no more than the images voted for.
    pub fn new(k: usize) -> Self {
        Self {
            k: k.max(1),
            items: Vec::with_capacity(k.clamp(1, 64)),
        }
    }

    /// Entries, best first: (value, image id).
    pub fn items(&self) -> &[(f32, u32)] {
        &self.items
    }

    /// Image `j` now has value `h` (never lower than before).
    #[inline]
    pub fn update(&mut self, j: u32, h: f32) {
        if self.items.len() == self.k && h < self.items[self.k - 1].0 {
            return;
        }
        self.update_slow(j, h);
    }

    fn update_slow(&mut self, j: u32, h: f32) {
        let mut p = match self.items.iter().position(|&(_, id)| id == j) {
            Some(p) => {
                self.items[p].0 = h;
                p
            }
            None if self.items.len() < self.k => {
                self.items.push((h, j));
                self.items.len() - 1
            }
            None => {
                let last = self.k - 1;
                if !better((h, j), self.items[last]) {
                    return;
                }
                self.items[last] = (h, j);
                last
            }
        };
        while p > 0 && better(self.items[p], self.items[p - 1]) {
            self.items.swap(p, p - 1);
            p -= 1;
        }
    }
}

/// Vote histogram and its statistics for one query.
pub struct Voter<'a> {
    postings: Postings<'a>,
    idf: &'a [f32],
    image_max: &'a [f32],
    overlay: Option<&'a Overlay>,
    /// The overlay's added postings, flat.
    added: Option<&'a Flat>,
    /// Removed ids (bitset; empty without an overlay).
    removed: &'a [u64],
    hist: Vec<f32>,
    touched: Vec<u32>,
    top: TopK,
    /// Σ v² per image, with its own top 2, when a rule needs them.
    squares: Option<(Vec<f32>, TopK)>,
    tally: Tally,
    /// g(distance), when votes are weighed by signatures.
    hamming: Option<[f32; BITS + 1]>,
    /// The file's images' features (sorted by word), by image, and each
    /// postings entry's run of them.
    geometry_offsets: &'a [u64],
    geometry: &'a [PackedFeature],
    feature_runs: &'a [[u32; 2]],
    /// Where the added images' features are read.
    added_geometry: Option<&'a dyn MapRead>,
}

impl<'a> Voter<'a> {
    /// A voter for a query over `map`.
    pub fn new(map: &MapView<'a>) -> Self {
        Self::with_needs(map, Needs::default())
    }

    /// A voter that also tracks what `needs` asks for.
    pub fn with_needs(map: &MapView<'a>, needs: Needs) -> Self {
        let overlay = map.overlay;
        let ids = overlay.map_or(map.image_max.len(), |o| o.ids() as usize);
        let removed = overlay.map_or(0, |o| o.removed());
        let vote_cap = map
            .image_max
            .iter()
            .copied()
            .fold(overlay.map_or(0.0, |o| o.vote_cap()), f32::max);
        Self {
            postings: map.postings,
            idf: map.idf,
            image_max: map.image_max,
            overlay,
            added: overlay.map(|o| o.flat()),
            removed: overlay.map_or(&[], |o| o.removed_bits()),
            hist: vec![0.0; ids],
            touched: Vec::new(),
            top: TopK::new(needs.top.max(2)),
            squares: needs.squares.then(|| (vec![0.0; ids], TopK::new(2))),
            tally: Tally {
                images: ids - removed,
                vote_cap,
                ..Tally::default()
            },
            hamming: None,
            geometry_offsets: map.geometry_offsets,
            geometry: map.geometry,
            feature_runs: map.feature_runs,
            added_geometry: None,
        }
    }

    /// Weigh votes by signatures with `weights`, reading the features of
    /// images added to `map` (a live map) through it.
    pub fn with_hamming(mut self, map: &'a dyn MapRead, weights: HammingWeights) -> Self {
        self.hamming = Some(weights.table());
        self.added_geometry = Some(map);
        self
    }

    /// Image j's features of word `w`: the run of postings entry `entry` of
    /// the file when indexed, else found among the image's features.
    #[inline]
    fn run(&self, entry: Option<usize>, j: u32, w: u32) -> &'a [PackedFeature] {
        if let Some(&[start, len]) = entry.and_then(|e| self.feature_runs.get(e)) {
            let start = start as usize;
            return self
                .geometry
                .get(start..start + len as usize)
                .unwrap_or(&[]);
        }
        let j = j as usize;
        let features = match (
            self.geometry_offsets.get(j),
            self.geometry_offsets.get(j + 1),
        ) {
            (Some(&a), Some(&b)) => self.geometry.get(a as usize..b as usize).unwrap_or(&[]),
            _ => self
                .added_geometry
                .map_or(&[][..], |m| m.geometry(j as u32)),
        };
        word_run(features, w)
    }

    /// Mean g(distance) between `signature` and image j's features of word
    /// `w` (`entry`: its postings entry in the file, if it is one); 1 without
    /// weights, or for an image whose features are not stored.
    #[inline]
    fn agreement(&self, entry: Option<usize>, j: u32, w: u32, signature: u64) -> f32 {
        let Some(table) = &self.hamming else {
            return 1.0;
        };
        let run = self.run(entry, j, w);
        if run.is_empty() {
            return 1.0;
        }
        let sum: f32 = run
            .iter()
            .map(|f| table[distance(f.signature(), signature) as usize])
            .sum();
        sum / run.len() as f32
    }

    /// The query has exactly `n` features.
    pub fn set_total(&mut self, n: usize) {
        self.tally.total = Some(n);
        self.tally.expected_total = Some(n as f64);
    }

    /// The query is expected to have about `n` features (N still unknown).
    pub fn set_expected_total(&mut self, n: f64) {
        if self.tally.total.is_none() {
            self.tally.expected_total = Some(n);
        }
    }

    /// Apply the votes of one feature quantized to word `w` with Hamming
    /// signature `signature` (read only with weights).
    #[inline]
    pub fn vote(&mut self, w: u32, signature: u64) {
        self.tally.features += 1;
        let factor = self.idf.get(w as usize).copied().unwrap_or(0.0);
        if factor <= 0.0 {
            return;
        }
        let (images, weights) = self.postings.list(w);
        let mut added = 0.0f64;
        let weighed = self.hamming.is_some();
        if self.removed.is_empty() && !weighed {
            for (&j, &d) in images.iter().zip(weights) {
                added += self.cast(j, factor * d);
            }
        } else {
            let start = self.postings.start(w);
            for (k, (&j, &d)) in images.iter().zip(weights).enumerate() {
                if !is_set(self.removed, j) {
                    let a = self.agreement(Some(start + k), j, w, signature);
                    added += self.cast(j, factor * d * a);
                }
            }
        }
        if let Some(flat) = self.added {
            for &(j, d) in flat.list(w) {
                if !is_set(self.removed, j) {
                    let a = self.agreement(None, j, w, signature);
                    added += self.cast(j, factor * d * a);
                }
            }
        }
        let t = &mut self.tally;
        t.sum += added;
        let items = self.top.items();
        if let Some(&(max, leader)) = items.first() {
            t.leader = Some(leader);
            t.max = max;
            t.second = items.get(1).map_or(0.0, |e| e.0);
        }
    }

    /// Add vote `v` to image `j`; returns what was added.
    #[inline]
    fn cast(&mut self, j: u32, v: f32) -> f64 {
        let Some(h) = self.hist.get_mut(j as usize).filter(|_| v > 0.0) else {
            return 0.0;
        };
        if *h == 0.0 {
            self.touched.push(j);
        }
        *h += v;
        self.top.update(j, *h);
        if let Some((sq, sq_top)) = &mut self.squares {
            let s = &mut sq[j as usize];
            *s += v * v;
            sq_top.update(j, *s);
        }
        v as f64
    }

    /// The raw histogram h.
    pub fn histogram(&self) -> &[f32] {
        &self.hist
    }

    /// Images with a non-zero vote, in the order they first received one.
    pub fn touched(&self) -> &[u32] {
        &self.touched
    }

    /// Take `cap` as the largest vote one feature can give any image (the
    /// tally's `vote_cap`): a shard of a larger map bounds the images it has
    /// not voted for with the whole map's cap, as the whole map would.
    pub fn set_vote_cap(&mut self, cap: f32) {
        self.tally.vote_cap = cap;
    }

    /// [`VoteStats::best_outside`] for n = 0, 1, …, `count` − 1, from one
    /// scan of the images with votes: it keeps their `count` highest bounds
    /// h(j) + left·cap_j, and among them the first outside the first n
    /// leaders is the highest outside (the n leaders take at most n of them).
    /// The bounds cannot be kept as votes arrive: every feature lowers each
    /// image's bound by its own cap, reordering images no vote touched.
    pub fn best_outside_each(&self, count: usize, left: f32) -> Vec<f32> {
        let mut best: Vec<(f32, u32)> = Vec::with_capacity(count + 1);
        for &j in &self.touched {
            let bound = self.hist[j as usize] + left * self.image_vote_cap(j);
            if best.len() == count && best.last().is_none_or(|e| bound <= e.0) {
                continue;
            }
            let at = best.partition_point(|e| e.0 >= bound);
            best.insert(at, (bound, j));
            best.truncate(count);
        }
        let untouched = if self.touched.len() < self.tally.images {
            left * self.tally.vote_cap
        } else {
            0.0
        };
        let top = self.top.items();
        (0..count)
            .map(|n| {
                let leaders = &top[..n.min(top.len())];
                best.iter()
                    .find(|e| !leaders.iter().any(|l| l.1 == e.1))
                    .map_or(untouched, |e| e.0.max(untouched))
            })
            .collect()
    }
}

impl VoteStats for Voter<'_> {
    fn tally(&self) -> &Tally {
        &self.tally
    }

    fn histogram_and_touched(&self) -> Option<(&[f32], &[u32])> {
        Some((&self.hist, &self.touched))
    }

    fn top(&self) -> &[(f32, u32)] {
        self.top.items()
    }

    fn squares_of(&self, j: u32) -> f32 {
        self.squares
            .as_ref()
            .and_then(|(sq, _)| sq.get(j as usize).copied())
            .unwrap_or(0.0)
    }

    fn max_squares_except(&self, j: u32) -> f32 {
        let Some((_, top)) = &self.squares else {
            return 0.0;
        };
        top.items()
            .iter()
            .find(|&&(_, id)| id != j)
            .map_or(0.0, |e| e.0)
    }

    fn image_vote_cap(&self, j: u32) -> f32 {
        match self.image_max.get(j as usize) {
            Some(&m) => m,
            None => self.overlay.and_then(|o| o.image_max(j)).unwrap_or(0.0),
        }
    }

    fn best_outside(&self, n: usize, left: f32) -> f32 {
        self.best_outside_each(n + 1, left)[n]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::{ImageWords, MapBuilder};

    /// A map whose images store words and signatures: image j holds words
    /// `j % 7 ..` with signatures drawn from `seed`.
    fn signed_map(seed: u64) -> crate::index::MapIndex {
        use crate::geometry::Keypoint;
        let mut b = MapBuilder::new(12);
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            state
        };
        for j in 0..9u32 {
            let words: Vec<u32> = (0..15).map(|i| (j % 7 + i * (i % 3)) % 12).collect();
            let signatures: Vec<u64> = words.iter().map(|_| next()).collect();
            let kps = vec![Keypoint::default(); words.len()];
            b.add(ImageWords::with_geometry(
                format!("{j}"),
                &words,
                &signatures,
                &kps,
            ));
        }
        b.build("t", "0", None)
    }

    #[test]
    fn weighed_votes_read_the_indexed_runs_as_a_search_would_find_them() {
        let map = signed_map(3);
        let view = map.view();
        assert_eq!(view.feature_runs.len(), view.postings.len());
        let unindexed = MapView {
            feature_runs: &[],
            ..view
        };
        let weights = HammingWeights {
            max_distance: 40,
            sigma: 20.0,
        };
        let mut indexed = Voter::new(&view).with_hamming(&map, weights);
        let mut searched = Voter::new(&unindexed).with_hamming(&map, weights);
        let mut plain = Voter::new(&view);
        for (i, w) in [0u32, 3, 5, 5, 11, 2, 7, 1, 9].into_iter().enumerate() {
            let signature = 0x9E37_79B9_7F4A_7C15u64.rotate_left(i as u32 * 7);
            indexed.vote(w, signature);
            searched.vote(w, signature);
            plain.vote(w, signature);
        }
        assert_eq!(indexed.histogram(), searched.histogram());
        // the weights are at most 1 and differ somewhere from plain tf-idf
        let (h, p) = (indexed.histogram(), plain.histogram());
        assert!(h.iter().zip(p).all(|(a, b)| *a <= *b + 1e-6));
        assert!(h.iter().zip(p).any(|(a, b)| *a < *b - 1e-6));
    }

    #[test]
    fn a_vote_weighs_the_mean_gaussian_of_the_distances() {
        use crate::geometry::Keypoint;
        let mut b = MapBuilder::new(2);
        let kps = [Keypoint::default(); 3];
        // image 0: word 0 twice (signatures 0 and 0b1111), word 1 once
        b.add(ImageWords::with_geometry(
            "a",
            &[0, 0, 1],
            &[0, 0b1111, 0],
            &kps,
        ));
        b.add(ImageWords::with_geometry("b", &[1], &[0], &kps[..1]));
        let map = b.build("t", "0", None);
        let view = map.view();
        let weights = HammingWeights {
            max_distance: 3,
            sigma: 2.0,
        };
        let mut plain = Voter::new(&view);
        plain.vote(0, 0b1);
        let mut weighed = Voter::new(&view).with_hamming(&map, weights);
        weighed.vote(0, 0b1);
        // distances 1 and 3: (g(1) + g(3)) / 2 of the plain vote
        let g = |d: f32| (-(d / 2.0f32).powi(2)).exp();
        let want = plain.histogram()[0] * (g(1.0) + g(3.0)) / 2.0;
        assert!((weighed.histogram()[0] - want).abs() < 1e-6);
        // beyond the largest distance a feature adds nothing
        let mut far = Voter::new(&view).with_hamming(&map, weights);
        far.vote(0, u64::MAX);
        assert_eq!(far.histogram()[0], 0.0);
        assert!(far.touched().is_empty());
    }

    #[test]
    fn incremental_stats_match_a_full_scan() {
        let mut b = MapBuilder::new(6);
        let images: [&[u32]; 5] = [&[0, 1, 1], &[1, 2, 3], &[3, 4], &[5, 5, 0], &[2, 4, 5]];
        for (i, w) in images.iter().enumerate() {
            b.add(ImageWords::from_words(format!("{i}"), w));
        }
        let map = b.build("t", "0", None);
        let view = map.view();
        let stream = [1u32, 3, 5, 5, 0, 2, 4, 1, 3, 3, 0];
        let needs = Needs {
            top: 3,
            squares: true,
            outside: true,
        };
        let mut voter = Voter::with_needs(&view, needs);
        let mut squares = [0f32; 5];
        for &w in &stream {
            let (ids, ds) = view.postings.list(w);
            let factor = view.idf[w as usize];
            for (&j, &d) in ids.iter().zip(ds) {
                squares[j as usize] += (factor * d) * (factor * d);
            }
            voter.vote(w, 0);
            let h = voter.histogram();
            let t = voter.tally();
            let max = h.iter().copied().fold(0.0f32, f32::max);
            let sum: f64 = h.iter().map(|&v| v as f64).sum();
            assert_eq!(t.max, max);
            assert_eq!(h[t.leader.unwrap() as usize], max);
            let second = h
                .iter()
                .enumerate()
                .filter(|&(j, _)| Some(j as u32) != t.leader)
                .map(|(_, &v)| v)
                .fold(0.0f32, f32::max);
            assert_eq!(t.second, second);
            assert!((t.sum - sum).abs() < 1e-6);
            let mut touched = voter.touched().to_vec();
            touched.sort_unstable();
            let nonzero: Vec<u32> = (0..5).filter(|&j| h[j as usize] > 0.0).collect();
            assert_eq!(touched, nonzero);
            // the top 3 of a full sort (value descending, id ascending)
            let mut order: Vec<(f32, u32)> = (0..5).map(|j| (h[j as usize], j)).collect();
            order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            let want: Vec<(f32, u32)> = order.into_iter().filter(|e| e.0 > 0.0).take(3).collect();
            assert_eq!(voter.top(), &want[..]);
            for j in 0..5u32 {
                assert!((voter.squares_of(j) - squares[j as usize]).abs() < 1e-7);
                let other = (0..5u32)
                    .filter(|&i| i != j)
                    .map(|i| squares[i as usize])
                    .fold(0.0f32, f32::max);
                assert!((voter.max_squares_except(j) - other).abs() < 1e-7);
            }
            // best_outside: every image outside the first k leaders, by brute force
            let mut each = Vec::new();
            for k in 0..=3 {
                let left = 2.0;
                let leaders: Vec<u32> = voter.top().iter().take(k).map(|e| e.1).collect();
                let want = (0..5u32)
                    .filter(|j| !leaders.contains(j))
                    .map(|j| {
                        let cap = if h[j as usize] > 0.0 {
                            voter.image_vote_cap(j)
                        } else {
                            t.vote_cap
                        };
                        h[j as usize] + left * cap
                    })
                    .fold(0.0f32, f32::max);
                assert_eq!(voter.best_outside(k, left), want);
                each.push(want);
            }
            assert_eq!(voter.best_outside_each(4, 2.0), each);
            assert!(voter.best_outside_each(0, 2.0).is_empty());
        }
        assert_eq!(voter.tally().features, stream.len());
    }
}

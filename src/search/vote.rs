//! The voter: applies one quantized feature at a time to the vote histogram
//! over map images and keeps, incrementally, the statistics the stopping rules
//! read. A feature of word w adds idf(w)·d̂_j(w)/N to h(j) for every image j in
//! postings(w), so after all N features h(j) = q·d̂_j. The cost of a vote is the
//! length of w's posting list; nothing scans the whole map.

use crate::index::{MapView, Postings};

/// Running statistics of the histogram after `features` votes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    /// Features voted so far (t).
    pub features: usize,
    /// Features in the query (N).
    pub total: usize,
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
    /// Largest vote one feature can give one image, idf(w)·d̂_j(w)/N over all
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

    /// Features not voted yet.
    pub fn remaining(&self) -> usize {
        self.total - self.features
    }
}

/// Vote histogram and its statistics for one query.
pub struct Voter<'a> {
    postings: Postings<'a>,
    idf: &'a [f32],
    image_max: &'a [f32],
    hist: Vec<f32>,
    touched: Vec<u32>,
    scale: f32,
    tally: Tally,
}

impl<'a> Voter<'a> {
    /// A voter for a query of `total` features over `map`.
    pub fn new(map: &MapView<'a>, total: usize) -> Self {
        let images = map.image_max.len();
        let scale = 1.0 / total.max(1) as f32;
        let vote_cap = map.image_max.iter().copied().fold(0.0, f32::max) * scale;
        Self {
            postings: map.postings,
            idf: map.idf,
            image_max: map.image_max,
            hist: vec![0.0; images],
            touched: Vec::new(),
            scale,
            tally: Tally {
                total,
                images,
                vote_cap,
                ..Tally::default()
            },
        }
    }

    /// Apply the votes of one feature quantized to word `w`.
    #[inline]
    pub fn vote(&mut self, w: u32) {
        let t = &mut self.tally;
        t.features += 1;
        let factor = self.idf.get(w as usize).copied().unwrap_or(0.0) * self.scale;
        if factor <= 0.0 {
            return;
        }
        let (images, weights) = self.postings.list(w);
        let mut added = 0.0f64;
        for (&j, &d) in images.iter().zip(weights) {
            let Some(h) = self.hist.get_mut(j as usize) else {
                continue;
            };
            let v = factor * d;
            if *h == 0.0 {
                self.touched.push(j);
            }
            *h += v;
            added += v as f64;
            let h = *h;
            if t.leader == Some(j) {
                t.max = h;
            } else if h > t.max {
                t.second = t.max;
                t.max = h;
                t.leader = Some(j);
            } else if h > t.second {
                t.second = h;
            }
        }
        t.sum += added;
    }

    pub fn tally(&self) -> &Tally {
        &self.tally
    }

    /// The raw histogram h.
    pub fn histogram(&self) -> &[f32] {
        &self.hist
    }

    /// Images with a non-zero vote, in the order they first received one.
    pub fn touched(&self) -> &[u32] {
        &self.touched
    }

    /// Upper bound on what one more feature can add to h(j).
    pub fn image_vote_cap(&self, j: u32) -> f32 {
        self.image_max.get(j as usize).copied().unwrap_or(0.0) * self.scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::{ImageWords, MapBuilder};

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
        let mut voter = Voter::new(&view, stream.len());
        for &w in &stream {
            voter.vote(w);
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
        }
        assert_eq!(voter.tally().features, stream.len());
    }
}

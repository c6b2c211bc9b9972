//! Sequences: frames from one camera moving through the map, localized
//! together by a discrete Bayes filter over map images.
//!
//! The state of a sequence is a belief over map images, kept sparse like
//! every [`Posterior`]: the [`SequenceModel::track`] most probable images
//! and one probability shared by all the others, so its size follows the
//! images tracked, not the map. For each frame:
//!
//! 1. **predict** ([`Filter::predict`]): the belief moves by the motion model
//!    over the map's [`Topology`]: b'(j) = (1 − α)·Σᵢ b(i)·T(i, j) + α/M,
//!    with T the [`Motion`] kernel for the frames elapsed and α its teleport
//!    chance (M map images). Along an open route (order topology) the part
//!    of T(i, ·) past the route's ends leaves the map: that mass is spread
//!    over every image, like the teleport, instead of piling up on the last
//!    images (a camera driving on past the map's last image, e.g. around a
//!    loop back to its first, is not held there). The untracked images
//!    share one probability u; the kernel moves a uniform belief to a
//!    (nearly) uniform one, so only the tracked images' excess b(i) − u is
//!    moved explicitly. The prediction is the frame's prior;
//! 2. **search** with that prior ([`crate::search::SearchOptions::prior`]):
//!    the rule `posterior` may stop once the leader's posterior is ≥ 1 − ε;
//! 3. **update** ([`Filter::update`]): the search's posterior
//!    p(j) ∝ b'(j)·exp(κ·h(j)/√t) ([`crate::search::prior`]) is the new belief.
//!
//! A sequence restarts (uniform prior, the frame localized on its own) on
//! its first frame, on a frame whose index is not after the previous one,
//! and after a gap of more than [`SequenceModel::max_gap`] frames.
//! Plain arrays only: the service keeps one [`Filter`] per sequence name, the
//! evaluation and the CLI one for their image lists.

pub mod topology;

pub use topology::{Motion, Topology, TopologyKind};

use crate::search::prior::{DEFAULT_KAPPA, DEFAULT_KEEP};
use crate::search::{Posterior, Prior};
use serde::{Deserialize, Serialize};

/// The filter's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SequenceModel {
    pub motion: Motion,
    /// Evidence weight κ: a frame's votes h(j) after t features count as
    /// log-likelihood κ·h(j)/√t.
    pub kappa: f64,
    /// Images the belief tracks (the others share one probability).
    pub track: usize,
    /// A gap of more than this many frames between two frames restarts
    /// the sequence.
    pub max_gap: u64,
    /// The leader's place for the rule `posterior`: the images within this
    /// many ids of it (order topology; 0 otherwise).
    pub window: u32,
}

impl Default for SequenceModel {
    fn default() -> Self {
        Self {
            motion: Motion::default(),
            kappa: DEFAULT_KAPPA,
            track: DEFAULT_KEEP,
            max_gap: 10,
            window: 2,
        }
    }
}

impl SequenceModel {
    /// The prior of a frame that knows nothing of where it is: uniform over
    /// `images` ids, votes weighed at κ, keeping the `track` most probable.
    pub fn uniform_prior(&self, images: usize) -> Prior {
        Prior::uniform(images, self.kappa).keeping(self.track)
    }

    /// The values' ranges.
    pub fn check(&self) -> Result<(), String> {
        self.motion.check()?;
        if !(self.kappa.is_finite() && self.kappa > 0.0) {
            return Err(format!(
                "kappa must be a finite number > 0, got {}",
                self.kappa
            ));
        }
        if !(1..=100_000).contains(&self.track) {
            return Err(format!("track must lie in 1..=100000, got {}", self.track));
        }
        if self.max_gap == 0 {
            return Err("max_gap must be at least 1".into());
        }
        Ok(())
    }
}

/// Why a sequence started afresh with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Restart {
    /// Its first frame.
    First,
    /// The frame's index is not after the previous frame's.
    OutOfOrder,
    /// More than `max_gap` frames since the previous one.
    Gap,
}

impl Restart {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::First => "first",
            Self::OutOfOrder => "out_of_order",
            Self::Gap => "gap",
        }
    }
}

/// The prior for one frame.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub prior: Prior,
    /// Frames since the previous one (1 for consecutive frames).
    pub steps: u64,
    /// Set when the sequence starts afresh with this frame.
    pub restart: Option<Restart>,
    /// The frame's index (given, or the previous one's + 1).
    pub frame: u64,
}

/// One sequence's state.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    belief: Option<Posterior>,
    last_frame: Option<u64>,
    frames: u64,
}

impl Filter {
    pub fn new() -> Self {
        Self::default()
    }

    /// The current belief (after the last frame), if any frame was applied.
    pub fn belief(&self) -> Option<&Posterior> {
        self.belief.as_ref()
    }

    /// Frames applied since the sequence (re)started.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Index of the last frame applied.
    pub fn last_frame(&self) -> Option<u64> {
        self.last_frame
    }

    /// Bytes this state holds: proportional to the images tracked.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self
                .belief
                .as_ref()
                .map_or(0, |b| b.top.capacity() * std::mem::size_of::<(u32, f64)>())
    }

    /// The prior of the next frame (`frame`: its index, if the caller
    /// numbers frames; else the previous one's + 1). Restarts the sequence
    /// on an out-of-order frame or after a long gap.
    pub fn predict(
        &mut self,
        model: &SequenceModel,
        topology: &Topology,
        frame: Option<u64>,
    ) -> Prediction {
        let images = topology.images();
        let next = self.last_frame.map_or(0, |f| f.saturating_add(1));
        let frame = frame.unwrap_or(next);
        let restart = match (self.belief.is_some(), self.last_frame) {
            (false, _) | (_, None) => Some(Restart::First),
            (true, Some(last)) if frame <= last => Some(Restart::OutOfOrder),
            (true, Some(last)) if frame - last > model.max_gap => Some(Restart::Gap),
            _ => None,
        };
        let window = match topology {
            Topology::Order { .. } => model.window,
            _ => 0,
        };
        let uniform = || model.uniform_prior(images).with_window(window);
        let (prior, steps) = match (restart, &self.belief) {
            (None, Some(belief)) => {
                let steps = frame - self.last_frame.unwrap_or(frame);
                (
                    predict(belief, model, topology, steps).with_window(window),
                    steps,
                )
            }
            _ => {
                self.reset();
                (uniform(), 0)
            }
        };
        Prediction {
            prior,
            steps,
            restart,
            frame,
        }
    }

    /// Take the posterior of the frame predicted last as the new belief.
    pub fn update(&mut self, posterior: Posterior, prediction: &Prediction) {
        self.belief = Some(posterior);
        self.last_frame = Some(prediction.frame);
        self.frames += 1;
    }

    /// Forget every frame.
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

/// The belief moved by the motion model: the next frame's prior.
pub fn predict(
    belief: &Posterior,
    model: &SequenceModel,
    topology: &Topology,
    steps: u64,
) -> Prior {
    let images = topology.images().max(1);
    let u = belief.floor();
    let mut moved: Vec<(u32, f64)> = Vec::new();
    // mass that left the route past its ends: anywhere in the map
    let mut off_route = 0.0;
    for &(i, p) in &belief.top {
        let mut kept = 0.0;
        for (j, w) in model.motion.from(topology, i, steps) {
            moved.push((j, (p - u) * w));
            kept += w;
        }
        off_route += (p - u).max(0.0) * (1.0 - kept).max(0.0);
    }
    moved.sort_unstable_by_key(|e| e.0);
    let mut merged: Vec<(u32, f64)> = Vec::with_capacity(moved.len());
    for (j, x) in moved {
        match merged.last_mut() {
            Some(last) if last.0 == j => last.1 += x,
            _ => merged.push((j, x)),
        }
    }
    let alpha = model.motion.teleport;
    let jump = (alpha + (1.0 - alpha) * off_route) / images as f64;
    for e in &mut merged {
        e.1 = (1.0 - alpha) * (u + e.1).max(0.0) + jump;
    }
    let keep = model.track.min(merged.len());
    if keep > 0 && keep < merged.len() {
        merged.select_nth_unstable_by(keep - 1, |a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    }
    merged.truncate(keep);
    Prior::new(images, merged, (1.0 - alpha) * u + jump, model.kappa).keeping(model.track)
}

#[cfg(test)]
mod tests;

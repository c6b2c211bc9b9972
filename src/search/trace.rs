//! The vote race as plain data: what a search looked like as its features
//! arrived (the leader's and the runner-up's votes, the mean vote, the
//! rule's statistic against its threshold), sampled every `every` features
//! and bounded in size, with the feature count at the end of each batch
//! (tile). Recorded only when asked for ([`Search::trace`](super::Search::trace)).

use super::vote::Tally;

/// The state of the race after `features` votes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracePoint {
    /// Features voted so far (t).
    pub features: u32,
    /// The leading image, if any vote was cast.
    pub leader: Option<u32>,
    /// Its votes, max h.
    pub leader_votes: f32,
    /// The highest votes of any other image.
    pub runner_up_votes: f32,
    /// mean(h) over all map images.
    pub mean_votes: f64,
    /// The rule's statistic and the threshold it must pass, for rules that
    /// compare one ([`StopRule::statistic`](super::stop::StopRule::statistic)).
    pub statistic: Option<(f64, f64)>,
}

impl TracePoint {
    pub fn of(tally: &Tally, statistic: Option<(f64, f64)>) -> Self {
        Self {
            features: tally.features as u32,
            leader: tally.leader,
            leader_votes: tally.max,
            runner_up_votes: tally.second,
            mean_votes: tally.mean(),
            statistic,
        }
    }
}

/// A bounded record of the race: at most `max_points` sampled points (the
/// sampling step doubles, dropping every other point, when they would be
/// more) plus the last one.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Features between two sampled points.
    pub every: u32,
    /// Sampled points in voting order; the last is where the search ended.
    pub points: Vec<TracePoint>,
    /// Features given to the search after each batch (tile), in order.
    pub batch_ends: Vec<u32>,
    /// Features voted before the rule was first consulted (the warm-up).
    pub warm_up: u32,
    max_points: usize,
}

impl Trace {
    /// Sample every `every` features, keeping at most `max_points` points
    /// (both at least 1; `max_points` is rounded up to an even number).
    pub fn new(every: u32, max_points: usize) -> Self {
        let max_points = max_points.max(2).next_multiple_of(2);
        Self {
            every: every.max(1),
            points: Vec::with_capacity(max_points + 1),
            batch_ends: Vec::new(),
            warm_up: 0,
            max_points,
        }
    }

    /// Whether the point after `features` votes is sampled.
    pub fn wants(&self, features: usize) -> bool {
        features > 0 && (features as u64).is_multiple_of(self.every as u64)
    }

    /// Record a sampled point (one [`wants`](Self::wants)).
    pub fn record(&mut self, point: TracePoint) {
        if self.points.len() == self.max_points {
            self.every *= 2;
            let every = self.every;
            self.points.retain(|p| p.features % every == 0);
            if !point.features.is_multiple_of(every) {
                return;
            }
        }
        self.points.push(point);
    }

    /// A batch ended after `features` features were given.
    pub fn batch_end(&mut self, features: usize) {
        self.batch_ends.push(features as u32);
    }

    /// Record where the search ended, unless it is the last point already.
    pub fn finish(&mut self, point: TracePoint) {
        if self.points.last().map(|p| p.features) != Some(point.features) {
            self.points.push(point);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(features: u32) -> TracePoint {
        TracePoint {
            features,
            leader: Some(0),
            leader_votes: features as f32,
            runner_up_votes: 0.0,
            mean_votes: 0.0,
            statistic: None,
        }
    }

    fn run(every: u32, max_points: usize, votes: u32) -> Trace {
        let mut t = Trace::new(every, max_points);
        for f in 1..=votes {
            if t.wants(f as usize) {
                t.record(point(f));
            }
        }
        t.finish(point(votes));
        t
    }

    #[test]
    fn points_stay_bounded_evenly_spaced_and_end_at_the_stop() {
        for votes in [0u32, 1, 7, 8, 100, 1000, 4000, 100_000] {
            let t = run(4, 64, votes);
            assert!(t.points.len() <= 65, "{votes}: {}", t.points.len());
            let sampled = &t.points[..t.points.len().saturating_sub(1)];
            for (k, p) in sampled.iter().enumerate() {
                assert_eq!(p.features, (k as u32 + 1) * t.every, "{votes}");
            }
            assert_eq!(t.points.last().map(|p| p.features), Some(votes));
            // at least half the room is used once the points fill it
            if votes >= 4 * 64 {
                assert!(t.points.len() > 32, "{votes}: {}", t.points.len());
            }
        }
    }
}

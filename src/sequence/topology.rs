//! Which map images neighbour which: the map's topology, and the motion
//! model over it (where a camera at image i may be one or more frames
//! later).
//!
//! - [`Topology::Order`]: images were captured along a route, so image i's
//!   neighbours are i ± 1, i ± 2, … (the default);
//! - [`Topology::Poses`]: images with a position (x, y); neighbours are the
//!   images within a distance;
//! - [`Topology::None`]: no neighbours; the motion model only keeps the
//!   camera where it was (or lets it jump anywhere, see
//!   [`Motion::teleport`]).

use serde::{Deserialize, Serialize};

/// How map images neighbour each other.
#[derive(Debug, Clone, PartialEq)]
pub enum Topology {
    /// By order in the map: image ids along a route.
    Order { images: usize },
    /// By distance between positions (NaN: an image without a pose, which
    /// has no neighbours but itself).
    Poses { positions: Vec<[f64; 2]> },
    /// No neighbours.
    None { images: usize },
}

/// The kind of topology a configuration asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TopologyKind {
    /// Poses when the map has them (fields `x` and `y`), else order.
    Auto,
    Order,
    Poses,
    None,
}

impl std::str::FromStr for TopologyKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "order" => Ok(Self::Order),
            "poses" => Ok(Self::Poses),
            "none" => Ok(Self::None),
            _ => Err(format!(
                "`{s}` is not a topology: auto, order, poses or none"
            )),
        }
    }
}

impl Topology {
    /// The topology `kind` of a map of `images` images with these positions
    /// (`None`: the map has no x, y poses).
    pub fn of(
        kind: TopologyKind,
        images: usize,
        positions: Option<Vec<[f64; 2]>>,
    ) -> Result<Self, String> {
        Ok(match (kind, positions) {
            (TopologyKind::Auto | TopologyKind::Poses, Some(positions)) => {
                Self::Poses { positions }
            }
            (TopologyKind::Poses, None) => {
                return Err("topology `poses` needs a map with pose fields x and y".into());
            }
            (TopologyKind::Auto | TopologyKind::Order, _) => Self::Order { images },
            (TopologyKind::None, _) => Self::None { images },
        })
    }

    pub fn images(&self) -> usize {
        match self {
            Self::Order { images } | Self::None { images } => *images,
            Self::Poses { positions } => positions.len(),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Self::Order { .. } => "order",
            Self::Poses { .. } => "poses",
            Self::None { .. } => "none",
        }
    }
}

/// The motion model: how far the camera moves between two frames, over the
/// topology. Moving `steps` frames at once widens the kernel to
/// σ·√steps and its reach to reach·steps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// Spread of one frame's move: in images along the route (order) or in
    /// pose units (poses). The weight of a move by d is exp(−d²/(2σ²)).
    pub sigma: f64,
    /// Expected move per frame along the map's order, in images (order
    /// only): 1 when the camera advances along the route about one map
    /// image per frame, 0 when its direction is unknown.
    pub drift: f64,
    /// Farthest one frame's move from the expected position: in images (order) or pose units (poses).
    pub reach: f64,
    /// Chance per frame that the camera jumps anywhere in the map (kidnap,
    /// a wrong earlier frame); keeps every image possible.
    pub teleport: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Self {
            sigma: 1.0,
            drift: 1.0,
            reach: 4.0,
            teleport: 0.05,
        }
    }
}

impl Motion {
    /// The values' ranges.
    pub fn check(&self) -> Result<(), String> {
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return Err(format!(
                "sigma must be a finite number > 0, got {}",
                self.sigma
            ));
        }
        if !self.drift.is_finite() {
            return Err(format!("drift must be a finite number, got {}", self.drift));
        }
        if !(self.reach.is_finite() && self.reach >= 0.0) {
            return Err(format!(
                "reach must be a finite number ≥ 0, got {}",
                self.reach
            ));
        }
        if !(0.0..1.0).contains(&self.teleport) {
            return Err(format!(
                "teleport must lie in [0, 1), got {}",
                self.teleport
            ));
        }
        Ok(())
    }

    /// Where a camera at image `i` may be `steps` frames later: (image,
    /// weight), the teleport jump aside. The weights sum to 1 but along an
    /// open route ([`Topology::Order`]): there the kernel is normalized over
    /// the whole line, and the part of it past either end of the route is
    /// missing — the camera left the mapped route and may be anywhere
    /// ([`crate::sequence::predict`] spreads that mass over the map). Piling
    /// it on the last images instead would hold the belief at the route's
    /// end while the camera goes on (around a loop, back to its start).
    pub fn from(&self, topology: &Topology, i: u32, steps: u64) -> Vec<(u32, f64)> {
        let g = steps.max(1) as f64;
        let sigma2 = self.sigma * self.sigma * g;
        let reach = self.reach * g;
        let weight = |d: f64| (-(d * d) / (2.0 * sigma2)).exp();
        let (mut out, total): (Vec<(u32, f64)>, f64) = match topology {
            Topology::None { .. } => (vec![(i, 1.0)], 1.0),
            Topology::Order { images } => {
                let centre = i as f64 + self.drift * g;
                let lo = (centre - reach).ceil() as i64;
                let hi = (centre + reach).floor() as i64;
                let line: f64 = (lo..=hi).map(|j| weight(j as f64 - centre)).sum();
                let on_route = (lo.max(0)..=hi.min(*images as i64 - 1))
                    .map(|j| (j as u32, weight(j as f64 - centre)))
                    .collect();
                (on_route, line)
            }
            Topology::Poses { positions } => match positions.get(i as usize) {
                Some(&[x, y]) if x.is_finite() && y.is_finite() => {
                    let near: Vec<(u32, f64)> = positions
                        .iter()
                        .enumerate()
                        .filter_map(|(j, &[a, b])| {
                            let d = ((a - x).powi(2) + (b - y).powi(2)).sqrt();
                            (d <= reach).then(|| (j as u32, weight(d)))
                        })
                        .collect();
                    let total = near.iter().map(|e| e.1).sum();
                    (near, total)
                }
                _ => (vec![(i, 1.0)], 1.0),
            },
        };
        if total > 0.0 {
            for e in &mut out {
                e.1 /= total;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_moves_to_nearby_images_and_off_the_route_past_its_ends() {
        let t = Topology::Order { images: 10 };
        let m = Motion {
            drift: 0.0,
            ..Motion::default()
        };
        let row = m.from(&t, 0, 1);
        assert_eq!(
            row.iter().map(|e| e.0).collect::<Vec<_>>(),
            vec![0, 1, 2, 3, 4]
        );
        // the half of the kernel before image 0 left the route
        let kept: f64 = row.iter().map(|e| e.1).sum();
        assert!(kept > 0.5 && kept < 0.7, "{kept}");
        let mid = m.from(&t, 5, 1);
        assert!((mid.iter().map(|e| e.1).sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(mid.len(), 9);
        // symmetric, peaked at the start
        assert!((mid[3].1 - mid[5].1).abs() < 1e-12 && mid[4].1 > mid[3].1);
        // two frames reach twice as far
        assert_eq!(m.from(&t, 5, 2).len(), 10);
        // moving forward: peaked one image ahead
        let ahead = Motion::default().from(&t, 5, 1);
        let best = ahead.iter().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
        assert_eq!(best.0, 6);
    }

    #[test]
    fn poses_move_within_the_reach() {
        let t = Topology::Poses {
            positions: vec![[0.0, 0.0], [1.0, 0.0], [10.0, 0.0], [f64::NAN, 0.0]],
        };
        let m = Motion {
            reach: 2.0,
            ..Motion::default()
        };
        let ids: Vec<u32> = m.from(&t, 0, 1).iter().map(|e| e.0).collect();
        assert_eq!(ids, vec![0, 1]);
        assert_eq!(m.from(&t, 3, 1), vec![(3, 1.0)]);
        assert_eq!(m.from(&Topology::None { images: 4 }, 2, 5), vec![(2, 1.0)]);
    }

    #[test]
    fn kinds_resolve_against_the_map() {
        let xy = Some(vec![[0.0, 0.0]]);
        assert_eq!(
            Topology::of(TopologyKind::Auto, 1, xy.clone())
                .unwrap()
                .name(),
            "poses"
        );
        assert_eq!(
            Topology::of(TopologyKind::Auto, 1, None).unwrap().name(),
            "order"
        );
        assert!(Topology::of(TopologyKind::Poses, 1, None).is_err());
        assert_eq!(
            Topology::of(TopologyKind::None, 1, xy).unwrap().name(),
            "none"
        );
        assert!("sideways".parse::<TopologyKind>().is_err());
    }
}

//! When the ORB pass answers, and with which candidate: a [`Setting`] read
//! against what verifying the best-voted candidates found ([`Checked`], in
//! vote order).

use super::Checked;

/// Map images more than this many apart are other places (the sequence
/// the map was taken in; gardens-point's ground truth tolerance).
pub const PLACE_APART: usize = 2;

/// Which verified candidate the pass answers with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pick {
    /// Of those with `floor` inliers within the window and at least
    /// `share` of the most inliers among them, the one whose scale is
    /// nearest the query's.
    NearestScale { share: f64 },
    /// The one with the most inliers, if it has `floor` and its scale is
    /// within the window.
    MostInliers,
    /// The place of the one with the most inliers, refined by scale: of it
    /// and the verified candidates within [`PLACE_APART`] map images of it
    /// with at least `share` of its inliers, the one whose scale is nearest
    /// the query's, if it has `floor` and its scale is within the window.
    Refined { share: f64 },
}

impl Pick {
    /// A short name for tables: `nearest-0.7`, `most`, `refined-0.5`.
    pub fn name(self) -> String {
        match self {
            Pick::NearestScale { share } => format!("nearest-{share}"),
            Pick::MostInliers => "most".into(),
            Pick::Refined { share } => format!("refined-{share}"),
        }
    }
}

/// One setting of the pass: which verified candidate it answers with, the
/// inliers it needs, how far from the query's its scale may be
/// (|ln s| ≤ `window`), and the margin over other places: the pick must
/// have at least `margin` times the inliers of every checked candidate more
/// than [`PLACE_APART`] map images away (0: no such check); with `agree`,
/// the pick must also lie within [`PLACE_APART`] map images of the votes'
/// first candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setting {
    pub pick: Pick,
    pub floor: usize,
    pub window: f64,
    pub margin: f64,
    pub agree: bool,
}

impl Setting {
    /// A setting without `agree`.
    pub const fn new(pick: Pick, floor: usize, window: f64, margin: f64) -> Self {
        Self {
            pick,
            floor,
            window,
            margin,
            agree: false,
        }
    }

    /// How tables name it: `nearest-0.7 15, |ln s| <= 0.2, margin 0` (and
    /// `, agree`).
    pub fn label(self) -> String {
        format!(
            "{} {}, |ln s| <= {}, margin {}{}",
            self.pick.name(),
            self.floor,
            self.window,
            self.margin,
            if self.agree { ", agree" } else { "" }
        )
    }
}

/// How far a candidate's scale is from the query's: |ln s| (no scale: as
/// far as can be).
fn scale_gap(c: &Checked) -> f64 {
    match c.scale {
        Some(s) if s > 0.0 => f64::from(s).ln().abs(),
        _ => f64::INFINITY,
    }
}

/// The pass's answer under `setting`, given what verifying the candidates
/// found (`checked`, in vote order), if it answers: the picked map image,
/// then the other checked ones in vote order.
pub fn answer(checked: &[Checked], setting: Setting) -> Option<Vec<u32>> {
    let Setting {
        pick,
        floor,
        window,
        margin,
        agree,
    } = setting;
    let fits = |c: &&Checked| c.inliers >= floor && scale_gap(c) <= window;
    // the most inliers, the nearer scale on ties
    let strongest = || {
        checked.iter().max_by(|a, b| {
            a.inliers
                .cmp(&b.inliers)
                .then(scale_gap(b).total_cmp(&scale_gap(a)))
        })
    };
    let nearest = |a: &&Checked, b: &&Checked| scale_gap(a).total_cmp(&scale_gap(b));
    let best = match pick {
        Pick::NearestScale { share } => {
            let most = checked.iter().filter(fits).map(|c| c.inliers).max()?;
            checked
                .iter()
                .filter(fits)
                .filter(|c| c.inliers as f64 >= share * most as f64)
                .min_by(nearest)?
        }
        Pick::MostInliers => strongest().filter(fits)?,
        Pick::Refined { share } => {
            let strongest = strongest()?;
            checked
                .iter()
                .filter(|c| c.image.abs_diff(strongest.image) as usize <= PLACE_APART)
                .filter(|c| c.inliers as f64 >= share * strongest.inliers as f64)
                .min_by(nearest)
                .filter(fits)?
        }
    };
    let apart = |c: &Checked| c.image.abs_diff(best.image) as usize > PLACE_APART;
    let other_place = checked
        .iter()
        .filter(|c| apart(c))
        .map(|c| c.inliers)
        .max()
        .unwrap_or(0);
    if (best.inliers as f64) < margin * other_place as f64 {
        return None;
    }
    if agree && apart(checked.first()?) {
        return None;
    }
    let rest = checked.iter().filter(|c| c.image != best.image);
    Some(
        std::iter::once(best.image)
            .chain(rest.map(|c| c.image))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(image: u32, inliers: usize, scale: f32) -> Checked {
        Checked {
            image,
            inliers,
            scale: Some(scale),
        }
    }

    const NEAREST: Setting = Setting::new(Pick::NearestScale { share: 0.7 }, 10, 0.2, 0.0);

    #[test]
    fn nearest_scale_takes_the_candidate_seen_at_the_querys_scale() {
        // 12 inliers at scale 1.0 beat 15 at scale 1.15 (both within 0.7)
        let checked = [c(30, 15, 1.15), c(31, 12, 1.0), c(80, 9, 1.0)];
        assert_eq!(answer(&checked, NEAREST), Some(vec![31, 30, 80]));
        // under the share of the most inliers it is not a choice
        let checked = [c(30, 15, 1.15), c(31, 10, 1.0)];
        assert_eq!(answer(&checked, NEAREST), Some(vec![30, 31]));
    }

    #[test]
    fn no_answer_under_the_floor_outside_the_window_or_without_a_scale() {
        assert_eq!(answer(&[c(3, 9, 1.0)], NEAREST), None);
        assert_eq!(answer(&[c(3, 40, 1.3)], NEAREST), None);
        let unscaled = Checked {
            image: 3,
            inliers: 40,
            scale: None,
        };
        assert_eq!(answer(&[unscaled], NEAREST), None);
        assert_eq!(answer(&[], NEAREST), None);
    }

    #[test]
    fn agree_needs_the_votes_first_candidate_at_the_same_place() {
        let agree = Setting {
            agree: true,
            ..NEAREST
        };
        let checked = [c(50, 4, 1.0), c(10, 30, 1.0)];
        assert_eq!(answer(&checked, NEAREST), Some(vec![10, 50]));
        assert_eq!(answer(&checked, agree), None);
        let checked = [c(12, 4, 1.0), c(10, 30, 1.0)];
        assert_eq!(answer(&checked, agree), Some(vec![10, 12]));
    }

    #[test]
    fn a_margin_over_other_places_is_required_when_asked() {
        let margin = Setting::new(Pick::MostInliers, 10, 0.2, 1.25);
        // 20 against 18 elsewhere: under 1.25 times
        let checked = [c(10, 20, 1.0), c(60, 18, 1.0), c(11, 19, 1.0)];
        assert_eq!(answer(&checked, margin), None);
        let checked = [c(10, 30, 1.0), c(60, 18, 1.0)];
        assert_eq!(answer(&checked, margin), Some(vec![10, 60]));
    }

    #[test]
    fn refined_moves_to_the_nearer_scale_within_the_place() {
        let refined = Setting::new(Pick::Refined { share: 0.5 }, 10, 0.2, 0.0);
        let checked = [c(20, 30, 1.3), c(21, 16, 1.05), c(40, 25, 1.0)];
        assert_eq!(answer(&checked, refined), Some(vec![21, 20, 40]));
        // the refined pick must itself fit the window
        let checked = [c(20, 30, 1.3), c(21, 16, 1.25)];
        assert_eq!(answer(&checked, refined), None);
    }
}

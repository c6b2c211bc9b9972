//! The ORB pass's settings: the service's `[orb_pass]` section
//! ([`OrbPassParams`]), and the similarity its candidates are verified with
//! ([`FIT`]).

use super::{MAX_ORB_KEYPOINTS, ORB_KEYPOINTS, Pick, Setting};
use crate::geometry::verify::{Estimator, FitParams, Model};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The similarity the pass verifies its candidates with: RANSAC, 6 px, up
/// to 2000 iterations.
pub const FIT: FitParams = FitParams {
    model: Model::Similarity,
    estimator: Estimator::Ransac,
    threshold_px: 6.0,
    confidence: 0.99,
    max_iters: 2000,
};

/// The pass's settings (the service's `[orb_pass]` section). The defaults
/// of the setting are the one chosen on gardens-point
/// (docs/performance.md, "An ORB pass before SIFT").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrbPassParams {
    /// Run the pass when the request does not say (`orb_pass=`); on by
    /// default. The map needs its ORB side (`bowloc map orb-pass`); a map
    /// without one is served without the pass.
    pub enabled: bool,
    /// The map's ORB side; empty: `MAP.orbpass` beside the map.
    pub file: PathBuf,
    /// Best-voted map images verified.
    pub top: usize,
    /// Inliers the pass's pick needs.
    pub floor: usize,
    /// How far the pick's scale may be from the query's: |ln s| at most this.
    pub window: f64,
    /// Of the candidates within the floor and the window, those with at
    /// least this share of the most inliers may be picked, the one whose
    /// scale is nearest the query's first.
    pub share: f64,
    /// The pick must see the place of the votes' first candidate (within
    /// [`super::PLACE_APART`] map images).
    pub agree: bool,
    /// Binary words of the side's vocabulary, when it is built.
    pub words: usize,
    /// ORB keypoints each map image keeps, when the side is built (queries
    /// keep as many as their side's images did).
    pub keypoints: usize,
    /// Where ORB's keypoints come from, when the side is built: `none`,
    /// ORB's own strongest corners, or `COLSxROWS`, spread over a grid.
    pub grid: String,
}

impl Default for OrbPassParams {
    fn default() -> Self {
        Self {
            enabled: true,
            file: PathBuf::new(),
            top: 10,
            floor: 12,
            window: 0.2,
            share: 0.9,
            agree: true,
            words: 1000,
            keypoints: ORB_KEYPOINTS,
            grid: "none".into(),
        }
    }
}

/// `none`, or `COLSxROWS` with 1 to [`MAX_ORB_KEYPOINTS`] cells (a grid
/// needs at least a keypoint a cell: [`OrbPassParams::validate`]).
pub fn parse_grid(v: &str) -> Result<Option<(usize, usize)>, String> {
    if v == "none" {
        return Ok(None);
    }
    v.split_once('x')
        .and_then(|(c, r)| Some((c.parse().ok()?, r.parse().ok()?)))
        .filter(|&(c, r): &(usize, usize)| {
            c.checked_mul(r)
                .is_some_and(|n| (1..=MAX_ORB_KEYPOINTS).contains(&n))
        })
        .map(Some)
        .ok_or_else(|| format!("`{v}`: want COLSxROWS (1 to {MAX_ORB_KEYPOINTS} cells) or none"))
}

impl OrbPassParams {
    /// When the pass answers, and with which candidate.
    pub fn setting(&self) -> Setting {
        Setting {
            agree: self.agree,
            ..Setting::new(
                Pick::NearestScale { share: self.share },
                self.floor,
                self.window,
                0.0,
            )
        }
    }

    /// The side's ORB grid.
    pub fn grid(&self) -> Result<Option<(usize, usize)>, String> {
        parse_grid(&self.grid).map_err(|e| format!("grid {e}"))
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.top == 0 {
            return Err("top must be at least 1".into());
        }
        if self.floor < 3 {
            return Err(format!(
                "floor must be at least 3 (any 2 pairs agree with a similarity), got {}",
                self.floor
            ));
        }
        if !(self.window >= 0.0 && self.window.is_finite()) {
            return Err(format!("window must be 0 or more, got {}", self.window));
        }
        if !(0.0..=1.0).contains(&self.share) {
            return Err(format!("share must be within 0 and 1, got {}", self.share));
        }
        if !(2..=65536).contains(&self.words) {
            return Err(format!("words must be 2 to 65536, got {}", self.words));
        }
        check_keypoints(self.keypoints, self.grid()?)
    }
}

/// Whether ORB can keep `keypoints` per image spread over `grid`: 1 to
/// [`MAX_ORB_KEYPOINTS`] of them, and at least one cell but no more cells
/// than keypoints. The
/// setting is checked with it, and so is every detector made
/// (`features::orb`), whose keypoints may come from a side's file.
pub fn check_keypoints(keypoints: usize, grid: Option<(usize, usize)>) -> Result<(), String> {
    if !(1..=MAX_ORB_KEYPOINTS).contains(&keypoints) {
        return Err(format!(
            "keypoints must be 1 to {MAX_ORB_KEYPOINTS}, got {keypoints}"
        ));
    }
    match grid {
        Some((cols, rows)) if cols.saturating_mul(rows) == 0 => {
            Err(format!("grid {cols}x{rows} has no cells"))
        }
        Some((cols, rows)) if cols.saturating_mul(rows) > keypoints => Err(format!(
            "grid {cols}x{rows} has more cells than the {keypoints} keypoints to spread over them"
        )),
        _ => Ok(()),
    }
}

/// How a grid is written: `none` or `COLSxROWS` ([`parse_grid`]'s input).
pub fn grid_name(grid: Option<(usize, usize)>) -> String {
    grid.map_or("none".into(), |(cols, rows)| format!("{cols}x{rows}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_the_chosen_setting_and_valid() {
        let p = OrbPassParams::default();
        assert!(p.validate().is_ok());
        assert_eq!(
            p.setting().label(),
            "nearest-0.9 12, |ln s| <= 0.2, margin 0, agree"
        );
        assert_eq!(p.grid(), Ok(None));
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = |p: OrbPassParams| p.validate().unwrap_err();
        assert!(
            bad(OrbPassParams {
                top: 0,
                ..Default::default()
            })
            .contains("top")
        );
        assert!(
            bad(OrbPassParams {
                floor: 2,
                ..Default::default()
            })
            .contains("floor")
        );
        assert!(
            bad(OrbPassParams {
                window: f64::NAN,
                ..Default::default()
            })
            .contains("window")
        );
        assert!(
            bad(OrbPassParams {
                share: 1.5,
                ..Default::default()
            })
            .contains("share")
        );
        assert!(
            bad(OrbPassParams {
                grid: "4by3".into(),
                ..Default::default()
            })
            .contains("grid")
        );
        assert!(
            bad(OrbPassParams {
                keypoints: 0,
                ..Default::default()
            })
            .contains("keypoints")
        );
        assert!(
            bad(OrbPassParams {
                keypoints: 100,
                grid: "20x10".into(),
                ..Default::default()
            })
            .contains("more cells")
        );
        assert_eq!(parse_grid("4x3"), Ok(Some((4, 3))));
        for grid in [None, Some((4, 3))] {
            assert_eq!(parse_grid(&grid_name(grid)), Ok(grid));
        }
        assert!(parse_grid("0x3").is_err());
        assert!(parse_grid("400x300").is_err());
        // a product past usize is refused, not wrapped
        assert!(parse_grid(&format!("{}x3", usize::MAX)).is_err());
    }
}

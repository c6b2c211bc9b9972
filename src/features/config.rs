//! Extraction settings. A vocabulary records the settings it was trained with,
//! so maps and queries extract the same kind of descriptor.

use serde::{Deserialize, Serialize};

/// OpenCV SIFT parameters (defaults are OpenCV's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SiftParams {
    /// Keep at most this many strongest keypoints (0 = all).
    pub max_features: u32,
    pub octave_layers: u32,
    pub contrast_threshold: f64,
    pub edge_threshold: f64,
    pub sigma: f64,
}

impl Default for SiftParams {
    fn default() -> Self {
        Self {
            max_features: 0,
            octave_layers: 3,
            contrast_threshold: 0.04,
            edge_threshold: 10.0,
            sigma: 1.6,
        }
    }
}

/// How an image becomes descriptors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExtractConfig {
    /// Downscale so the longer side is at most this many pixels (0 = keep size).
    pub max_side: u32,
    /// Apply RootSIFT (L1-normalise, then square root) to each descriptor.
    pub rootsift: bool,
    pub sift: SiftParams,
}

impl Default for ExtractConfig {
    fn default() -> Self {
        Self {
            max_side: 640,
            rootsift: true,
            sift: SiftParams::default(),
        }
    }
}

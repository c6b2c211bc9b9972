//! The answer to one query as users see it, shared by `bowloc query` and the
//! HTTP service: candidates with their map metadata, how many features were
//! used and why the search stopped, and where the time went.

use crate::index::{ImageInfo, MapIndex};
use crate::search::{RuleSpec, SearchOutcome, StopInfo};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Duration;

#[derive(Debug, Clone, Serialize)]
pub struct Localization {
    pub candidates: Vec<Candidate>,
    pub features: FeatureUse,
    pub rule: RuleReport,
    pub stop: StopInfo,
    /// Seed of the feature permutation (repeat it to reproduce the answer).
    pub seed: u64,
    pub image: ImageSize,
    pub timings_ms: Timings,
    pub map: MapIdentity,
}

#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    pub rank: usize,
    pub id: u32,
    pub name: String,
    /// Estimated full bag-of-words tf-idf score (comparable across queries).
    pub score: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<HashMap<String, f64>>,
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct FeatureUse {
    pub total: usize,
    pub used: usize,
    pub fraction: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct RuleReport {
    pub name: String,
    /// What the parameter is (`threshold`, `delta`, ...), absent for `none`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameter: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
}

impl From<&RuleSpec> for RuleReport {
    fn from(r: &RuleSpec) -> Self {
        let parameter = r.parameter_name();
        Self {
            name: r.name.clone(),
            parameter,
            value: parameter.map(|_| r.parameter),
        }
    }
}

#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ImageSize {
    pub width: u32,
    pub height: u32,
}

/// Milliseconds per stage.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Timings {
    pub decode: f64,
    pub extract: f64,
    pub quantize: f64,
    pub vote: f64,
    pub total: f64,
}

pub fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

#[derive(Debug, Clone, Serialize)]
pub struct MapIdentity {
    pub name: String,
    pub images: usize,
    pub words: usize,
    pub vocabulary: String,
}

impl MapIdentity {
    pub fn of(map: &MapIndex) -> Self {
        let m = map.meta();
        Self {
            name: m.name.clone(),
            images: m.images,
            words: m.words,
            vocabulary: m.vocab_hash.clone(),
        }
    }
}

impl Candidate {
    fn new(rank: usize, score: f32, info: ImageInfo<'_>) -> Self {
        Self {
            rank,
            id: info.id,
            name: info.name.to_owned(),
            score,
            place: info.place.map(str::to_owned),
            pose: info
                .pose
                .map(|p| p.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()),
        }
    }
}

/// Everything measured outside the search itself.
#[derive(Debug, Clone, Copy, Default)]
pub struct EdgeTimings {
    pub decode: Duration,
    pub extract: Duration,
}

impl Localization {
    pub fn new(
        map: &MapIndex,
        rule: &RuleSpec,
        seed: u64,
        image: ImageSize,
        outcome: SearchOutcome,
        edge: EdgeTimings,
    ) -> Self {
        let candidates = outcome
            .candidates
            .iter()
            .enumerate()
            .map(|(i, r)| Candidate::new(i + 1, r.score, map.image(r.id)))
            .collect();
        let t = outcome.timings;
        Self {
            candidates,
            features: FeatureUse {
                total: outcome.features_total,
                used: outcome.features_used,
                fraction: outcome.fraction_used(),
            },
            rule: rule.into(),
            stop: outcome.stop,
            seed,
            image,
            timings_ms: Timings {
                decode: ms(edge.decode),
                extract: ms(edge.extract),
                quantize: ms(t.quantize),
                vote: ms(t.vote),
                total: ms(edge.decode + edge.extract + t.quantize + t.vote),
            },
            map: MapIdentity::of(map),
        }
    }
}

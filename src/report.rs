//! The answer to one query as users see it, shared by `bowloc query` and the
//! HTTP service: candidates with their map metadata, how many features were
//! used and why the search stopped, and where the time went. The types also
//! describe themselves as OpenAPI schemas (utoipa) for the service's API
//! document.

use crate::features::TileGrid;
use crate::index::{ImageInfo, MapRead};
use crate::search::{RuleSpec, SearchOutcome, StopInfo};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Duration;
use utoipa::ToSchema;
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{ObjectBuilder, Schema, Type};

/// Largest seed drawn for a query that gives none: 2^53 − 1, the largest
/// integer a JSON number (a double) holds exactly, so that a client can send
/// a reported seed back unchanged.
pub const MAX_DRAWN_SEED: u64 = (1 << 53) - 1;

/// A seed for a query that gives none, uniform in 0..=[`MAX_DRAWN_SEED`].
pub fn draw_seed() -> u64 {
    rand::random_range(0..=MAX_DRAWN_SEED)
}

/// The answer to one query.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Localization {
    /// Best map images first (at most `top_n`); empty when the image has no
    /// features.
    pub candidates: Vec<Candidate>,
    pub features: FeatureUse,
    /// How much of the image was extracted (streaming extraction).
    pub tiles: TileUse,
    pub rule: RuleReport,
    pub stop: StopInfo,
    /// Seed of the feature permutation (repeat it to reproduce the answer).
    /// A seed drawn for a query that gave none is below 2^53, so a JSON
    /// number holds it exactly; a seed given is reported as given.
    pub seed: u64,
    pub image: ImageSize,
    /// Milliseconds per stage.
    pub timings_ms: Timings,
    pub map: MapIdentity,
    /// With verification: whether the best candidate is verified (has at
    /// least `min_inliers` inliers). Absent without verification.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verified: Option<bool>,
}

/// One map image proposed as the query's place.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Candidate {
    /// 1 for the best.
    #[schema(minimum = 1)]
    pub rank: usize,
    /// Map image id (its line in the map's image list, from 0).
    pub id: u32,
    pub name: String,
    /// Without verification: the estimated full bag-of-words tf-idf score.
    /// With verification: the inlier count (0 for a candidate beyond the
    /// verified top k). Either way comparable across queries.
    pub score: f32,
    /// With verification, the vote score the candidate had (the score
    /// without verification).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub votes: Option<f32>,
    /// With verification, for the top k vote candidates: correspondences
    /// agreeing with one geometric model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inliers: Option<u32>,
    /// With verification, for the top k vote candidates: at least the
    /// configured `min_inliers`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verified: Option<bool>,
    /// Place label, when the map has one for this image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<String>,
    /// Pose fields, when the map has them for this image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<HashMap<String, f64>>,
}

/// How many of the query's features were extracted and used.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub struct FeatureUse {
    /// The query's features N: exact when every tile was extracted
    /// (`tiles.extracted == tiles.total`), else estimated from the tiles
    /// extracted (their features over their share of the image), rounded.
    pub total: usize,
    /// Features extracted (from the tiles extracted).
    pub extracted: usize,
    /// Features quantized and voted before the search stopped.
    pub used: usize,
    /// used / total (1 when the image has no features).
    pub fraction: f64,
}

/// The tiles of streaming extraction: the image is cut into a grid, tiles
/// are extracted in a random order, and extraction ends when the search stops.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub struct TileUse {
    /// Tiles extracted.
    pub extracted: usize,
    /// Tiles of the image (1: the whole image at once).
    pub total: usize,
    /// The grid asked for, `COLSxROWS+MARGIN` (a small image gets fewer tiles).
    #[schema(value_type = String, example = "2x2+24")]
    #[serde(serialize_with = "crate::report::display")]
    pub grid: TileGrid,
}

fn display<T: std::fmt::Display, S: serde::Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

/// What the extraction edge tells the report.
#[derive(Debug, Clone, Copy)]
pub struct Extraction {
    pub tiles_extracted: usize,
    pub tiles_total: usize,
    pub grid: TileGrid,
    /// N, or its estimate while tiles were left.
    pub expected_features: f64,
    /// Every tile was extracted.
    pub complete: bool,
}

/// The stopping rule the search ran with.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RuleReport {
    pub name: String,
    /// What the parameter is (`threshold`, `delta`, ...), absent for `none`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameter: Option<&'static str>,
    /// The parameter's value, absent for `none`.
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

/// Size of the decoded query image in pixels.
#[derive(Debug, Clone, Copy, Default, Serialize, ToSchema)]
pub struct ImageSize {
    pub width: u32,
    pub height: u32,
}

/// Milliseconds per stage.
#[derive(Debug, Clone, Copy, Default, Serialize, ToSchema)]
pub struct Timings {
    pub decode: f64,
    pub extract: f64,
    pub quantize: f64,
    pub vote: f64,
    /// Geometric verification (0 without).
    pub verify: f64,
    pub total: f64,
}

pub fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Which map answered.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MapIdentity {
    pub name: String,
    /// Images in the map.
    pub images: usize,
    /// Visual words of its vocabulary.
    pub words: usize,
    /// Hash of the vocabulary the map was built with.
    pub vocabulary: String,
}

impl MapIdentity {
    pub fn of(map: &dyn MapRead) -> Self {
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
            votes: None,
            inliers: None,
            verified: None,
            place: info.place.map(str::to_owned),
            pose: info
                .pose
                .map(|p| p.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()),
        }
    }
}

impl FeatureUse {
    fn new(outcome: &SearchOutcome, extraction: &Extraction) -> Self {
        let total = if extraction.complete {
            outcome.features_total
        } else {
            (extraction.expected_features.round() as usize).max(outcome.features_total)
        };
        let used = outcome.features_used;
        Self {
            total,
            extracted: outcome.features_total,
            used,
            fraction: if total == 0 {
                1.0
            } else {
                used as f64 / total as f64
            },
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
        map: &dyn MapRead,
        rule: &RuleSpec,
        seed: u64,
        image: ImageSize,
        outcome: SearchOutcome,
        edge: EdgeTimings,
        extraction: Extraction,
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
            features: FeatureUse::new(&outcome, &extraction),
            tiles: TileUse {
                extracted: extraction.tiles_extracted,
                total: extraction.tiles_total,
                grid: extraction.grid,
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
                verify: ms(t.verify),
                total: ms(edge.decode + edge.extract + t.quantize + t.vote + t.verify),
            },
            map: MapIdentity::of(map),
            verified: None,
        }
    }

    /// Apply geometric verification: `reranked` holds the vote candidates of
    /// this answer in their new order; keep the first `top_n` scoring at
    /// least `min_score` (inliers), and count `elapsed` as verification time.
    pub fn verified(
        mut self,
        map: &dyn MapRead,
        reranked: &[crate::geometry::verify::Reranked],
        top_n: usize,
        min_score: f32,
        elapsed: Duration,
    ) -> Self {
        self.candidates = reranked
            .iter()
            .filter(|r| r.score() >= min_score)
            .take(top_n)
            .enumerate()
            .map(|(i, r)| {
                let mut c = Candidate::new(i + 1, r.score(), map.image(r.id));
                c.votes = Some(r.votes);
                c.inliers = r.verification.map(|v| v.inliers as u32);
                c.verified = r.verification.map(|v| v.verified);
                c
            })
            .collect();
        self.verified = Some(
            self.candidates
                .first()
                .and_then(|c| c.verified)
                .unwrap_or(false),
        );
        self.timings_ms.verify += ms(elapsed);
        self.timings_ms.total += ms(elapsed);
        self
    }
}

/// [`StopInfo`] lives in the search core, which knows nothing of API
/// documents; its schema is written out here (a test checks it against the
/// serialized form).
impl utoipa::PartialSchema for StopInfo {
    fn schema() -> RefOr<Schema> {
        let text = |description: &str| {
            ObjectBuilder::new()
                .schema_type(Type::String)
                .description(Some(description))
        };
        ObjectBuilder::new()
            .description(Some("Where and why the search stopped."))
            .property(
                "kind",
                text("`rule`: the stopping rule fired; `exhausted`: every feature was used; `deadline`: the request's deadline passed (the answer so far).")
                    .enum_values(Some(["rule", "exhausted", "deadline"])),
            )
            .required("kind")
            .property(
                "at_feature",
                ObjectBuilder::new()
                    .schema_type(Type::Integer)
                    .minimum(Some(0))
                    .description(Some("Features voted when the search stopped.")),
            )
            .required("at_feature")
            .property("detail", text("Why, for people."))
            .required("detail")
            .into()
    }
}

impl ToSchema for StopInfo {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::search::StopKind;
    use utoipa::PartialSchema;

    #[test]
    fn drawn_seeds_are_exact_in_json_and_span_their_range() {
        let seeds: Vec<u64> = (0..4000).map(|_| draw_seed()).collect();
        for &s in &seeds {
            assert!(s <= MAX_DRAWN_SEED);
            let through_json: f64 = serde_json::from_str(&s.to_string()).unwrap();
            assert_eq!(through_json as u64, s);
        }
        assert!(seeds.iter().any(|&s| s > MAX_DRAWN_SEED / 2));
    }

    fn object(schema: RefOr<Schema>) -> utoipa::openapi::schema::Object {
        match schema {
            RefOr::T(Schema::Object(o)) => o,
            _ => panic!("object schema expected"),
        }
    }

    #[test]
    fn stop_schema_matches_its_serialized_form() {
        let schema = object(StopInfo::schema());
        let mut documented: Vec<&String> = schema.properties.keys().collect();
        documented.sort();
        let kinds: Vec<serde_json::Value> = object(schema.properties["kind"].clone())
            .enum_values
            .unwrap();
        for kind in [StopKind::Rule, StopKind::Exhausted, StopKind::Deadline] {
            let value = serde_json::to_value(StopInfo {
                kind,
                at_feature: 3,
                detail: String::new(),
            })
            .unwrap();
            let mut keys: Vec<&String> = value.as_object().unwrap().keys().collect();
            keys.sort();
            assert_eq!(keys, documented);
            assert!(kinds.contains(&value["kind"]), "{}", value["kind"]);
        }
    }
}

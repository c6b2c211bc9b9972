//! The answer to one query as users see it, shared by `bowloc query` and the
//! HTTP service: candidates with their map metadata, how many features were
//! used and why the search stopped, where the time went and, on request, the
//! vote race and the inlier matches (the trace). The types also
//! describe themselves as OpenAPI schemas (utoipa) for the service's API
//! document.

use crate::features::TileGrid;
use crate::index::{ImageInfo, MapRead};
use crate::search::{RuleSpec, SearchOutcome, StopInfo, StopKind, Trace};
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
    /// features. With verification the first is the verified answer and,
    /// with `verify.rerank = "answer"` (the default), the others follow in
    /// vote order.
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
    /// With `trace=true` or `trace=full`: the vote race. Absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trace: Option<RaceTrace>,
    /// With `sequence`: the sequence's filtered answer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sequence: Option<SequenceAnswer>,
    /// When the ORB pass looked at the query first (`orb_pass`): whether it
    /// answered. Absent when it did not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orb_pass: Option<OrbPassUse>,
    /// With a prior: the search's posterior, which a sequence takes as its
    /// new belief (not sent).
    #[serde(skip)]
    #[schema(ignore)]
    pub posterior: Option<crate::search::Posterior>,
}

/// The vote race: the search's state as the features arrived, sampled
/// every `every` features (at most 256 points and the stop), for drawing.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RaceTrace {
    /// Features between two sampled points (it doubles for long races to
    /// keep the points bounded).
    #[schema(minimum = 1)]
    pub every: u32,
    /// Sampled points in voting order; the last one is where the search
    /// ended (`stop.at_feature`).
    pub points: Vec<RacePoint>,
    /// Features given to the search after each tile, in extraction order.
    pub tile_ends: Vec<u32>,
    /// Features voted before the rule was first consulted (`min_features`);
    /// the statistic before it did not count.
    pub warm_up: u32,
    /// With `trace=full`: the same features voted to the end, without a
    /// rule, every tile extracted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub full: Option<FullRace>,
    /// Longer side of the extraction frame: SIFT saw each image (query and
    /// map) downscaled so its longer side is at most this (0: full size).
    /// Match positions are in pixels of that frame.
    pub frame_side: u32,
    /// With verification: the inliers of each candidate that has some.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub matches: Vec<CandidateMatches>,
}

/// Most match lines reported per candidate.
pub const MAX_MATCH_LINES: usize = 100;

/// A verified candidate's inliers as lines between the two images.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CandidateMatches {
    /// The map image id.
    pub id: u32,
    /// Inlier pairs `[query x, query y, map x, map y]`, in pixels of each
    /// image's extraction frame (`frame_side`); at most 100, evenly chosen.
    pub lines: Vec<[f32; 4]>,
}

impl CandidateMatches {
    /// The pairs `query[i]` ↔ `map[i]`, thinned evenly to at most
    /// [`MAX_MATCH_LINES`].
    pub fn new(id: u32, query: &[[f32; 2]], map: &[[f32; 2]]) -> Self {
        let n = query.len().min(map.len());
        let step = n.div_ceil(MAX_MATCH_LINES).max(1);
        let lines = (0..n)
            .step_by(step)
            .map(|i| [query[i][0], query[i][1], map[i][0], map[i][1]])
            .collect();
        Self { id, lines }
    }
}

/// The state of the race after `features` votes.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub struct RacePoint {
    /// Features voted so far.
    pub features: u32,
    /// The leading map image's id (absent before any vote reached one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leader: Option<u32>,
    /// The leader's summed votes, max(h).
    pub leader_votes: f32,
    /// The highest summed votes of any other image.
    pub runner_up_votes: f32,
    /// The mean vote over all map images, mean(h).
    pub mean_votes: f64,
    /// The number the rule compares with its threshold, as the rule's
    /// description says (absent for a rule that compares none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub statistic: Option<f64>,
    /// The threshold the statistic must pass.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
}

/// The full search over every feature, for comparison with the answer.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FullRace {
    /// Features the full search voted (N, unless the deadline cut it).
    pub features: usize,
    /// `exhausted`, or `deadline` when the request's deadline cut it short.
    pub stop: StopInfo,
    #[schema(minimum = 1)]
    pub every: u32,
    pub points: Vec<RacePoint>,
    /// The full search's best map images by votes (at most `top_n`, before
    /// any verification).
    pub candidates: Vec<Candidate>,
}

impl From<&Trace> for RaceTrace {
    fn from(t: &Trace) -> Self {
        Self {
            every: t.every,
            points: race_points(t),
            tile_ends: t.batch_ends.clone(),
            warm_up: t.warm_up,
            full: None,
            frame_side: 0,
            matches: Vec::new(),
        }
    }
}

fn race_points(t: &Trace) -> Vec<RacePoint> {
    t.points
        .iter()
        .map(|p| RacePoint {
            features: p.features,
            leader: p.leader,
            leader_votes: p.leader_votes,
            runner_up_votes: p.runner_up_votes,
            mean_votes: p.mean_votes,
            statistic: p.statistic.map(|s| s.0),
            threshold: p.statistic.map(|s| s.1),
        })
        .collect()
}

/// The sequence filter's answer for one frame.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SequenceAnswer {
    /// The sequence's name.
    pub name: String,
    /// The frame's index: as given, else the previous frame's + 1.
    pub frame: u64,
    /// Frames the sequence has applied since it (re)started, this one included.
    pub frames: u64,
    /// Why the sequence started afresh with this frame (`first`,
    /// `out_of_order`, `gap`); absent when the frame continued it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restart: Option<&'static str>,
    /// Map images by posterior probability given every frame so far, best
    /// first (at most `top_n`).
    pub candidates: Vec<FilteredCandidate>,
}

/// A map image by its probability under the sequence filter.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FilteredCandidate {
    #[schema(minimum = 1)]
    pub rank: usize,
    pub id: u32,
    pub name: String,
    /// Posterior probability of this map image.
    pub probability: f64,
}

impl SequenceAnswer {
    /// The answer for a frame whose search gave `posterior`.
    pub fn new(
        map: &dyn MapRead,
        name: &str,
        prediction: &crate::sequence::Prediction,
        frames: u64,
        posterior: &crate::search::Posterior,
        top_n: usize,
    ) -> Self {
        Self {
            name: name.to_owned(),
            frame: prediction.frame,
            frames,
            restart: prediction.restart.map(|r| r.as_str()),
            candidates: posterior
                .top
                .iter()
                .take(top_n)
                .enumerate()
                .map(|(i, &(id, probability))| FilteredCandidate {
                    rank: i + 1,
                    id,
                    name: map.image(id).name.to_owned(),
                    probability,
                })
                .collect(),
        }
    }
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
    /// With verification: the inlier count of its place, its own plus its
    /// checked neighbours' (`verify.order = "place-scale"`, the default, or
    /// `"place"`), or its own (0 for a candidate beyond the verified top k).
    /// Either way comparable across queries.
    pub score: f32,
    /// Its votes h against the best image outside its place (the images
    /// within `search.place_window` along the map's order):
    /// h / (h + h_elsewhere), in [0, 1]; ½ for a tie. It means the same for
    /// every query: a threshold on the top candidate's picks the answers to
    /// trust (docs/results.md, "Distinctness").
    #[schema(minimum = 0, maximum = 1)]
    pub distinct: f32,
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
    /// With verification, for a verified candidate: how much larger the
    /// map image sees the scene than the query, the spread of its inliers
    /// in the map image over their spread in the query (both images
    /// downscaled to the extraction frame). Above 1 the map image was taken
    /// nearer what both show (along a route: ahead of the query), below 1
    /// further from it; the default order answers with the verified image
    /// of the place whose scale is nearest 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0)]
    pub scale: Option<f32>,
    /// Place label, when the map has one for this image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<String>,
    /// Pose fields, when the map has them for this image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<HashMap<String, f64>>,
    /// With `sequence` or `near`: the probability of this map image given
    /// this frame's votes alone (a uniform prior over the images allowed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub probability: Option<f64>,
}

/// How many of the query's features were extracted and used.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub struct FeatureUse {
    /// The query's features N: exact when every tile was extracted
    /// (`tiles.extracted == tiles.total`), else estimated from the tiles
    /// extracted (their features over their share of the image), rounded.
    pub total: usize,
    /// Features extracted (from the tiles extracted; after a coarse pass
    /// that did not end the search, the tiles', as the search started over
    /// on them).
    pub extracted: usize,
    /// Features quantized and voted before the search stopped.
    pub used: usize,
    /// used / total (1 when the image has no features).
    pub fraction: f64,
}

/// The tiles of streaming extraction: the image is cut into a grid, tiles
/// are extracted richest first (or at random), and extraction ends when the
/// search stops.
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
    /// The order the tiles were extracted in: `richest` (most FAST corners
    /// first), `spread` or `random`.
    #[schema(value_type = String, example = "richest")]
    #[serde(serialize_with = "crate::report::display")]
    pub order: crate::search::TileOrder,
    /// Extraction time saved by stopping before the last tile: what the
    /// tiles not extracted were expected to take (0 when every tile was
    /// extracted). Each is priced as a time budget prices the next tile: the
    /// mean time of the tiles extracted apart from their keypoints, plus the
    /// keypoints it was expected to hold (by its FAST corners) at what a
    /// keypoint has cost this server lately; after the coarse pass alone,
    /// each at what the tile at its place in the order has taken lately.
    pub saved_ms: f64,
    /// Tiles extracted ahead of their turn on a core that would otherwise
    /// idle (not sent: they follow the server's load; `/metrics` counts
    /// them).
    #[serde(skip)]
    #[schema(ignore)]
    pub ahead: crate::features::TilesAhead,
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
    pub tile_order: crate::search::TileOrder,
    /// N, or its estimate while tiles were left.
    pub expected_features: f64,
    /// Every tile was extracted.
    pub complete: bool,
    /// What the tiles not extracted were expected to take.
    pub skipped: Duration,
    /// [`TileUse::ahead`].
    pub ahead: crate::features::TilesAhead,
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
    /// Inliers that also stop the search at a tile's end once its answer
    /// has them at the query's scale (`or_verified`); absent without.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub or_verified: Option<u32>,
}

impl From<&RuleSpec> for RuleReport {
    fn from(r: &RuleSpec) -> Self {
        let parameter = r.parameter_name();
        Self {
            name: r.name.clone(),
            parameter,
            value: parameter.map(|_| r.parameter),
            or_verified: r.or_verified,
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
    /// The ORB pass: ORB, its votes and checks (0 when it did not run).
    pub orb_pass: f64,
    pub total: f64,
}

/// What the ORB pass did for a query.
#[derive(Debug, Clone, Copy, Serialize, ToSchema)]
pub struct OrbPassUse {
    /// The pass answered: the candidates are its own (each one's score its
    /// inliers) and no SIFT feature was extracted (stop kind `orb-pass`).
    /// Otherwise the SIFT search answered after it.
    pub answered: bool,
    /// Best-voted map images it verified.
    pub checked: usize,
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
    /// The ranked vote candidates of a search, with their map metadata.
    fn ranked(map: &dyn MapRead, outcome: &SearchOutcome) -> Vec<Self> {
        outcome
            .candidates
            .iter()
            .enumerate()
            .map(|(i, r)| Self::new(i + 1, r.score, r.distinct, map.image(r.id)))
            .collect()
    }

    fn new(rank: usize, score: f32, distinct: f32, info: ImageInfo<'_>) -> Self {
        Self {
            rank,
            id: info.id,
            name: info.name.to_owned(),
            score,
            distinct,
            votes: None,
            inliers: None,
            verified: None,
            scale: None,
            place: info.place.map(str::to_owned),
            pose: info
                .pose
                .map(|p| p.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()),
            probability: None,
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
        let mut candidates = Candidate::ranked(map, &outcome);
        if let Some(frame) = outcome.frame_posterior.as_ref() {
            for c in &mut candidates {
                c.probability = Some(
                    frame
                        .top
                        .iter()
                        .find(|e| e.0 == c.id)
                        .map_or(frame.floor(), |e| e.1),
                );
            }
        }
        let t = outcome.timings;
        Self {
            candidates,
            features: FeatureUse::new(&outcome, &extraction),
            tiles: TileUse {
                extracted: extraction.tiles_extracted,
                total: extraction.tiles_total,
                grid: extraction.grid,
                order: extraction.tile_order,
                saved_ms: ms(extraction.skipped),
                ahead: extraction.ahead,
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
                orb_pass: 0.0,
                total: ms(edge.decode + edge.extract + t.quantize + t.vote + t.verify),
            },
            map: MapIdentity::of(map),
            verified: None,
            trace: outcome.trace.as_ref().map(RaceTrace::from),
            sequence: None,
            orb_pass: None,
            posterior: outcome.posterior,
        }
    }

    /// Whether the best candidate is verified.
    fn first_verified(&self) -> bool {
        self.candidates
            .first()
            .and_then(|c| c.verified)
            .unwrap_or(false)
    }

    /// Drop the candidates whose distinctness is below `min` and rank the
    /// others 1, 2, …; `verified` then speaks of the new best candidate.
    pub fn keeping_distinct(mut self, min: f32) -> Self {
        if min <= 0.0 {
            return self;
        }
        self.candidates.retain(|c| c.distinct >= min);
        for (i, c) in self.candidates.iter_mut().enumerate() {
            c.rank = i + 1;
        }
        // a traced answer draws matches only for the candidates it keeps
        if let Some(trace) = &mut self.trace {
            let kept = &self.candidates;
            trace.matches.retain(|m| kept.iter().any(|c| c.id == m.id));
        }
        if self.verified.is_some() {
            self.verified = Some(self.first_verified());
        }
        self
    }

    /// Add the full search over every feature (traced) to the trace, for
    /// comparison.
    pub fn compare_with_full(&mut self, map: &dyn MapRead, full: SearchOutcome, top_n: usize) {
        let Some(trace) = &mut self.trace else { return };
        let Some(t) = &full.trace else { return };
        let mut candidates = Candidate::ranked(map, &full);
        candidates.truncate(top_n);
        trace.full = Some(FullRace {
            features: full.features_used,
            every: t.every,
            points: race_points(t),
            candidates,
            stop: full.stop,
        });
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
        let voted = |id: u32| self.candidates.iter().find(|c| c.id == id);
        let distinct = |id: u32| voted(id).map_or(0.0, |c| c.distinct);
        self.candidates = reranked
            .iter()
            .filter(|r| r.score() >= min_score)
            .take(top_n)
            .enumerate()
            .map(|(i, r)| {
                let mut c =
                    Candidate::new(i + 1, r.score(), distinct(r.distinct_from), map.image(r.id));
                c.votes = Some(r.votes);
                c.inliers = r.verification.map(|v| v.inliers as u32);
                c.verified = r.verification.map(|v| v.verified);
                c.scale = r
                    .verification
                    .filter(|v| v.verified)
                    .and_then(|_| r.scale());
                // a posterior (rule `posterior`, a sequence) stays the image's
                c.probability = voted(r.id).and_then(|v| v.probability);
                c
            })
            .collect();
        self.verified = Some(self.first_verified());
        self.timings_ms.verify += ms(elapsed);
        self.timings_ms.total += ms(elapsed);
        self
    }
}

impl Localization {
    /// Count the ORB pass that looked at the query first: its time, and
    /// whether it answered.
    pub fn after_orb_pass(self, took: Duration, checked: usize) -> Self {
        self.counting_orb_pass(took, checked, false)
    }

    fn counting_orb_pass(mut self, took: Duration, checked: usize, answered: bool) -> Self {
        self.orb_pass = Some(OrbPassUse { answered, checked });
        self.timings_ms.orb_pass += ms(took);
        self.timings_ms.total += ms(took);
        self
    }

    /// The ORB pass's answer instead of the search's: `ranked`, the picked
    /// map image and then the other checked ones in vote order, each with
    /// its inliers and scale from `checked`, verified when it has `floor`
    /// inliers. The first `top_n` scoring at least `min_score` (inliers)
    /// are kept. The answer must come from a search stopped before any
    /// feature ([`crate::search::StopKind::OrbPass`]).
    #[allow(clippy::too_many_arguments)]
    pub fn answered_by_orb_pass(
        mut self,
        map: &dyn MapRead,
        ranked: &[u32],
        checked: &[crate::orb_pass::Checked],
        floor: usize,
        top_n: usize,
        min_score: f32,
        took: Duration,
    ) -> Self {
        let of = |id: u32| checked.iter().find(|c| c.image == id);
        self.candidates = ranked
            .iter()
            .filter_map(|&id| of(id))
            .filter(|c| c.inliers as f32 >= min_score)
            .take(top_n)
            .enumerate()
            .map(|(i, k)| {
                let mut c = Candidate::new(i + 1, k.inliers as f32, 0.0, map.image(k.image));
                c.inliers = Some(k.inliers as u32);
                c.verified = Some(k.inliers >= floor);
                c.scale = k.scale;
                c
            })
            .collect();
        self.verified = Some(self.first_verified());
        self.features.fraction = 0.0;
        self.counting_orb_pass(took, checked.len(), true)
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
        let kinds = StopKind::ALL.map(|k| format!("`{}`: {}", k.name(), k.about()));
        ObjectBuilder::new()
            .description(Some("Where and why the search stopped."))
            .property(
                "kind",
                text(&format!("{}.", kinds.join("; ")))
                    .enum_values(Some(StopKind::ALL.map(StopKind::name))),
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
        for kind in StopKind::ALL {
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

//! The service's own endpoints: liveness (`/healthz`), readiness (`/readyz`),
//! what is loaded (`/map`), Prometheus metrics (`/metrics`) and the API
//! document (`/openapi.json`).

use super::AppState;
use super::errors::{ApiError, ErrorBody};
use super::plan_memory::PlanMemory;
use crate::features::ExtractConfig;
use crate::index::MapMeta;
use crate::index::MapRead;
use crate::report::MapIdentity;
use crate::vocabulary::VocabularyMeta;
use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::sync::Arc;
use utoipa::ToSchema;

/// A status word.
#[derive(Debug, Serialize, ToSchema)]
pub struct Status {
    /// `alive` or `ready`.
    pub status: &'static str,
}

/// The process is up (it may still be loading the map).
#[utoipa::path(get, path = "/healthz", tag = "operations",
    responses((status = 200, description = "The process answers.", body = Status)))]
pub async fn healthz() -> Json<Status> {
    Json(Status { status: "alive" })
}

/// The map is loaded and the service takes traffic.
#[utoipa::path(get, path = "/readyz", tag = "operations",
    responses(
        (status = 200, description = "Ready for traffic.", body = Status),
        (status = 503, description = "Still loading or building the map (`not_ready`; `error.step` names the step, e.g. `Lloyd iterations 12/40` while k-means trains the default vocabulary), or shutting down (`shutting_down`).", body = ErrorBody),
    ))]
pub async fn readyz(State(state): State<Arc<AppState>>) -> Result<Json<Status>, ApiError> {
    if state.is_shutting_down() {
        return Err(ApiError::shutting_down());
    }
    state.localizer()?;
    Ok(Json(Status { status: "ready" }))
}

/// What is loaded.
#[derive(Debug, Serialize, ToSchema)]
pub struct MapInfo {
    /// The identity every answer carries.
    pub identity: MapIdentity,
    pub map_path: String,
    /// The map file's metadata: name, images, words, postings, vocab_hash,
    /// pose_fields, features, images_without_features.
    #[schema(value_type = Object)]
    pub map: MapMeta,
    pub vocabulary_path: String,
    /// The vocabulary file's metadata: words, dim, the extraction settings
    /// it was trained with, k-means seed, trained_on, iterations.
    #[schema(value_type = Object)]
    pub vocabulary: VocabularyMeta,
    /// How queries are extracted (the vocabulary's settings within the
    /// service's limits).
    #[schema(value_type = Object)]
    pub query_extract: ExtractConfig,
    /// The changes since the map file was written: generation, images of
    /// the file and now, added and removed, change log size, last compaction.
    pub changes: crate::live::ChangesInfo,
    /// The extraction plan learned for the map (`search.tiles` ending in
    /// `,auto`); absent when the plan is fixed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extraction_plan: Option<PlanInfo>,
    /// The ORB pass's side, when one is loaded for the map; absent when
    /// the map has none (the pass is off, whatever `orb_pass.enabled` says).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orb_pass: Option<OrbPassInfo>,
}

/// The ORB pass as loaded.
#[derive(Debug, Serialize, ToSchema)]
pub struct OrbPassInfo {
    /// The pass looks at requests that do not say (`orb_pass.enabled`).
    pub enabled: bool,
    /// It may run now: false while the map has changes its side does not
    /// have (until the side is rebuilt for the compacted map).
    pub current: bool,
    /// The side's file.
    pub file: String,
    /// ORB keypoints per image its map images kept (its queries keep as
    /// many), the grid they were spread over (`none`: ORB's own strongest
    /// corners) and its binary words.
    pub keypoints: usize,
    pub grid: String,
    pub words: usize,
}

/// What the service has learned of its extraction plans.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlanInfo {
    /// The plan preferred now, `tiles` or `coarse` (a request still draws
    /// its plan); null while the trials run.
    pub preferred: Option<&'static str>,
    /// Requests that drew a plan, since the plan was first learned
    /// (counting those before a restart it was resumed from).
    pub requests: u64,
    /// What each plan has cost: `tiles`, then `coarse`.
    pub plans: Vec<PlanCost>,
    /// The file it is kept in (`search.remember_plan`); absent when it is
    /// not kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// The requests of the kept plan this start resumed (null: it ran its
    /// trials).
    pub resumed_from: Option<u64>,
}

/// What one extraction plan has cost.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlanCost {
    /// `tiles` or `coarse`.
    pub plan: &'static str,
    /// Requests answered with it.
    pub requests: u64,
    /// Its typical request (geometric mean of extraction, quantization,
    /// voting and verification), ms; null before its first request.
    pub typical_ms: Option<f64>,
    /// Share of its requests that ended on their first unit (moving
    /// average).
    pub ended_first: f64,
}

impl PlanInfo {
    fn of(choice: &crate::features::CoarseChoice, memory: Option<&PlanMemory>) -> Self {
        use crate::features::CoarseChoice;
        let learned = choice.learned();
        let plans = learned
            .plans()
            .into_iter()
            .map(|(plan, arm)| PlanCost {
                plan,
                requests: arm.samples,
                typical_ms: (arm.samples > 0).then(|| arm.typical_ms()),
                ended_first: arm.ended_first,
            })
            .collect();
        Self {
            preferred: choice.preferred().map(CoarseChoice::plan_name),
            requests: learned.requests,
            plans,
            file: memory.map(|m| m.path().display().to_string()),
            resumed_from: memory.and_then(PlanMemory::resumed),
        }
    }
}

/// The loaded map and vocabulary.
#[utoipa::path(get, path = "/map", tag = "operations",
    responses(
        (status = 200, description = "The loaded map and vocabulary.", body = MapInfo),
        (status = 503, description = "Not loaded yet (`not_ready`).", body = ErrorBody),
    ))]
pub async fn map(State(state): State<Arc<AppState>>) -> Result<Json<MapInfo>, ApiError> {
    let l = state.localizer()?;
    let files = &state.config.files;
    let snapshot = l.map.snapshot();
    Ok(Json(MapInfo {
        identity: MapIdentity::of(&*snapshot),
        map_path: files.map.display().to_string(),
        map: snapshot.meta().clone(),
        changes: l.map.status(),
        vocabulary_path: files.vocabulary.display().to_string(),
        vocabulary: l.vocab.meta().clone(),
        query_extract: l.extract.clone(),
        extraction_plan: l
            .coarse_choice
            .as_ref()
            .map(|choice| PlanInfo::of(choice, state.plan_memory())),
        orb_pass: l.orb_pass.as_ref().map(|pass| OrbPassInfo {
            enabled: state.config.orb_pass.enabled,
            current: pass.is_current(snapshot.generation()),
            file: state.config.orb_pass_file().display().to_string(),
            keypoints: pass.meta.keypoints,
            grid: crate::orb_pass::params::grid_name(pass.meta.grid),
            words: pass.meta.words,
        }),
    }))
}

/// Metrics in the Prometheus text format.
#[utoipa::path(get, path = "/metrics", tag = "operations",
    responses((status = 200, description = "Prometheus text exposition format 0.0.4.",
        content_type = "text/plain", body = String)))]
pub async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    super::metrics::collect_process();
    let pool = &state.pool;
    let busy = pool.busy();
    super::metrics::pool(
        pool.workers(),
        busy,
        pool.admitted().saturating_sub(busy),
        pool.queue_capacity(),
    );
    (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
        )],
        super::metrics::render(&state.metrics),
    )
        .into_response()
}

/// This API's OpenAPI document (the same as `docs/openapi.json`).
#[utoipa::path(get, path = "/openapi.json", tag = "operations",
    responses((status = 200, description = "OpenAPI 3.1 document.", content_type = "application/json", body = Object)))]
pub async fn openapi() -> Response {
    (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        )],
        super::openapi::json(),
    )
        .into_response()
}

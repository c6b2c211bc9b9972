//! The service's own endpoints: liveness (`/healthz`), readiness (`/readyz`),
//! what is loaded (`/map`), Prometheus metrics (`/metrics`) and the API
//! document (`/openapi.json`).

use super::AppState;
use super::errors::{ApiError, ErrorBody};
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

//! The map's images over HTTP: `PUT /images/{id}` adds (or replaces) an
//! image, `DELETE /images/{id}` removes one, `GET /images` and
//! `GET /images/{id}` list them, `POST /map/compact` folds the change log into
//! the map file. An image's id is its name in the map. Writes need the
//! configured bearer token ([`require_write_token`]); each is durable (in
//! the change log, fsynced) before it is answered, and visible whole to the
//! queries that start after it.

use super::AppState;
use super::body::{ImageUpload, image_body_description, receive_image, unsupported_description};
use super::errors::{ApiError, ErrorBody};
use super::openapi::Binary;
use crate::index::MapRead;
use crate::index::metadata::{PoseError, pose_row};
use crate::live::{Change, Compaction, NewImage, Snapshot, WriteError, now_ms};
use axum::Json;
use axum::extract::{Path, RawQuery, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;
use subtle::ConstantTimeEq;
use utoipa::{IntoParams, ToSchema};

/// Longest id, in bytes.
pub const MAX_ID_LEN: usize = 255;
/// Longest place label, in bytes.
pub const MAX_PLACE_LEN: usize = 1024;
/// Most images one page of `GET /images` lists.
pub const MAX_PAGE: usize = 1000;
/// Images a page of `GET /images` lists when the request does not say.
pub const DEFAULT_PAGE: usize = 100;

/// The rule a new image's id follows, as the API document and the errors
/// say it.
pub fn id_rule() -> String {
    format!(
        "1 to {MAX_ID_LEN} characters among letters, digits and `. _ ~ / -`, not starting \
         with `/`"
    )
}

/// A new image's id follows [`id_rule`]: 1 to [`MAX_ID_LEN`] characters
/// among letters, digits and `. _ ~ / -`, not starting with `/`. (The
/// images of a map file keep their names from its image list, whatever
/// they are, and are addressed by them.)
pub fn check_id(id: &str) -> Result<(), ApiError> {
    let ok = !id.is_empty()
        && id.len() <= MAX_ID_LEN
        && !id.starts_with('/')
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._~/-".contains(&b));
    if ok {
        Ok(())
    } else {
        Err(ApiError::bad_request(
            "invalid_id",
            format!("an image id is {}", id_rule()),
        ))
    }
}

/// Refuses a request without the configured write token: 403
/// `writes_disabled` when none is configured, 401 `unauthorized` without an
/// `Authorization: Bearer` header, 403 `forbidden` with another token (the
/// comparison takes the same time wherever the tokens differ).
pub async fn require_write_token(
    State(state): State<Arc<AppState>>,
    request: Request,
    next: Next,
) -> Response {
    let Some(token) = &state.config.auth.write_token else {
        return ApiError::new(
            StatusCode::FORBIDDEN,
            "writes_disabled",
            "the write endpoints are disabled: configure a token ([auth] write_token or \
             BOWLOC_AUTH__WRITE_TOKEN)",
        )
        .into_response();
    };
    let given = request
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim);
    match given {
        None => {
            let mut r = ApiError::new(
                StatusCode::UNAUTHORIZED,
                "unauthorized",
                "this endpoint needs `Authorization: Bearer TOKEN`",
            )
            .into_response();
            r.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            r
        }
        Some(given) if bool::from(given.as_bytes().ct_eq(token.as_bytes())) => {
            next.run(request).await
        }
        Some(_) => ApiError::new(
            StatusCode::FORBIDDEN,
            "forbidden",
            "the bearer token is not the write token",
        )
        .into_response(),
    }
}

/// Ids being written now: a second write to one of them is refused.
#[derive(Default)]
pub struct Writing(Mutex<HashSet<String>>);

/// Holds an id until dropped.
struct Claim<'a>(&'a Writing, String);

impl Writing {
    fn claim(&self, id: &str) -> Result<Claim<'_>, ApiError> {
        let mut ids = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if !ids.insert(id.to_owned()) {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                "write_conflict",
                format!("image `{id}` is being written by another request; retry once it is done"),
            ));
        }
        Ok(Claim(self, id.to_owned()))
    }
}

impl Drop for Claim<'_> {
    fn drop(&mut self) {
        let mut ids = self.0.0.lock().unwrap_or_else(|e| e.into_inner());
        ids.remove(&self.1);
    }
}

fn write_error(e: WriteError) -> ApiError {
    use crate::live::ApplyError;
    match e {
        WriteError::ReadOnly => ApiError::new(
            StatusCode::FORBIDDEN,
            "writes_disabled",
            "this map was loaded without its change log and takes no changes",
        ),
        WriteError::Apply(ApplyError::NotFound(id)) => image_not_found(&id),
        WriteError::Apply(e @ ApplyError::Full(_)) => ApiError::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "map_full",
            format!("{e} (changes.max_images); remove images first"),
        ),
        WriteError::Apply(ApplyError::Invalid(m)) => ApiError::bad_request("invalid_parameter", m),
        e @ (WriteError::Log(_) | WriteError::Broken(_)) => {
            tracing::error!("map write failed: {e}");
            ApiError::storage_unavailable(e.to_string())
        }
    }
}

/// The index of image `id`: any name in the map is an id (a map built from
/// an image list keeps the list's names, whatever they are); an unknown id
/// is 404, or 400 when it could not even be a new id.
fn existing(s: &Snapshot, id: &str) -> Result<u32, ApiError> {
    match s.id_of(id) {
        Some(index) => Ok(index),
        None => {
            check_id(id)?;
            Err(image_not_found(id))
        }
    }
}

fn image_not_found(id: &str) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "image_not_found",
        format!("no image `{id}` in the map"),
    )
}

/// Run a blocking write (it fsyncs) off the async threads.
async fn blocking<T: Send + 'static>(
    job: impl FnOnce() -> Result<T, WriteError> + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(job)
        .await
        .map_err(|e| ApiError::internal(format!("the write failed unexpectedly: {e}")))?
        .map_err(write_error)
}

/// One image of the map.
#[derive(Debug, Serialize, ToSchema)]
pub struct ImageItem {
    /// The image's id: its name in the map.
    pub id: String,
    /// Its position in the map now: the `id` of `/localize` candidates
    /// (it changes when a compaction renumbers the images).
    pub index: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<HashMap<String, f64>>,
    /// Its features (0: it can never be found; for a synthetic map file,
    /// which stores none, 0 too).
    pub features: usize,
    /// When it was added over the API, in milliseconds since the Unix
    /// epoch; absent for images of the map file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub added_at_ms: Option<u64>,
}

impl ImageItem {
    /// Image `index` of snapshot `s`.
    pub fn of(s: &Snapshot, index: u32) -> Self {
        let info = s.image(index);
        Self {
            id: info.name.to_owned(),
            index,
            place: info.place.map(str::to_owned),
            pose: info
                .pose
                .map(|p| p.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()),
            features: s.features_of(index),
            added_at_ms: s.added(index).map(|a| a.added_at_ms),
        }
    }
}

/// The answer to a write.
#[derive(Debug, Serialize, ToSchema)]
pub struct Written {
    pub id: String,
    /// The map's generation after the change.
    pub generation: u64,
    /// Features of the added image (absent for a removal).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub features: Option<usize>,
    /// Its position in the map (absent for a removal).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub index: Option<u32>,
    /// An add replaced the image of the same id.
    pub replaced: bool,
    /// Why the image may not be found, e.g. it has no features.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warning: Option<String>,
}

/// Query parameters of `PUT /images/{id}`: `place`, and the map's pose
/// fields by name (e.g. `x`, `y`: numbers).
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PutParams {
    /// Place label (at most 1024 bytes).
    // utoipa takes only a literal here; a test holds it to MAX_PLACE_LEN
    #[param(max_length = 1024)]
    pub place: Option<String>,
}

/// The place and pose a PUT asks for, checked against the map's pose fields.
fn put_fields(query: Option<&str>, pose_fields: &[String]) -> Result<(String, Vec<f64>), ApiError> {
    let pairs: Vec<(String, String)> = serde_urlencoded::from_str(query.unwrap_or(""))
        .map_err(|e| ApiError::bad_request("invalid_parameter", e.to_string()))?;
    let mut place = None;
    let mut pose = Vec::new();
    for (k, v) in &pairs {
        if k != "place" {
            pose.push((k.as_str(), v.as_str()));
        } else if place.is_some() {
            return Err(ApiError::invalid_parameter(k, "given more than once"));
        } else if v.len() > MAX_PLACE_LEN {
            return Err(ApiError::invalid_parameter(
                "place",
                format!("longer than {MAX_PLACE_LEN} bytes"),
            ));
        } else {
            place = Some(v.clone());
        }
    }
    let pose = pose_row(pose_fields, pose).map_err(|e| match &e {
        PoseError::Unknown { field, .. } => {
            let known = if pose_fields.is_empty() {
                "`place` (this map has no pose fields)".to_owned()
            } else {
                format!("`place` and the pose fields `{}`", pose_fields.join("`, `"))
            };
            ApiError::invalid_parameter(field, format!("unknown parameter; accepted: {known}"))
        }
        e => ApiError::invalid_parameter(e.field(), e.to_string()),
    })?;
    Ok((place.unwrap_or_default(), pose))
}

/// Add an image to the map, or replace the image of this id.
///
/// The body is the image, as for `/localize` (raw, or multipart field
/// `image`). It is extracted whole with the vocabulary's settings, as
/// `bowloc map build` indexes images, and weighted under the map's frozen
/// idf (recomputed at the next compaction). The answer comes once the change
/// is durable; queries starting after it see the image.
#[utoipa::path(
    put,
    path = "/images/{id}",
    tag = "images",
    params(
        ("id" = String, Path, description = format!("The image's id (its name in the map): {}.", id_rule())),
        PutParams,
    ),
    request_body(
        description = image_body_description("The image"),
        content(
            (Binary = "image/jpeg"),
            (Binary = "image/png"),
            (Binary = "application/octet-stream"),
            (ImageUpload = "multipart/form-data"),
        ),
    ),
    security(("bearer" = [])),
    responses(
        (status = 201, description = "Added.", body = Written),
        (status = 200, description = "Replaced the image of this id.", body = Written),
        (status = 400, description = "Bad id (`invalid_id`), parameter (`invalid_parameter`), empty body (`empty_body`) or multipart (`invalid_multipart`, `missing_image_field`).", body = ErrorBody),
        (status = 401, description = "No bearer token (`unauthorized`).", body = ErrorBody),
        (status = 403, description = "Wrong token (`forbidden`), or no token configured (`writes_disabled`).", body = ErrorBody),
        (status = 409, description = "Another request is writing this id (`write_conflict`).", body = ErrorBody),
        (status = 413, description = "Body over `limits.body_bytes` (`body_too_large`).", body = ErrorBody),
        (status = 415, description = unsupported_description(), body = ErrorBody),
        (status = 422, description = "Not a decodable image (`undecodable_image`), too many pixels (`image_too_large`), extraction failed (`extraction_failed`).", body = ErrorBody),
        (status = 408, description = "The body did not arrive in time (`request_timeout`, `body_timeout`).", body = ErrorBody),
        (status = 431, description = "Headers over the limits (`headers_too_large`).", body = ErrorBody),
        (status = 503, description = "Not ready (`not_ready`), overloaded (`overloaded`, `queue_timeout`, `deadline_exceeded`), or the change log cannot be written (`storage_unavailable`).", body = ErrorBody),
        (status = 507, description = "The map holds `changes.max_images` images (`map_full`).", body = ErrorBody),
    )
)]
pub async fn put_image(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
    request: Request,
) -> Result<Response, ApiError> {
    let deadline = Instant::now() + state.config.deadline();
    let localizer = state.localizer()?;
    check_id(&id)?;
    let (place, pose) = put_fields(
        query.as_deref(),
        &localizer.map.snapshot().meta().pose_fields,
    )?;
    let _claim = state.writing.claim(&id)?;
    let image = receive_image(&state, request, deadline, localizer.limits).await?;
    let extractor = localizer.clone();
    let features = state
        .on_worker(deadline, "extraction", move || {
            Ok(extractor.map_features(&image)?)
        })
        .await?;
    let n = features.len();
    let change = Change::Add(NewImage {
        name: id.clone(),
        place,
        pose,
        features,
        added_at_ms: now_ms(),
    });
    let writer = localizer.clone();
    let (applied, generation) = blocking(move || writer.map.apply(change)).await?;
    state.after_write(&localizer);
    let status = if applied.replaced {
        StatusCode::OK
    } else {
        StatusCode::CREATED
    };
    let warning = (n == 0)
        .then(|| "the image has no features: it was added but no query can find it".to_owned());
    let body = Written {
        id,
        generation,
        features: Some(n),
        index: Some(applied.id),
        replaced: applied.replaced,
        warning,
    };
    Ok((status, Json(body)).into_response())
}

/// Remove an image from the map.
#[utoipa::path(
    delete,
    path = "/images/{id}",
    tag = "images",
    params(("id" = String, Path, description = "The image's id (its name in the map).")),
    security(("bearer" = [])),
    responses(
        (status = 200, description = "Removed; queries starting after the answer no longer find it.", body = Written),
        (status = 400, description = "No such image, and not a valid id (`invalid_id`).", body = ErrorBody),
        (status = 401, description = "No bearer token (`unauthorized`).", body = ErrorBody),
        (status = 403, description = "Wrong token (`forbidden`), or no token configured (`writes_disabled`).", body = ErrorBody),
        (status = 404, description = "No image of this id (`image_not_found`).", body = ErrorBody),
        (status = 409, description = "Another request is writing this id (`write_conflict`).", body = ErrorBody),
        (status = 503, description = "Not ready (`not_ready`), or the change log cannot be written (`storage_unavailable`).", body = ErrorBody),
    )
)]
pub async fn delete_image(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Written>, ApiError> {
    let localizer = state.localizer()?;
    existing(&localizer.map.snapshot(), &id)?;
    let _claim = state.writing.claim(&id)?;
    let writer = localizer.clone();
    let name = id.clone();
    let (_, generation) = blocking(move || writer.map.apply(Change::Remove { name })).await?;
    state.after_write(&localizer);
    Ok(Json(Written {
        id,
        generation,
        features: None,
        index: None,
        replaced: false,
        warning: None,
    }))
}

/// Query parameters of `GET /images`.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListParams {
    /// Images to skip, in index order (default 0).
    #[param(value_type = Option<u32>, minimum = 0)]
    pub offset: Option<String>,
    /// Images per page, 1 to 1000 (default 100).
    // utoipa takes only literals here; a test holds them to MAX_PAGE and
    // DEFAULT_PAGE
    #[param(value_type = Option<u32>, minimum = 1, maximum = 1000)]
    pub limit: Option<String>,
}

/// One page of the map's images.
#[derive(Debug, Serialize, ToSchema)]
pub struct ImagePage {
    /// The generation listed.
    pub generation: u64,
    /// Images in the map.
    pub total: usize,
    pub offset: usize,
    pub limit: usize,
    pub images: Vec<ImageItem>,
}

fn whole(name: &str, v: &str, range: std::ops::RangeInclusive<usize>) -> Result<usize, ApiError> {
    v.trim()
        .parse::<usize>()
        .ok()
        .filter(|n| range.contains(n))
        .ok_or_else(|| {
            ApiError::invalid_parameter(
                name,
                format!(
                    "`{v}` is not a whole number in {}..={}",
                    range.start(),
                    range.end()
                ),
            )
        })
}

/// The map's images, in index order, a page at a time.
#[utoipa::path(
    get,
    path = "/images",
    tag = "images",
    params(ListParams),
    responses(
        (status = 200, description = "One page of images, from one snapshot of the map.", body = ImagePage),
        (status = 400, description = "Bad parameter (`invalid_parameter`).", body = ErrorBody),
        (status = 503, description = "Not loaded yet (`not_ready`).", body = ErrorBody),
    )
)]
pub async fn list_images(
    State(state): State<Arc<AppState>>,
    RawQuery(query): RawQuery,
) -> Result<Json<ImagePage>, ApiError> {
    let params: ListParams = serde_urlencoded::from_str(query.as_deref().unwrap_or(""))
        .map_err(|e| ApiError::bad_request("invalid_parameter", e.to_string()))?;
    let offset = match &params.offset {
        // the API document's int32
        Some(v) => whole("offset", v, 0..=i32::MAX as usize)?,
        None => 0,
    };
    let limit = match &params.limit {
        Some(v) => whole("limit", v, 1..=MAX_PAGE)?,
        None => DEFAULT_PAGE,
    };
    let s = state.localizer()?.map.snapshot();
    let images = s
        .ids()
        .skip(offset)
        .take(limit)
        .map(|j| ImageItem::of(&s, j))
        .collect();
    Ok(Json(ImagePage {
        generation: s.generation(),
        total: s.len(),
        offset,
        limit,
        images,
    }))
}

/// One image of the map.
#[utoipa::path(
    get,
    path = "/images/{id}",
    tag = "images",
    params(("id" = String, Path, description = "The image's id (its name in the map).")),
    responses(
        (status = 200, description = "The image.", body = ImageItem),
        (status = 400, description = "No such image, and not a valid id (`invalid_id`).", body = ErrorBody),
        (status = 404, description = "No image of this id (`image_not_found`).", body = ErrorBody),
        (status = 503, description = "Not loaded yet (`not_ready`).", body = ErrorBody),
    )
)]
pub async fn get_image(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<ImageItem>, ApiError> {
    let s = state.localizer()?.map.snapshot();
    let index = existing(&s, &id)?;
    Ok(Json(ImageItem::of(&s, index)))
}

/// The answer of a compaction.
#[derive(Debug, Serialize, ToSchema)]
pub struct Compacted {
    /// Whether anything was folded (false: no changes).
    pub compacted: bool,
    /// The generation the map file now holds.
    pub generation: u64,
    /// The compaction, when one ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compaction: Option<Compaction>,
}

/// Fold the change log into a new map file now.
///
/// The map is rebuilt from scratch over its images (idf recomputed),
/// written atomically, and the log emptied. Writes wait meanwhile; queries
/// do not.
#[utoipa::path(
    post,
    path = "/map/compact",
    tag = "images",
    security(("bearer" = [])),
    responses(
        (status = 200, description = "Compacted, or nothing to compact.", body = Compacted),
        (status = 401, description = "No bearer token (`unauthorized`).", body = ErrorBody),
        (status = 403, description = "Wrong token (`forbidden`), or no token configured (`writes_disabled`).", body = ErrorBody),
        (status = 503, description = "Not loaded yet (`not_ready`), or the map file or log cannot be written (`storage_unavailable`).", body = ErrorBody),
    )
)]
pub async fn compact(State(state): State<Arc<AppState>>) -> Result<Json<Compacted>, ApiError> {
    let localizer = state.localizer()?;
    let writer = localizer.clone();
    let compaction = blocking(move || writer.map.compact()).await?;
    Ok(Json(Compacted {
        compacted: compaction.is_some(),
        generation: localizer.map.snapshot().generation(),
        compaction,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids() {
        for ok in ["a", "day_left/Image001.jpg", "x-1.~", &"a".repeat(255)] {
            assert!(check_id(ok).is_ok(), "{ok}");
        }
        for bad in ["", "/abs", "a b", "é", "a?b", &"a".repeat(256), "a\nb"] {
            assert_eq!(check_id(bad).unwrap_err().code, "invalid_id", "{bad}");
        }
    }

    #[test]
    fn place_and_pose_fields() {
        let fields = vec!["x".to_owned(), "y".to_owned()];
        let (place, pose) = put_fields(Some("place=lab&x=1.5"), &fields).unwrap();
        assert_eq!(place, "lab");
        assert_eq!(pose[0], 1.5);
        assert!(pose[1].is_nan());
        assert_eq!(put_fields(None, &fields).unwrap(), (String::new(), vec![]));
        for bad in ["z=1", "x=abc", "x=inf", "place=a&place=b"] {
            let e = put_fields(Some(bad), &fields).unwrap_err();
            assert_eq!(e.code, "invalid_parameter", "{bad}");
        }
        let e = put_fields(Some("x=1"), &[]).unwrap_err();
        assert!(e.message.contains("no pose fields"), "{}", e.message);
    }
}

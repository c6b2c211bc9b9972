//! `GET /images/{id}/thumbnail`: a small JPEG of map image `id`, read from
//! the configured image folder (`files.images`) under the name the map
//! records for that id. Only a map id selects the file, never a path from
//! the request, and the resolved file must lie inside the folder; anything
//! else is 404. Thumbnails are made on the worker pool and the most recent
//! ones kept in memory.

use super::AppState;
use super::errors::{ApiError, ErrorBody};
use super::openapi::Binary;
use crate::index::MapRead;
use axum::body::Bytes;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::num::NonZeroUsize;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use utoipa::IntoParams;

/// Thumbnails kept in memory (the least recently used go first).
const CACHED: usize = 256;
/// Longer side of a thumbnail when the request gives none.
pub const DEFAULT_SIZE: u32 = 160;
/// Largest `size`: the extraction's default frame, so a map image fetched
/// at this size is what SIFT saw of it.
pub const MAX_SIZE: u32 = 640;
/// Smallest `size`.
pub const MIN_SIZE: u32 = 16;

/// The most recently used thumbnails, by (map file fingerprint, image id, size).
pub struct ThumbnailCache(Mutex<lru::LruCache<(u64, u32, u32), Bytes>>);

impl Default for ThumbnailCache {
    fn default() -> Self {
        Self(Mutex::new(lru::LruCache::new(
            NonZeroUsize::new(CACHED).expect("non-zero"),
        )))
    }
}

impl ThumbnailCache {
    fn get(&self, key: &(u64, u32, u32)) -> Option<Bytes> {
        self.0.lock().ok()?.get(key).cloned()
    }

    fn put(&self, key: (u64, u32, u32), jpeg: Bytes) {
        if let Ok(mut cache) = self.0.lock() {
            cache.put(key, jpeg);
        }
    }
}

/// Query parameters of the thumbnail.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ThumbnailParams {
    /// Longer side in pixels, 16 to 640 (default 160); a smaller image
    /// keeps its size.
    // utoipa takes only literals here; a test holds them (and the numbers
    // above) to MIN_SIZE, MAX_SIZE and DEFAULT_SIZE
    #[param(value_type = Option<u32>, minimum = 16, maximum = 640)]
    pub size: Option<String>,
}

impl ThumbnailParams {
    fn size(query: Option<&str>) -> Result<u32, ApiError> {
        let p: Self = serde_urlencoded::from_str(query.unwrap_or(""))
            .map_err(|e| ApiError::bad_request("invalid_parameter", e.to_string()))?;
        let Some(v) = p.size else {
            return Ok(DEFAULT_SIZE);
        };
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|s| (MIN_SIZE..=MAX_SIZE).contains(s))
            .ok_or_else(|| {
                ApiError::invalid_parameter(
                    "size",
                    format!("`{v}` is not a whole number in {MIN_SIZE}..={MAX_SIZE}"),
                )
            })
    }
}

/// A map image id as the path gives it: decimal digits only (no sign, no
/// spaces, nothing path-like), within u32.
pub fn parse_id(text: &str) -> Option<u32> {
    if text.is_empty() || text.len() > 10 || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

/// The file of map image `name` inside `folder`, if it exists there: the
/// name is joined to the folder, both are resolved (symbolic links, `..`),
/// and a result outside the folder is refused.
pub fn resolve(folder: &std::path::Path, name: &str) -> Option<PathBuf> {
    if folder.as_os_str().is_empty() {
        return None;
    }
    let root = folder.canonicalize().ok()?;
    let file = root.join(name).canonicalize().ok()?;
    (file.starts_with(&root) && file.is_file()).then_some(file)
}

/// A map image as a small JPEG.
///
/// The image is the one the map records under this id (its line in the
/// map's image list, from 0), read from the configured image folder
/// (`files.images`); an id outside the map, anything but a decimal id, or a
/// file missing from the folder is 404 `not_found`.
#[utoipa::path(
    get,
    path = "/images/{id}/thumbnail",
    tag = "page",
    params(
        ("id" = u32, Path, description = "Map image id (the `id` of a `/localize` candidate)."),
        ThumbnailParams,
    ),
    responses(
        (status = 200, description = "The image as a JPEG, longer side at most `size`.",
            content((Binary = "image/jpeg"))),
        (status = 400, description = "Bad `size` or an unknown parameter (`invalid_parameter`).", body = ErrorBody),
        (status = 404, description = "No such map image, or no image folder configured, or its file is missing (`not_found`).", body = ErrorBody),
        (status = 422, description = "The map image's file cannot be made into a thumbnail (`undecodable_image`).", body = ErrorBody),
        (status = 503, description = "Map not loaded yet (`not_ready`), or all workers busy (`overloaded`, `queue_timeout`); see Retry-After.", body = ErrorBody,
            headers(("Retry-After" = u32, description = "Seconds to wait before retrying."))),
    )
)]
pub async fn thumbnail(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
) -> Result<Response, ApiError> {
    let deadline = Instant::now() + state.config.deadline();
    let size = ThumbnailParams::size(query.as_deref())?;
    let localizer = state.localizer()?;
    let missing = || ApiError::not_found_because(format!("no map image `{id}`"));
    let snapshot = localizer.map.snapshot();
    let id = parse_id(&id)
        .filter(|&i| snapshot.contains(i))
        .ok_or_else(missing)?;
    // ids are the map file's until a compaction renumbers them, and a
    // compaction writes a new file: its fingerprint keeps ids apart
    let key = (snapshot.base().fingerprint(), id, size);
    if let Some(jpeg) = state.thumbnails.get(&key) {
        return Ok(jpeg_response(jpeg));
    }
    let name = snapshot.image(id).name.to_owned();
    let file = resolve(&state.config.files.images, &name).ok_or_else(|| {
        ApiError::not_found_because(format!("map image {id} has no file in the image folder"))
    })?;
    let limits = localizer.limits;
    let jpeg = state
        .on_worker(deadline, "thumbnail", move || {
            let bytes = std::fs::read(&file).map_err(|_| {
                ApiError::not_found_because(format!("map image {id} cannot be read"))
            })?;
            crate::features::thumbnail(&bytes, size, limits)
                .map_err(|e| ApiError::undecodable(format!("map image {id}: {e}")))
        })
        .await?;
    let jpeg = Bytes::from(jpeg);
    state.thumbnails.put(key, jpeg.clone());
    Ok(jpeg_response(jpeg))
}

fn jpeg_response(jpeg: Bytes) -> Response {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("image/jpeg")),
            (
                header::CACHE_CONTROL,
                HeaderValue::from_static("private, max-age=300"),
            ),
        ],
        jpeg,
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_plain_decimal_numbers() {
        assert_eq!(parse_id("0"), Some(0));
        assert_eq!(parse_id("199"), Some(199));
        assert_eq!(parse_id("4294967295"), Some(u32::MAX));
        for bad in [
            "",
            "-1",
            "+1",
            " 1",
            "1 ",
            "1.0",
            "4294967296",
            "99999999999",
            "..",
            "../1",
            "%2e%2e",
            "1/2",
            "0x10",
            "a",
        ] {
            assert_eq!(parse_id(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn names_cannot_leave_the_folder() {
        let root = tempfile::tempdir().unwrap();
        let inside = root.path().join("maps");
        std::fs::create_dir_all(inside.join("a")).unwrap();
        std::fs::write(inside.join("a/1.jpg"), b"x").unwrap();
        std::fs::write(root.path().join("secret.jpg"), b"x").unwrap();
        std::os::unix::fs::symlink(root.path().join("secret.jpg"), inside.join("link.jpg"))
            .unwrap();
        assert!(resolve(&inside, "a/1.jpg").is_some());
        assert!(resolve(&inside, "a/../a/1.jpg").is_some());
        for bad in [
            "../secret.jpg",
            "a/../../secret.jpg",
            "link.jpg",
            "a",
            "missing.jpg",
        ] {
            assert_eq!(resolve(&inside, bad), None, "{bad}");
        }
        let absolute = root.path().join("secret.jpg");
        assert_eq!(resolve(&inside, absolute.to_str().unwrap()), None);
        assert_eq!(resolve(std::path::Path::new(""), "a/1.jpg"), None);
    }

    #[test]
    fn sizes_are_checked() {
        assert_eq!(ThumbnailParams::size(None).unwrap(), DEFAULT_SIZE);
        assert_eq!(ThumbnailParams::size(Some("size=640")).unwrap(), 640);
        for bad in [
            "size=15", "size=641", "size=-1", "size=abc", "size=", "width=3",
        ] {
            assert_eq!(
                ThumbnailParams::size(Some(bad)).unwrap_err().status,
                400,
                "{bad}"
            );
        }
    }
}

//! `POST /localize`: the query parameters and their checks, reading the image
//! from a raw or multipart body, running the query on the worker pool with the
//! request's deadline, and answering in JSON or protobuf.

use super::AppState;
use super::errors::{ApiError, ErrorBody};
use super::openapi::Binary;
use super::proto;
use crate::features::TileGrid;
use crate::index::MapRead;
use crate::pipeline::Tracing;
use crate::report::{Localization, SequenceAnswer};
use crate::search::stop::{GENERIC_PARAMETER, OR_VERIFIED, parse_rule};
use crate::search::{Prior, RuleSpec, SearchOptions};
use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, RawQuery, Request, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;
use std::time::Instant;
use utoipa::IntoParams;

/// Query parameters of `POST /localize`. Each one absent takes the
/// configured default; unknown parameters are errors.
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct LocalizeParams {
    /// Candidates to return, 1 to the configured `limits.max_top_n`.
    #[param(value_type = Option<u32>, minimum = 1)]
    pub top_n: Option<String>,
    /// Stopping rule (see the enumeration). Without a parameter it takes the
    /// configured one if it is the configured rule.
    #[param(value_type = Option<String>)]
    pub rule: Option<String>,
    // The rule parameters (the generic one and each registry rule's) are
    // described, with their ranges, from the registry in the API document.
    #[param(value_type = Option<f64>)]
    pub threshold: Option<String>,
    #[param(value_type = Option<f64>)]
    pub delta: Option<String>,
    #[param(value_type = Option<f64>)]
    pub fraction: Option<String>,
    #[param(value_type = Option<u32>)]
    pub inliers: Option<String>,
    #[param(value_type = Option<f64>)]
    pub epsilon: Option<String>,
    /// Also stop at a tile's end (tiles left) when the answer verification
    /// would give then has at least this many inliers against the features
    /// voted so far and shows the scene at the query's scale, whichever of
    /// the rule and this check comes first (a vote rule only). Default: the
    /// configured `search.or_verified` (12) when the request uses the
    /// configured rule, none when it names another rule or gives a
    /// parameter.
    // its range, the `verified` rule's, is set from the registry in the API
    // document
    #[param(value_type = Option<u32>)]
    pub or_verified: Option<String>,
    /// Seed of the feature permutation (0 to 2^63−1, the API document's
    /// int64). Without it each request draws its own, below 2^53 so that it
    /// survives a JSON number; the answer reports the seed used.
    #[param(value_type = Option<i64>, minimum = 0)]
    pub seed: Option<String>,
    /// Drop candidates scoring below this (≥ 0).
    #[param(value_type = Option<f32>)]
    pub min_score: Option<String>,
    /// Drop candidates whose `distinct` is below this (0 to 1; after
    /// verification, if any): 0.6 answers only when the leader stands out
    /// of the map. Default: the configured `search.min_distinct`.
    #[param(value_type = Option<f32>, minimum = 0, maximum = 1)]
    pub min_distinct: Option<String>,
    /// Features voted before the rule is first consulted (the warm-up).
    /// Defaults to the configured warm-up when the request uses the configured
    /// rule, to 0 when it names another.
    #[param(value_type = Option<u32>, minimum = 0)]
    pub min_features: Option<String>,
    /// Streaming extraction's tile grid, `COLSxROWS` or `COLSxROWS+MARGIN`
    /// (`1x1`: extract the whole image first), optionally followed by
    /// `,coarse` (a half-size pass over the whole image before the tiles).
    /// Default: the configured grid.
    #[param(value_type = Option<String>, example = "2x2+24")]
    pub tiles: Option<String>,
    /// The order the tiles are extracted in: `richest` (most FAST corners
    /// first), `spread` (the richest tile, then the farthest from those
    /// taken) or `random` (drawn from the seed). Default: the configured order.
    #[param(value_type = Option<String>, example = "richest")]
    pub tile_order: Option<String>,
    /// Verify the top vote candidates geometrically and re-rank them by
    /// inliers (`true` or `false`; default from the `[verify]` section).
    /// With verification the score is an inlier count: by default the
    /// inliers of the candidate's place (its own and its checked neighbours').
    #[param(value_type = Option<bool>)]
    pub verify: Option<String>,
    /// Return the vote race in `trace` (`true`): the leader's and the
    /// runner-up's votes, the mean vote and the rule's statistic against its
    /// threshold as the features arrived (at most 256 points). `full` also
    /// extracts every tile and votes every feature without a rule, to show
    /// where the full search ends and what it answers (that extra work is
    /// not in `timings_ms`). Default `false`.
    #[param(value_type = Option<String>, pattern = "^(true|false|full)$")]
    pub trace: Option<String>,
    /// Name of the sequence this frame belongs to (1 to 128 letters, digits,
    /// `-`, `_`, `.`, `:`): the service keeps a belief over map images per
    /// sequence, and the answer's `sequence` carries the filtered candidates.
    /// Without a rule, the frame uses the configured `sequence.rule`.
    #[param(value_type = Option<String>, example = "robot-1")]
    pub sequence: Option<String>,
    /// With `sequence`: the frame's index (0 to 2^63−1). A frame not after the
    /// previous one, or more than `sequence.max_gap` after it, restarts the
    /// sequence. Default: the previous frame's + 1.
    #[param(value_type = Option<i64>, minimum = 0)]
    pub frame: Option<String>,
    /// `x,y,radius`: only map images whose pose (fields x, y) lies within
    /// the radius of (x, y) may be candidates (maps with poses).
    #[param(value_type = Option<String>, example = "12.5,-3,10")]
    pub near: Option<String>,
}

/// A pose restriction: (x, y, radius).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

impl Near {
    /// The images of `map` within the radius (read in place: no list of
    /// every image's position is made); `None` when the map has no poses
    /// with fields x and y.
    pub fn images(&self, map: &dyn MapRead) -> Option<Vec<u32>> {
        let mut within = Vec::new();
        map.each_position(&mut |j, [x, y]| {
            if ((x - self.x).powi(2) + (y - self.y).powi(2)).sqrt() <= self.radius {
                within.push(j);
            }
        })
        .then_some(within)
    }
}

/// What a request may ask for within the configuration.
#[derive(Debug, Clone)]
pub struct Defaults {
    /// Everything but the seed, which each request draws.
    pub options: SearchOptions,
    pub max_top_n: usize,
}

impl LocalizeParams {
    /// Parse a raw query string (`None`: no query).
    pub fn from_query(query: Option<&str>) -> Result<Self, ApiError> {
        serde_urlencoded::from_str(query.unwrap_or(""))
            .map_err(|e| ApiError::bad_request("invalid_parameter", e.to_string()))
    }

    /// The search these parameters ask for, on top of `defaults`.
    pub fn options(&self, defaults: &Defaults) -> Result<SearchOptions, ApiError> {
        let mut o = defaults.options.clone();
        o.rule = self.rule(&defaults.options.rule)?;
        if o.rule.name != defaults.options.rule.name {
            // the configured warm-up belongs to the configured rule
            o.min_features = 0;
        }
        if let Some(v) = &self.min_features {
            // the API document's int32
            o.min_features = whole("min_features", v, i32::MAX as u64)? as usize;
        }
        if let Some(v) = &self.top_n {
            let n: usize = v.trim().parse().map_err(|_| {
                ApiError::invalid_parameter("top_n", format!("`{v}` is not a whole number"))
            })?;
            if n == 0 || n > defaults.max_top_n {
                return Err(ApiError::invalid_parameter(
                    "top_n",
                    format!("must lie in 1..={}, got {n}", defaults.max_top_n),
                ));
            }
            o.top_n = n;
        }
        o.seed = match &self.seed {
            // the API document's int64
            Some(v) => whole("seed", v, i64::MAX as u64)?,
            None => crate::report::draw_seed(),
        };
        if let Some(v) = &self.tile_order {
            o.tile_order = v
                .trim()
                .parse()
                .map_err(|e: String| ApiError::invalid_parameter("tile_order", e))?;
        }
        if let Some(v) = &self.min_score {
            let s = number("min_score", v)?;
            if !(0.0..=f32::MAX as f64).contains(&s) {
                return Err(ApiError::invalid_parameter(
                    "min_score",
                    format!("must be a number in 0..={}, got {s}", f32::MAX),
                ));
            }
            o.min_score = s as f32;
        }
        if let Some(v) = &self.min_distinct {
            o.min_distinct = SearchOptions::check_min_distinct(number("min_distinct", v)?)
                .map_err(|e| ApiError::invalid_parameter("min_distinct", e))?;
        }
        Ok(o)
    }

    /// The tile grid asked for, if any.
    pub fn tiles(&self) -> Result<Option<TileGrid>, ApiError> {
        self.tiles
            .as_deref()
            .map(|v| {
                v.trim()
                    .parse()
                    .map_err(|e: String| ApiError::invalid_parameter("tiles", e))
            })
            .transpose()
    }

    /// The sequence named, checked.
    pub fn sequence(&self) -> Result<Option<&str>, ApiError> {
        let name = self.sequence.as_deref();
        if name.is_none() && self.frame.is_some() {
            return Err(ApiError::invalid_parameter(
                "frame",
                "a frame index needs a sequence",
            ));
        }
        name.map(|n| {
            super::sequences::valid_name(n).map_err(|e| ApiError::invalid_parameter("sequence", e))
        })
        .transpose()
    }

    /// The frame index given, if any.
    pub fn frame(&self) -> Result<Option<u64>, ApiError> {
        self.frame
            .as_deref()
            .map(|v| whole("frame", v, i64::MAX as u64))
            .transpose()
    }

    /// The pose restriction asked for, if any.
    pub fn near(&self) -> Result<Option<Near>, ApiError> {
        let Some(v) = &self.near else { return Ok(None) };
        let parts: Vec<&str> = v.split(',').collect();
        let [x, y, r] = parts[..] else {
            return Err(ApiError::invalid_parameter(
                "near",
                format!("`{v}` is not x,y,radius"),
            ));
        };
        let (x, y, radius) = (number("near", x)?, number("near", y)?, number("near", r)?);
        if radius < 0.0 {
            return Err(ApiError::invalid_parameter(
                "near",
                format!("the radius must be ≥ 0, got {radius}"),
            ));
        }
        Ok(Some(Near { x, y, radius }))
    }

    /// The rule parameters as given, by name: [`GENERIC_PARAMETER`] and the
    /// name of each registry rule's parameter (a test holds this list to the
    /// registry, so a rule with a new parameter needs its field here).
    fn rule_parameters(&self) -> [(&'static str, &Option<String>); 5] {
        [
            (GENERIC_PARAMETER, &self.threshold),
            ("delta", &self.delta),
            ("fraction", &self.fraction),
            ("inliers", &self.inliers),
            ("epsilon", &self.epsilon),
        ]
    }

    /// Whether the request names a rule or a rule parameter.
    pub fn names_a_rule(&self) -> bool {
        self.rule.is_some() || self.rule_parameters().iter().any(|(_, v)| v.is_some())
    }

    /// Whether to verify, on top of the configured default.
    pub fn verify(&self, default: bool) -> Result<bool, ApiError> {
        match self.verify.as_deref().map(str::trim) {
            None => Ok(default),
            Some("true") => Ok(true),
            Some("false") => Ok(false),
            Some(v) => Err(ApiError::invalid_parameter(
                "verify",
                format!("`{v}` is not `true` or `false`"),
            )),
        }
    }

    /// What to record of the vote race.
    pub fn tracing(&self) -> Result<Tracing, ApiError> {
        match self.trace.as_deref().map(str::trim) {
            None | Some("false") => Ok(Tracing::Off),
            Some("true") => Ok(Tracing::On),
            Some("full") => Ok(Tracing::Full),
            Some(v) => Err(ApiError::invalid_parameter(
                "trace",
                format!("`{v}` is not `true`, `false` or `full`"),
            )),
        }
    }

    /// The rule and its parameter, through the registry's one parser.
    fn rule(&self, default: &RuleSpec) -> Result<RuleSpec, ApiError> {
        let mut given = Vec::new();
        for (name, value) in self.rule_parameters() {
            if let Some(v) = value {
                given.push((name, number(name, v)?));
            }
        }
        let name = self.rule.as_deref().unwrap_or(&default.name);
        let rule = if given.is_empty() && name == default.name {
            default.clone()
        } else {
            parse_rule(name, &given).map_err(|e| match e.parameter {
                None => ApiError::bad_request("unknown_rule", e.message),
                Some(p) => ApiError::invalid_parameter(&p, e.message),
            })?
        };
        let inliers = self
            .or_verified
            .as_deref()
            .map(|v| number(OR_VERIFIED, v))
            .transpose()?;
        if inliers == Some(0.0) {
            // 0 turns a configured check off in the configuration and the
            // CLI; here naming the rule and its parameter does
            return Err(ApiError::invalid_parameter(
                OR_VERIFIED,
                "must be at least 4; a request that names the rule and its parameter \
                 runs without the configured check",
            ));
        }
        rule.or_verified(inliers)
            .map_err(|e| ApiError::invalid_parameter(OR_VERIFIED, e))
    }
}

/// A whole number in `0..=max`.
fn whole(name: &str, v: &str, max: u64) -> Result<u64, ApiError> {
    v.trim()
        .parse::<u64>()
        .ok()
        .filter(|&n| n <= max)
        .ok_or_else(|| {
            ApiError::invalid_parameter(name, format!("`{v}` is not a whole number in 0..={max}"))
        })
}

/// A finite number.
fn number(name: &str, v: &str) -> Result<f64, ApiError> {
    let x: f64 = v
        .trim()
        .parse()
        .map_err(|_| ApiError::invalid_parameter(name, format!("`{v}` is not a number")))?;
    if !x.is_finite() {
        return Err(ApiError::invalid_parameter(
            name,
            format!("must be a finite number, got `{v}`"),
        ));
    }
    Ok(x)
}

/// How the answer is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Json,
    Protobuf,
}

impl Format {
    /// Protobuf when `Accept` lists `application/x-protobuf` (or
    /// `application/protobuf`) with a non-zero quality; JSON otherwise.
    pub fn from_accept(headers: &HeaderMap) -> Self {
        let wants_protobuf = headers
            .get_all(header::ACCEPT)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .any(|item| {
                let mut parts = item.split(';').map(str::trim);
                let media = parts.next().unwrap_or("").to_ascii_lowercase();
                let refused = parts.any(|p| {
                    p.strip_prefix("q=")
                        .and_then(|q| q.trim().parse::<f32>().ok())
                        .is_some_and(|q| q <= 0.0)
                });
                (media == proto::CONTENT_TYPE || media == "application/protobuf") && !refused
            });
        if wants_protobuf {
            Self::Protobuf
        } else {
            Self::Json
        }
    }
}

/// How the image arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BodyKind {
    Raw,
    Multipart,
}

/// Check the content type before reading anything.
fn body_kind(headers: &HeaderMap) -> Result<BodyKind, ApiError> {
    let expected = "send the image as the body with Content-Type image/* or \
                    application/octet-stream, or as multipart/form-data with a field `image`";
    let Some(value) = headers.get(header::CONTENT_TYPE) else {
        return Err(ApiError::unsupported_media_type(format!(
            "no Content-Type; {expected}"
        )));
    };
    let text = value.to_str().unwrap_or("");
    let media = text
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    match media.as_str() {
        "multipart/form-data" => Ok(BodyKind::Multipart),
        "application/octet-stream" => Ok(BodyKind::Raw),
        m if m.starts_with("image/") => Ok(BodyKind::Raw),
        _ => Err(ApiError::unsupported_media_type(format!(
            "Content-Type `{text}` is not accepted; {expected}"
        ))),
    }
}

/// Whether a body error was caused by a `T` (the size limit, a timeout).
fn caused_by<T: std::error::Error + 'static>(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if c.is::<T>() {
            return true;
        }
        cause = c.source();
    }
    false
}

/// The answer to a body that could not be read whole.
fn body_error(
    e: &(dyn std::error::Error + 'static),
    limit: usize,
    otherwise: ApiError,
) -> ApiError {
    if caused_by::<http_body_util::LengthLimitError>(e) {
        ApiError::body_too_large(limit)
    } else if caused_by::<tower_http::timeout::TimeoutError>(e) {
        ApiError::body_timeout()
    } else {
        otherwise
    }
}

/// The request's image, arrived before `deadline` (a body still arriving
/// then is not waited for) and probed — format and pixel count from its
/// header — before it takes a worker.
pub(super) async fn receive_image(
    state: &AppState,
    request: Request,
    deadline: Instant,
    limits: crate::features::DecodeLimits,
) -> Result<Bytes, ApiError> {
    let image = tokio::time::timeout_at(deadline.into(), read_image(state, request))
        .await
        .map_err(|_| ApiError::request_timeout())??;
    crate::features::probe(&image, limits)?;
    Ok(image)
}

/// The image bytes of the request.
async fn read_image(state: &AppState, request: Request) -> Result<Bytes, ApiError> {
    let limit = state.config.limits.body_bytes;
    let kind = body_kind(request.headers())?;
    let declared = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(ApiError::body_too_large(limit));
    }
    match kind {
        BodyKind::Raw => axum::body::to_bytes(request.into_body(), limit)
            .await
            .map_err(|e| {
                let e = e.into_inner();
                let message = format!("cannot read the body: {e}");
                body_error(
                    e.as_ref(),
                    limit,
                    ApiError::bad_request("body_read_error", message),
                )
            }),
        BodyKind::Multipart => {
            // The body limit applies through the router's DefaultBodyLimit.
            let mut multipart = Multipart::from_request(request, &())
                .await
                .map_err(|e| ApiError::bad_request("invalid_multipart", e.body_text()))?;
            let multipart_error = |e: axum::extract::multipart::MultipartError| {
                if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
                    ApiError::body_too_large(limit)
                } else {
                    let otherwise = ApiError::bad_request("invalid_multipart", e.body_text());
                    body_error(&e, limit, otherwise)
                }
            };
            let mut image = None;
            while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
                if field.name() != Some("image") {
                    continue;
                }
                if image.is_some() {
                    return Err(ApiError::bad_request(
                        "invalid_multipart",
                        "the multipart body has more than one field named `image`",
                    ));
                }
                image = Some(field.bytes().await.map_err(multipart_error)?);
            }
            image.ok_or_else(|| {
                ApiError::bad_request(
                    "missing_image_field",
                    "the multipart body has no field named `image`",
                )
            })
        }
    }
}

/// What the request log line reports about a localization.
#[derive(Debug, Clone, Copy)]
pub struct LocalizeSummary {
    pub features: usize,
    pub fraction: f64,
    pub candidates: usize,
}

/// Localize an image.
///
/// The body is the image itself (`Content-Type: image/*` or
/// `application/octet-stream`) or `multipart/form-data` with a field `image`.
/// An image in which no features are found is answered 200 with no
/// candidates, `features.total` 0 and stop kind `exhausted`. When the
/// request's deadline passes during the search, the answer so far is sent
/// with stop kind `deadline`. Errors are always JSON.
#[utoipa::path(
    post,
    path = "/localize",
    tag = "localize",
    params(LocalizeParams),
    request_body(
        description = "The query image (JPEG, PNG, BMP, TIFF, WebP, PNM), raw or as multipart field `image`.",
        content(
            (Binary = "image/jpeg"),
            (Binary = "image/png"),
            (Binary = "application/octet-stream"),
            (ImageUpload = "multipart/form-data"),
        ),
    ),
    responses(
        (status = 200, description = "Candidates best first, with features used, stop and timings.",
            content(
                (Localization = "application/json"),
                (Binary = "application/x-protobuf"),
            )),
        (status = 400, description = "Bad parameter (`invalid_parameter`, `unknown_rule`), empty body (`empty_body`), bad multipart (`invalid_multipart`, also for two fields `image`; `missing_image_field`).", body = ErrorBody),
        (status = 413, description = "Body over `limits.body_bytes` (`body_too_large`).", body = ErrorBody),
        (status = 415, description = "Content type not accepted (`unsupported_media_type`), or an image format other than JPEG, PNG, BMP, TIFF, WebP and PNM, e.g. GIF (`unsupported_image_format`).", body = ErrorBody),
        (status = 422, description = "Not a decodable image (`undecodable_image`), more pixels than `limits.pixels` (`image_too_large`), extraction failed (`extraction_failed`).", body = ErrorBody),
        (status = 408, description = "The body was still arriving at the request's deadline (`request_timeout`), or stopped arriving for `server.body_timeout_ms` (`body_timeout`).", body = ErrorBody),
        (status = 431, description = "More header fields than `limits.headers`, or more header bytes than `limits.header_bytes` (`headers_too_large`).", body = ErrorBody),
        (status = 503, description = "Map not loaded yet (`not_ready`), all workers busy and queue full (`overloaded`), no worker free before the deadline (`queue_timeout`), or the deadline passed before the search voted a feature (`deadline_exceeded`); see Retry-After.", body = ErrorBody,
            headers(("Retry-After" = u32, description = "Seconds to wait before retrying."))),
    )
)]
pub async fn localize(
    State(state): State<Arc<AppState>>,
    RawQuery(query): RawQuery,
    request: Request,
) -> Result<Response, ApiError> {
    let arrived = Instant::now();
    let deadline = arrived + state.config.deadline();
    let localizer = state.localizer()?;
    let format = Format::from_accept(request.headers());
    let params = LocalizeParams::from_query(query.as_deref())?;
    let sequence = params.sequence()?;
    let frame = params.frame()?;
    let near = params.near()?;
    let snapshot = localizer.map.snapshot();
    let mut defaults = std::borrow::Cow::Borrowed(&state.defaults);
    if sequence.is_some() && !params.names_a_rule() {
        // a frame of a sequence stops by the sequence's rule
        let q = &state.config.sequence;
        let d = defaults.to_mut();
        d.options.rule = q
            .rule()
            .map_err(|e| ApiError::internal(format!("sequence.rule: {e}")))?;
        d.options.min_features = q.min_features.resolve(snapshot.auto_warmup());
    }
    let mut options = params.options(&defaults)?;
    let asked = params.tiles()?;
    let tiles = localizer.grid_for(&options.rule, asked);
    let rule = options.rule.clone();
    let verify = params.verify(state.config.verify.enabled)?;
    let tracing = params.tracing()?;
    options.deadline = Some(deadline);
    let model = state.config.sequence.model();
    let allowed = match near {
        Some(n) => Some(n.images(&*snapshot).ok_or_else(|| {
            ApiError::invalid_parameter("near", "the map has no poses with fields x and y")
        })?),
        None => None,
    };
    let images = snapshot.id_range();
    if sequence.is_none() {
        // a single query's prior: the images near= allows, else — for the
        // `posterior` rule — uniform, weighing votes at the configured κ
        options.prior = match &allowed {
            Some(ids) => Some(Arc::new(Prior::only(
                images,
                ids.iter().copied(),
                model.kappa,
            ))),
            None if options.rule.name == "posterior" => Some(Arc::new(model.uniform_prior(images))),
            None => None,
        };
    }
    let image = receive_image(&state, request, deadline, localizer.limits).await?;
    // A frame of a sequence holds its sequence's lock from prediction to
    // update, so frames of one sequence apply one at a time.
    let mut held = None;
    if let Some(name) = sequence {
        let topology = state.topology()?;
        let slot = state.sequences.slot(name);
        let mut filter = tokio::time::timeout_at(deadline.into(), slot.lock_owned())
            .await
            .map_err(|_| ApiError::queue_timeout())?;
        let prediction = filter.predict(&model, topology, frame);
        let prior = match &allowed {
            Some(ids) => Prior::new(
                images,
                ids.iter().map(|&j| (j, prediction.prior.of(j))).collect(),
                0.0,
                model.kappa,
            )
            .keeping(model.track)
            .with_window(prediction.prior.window),
            None => prediction.prior.clone(),
        };
        options.prior = Some(Arc::new(prior));
        held = Some((name, filter, prediction));
    }
    let top_n = options.top_n;
    let worker_localizer = localizer.clone();
    let answer = state
        .on_worker(deadline, "localization", move || {
            if Instant::now() >= deadline {
                return Err(ApiError::deadline_exceeded()); // no work for a lost cause
            }
            Ok(worker_localizer.localize_traced(&image, &options, tiles, verify, tracing)?)
        })
        .await?;
    if answer.stop.kind == crate::search::StopKind::Deadline && answer.features.used == 0 {
        return Err(ApiError::deadline_exceeded()); // the deadline passed before any vote
    }
    localizer.learn(&rule, asked, &answer);
    if let Some(choice) = &localizer.coarse_choice {
        super::metrics::coarse_choice(choice);
    }
    let mut answer = answer;
    if let Some((name, mut filter, prediction)) = held
        && let Some(posterior) = answer.posterior.take()
    {
        if let Some(r) = prediction.restart {
            super::metrics::sequence_restarted(r.as_str());
        }
        filter.update(posterior, &prediction);
        let belief = filter.belief().expect("just updated");
        answer.sequence = Some(SequenceAnswer::new(
            &*snapshot,
            name,
            &prediction,
            filter.frames(),
            belief,
            top_n,
        ));
    }
    super::metrics::localized(&answer);
    let summary = LocalizeSummary {
        features: answer.features.total,
        fraction: answer.features.fraction,
        candidates: answer.candidates.len(),
    };
    let mut response = encode(&answer, format);
    response.extensions_mut().insert(summary);
    Ok(response)
}

fn encode(answer: &Localization, format: Format) -> Response {
    match format {
        Format::Json => Json(answer).into_response(),
        Format::Protobuf => (
            [(
                header::CONTENT_TYPE,
                HeaderValue::from_static(proto::CONTENT_TYPE),
            )],
            proto::encode(answer),
        )
            .into_response(),
    }
}

/// Forget a sequence: its next frame starts it afresh.
#[utoipa::path(
    delete,
    path = "/sequences/{name}",
    tag = "localize",
    params(("name" = String, Path, description = "The sequence's name.")),
    responses(
        (status = 204, description = "The sequence was forgotten."),
        (status = 400, description = "Not a sequence name (`invalid_parameter`).", body = ErrorBody),
        (status = 404, description = "No such sequence is live (`unknown_sequence`).", body = ErrorBody),
    )
)]
pub async fn delete_sequence(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(name): axum::extract::Path<String>,
) -> Result<axum::http::StatusCode, ApiError> {
    let name =
        super::sequences::valid_name(&name).map_err(|e| ApiError::invalid_parameter("name", e))?;
    if state.sequences.remove(name) {
        Ok(axum::http::StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(
            axum::http::StatusCode::NOT_FOUND,
            "unknown_sequence",
            format!("no sequence `{name}` is live"),
        ))
    }
}

/// The multipart form of the request body (OpenAPI only).
#[derive(utoipa::ToSchema)]
#[allow(dead_code)]
pub struct ImageUpload {
    /// The image file.
    #[schema(value_type = String, format = Binary)]
    image: Vec<u8>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defaults() -> Defaults {
        Defaults {
            options: SearchOptions {
                rule: RuleSpec::new("peak-mean", Some(0.5)).unwrap(),
                ..Default::default()
            },
            max_top_n: 50,
        }
    }

    fn parse(q: &str) -> Result<SearchOptions, ApiError> {
        LocalizeParams::from_query(Some(q))?.options(&defaults())
    }

    fn code(q: &str) -> (&'static str, String) {
        let e = parse(q).unwrap_err();
        assert_eq!(e.status, 400, "{q}");
        (e.code, e.message)
    }

    #[test]
    fn near_reads_the_map_positions_added_images_included() {
        let s = crate::live::tests::posed_snapshot();
        let near = |x, y, radius| Near { x, y, radius }.images(&s).unwrap();
        assert_eq!(near(6.0, 7.0, 1.5), [2, 3]);
        assert_eq!(near(7.0, 8.0, 0.0), [3]);
        assert_eq!(near(1.0, 2.0, 0.5), [0]);
        assert!(near(100.0, 0.0, 1.0).is_empty());
        let unposed = crate::live::Snapshot::new(s.base().clone());
        let none = crate::index::MapBuilder::new(4).build("t", "v", None);
        assert!(
            Near {
                x: 0.0,
                y: 0.0,
                radius: 1.0
            }
            .images(&none)
            .is_none()
        );
        assert!(
            Near {
                x: 0.0,
                y: 0.0,
                radius: 1.0
            }
            .images(&unposed)
            .is_some()
        );
    }

    #[test]
    fn rule_parameters_are_the_registry_parameters() {
        use crate::search::stop::RULES;
        use std::collections::BTreeSet;
        let mut registry: BTreeSet<&str> = RULES
            .iter()
            .filter_map(|r| r.parameter.map(|p| p.name))
            .collect();
        registry.insert(GENERIC_PARAMETER);
        let listed: BTreeSet<&str> = LocalizeParams::default()
            .rule_parameters()
            .iter()
            .map(|(name, _)| *name)
            .collect();
        assert_eq!(listed, registry);
        // each name is the query parameter that fills its field
        for name in registry {
            let p = LocalizeParams::from_query(Some(&format!("{name}=0.5"))).unwrap();
            let given: Vec<&str> = p
                .rule_parameters()
                .iter()
                .filter(|(_, v)| v.is_some())
                .map(|(n, _)| *n)
                .collect();
            assert_eq!(given, [name]);
            assert!(p.names_a_rule(), "{name}");
        }
    }

    #[test]
    fn defaults_apply_when_absent() {
        let o = LocalizeParams::from_query(None)
            .unwrap()
            .options(&defaults())
            .unwrap();
        assert_eq!(o.rule, defaults().options.rule);
        assert_eq!(o.top_n, defaults().options.top_n);
        // The configured rule without a parameter keeps the configured one.
        assert_eq!(parse("rule=peak-mean").unwrap().rule.parameter, 0.5);
    }

    #[test]
    fn parameters_are_taken() {
        let o = parse("top_n=3&rule=hoeffding&delta=0.1&seed=42&min_score=0.2&min_distinct=0.6")
            .unwrap();
        assert_eq!(o.min_distinct, 0.6);
        assert_eq!(o.top_n, 3);
        assert_eq!(o.rule, RuleSpec::new("hoeffding", Some(0.1)).unwrap());
        assert_eq!(o.seed, 42);
        assert_eq!(o.min_score, 0.2);
        assert_eq!(
            parse("rule=hoeffding&threshold=0.1")
                .unwrap()
                .rule
                .parameter,
            0.1
        );
        assert_eq!(
            parse("rule=fixed&fraction=0.5").unwrap().rule.parameter,
            0.5
        );
        assert_eq!(parse("threshold=2").unwrap().rule.parameter, 2.0);
        assert_eq!(parse("rule=none").unwrap().rule.name, "none");
        assert_eq!(
            parse(&format!("seed={}", i64::MAX)).unwrap().seed,
            i64::MAX as u64
        );
    }

    #[test]
    fn bad_parameters_are_400_with_a_code() {
        let cases = [
            ("rule=fastest", "unknown_rule", "fastest"),
            ("top_n=0", "invalid_parameter", "top_n"),
            ("top_n=51", "invalid_parameter", "top_n"),
            (
                "top_n=99999999999999999999999",
                "invalid_parameter",
                "top_n",
            ),
            ("top_n=-1", "invalid_parameter", "top_n"),
            ("threshold=NaN", "invalid_parameter", "threshold"),
            ("threshold=inf", "invalid_parameter", "threshold"),
            ("threshold=-1", "invalid_parameter", "threshold"),
            ("threshold=abc", "invalid_parameter", "threshold"),
            ("threshold=", "invalid_parameter", "threshold"),
            ("seed=abc", "invalid_parameter", "seed"),
            ("seed=-3", "invalid_parameter", "seed"),
            ("seed=1.5", "invalid_parameter", "seed"),
            ("seed=9223372036854775808", "invalid_parameter", "seed"),
            ("min_score=-0.1", "invalid_parameter", "min_score"),
            ("min_score=1e39", "invalid_parameter", "min_score"),
            ("min_distinct=1.5", "invalid_parameter", "min_distinct"),
            ("min_distinct=-0.1", "invalid_parameter", "min_distinct"),
            ("min_distinct=NaN", "invalid_parameter", "min_distinct"),
            (
                "min_features=2147483648",
                "invalid_parameter",
                "min_features",
            ),
            ("rule=relative", "invalid_parameter", "needs its threshold"),
            (
                "rule=none&threshold=1",
                "invalid_parameter",
                "takes no parameter",
            ),
            ("rule=peak-mean&delta=0.1", "invalid_parameter", "delta"),
            (
                "rule=hoeffding&fraction=0.1",
                "invalid_parameter",
                "fraction",
            ),
            ("rule=hoeffding&delta=1.5", "invalid_parameter", "delta"),
            (
                "rule=stable-peak&threshold=2.5",
                "invalid_parameter",
                "whole number",
            ),
            (
                "threshold=1&delta=0.1",
                "invalid_parameter",
                "give one parameter",
            ),
            ("top_k=3", "invalid_parameter", "top_k"),
            ("top_n=1&top_n=2", "invalid_parameter", "top_n"),
        ];
        for (q, expected_code, mentions) in cases {
            let (c, m) = code(q);
            assert_eq!(c, expected_code, "{q}: {m}");
            assert!(m.contains(mentions), "{q}: {m}");
        }
    }

    #[test]
    fn verify_defaults_to_the_configuration() {
        let p = |q: &str| LocalizeParams::from_query(Some(q)).unwrap();
        assert!(p("").verify(true).unwrap());
        assert!(!p("").verify(false).unwrap());
        assert!(p("verify=true").verify(false).unwrap());
        assert!(!p("verify=false").verify(true).unwrap());
        assert_eq!(p("verify=1").verify(true).unwrap_err().status, 400);
    }

    #[test]
    fn trace_is_off_unless_asked() {
        let p = |q: &str| LocalizeParams::from_query(Some(q)).unwrap().tracing();
        assert_eq!(p("").unwrap(), Tracing::Off);
        assert_eq!(p("trace=false").unwrap(), Tracing::Off);
        assert_eq!(p("trace=true").unwrap(), Tracing::On);
        assert_eq!(p("trace=full").unwrap(), Tracing::Full);
        for bad in ["trace=1", "trace=", "trace=yes"] {
            assert_eq!(p(bad).unwrap_err().status, 400, "{bad}");
        }
    }

    #[test]
    fn seeds_are_drawn_when_absent() {
        let seeds: std::collections::HashSet<u64> =
            (0..1000).map(|_| parse("").unwrap().seed).collect();
        assert!(seeds.len() > 1);
        // JSON-safe: a u64 drawn at random would be above 2^53 but for 1 in 2048
        assert!(seeds.iter().all(|&s| s <= crate::report::MAX_DRAWN_SEED));
    }

    #[test]
    fn accept_chooses_the_format() {
        let with = |v: &str| {
            let mut h = HeaderMap::new();
            h.insert(header::ACCEPT, v.parse().unwrap());
            Format::from_accept(&h)
        };
        assert_eq!(Format::from_accept(&HeaderMap::new()), Format::Json);
        assert_eq!(with("application/json"), Format::Json);
        assert_eq!(with("*/*"), Format::Json);
        assert_eq!(with("application/x-protobuf"), Format::Protobuf);
        assert_eq!(
            with("application/json;q=0.5, application/x-protobuf"),
            Format::Protobuf
        );
        assert_eq!(with("application/x-protobuf;q=0"), Format::Json);
    }

    #[test]
    fn content_types() {
        let with = |v: &str| {
            let mut h = HeaderMap::new();
            h.insert(header::CONTENT_TYPE, v.parse().unwrap());
            body_kind(&h).map_err(|e| e.code)
        };
        assert_eq!(with("image/jpeg"), Ok(BodyKind::Raw));
        assert_eq!(with("IMAGE/PNG"), Ok(BodyKind::Raw));
        assert_eq!(with("application/octet-stream"), Ok(BodyKind::Raw));
        assert_eq!(
            with("multipart/form-data; boundary=x"),
            Ok(BodyKind::Multipart)
        );
        assert_eq!(with("text/plain"), Err("unsupported_media_type"));
        assert_eq!(
            with("application/x-www-form-urlencoded"),
            Err("unsupported_media_type")
        );
        assert_eq!(
            body_kind(&HeaderMap::new()).map_err(|e| e.code),
            Err("unsupported_media_type")
        );
    }
}

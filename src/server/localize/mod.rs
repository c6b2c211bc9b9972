//! `POST /localize` and `DELETE /sequences/{name}`: the request's
//! parameters (`params`) and image ([`super::body`]) in, the query run on
//! the worker pool within the request's deadline, the answer out in JSON or
//! protobuf as `Accept` asks.

mod params;

pub use params::{Defaults, LocalizeParams, Near};

use super::AppState;
use super::body::{ImageUpload, image_body_description, receive_image, unsupported_description};
use super::errors::{ApiError, ErrorBody};
use super::openapi::Binary;
use super::proto;
use crate::index::MapRead;
use crate::report::{Localization, SequenceAnswer};
use crate::search::{Prior, RuleSpec};
use crate::sequence::{Filter, Prediction, SequenceModel};
use axum::Json;
use axum::extract::{RawQuery, Request, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::time::Instant;

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
        description = image_body_description("The query image"),
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
        (status = 415, description = unsupported_description(), body = ErrorBody),
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
    let plan = localizer.plan(&options, asked);
    let verify = params.verify(state.config.verify.enabled)?;
    let tracing = params.tracing()?;
    options.deadline = Some(deadline);
    let pool = state.pool.clone();
    options.spare_core = state.config.spare_core(move || pool.admitted());
    let model = state.config.sequence.model();
    let allowed = match near {
        Some(n) => Some(n.images(&*snapshot).ok_or_else(|| {
            ApiError::invalid_parameter("near", "the map has no poses with fields x and y")
        })?),
        None => None,
    };
    let images = snapshot.id_range();
    if sequence.is_none() {
        options.prior = single_prior(allowed.as_deref(), images, &options.rule, &model);
    }
    let image = receive_image(&state, request, deadline, localizer.limits).await?;
    let mut held = None;
    if let Some(name) = sequence {
        let frame = HeldFrame::start(&state, name, frame, &model, deadline).await?;
        options.prior = Some(Arc::new(frame.prior(allowed.as_deref(), images, &model)));
        held = Some(frame);
    }
    let top_n = options.top_n;
    let worker_localizer = localizer.clone();
    let answer = state
        .on_worker(deadline, "localization", move || {
            if Instant::now() >= deadline {
                return Err(ApiError::deadline_exceeded()); // no work for a lost cause
            }
            Ok(worker_localizer.localize_traced(&image, &options, plan.grid, verify, tracing)?)
        })
        .await?;
    if answer.stop.kind == crate::search::StopKind::Deadline && answer.features.used == 0 {
        return Err(ApiError::deadline_exceeded()); // the deadline passed before any vote
    }
    localizer.learn(plan, &answer);
    if let Some(choice) = &localizer.coarse_choice {
        super::metrics::coarse_choice(choice, &plan);
    }
    super::metrics::tile_cost(localizer.tile_cost());
    let mut answer = answer;
    if let Some(frame) = held {
        frame.finish(&mut answer, &*snapshot, top_n);
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

/// A single query's prior: the images `near=` allows, else — for the
/// `posterior` rule — uniform, weighing votes at the configured κ; none
/// otherwise.
fn single_prior(
    allowed: Option<&[u32]>,
    images: usize,
    rule: &RuleSpec,
    model: &SequenceModel,
) -> Option<Arc<Prior>> {
    match allowed {
        Some(ids) => Some(Arc::new(Prior::only(
            images,
            ids.iter().copied(),
            model.kappa,
        ))),
        None if rule.name == "posterior" => Some(Arc::new(model.uniform_prior(images))),
        None => None,
    }
}

/// A frame of a sequence between prediction and update. It holds its
/// sequence's lock all that time, so frames of one sequence apply one at a
/// time.
struct HeldFrame<'a> {
    name: &'a str,
    filter: tokio::sync::OwnedMutexGuard<Filter>,
    prediction: Prediction,
}

impl<'a> HeldFrame<'a> {
    /// Lock the sequence `name` (made if new) before `deadline` and predict
    /// frame `frame` from its belief.
    async fn start(
        state: &AppState,
        name: &'a str,
        frame: Option<u64>,
        model: &SequenceModel,
        deadline: Instant,
    ) -> Result<Self, ApiError> {
        let topology = state.topology()?;
        let slot = state.sequences.slot(name);
        let mut filter = tokio::time::timeout_at(deadline.into(), slot.lock_owned())
            .await
            .map_err(|_| ApiError::queue_timeout())?;
        let prediction = filter.predict(model, topology, frame);
        Ok(Self {
            name,
            filter,
            prediction,
        })
    }

    /// The frame's prior: the prediction, kept to the images `near=`
    /// allows when it names some.
    fn prior(&self, allowed: Option<&[u32]>, images: usize, model: &SequenceModel) -> Prior {
        let predicted = &self.prediction.prior;
        match allowed {
            Some(ids) => Prior::new(
                images,
                ids.iter().map(|&j| (j, predicted.of(j))).collect(),
                0.0,
                model.kappa,
            )
            .keeping(model.track)
            .with_window(predicted.window),
            None => predicted.clone(),
        }
    }

    /// Update the sequence with the answer's posterior (when the search
    /// left one) and report the sequence's belief in the answer.
    fn finish(mut self, answer: &mut Localization, map: &dyn MapRead, top_n: usize) {
        let Some(posterior) = answer.posterior.take() else {
            return;
        };
        if let Some(r) = self.prediction.restart {
            super::metrics::sequence_restarted(r.as_str());
        }
        self.filter.update(posterior, &self.prediction);
        let belief = self.filter.belief().expect("just updated");
        answer.sequence = Some(SequenceAnswer::new(
            map,
            self.name,
            &self.prediction,
            self.filter.frames(),
            belief,
            top_n,
        ));
    }
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

#[cfg(test)]
mod tests {
    use super::*;

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
}

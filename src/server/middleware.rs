//! What wraps every request: the request id (`x-request-id` taken from the
//! client or generated, and echoed back), one log line per request with its
//! id, route, status, latency and fraction of features used, the per-route
//! request metrics, the header limits (a JSON 431), and turning a panic in a
//! handler into a JSON 500. A handler finds its request's id with
//! [`request_id`].

use super::errors::ApiError;
use super::localize::LocalizeSummary;
use super::metrics;
use super::workers::panic_message;
use axum::extract::{MatchedPath, Request, State};
use axum::http::HeaderName;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::time::{Duration, Instant};
use tracing::Instrument;

pub const REQUEST_ID: HeaderName = HeaderName::from_static("x-request-id");

tokio::task_local! {
    /// The id of the request the task is answering.
    static CURRENT_ID: String;
}

/// The id of the request this task is answering, if it is one.
pub fn request_id() -> Option<String> {
    CURRENT_ID.try_with(String::clone).ok()
}

/// Log and count one request.
pub async fn observe(request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched", |m| m.as_str())
        .to_owned();
    let method = request.method().clone();
    let id = request
        .headers()
        .get(&REQUEST_ID)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    metrics::in_flight(1.0);
    let _in_flight = InFlight;
    let span = tracing::info_span!("request", id = %id);
    let response = CURRENT_ID
        .scope(id.clone(), next.run(request).instrument(span))
        .await;
    let elapsed = started.elapsed();
    let status = response.status().as_u16();
    metrics::request(&route, method.as_str(), status, elapsed);
    let latency_ms = log_ms(elapsed);
    match response.extensions().get::<LocalizeSummary>() {
        Some(s) => tracing::info!(
            request_id = %id,
            method = %method,
            route,
            status,
            latency_ms,
            fraction_used = s.fraction,
            features = s.features,
            candidates = s.candidates,
            "request"
        ),
        None => tracing::info!(
            request_id = %id,
            method = %method,
            route,
            status,
            latency_ms,
            "request"
        ),
    }
    response
}

/// Milliseconds to the microsecond, as the logs give a time (`0.037`, not
/// `0.036681000000000005`).
pub fn log_ms(d: Duration) -> f64 {
    (d.as_secs_f64() * 1e6).round() / 1e3
}

/// The most header fields, and bytes of header lines, a request may have.
#[derive(Debug, Clone, Copy)]
pub struct HeaderLimits {
    pub fields: usize,
    pub bytes: usize,
}

/// Answer 431 `headers_too_large` to a request over the header limits.
pub async fn header_limits(
    State(limits): State<HeaderLimits>,
    request: Request,
    next: Next,
) -> Response {
    let headers = request.headers();
    // each line is `name: value` and CRLF
    let bytes: usize = headers
        .iter()
        .map(|(name, value)| name.as_str().len() + value.len() + 4)
        .sum();
    if headers.len() > limits.fields {
        return ApiError::headers_too_large(format!(
            "the request has {} header fields; at most {} are accepted",
            headers.len(),
            limits.fields
        ))
        .into_response();
    }
    if bytes > limits.bytes {
        return ApiError::headers_too_large(format!(
            "the request's header fields take {bytes} bytes; at most {} are accepted",
            limits.bytes
        ))
        .into_response();
    }
    next.run(request).await
}

/// Takes the in-flight gauge down again however the request ends.
struct InFlight;

impl Drop for InFlight {
    fn drop(&mut self) {
        metrics::in_flight(-1.0);
    }
}

/// The answer to a panic in a handler.
pub fn panic_response(payload: Box<dyn std::any::Any + Send + 'static>) -> Response {
    tracing::error!("handler panicked: {}", panic_message(payload.as_ref()));
    ApiError::internal("the request failed unexpectedly").into_response()
}

#[cfg(test)]
mod tests {
    use super::log_ms;
    use std::time::Duration;

    #[test]
    fn a_logged_time_reads_to_the_microsecond() {
        assert_eq!(log_ms(Duration::from_nanos(36_681)).to_string(), "0.037");
        assert_eq!(log_ms(Duration::from_micros(77_331)).to_string(), "77.331");
    }
}

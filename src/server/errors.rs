//! Every error the service answers with: an HTTP status, a stable
//! machine-readable code and a message, sent as JSON
//! `{"error": {"code": "...", "message": "..."}}` (also for protobuf
//! clients), with `Retry-After` where waiting helps. Each error response is
//! counted by status and code, and a 503 also as a rejection. [`CODES`]
//! lists every code with its status.

use crate::features::FeatureError;
use axum::Json;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

/// The body of every error response.
#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorBody {
    pub error: ErrorDetail,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorDetail {
    /// Stable code, e.g. `invalid_parameter`, `undecodable_image`, `overloaded`.
    pub code: String,
    /// What went wrong, for people.
    pub message: String,
    /// With `not_ready`: what loading the map is doing now, e.g.
    /// `k-means: Lloyd iterations 12/40`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step: Option<String>,
}

/// Every error code the service answers with, and its status.
pub const CODES: &[(u16, &str)] = &[
    (400, "invalid_parameter"),
    (400, "unknown_rule"),
    (400, "empty_body"),
    (400, "invalid_multipart"),
    (400, "missing_image_field"),
    (400, "body_read_error"),
    (400, "invalid_id"),
    (401, "unauthorized"),
    (403, "forbidden"),
    (403, "writes_disabled"),
    (404, "not_found"),
    (404, "unknown_sequence"),
    (404, "image_not_found"),
    (405, "method_not_allowed"),
    (409, "write_conflict"),
    (408, "request_timeout"),
    (408, "body_timeout"),
    (413, "body_too_large"),
    (415, "unsupported_media_type"),
    (415, "unsupported_image_format"),
    (422, "undecodable_image"),
    (422, "image_too_large"),
    (422, "extraction_failed"),
    (431, "headers_too_large"),
    (500, "internal"),
    (503, "not_ready"),
    (503, "overloaded"),
    (503, "queue_timeout"),
    (503, "deadline_exceeded"),
    (503, "shutting_down"),
    (503, "storage_unavailable"),
    (507, "map_full"),
];

/// An error answer.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    /// Seconds for `Retry-After`.
    pub retry_after: Option<u32>,
    /// The loading step, for `not_ready`.
    pub step: Option<String>,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self {
            status,
            code,
            message: message.into(),
            retry_after: None,
            step: None,
        }
    }

    pub fn with_step(mut self, step: String) -> Self {
        self.step = Some(step);
        self
    }

    fn retry_after(mut self, seconds: u32) -> Self {
        self.retry_after = Some(seconds);
        self
    }

    pub fn bad_request(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, code, message)
    }

    /// A bad query parameter; the message starts with its name.
    pub fn invalid_parameter(name: &str, message: impl std::fmt::Display) -> Self {
        let message = message.to_string();
        let message = if message.starts_with(name) {
            message
        } else {
            format!("{name}: {message}")
        };
        Self::bad_request("invalid_parameter", message)
    }

    pub fn unsupported_media_type(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            message,
        )
    }

    pub fn body_too_large(limit: usize) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body_too_large",
            format!("the request body exceeds the limit of {limit} bytes"),
        )
    }

    pub fn undecodable(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "undecodable_image",
            message,
        )
    }

    /// No worker free and the queue full.
    pub fn overloaded(queue: usize) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "overloaded",
            format!("all workers are busy and {queue} requests are waiting; retry later"),
        )
        .retry_after(1)
    }

    /// The deadline passed before a worker was free.
    pub fn queue_timeout() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "queue_timeout",
            "no worker became free before the request's deadline; retry later",
        )
        .retry_after(1)
    }

    /// The deadline passed before the work on the request began (or before
    /// the search voted a single feature); nothing more is done.
    pub fn deadline_exceeded() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "deadline_exceeded",
            "the request's deadline passed before its search could begin; retry later",
        )
        .retry_after(1)
    }

    /// The body was still arriving when the request's deadline passed.
    pub fn request_timeout() -> Self {
        Self::new(
            StatusCode::REQUEST_TIMEOUT,
            "request_timeout",
            "the request body did not arrive before the request's deadline",
        )
    }

    /// The body stopped arriving for longer than `server.body_timeout_ms`.
    pub fn body_timeout() -> Self {
        Self::new(
            StatusCode::REQUEST_TIMEOUT,
            "body_timeout",
            "the request body stopped arriving",
        )
    }

    /// More header fields or header bytes than the limits allow.
    pub fn headers_too_large(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "headers_too_large",
            message,
        )
    }

    pub fn not_ready(message: impl Into<String>) -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, "not_ready", message).retry_after(5)
    }

    pub fn shutting_down() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "shutting_down",
            "the service is shutting down",
        )
        .retry_after(5)
    }

    /// The change log or map file cannot be written: nothing was changed.
    pub fn storage_unavailable(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "storage_unavailable",
            message,
        )
        .retry_after(5)
    }

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    pub fn not_found() -> Self {
        Self::not_found_because("no such route")
    }

    /// 404 `not_found` saying what was not found.
    pub fn not_found_because(message: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    pub fn method_not_allowed() -> Self {
        Self::new(
            StatusCode::METHOD_NOT_ALLOWED,
            "method_not_allowed",
            "this route does not answer that method",
        )
    }

    pub fn body(&self) -> ErrorBody {
        ErrorBody {
            error: ErrorDetail {
                code: self.code.to_owned(),
                message: self.message.clone(),
                step: self.step.clone(),
            },
        }
    }
}

impl From<FeatureError> for ApiError {
    fn from(e: FeatureError) -> Self {
        let message = e.to_string();
        match e {
            FeatureError::Empty => Self::bad_request("empty_body", message),
            FeatureError::Undecodable(_) => Self::undecodable(message),
            FeatureError::Unsupported(_) => Self::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_image_format",
                message,
            ),
            FeatureError::TooLarge { .. } => {
                Self::new(StatusCode::UNPROCESSABLE_ENTITY, "image_too_large", message)
            }
            // OpenCV failing on an image it decoded: a property of the input.
            FeatureError::OpenCv(_) => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "extraction_failed",
                message,
            ),
            // Queries come from memory; a file error here is the service's own.
            FeatureError::Read { .. } => Self::internal(message),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        super::metrics::error(self.status.as_u16(), self.code);
        let mut response = (self.status, Json(self.body())).into_response();
        if let Some(s) = self.retry_after {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        response
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feature_errors_map_to_client_errors() {
        let cases = [
            (FeatureError::Empty, 400, "empty_body"),
            (
                FeatureError::Undecodable("x".into()),
                422,
                "undecodable_image",
            ),
            (
                FeatureError::TooLarge {
                    width: 50_000,
                    height: 50_000,
                    limit: 10,
                },
                422,
                "image_too_large",
            ),
            (
                FeatureError::Unsupported("GIF".into()),
                415,
                "unsupported_image_format",
            ),
            (FeatureError::OpenCv("x".into()), 422, "extraction_failed"),
        ];
        for (e, status, code) in cases {
            let a = ApiError::from(e);
            assert_eq!((a.status.as_u16(), a.code), (status, code));
        }
    }

    /// The codes in docs/service.md's error table, with their statuses.
    fn documented_codes() -> Vec<(u16, String)> {
        let doc = include_str!("../../docs/service.md");
        let table = doc
            .split("Errors are always JSON")
            .nth(1)
            .expect("docs/service.md has the error table");
        let mut codes = Vec::new();
        for line in table.lines().skip_while(|l| !l.starts_with('|')) {
            let Some(row) = line.strip_prefix("| ") else {
                break;
            };
            let mut cells = row.split(" | ");
            let statuses: Vec<u16> = cells
                .next()
                .unwrap_or("")
                .split(|c: char| !c.is_ascii_digit())
                .filter_map(|s| s.parse().ok())
                .collect();
            let rest = cells.next().unwrap_or("");
            for code in rest.split('`').skip(1).step_by(2) {
                if code.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                    codes.push((statuses.clone(), code.to_owned()));
                }
            }
        }
        codes
            .into_iter()
            .map(|(statuses, code)| {
                let status = CODES
                    .iter()
                    .find(|(_, c)| *c == code)
                    .map(|(s, _)| *s)
                    .unwrap_or_else(|| panic!("documented code `{code}` is not in CODES"));
                assert!(
                    statuses.contains(&status),
                    "`{code}` is documented under {statuses:?}, answered with {status}"
                );
                (status, code)
            })
            .collect()
    }

    #[test]
    fn every_code_is_documented_with_its_status() {
        let documented = documented_codes();
        for (status, code) in CODES {
            assert!(
                documented.iter().any(|(s, c)| s == status && c == code),
                "{status} `{code}` is missing from docs/service.md's error table"
            );
        }
    }

    #[tokio::test]
    async fn response_is_json_with_code_and_retry_after() {
        let r = ApiError::overloaded(4).into_response();
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(r.headers()[header::RETRY_AFTER], "1");
        assert_eq!(r.headers()[header::CONTENT_TYPE], "application/json");
        let bytes = axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(v["error"]["code"], "overloaded");
        assert!(
            v["error"]["message"]
                .as_str()
                .unwrap()
                .contains("4 requests")
        );
    }
}

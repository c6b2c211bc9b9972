//! Every error the service answers with: an HTTP status, a stable
//! machine-readable code and a message, sent as JSON
//! `{"error": {"code": "...", "message": "..."}}` (also for protobuf
//! clients), with `Retry-After` where waiting helps. Each error response is
//! counted in the rejected-requests metric under its code.

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
}

/// An error answer.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    /// Seconds for `Retry-After`.
    pub retry_after: Option<u32>,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self {
            status,
            code,
            message: message.into(),
            retry_after: None,
        }
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

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    pub fn not_found() -> Self {
        Self::new(StatusCode::NOT_FOUND, "not_found", "no such route")
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
        super::metrics::rejected(self.code);
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

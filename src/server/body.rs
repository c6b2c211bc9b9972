//! The image of a request body: raw (`image/*`, `application/octet-stream`)
//! or the field `image` of a multipart form, read within the size limit and
//! the request's deadline and probed before it takes a worker. `/localize`
//! and `POST /images` both receive their image here.

use super::AppState;
use super::errors::ApiError;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request};
use axum::http::{HeaderMap, header};
use std::time::Instant;

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
            let mut others = OtherFields::default();
            while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
                if field.name() != Some("image") {
                    others.add(field.name().unwrap_or_default());
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
            image
                .ok_or_else(|| ApiError::bad_request("missing_image_field", others.missing_image()))
        }
    }
}

/// The fields of a multipart body other than `image`, as its error names
/// them: the first few, each cut short, and how many more (a body holds as
/// many as its size allows, and the error must stay small).
#[derive(Default)]
struct OtherFields {
    named: Vec<String>,
    more: usize,
}

impl OtherFields {
    /// Fields named in full; beyond, only counted.
    const NAMED: usize = 4;
    /// Characters of a field's name shown.
    const NAME_CHARS: usize = 40;

    fn add(&mut self, name: &str) {
        if self.named.len() < Self::NAMED {
            self.named
                .push(name.chars().take(Self::NAME_CHARS).collect());
        } else {
            self.more += 1;
        }
    }

    /// Why the body is refused: the fields it has, so that a client
    /// sending its file as `file` sees what to rename.
    fn missing_image(&self) -> String {
        let names: Vec<String> = self.named.iter().map(|n| format!("`{n}`")).collect();
        let mut has = match &names[..] {
            [] => "no fields".to_owned(),
            [one] => format!("only the field {one}"),
            many => format!("the fields {}", many.join(", ")),
        };
        if self.more > 0 {
            has += &format!(" and {} more", self.more);
        }
        format!(
            "the multipart body has no field named `image` (it has {has}); send the image as the field `image`"
        )
    }
}

/// OpenAPI: the description of an image body, `subject` naming the image.
pub(super) fn image_body_description(subject: &str) -> String {
    format!(
        "{subject} ({}), raw or as multipart field `image`.",
        crate::features::SUPPORTED_FORMATS
    )
}

/// OpenAPI: the description of the 415 answer to an image body.
pub(super) fn unsupported_description() -> String {
    format!(
        "Content type not accepted (`unsupported_media_type`), or an image format other than {}, e.g. GIF (`unsupported_image_format`).",
        crate::features::SUPPORTED_FORMATS
    )
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

    #[test]
    fn a_body_without_the_image_field_is_told_the_fields_it_has() {
        let with = |fields: &[&str]| {
            let mut others = OtherFields::default();
            fields.iter().for_each(|f| others.add(f));
            others.missing_image()
        };
        assert!(with(&[]).contains("(it has no fields)"));
        assert!(with(&["file"]).contains("(it has only the field `file`)"));
        assert!(with(&["a", "b"]).contains("(it has the fields `a`, `b`)"));
        // a body of many fields, or of long names, gets a short error
        let long = "x".repeat(10_000);
        let many = vec![long.as_str(); 100_000];
        let e = with(&many);
        assert!(e.len() < 400, "{} bytes", e.len());
        assert!(e.contains("and 99996 more"), "{e}");
    }
}

//! The page a person opens in a browser (`GET /`): pick or drop an image,
//! choose the search settings, and see the query beside its top map
//! candidates (thumbnails, places, scores, inliers), the vote race as the
//! features arrived, and where the time went. Plain HTML, CSS and JavaScript
//! compiled into the binary; it talks to the service only through the
//! public API (`/localize?trace=…`, `/images/{id}/thumbnail`, `/map`).

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use std::sync::LazyLock;

/// The page, with the image formats the service decodes filled in.
static INDEX: LazyLock<String> = LazyLock::new(|| {
    include_str!("index.html").replace("{formats}", crate::features::SUPPORTED_FORMATS)
});
const SCRIPT: &str = include_str!("page.js");
const STYLE: &str = include_str!("page.css");

/// Everything the page loads comes from the service itself.
const POLICY: &str = "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; \
                      script-src 'self'; connect-src 'self'; frame-ancestors 'none'";

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(POLICY),
            ),
            (
                header::X_CONTENT_TYPE_OPTIONS,
                HeaderValue::from_static("nosniff"),
            ),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
        ],
        body,
    )
        .into_response()
}

/// The page: query, candidates and the vote race.
#[utoipa::path(get, path = "/", tag = "page",
    responses((status = 200, description = "The HTML page (its script and style are `/page.js` and `/page.css`).",
        content((String = "text/html")))))]
pub async fn index() -> Response {
    asset("text/html; charset=utf-8", &INDEX)
}

/// The page's script.
#[utoipa::path(get, path = "/page.js", tag = "page",
    responses((status = 200, description = "JavaScript of the page.", content((String = "text/javascript")))))]
pub async fn script() -> Response {
    asset("text/javascript; charset=utf-8", SCRIPT)
}

/// The page's style sheet.
#[utoipa::path(get, path = "/page.css", tag = "page",
    responses((status = 200, description = "CSS of the page.", content((String = "text/css")))))]
pub async fn style() -> Response {
    asset("text/css; charset=utf-8", STYLE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_names_the_formats_the_service_decodes() {
        assert!(INDEX.contains(crate::features::SUPPORTED_FORMATS));
        assert!(!INDEX.contains("{formats}"));
    }
}

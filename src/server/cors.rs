//! Cross-origin requests: which web pages served from other origins may
//! call the API from a browser (`server.cors_origins`), answered by
//! tower-http's CORS layer. None by default: the page at `GET /` is served
//! by the service itself and needs none.

use super::middleware::REQUEST_ID;
use axum::http::{HeaderName, HeaderValue, Method, Uri, header};
use std::time::Duration;
use tower_http::cors::{AllowOrigin, CorsLayer};

/// The configured value that lets every origin in.
pub const ANY: &str = "*";

/// What a page elsewhere may ask for (docs/service.md, "Pages elsewhere",
/// lists them; a test holds it to these).
pub const METHODS: [Method; 4] = [Method::GET, Method::POST, Method::PUT, Method::DELETE];
/// The request headers a page elsewhere may send.
pub const REQUEST_HEADERS: [HeaderName; 4] = [
    header::CONTENT_TYPE,
    header::ACCEPT,
    header::AUTHORIZATION,
    REQUEST_ID,
];
/// The answer's headers a page elsewhere may read.
pub const READABLE_HEADERS: [HeaderName; 3] =
    [REQUEST_ID, header::RETRY_AFTER, header::WWW_AUTHENTICATE];

/// How long a browser may keep a preflight's answer.
const PREFLIGHT_MAX_AGE: Duration = Duration::from_secs(600);

/// Why `origins` cannot be served, if so: each must be an origin as a
/// browser sends it in its `Origin` header (`https://robots.example`,
/// `http://10.0.0.7:3000`: a scheme, a lowercase host and a port if not
/// the scheme's own, no path), or the list is `["*"]` alone.
pub fn check(origins: &[String]) -> Result<(), String> {
    if origins.iter().any(|o| o == ANY) {
        return match origins.len() {
            1 => Ok(()),
            _ => Err(format!(
                "\"{ANY}\" lets every origin in and stands alone, not beside {} other origins",
                origins.len() - 1
            )),
        };
    }
    origins.iter().try_for_each(|o| check_origin(o))
}

fn check_origin(origin: &str) -> Result<(), String> {
    let as_sent =
        "an origin as a browser sends it, e.g. https://robots.example or http://10.0.0.7:3000";
    let uri: Uri = origin
        .parse()
        .map_err(|_| format!("`{origin}` is not {as_sent}"))?;
    let (Some(scheme), Some(authority)) = (uri.scheme_str(), uri.authority()) else {
        return Err(format!("`{origin}` is not {as_sent}"));
    };
    if !matches!(scheme, "http" | "https") {
        return Err(format!("`{origin}`: the scheme must be http or https"));
    }
    if authority.as_str().contains('@') {
        return Err(format!("`{origin}`: an origin has no user name"));
    }
    if origin != format!("{scheme}://{authority}") {
        return Err(format!(
            "`{origin}`: an origin has no path, query or trailing slash (`{scheme}://{authority}`)"
        ));
    }
    if origin != origin.to_ascii_lowercase() {
        return Err(format!(
            "`{origin}`: browsers send the origin in lowercase (`{}`)",
            origin.to_ascii_lowercase()
        ));
    }
    Ok(())
}

/// The layer answering preflights and marking answers for `origins`
/// (checked by [`check`]); `None` when the list is empty.
pub fn layer(origins: &[String]) -> Option<CorsLayer> {
    let allow = match origins {
        [] => return None,
        [any] if any == ANY => AllowOrigin::any(),
        list => AllowOrigin::list(
            list.iter()
                .map(|o| HeaderValue::from_str(o).expect("checked with the configuration")),
        ),
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods(METHODS)
            .allow_headers(REQUEST_HEADERS)
            .expose_headers(READABLE_HEADERS)
            .max_age(PREFLIGHT_MAX_AGE),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_service_docs_list_what_pages_elsewhere_may_send_and_read() {
        let docs = include_str!("../../docs/service.md").to_lowercase();
        let section = &docs[docs.find("**pages elsewhere.**").unwrap()..];
        let section = section[..section.find("```").unwrap()]
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        let methods: Vec<String> = METHODS.iter().map(|m| m.as_str().to_lowercase()).collect();
        let headers = |names: &[HeaderName]| -> Vec<String> {
            names.iter().map(|h| format!("`{}`", h.as_str())).collect()
        };
        for listed in [
            format!(
                "{} with {}",
                english(&methods),
                english(&headers(&REQUEST_HEADERS))
            ),
            format!("may read {}", english(&headers(&READABLE_HEADERS))),
        ] {
            assert!(
                section.contains(&listed),
                "docs/service.md does not say: {listed}"
            );
        }
    }

    /// `a, b and c`.
    fn english(items: &[String]) -> String {
        match items {
            [] => String::new(),
            [one] => one.clone(),
            [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
        }
    }

    fn origins(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn origins_are_taken_as_a_browser_sends_them() {
        for good in [
            &[][..],
            &["*"],
            &["https://robots.example"],
            &["http://10.0.0.7:3000", "https://robots.example:8443"],
        ] {
            assert_eq!(check(&origins(good)), Ok(()), "{good:?}");
        }
    }

    #[test]
    fn anything_else_is_refused_with_the_reason() {
        for (bad, why) in [
            (&["*", "https://a.example"][..], "stands alone"),
            (&["robots.example"], "not an origin"),
            (&["ftp://robots.example"], "http or https"),
            (&["https://robots.example/"], "no path"),
            (&["https://robots.example/page"], "no path"),
            (&["https://Robots.example"], "lowercase"),
            (&["https://user@robots.example"], "no user name"),
            (&[""], "not an origin"),
        ] {
            let e = check(&origins(bad)).unwrap_err();
            assert!(e.contains(why), "{bad:?}: {e}");
        }
    }
}

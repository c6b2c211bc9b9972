//! The HTTP service in-process (the router driven with `tower::oneshot`),
//! where finer control helps: protobuf answers decoded with prost and
//! compared with the JSON answer, the served OpenAPI document against the
//! committed one, and the not-ready state before the map is loaded; and
//! the connection layer on a loopback port, with an HTTP/2 client that
//! multiplexes requests on one connection.

mod common;

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use bowloc::dataset::image_list;
use bowloc::pipeline::{Localizer, build_map, build_vocabulary};
use bowloc::server::config::Config;
use bowloc::server::proto::pb;
use bowloc::server::{AppState, openapi, router};
use bowloc::vocabulary::kmeans::KmeansConfig;
use prost::Message;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use tower::ServiceExt;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A small vocabulary and map from the first 12 map images of rtabmap-loop,
/// built once for all tests of this file.
fn files() -> &'static (PathBuf, PathBuf) {
    static FILES: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    FILES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let images: Vec<_> = image_list(&common::dataset("rtabmap-loop").join("map.txt"))
            .unwrap()
            .into_iter()
            .take(12)
            .collect();
        let kmeans = KmeansConfig {
            k: 200,
            seed: 1,
            ..Default::default()
        };
        let vocab = build_vocabulary(&images, &Default::default(), &kmeans, true).unwrap();
        let map = build_map(&vocab, &images, None, "rtab-12", true).unwrap();
        let (v, m) = (dir.join("v.bowvoc"), dir.join("m.bowmap"));
        vocab.save(&v).unwrap();
        map.save(&m).unwrap();
        (v, m)
    })
}

fn state(loaded: bool) -> Arc<AppState> {
    state_with(loaded, Config::default())
}

fn state_with(loaded: bool, mut config: Config) -> Arc<AppState> {
    let (v, m) = files();
    config.files.vocabulary = v.clone();
    config.files.map = m.clone();
    config.files.images = common::dataset("rtabmap-loop");
    config.bootstrap.enabled = false;
    config.server.workers = 1;
    let state = AppState::new(config).unwrap();
    if loaded {
        state.set_localizer(Localizer::open(v, m, true).unwrap());
    }
    state
}

async fn send(
    state: &Arc<AppState>,
    request: Request<Body>,
) -> (StatusCode, header::HeaderMap, Vec<u8>) {
    let response = router(state.clone()).oneshot(request).await.unwrap();
    let (parts, body) = response.into_parts();
    let bytes = axum::body::to_bytes(body, 1 << 24).await.unwrap();
    (parts.status, parts.headers, bytes.to_vec())
}

fn localize(query: &str, accept: &str) -> Request<Body> {
    let image = std::fs::read(common::dataset("rtabmap-loop").join("images/5.jpg")).unwrap();
    Request::post(format!("/localize?{query}"))
        .header(header::CONTENT_TYPE, "image/jpeg")
        .header(header::ACCEPT, accept)
        .body(Body::from(image))
        .unwrap()
}

#[tokio::test]
async fn protobuf_answer_carries_the_json_answer() {
    let state = state(true);
    let (status, headers, json) =
        send(&state, localize("seed=3&top_n=4", "application/json")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_TYPE], "application/json");
    let json: serde_json::Value = serde_json::from_slice(&json).unwrap();

    let (status, headers, bytes) =
        send(&state, localize("seed=3&top_n=4", "application/x-protobuf")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_TYPE], "application/x-protobuf");
    let pb = pb::Localization::decode(bytes.as_slice()).expect("a valid protobuf message");

    assert!(!pb.candidates.is_empty());
    assert_eq!(
        pb.candidates.len(),
        json["candidates"].as_array().unwrap().len()
    );
    for (p, j) in pb
        .candidates
        .iter()
        .zip(json["candidates"].as_array().unwrap())
    {
        assert_eq!(p.rank as u64, j["rank"].as_u64().unwrap());
        assert_eq!(p.id as u64, j["id"].as_u64().unwrap());
        assert_eq!(p.name, j["name"].as_str().unwrap());
        assert!((p.score as f64 - j["score"].as_f64().unwrap()).abs() < 1e-6);
        assert_eq!(p.verified, j["verified"].as_bool());
        match (p.scale, j["scale"].as_f64()) {
            (Some(a), Some(b)) => assert!((f64::from(a) - b).abs() < 1e-6, "{a} {b}"),
            (a, b) => assert_eq!((a, b), (None, None)),
        }
    }
    // Image 5.jpg is map image 4: with the same seed it must come first.
    assert_eq!(pb.candidates[0].name, "images/5.jpg");
    let f = pb.features.unwrap();
    assert_eq!(f.total, json["features"]["total"].as_u64().unwrap());
    assert_eq!(f.used, json["features"]["used"].as_u64().unwrap());
    assert_eq!(
        pb.rule.unwrap().name,
        json["rule"]["name"].as_str().unwrap()
    );
    let stop = pb.stop.unwrap();
    assert_eq!(stop.kind, json["stop"]["kind"].as_str().unwrap());
    assert_eq!(
        stop.at_feature,
        json["stop"]["at_feature"].as_u64().unwrap()
    );
    assert_eq!(pb.seed, 3);
    let map = pb.map.unwrap();
    assert_eq!(
        (map.name.as_str(), map.images, map.words),
        ("rtab-12", 12, 200)
    );
    assert_eq!(map.vocabulary, json["map"]["vocabulary"].as_str().unwrap());
    assert_eq!(pb.image.unwrap().width, 512);
    assert!(pb.timings_ms.unwrap().total > 0.0);
}

#[tokio::test]
async fn rule_parameter_is_reported_in_protobuf() {
    let state = state(true);
    let (status, _, bytes) = send(
        &state,
        localize("rule=hoeffding&delta=0.2&seed=1", "application/x-protobuf"),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let rule = pb::Localization::decode(bytes.as_slice())
        .unwrap()
        .rule
        .unwrap();
    assert_eq!(rule.name, "hoeffding");
    assert_eq!(rule.parameter.as_deref(), Some("delta"));
    assert_eq!(rule.value, Some(0.2));
}

#[tokio::test]
async fn errors_stay_json_for_protobuf_clients() {
    let state = state(true);
    let (status, headers, body) = send(&state, localize("top_n=0", "application/x-protobuf")).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert_eq!(headers[header::CONTENT_TYPE], "application/json");
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["error"]["code"], "invalid_parameter");
    assert!(v["error"]["message"].as_str().unwrap().contains("top_n"));
}

#[tokio::test]
async fn served_openapi_equals_the_committed_document() {
    let committed = std::fs::read_to_string(root().join("docs/openapi.json")).unwrap();
    assert!(
        openapi::json() == committed,
        "docs/openapi.json is out of date: regenerate it with `make openapi`"
    );
    let state = state(false);
    let (status, headers, body) = send(
        &state,
        Request::get("/openapi.json").body(Body::empty()).unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_TYPE], "application/json");
    assert_eq!(String::from_utf8(body).unwrap(), committed);
}

#[tokio::test]
async fn before_the_map_is_loaded_only_liveness_answers() {
    let state = state(false);
    let get = |path: &str| Request::get(path).body(Body::empty()).unwrap();
    let (status, _, _) = send(&state, get("/healthz")).await;
    assert_eq!(status, StatusCode::OK);
    for request in [
        get("/readyz"),
        get("/map"),
        localize("", "application/json"),
    ] {
        let (status, headers, body) = send(&state, request).await;
        assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
        assert!(headers.contains_key(header::RETRY_AFTER));
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["error"]["code"], "not_ready");
        // the loading step (nothing loads here, so it never moves on)
        assert_eq!(v["error"]["step"], "starting");
    }
    state.set_localizer(Localizer::open(&files().0, &files().1, false).unwrap());
    let (status, _, _) = send(&state, get("/readyz")).await;
    assert_eq!(status, StatusCode::OK);
    state.begin_shutdown();
    let (status, _, body) = send(&state, get("/readyz")).await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["error"]["code"], "shutting_down");
}

#[tokio::test]
async fn thumbnails_are_read_by_map_id_only() {
    let state = state(true);
    let get = |path: &str| Request::get(path).body(Body::empty()).unwrap();
    for (path, side) in [
        ("/images/0/thumbnail", 160),
        ("/images/11/thumbnail?size=64", 64),
        ("/images/4/thumbnail?size=640", 512),
    ] {
        let (status, headers, body) = send(&state, get(path)).await;
        assert_eq!(status, StatusCode::OK, "{path}");
        assert_eq!(headers[header::CONTENT_TYPE], "image/jpeg");
        let size = imagesize::blob_size(&body).unwrap();
        assert_eq!(size.width.max(size.height), side, "{path}");
    }
    // outside the map (12 images), or anything that is not a plain id
    for path in [
        "/images/12/thumbnail",
        "/images/4294967295/thumbnail",
        "/images/99999999999999/thumbnail",
        "/images/-1/thumbnail",
        "/images/..%2F..%2F..%2Fetc%2Fpasswd/thumbnail",
        "/images/%2Fetc%2Fpasswd/thumbnail",
        "/images/images%2F5.jpg/thumbnail",
        "/images/../../etc/passwd/thumbnail",
        "/images/1%00/thumbnail",
        "/images/0x1/thumbnail",
    ] {
        let (status, _, body) = send(&state, get(path)).await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{path}");
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["error"]["code"], "not_found", "{path}");
    }
    let (status, _, _) = send(&state, get("/images/0/thumbnail?size=9999")).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
}

#[tokio::test]
async fn the_page_and_its_assets_are_served() {
    let state = state(false);
    for (path, media) in [
        ("/", "text/html; charset=utf-8"),
        ("/page.js", "text/javascript; charset=utf-8"),
        ("/page.css", "text/css; charset=utf-8"),
    ] {
        let (status, headers, body) =
            send(&state, Request::get(path).body(Body::empty()).unwrap()).await;
        assert_eq!(status, StatusCode::OK, "{path}");
        assert_eq!(headers[header::CONTENT_TYPE], media, "{path}");
        assert!(headers.contains_key(header::CONTENT_SECURITY_POLICY));
        assert!(!body.is_empty());
    }
}

/// GET `path`, accepting gzip.
fn get_gzip(path: &str) -> Request<Body> {
    Request::get(path)
        .header(header::ACCEPT_ENCODING, "gzip")
        .body(Body::empty())
        .unwrap()
}

#[tokio::test]
async fn answers_are_gzipped_for_clients_that_accept_it_but_not_jpegs() {
    let state = state(true);
    let plain = send(
        &state,
        Request::get("/openapi.json").body(Body::empty()).unwrap(),
    )
    .await;
    assert!(!plain.1.contains_key(header::CONTENT_ENCODING));
    let (status, headers, gzipped) = send(&state, get_gzip("/openapi.json")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_ENCODING], "gzip");
    assert!(
        gzipped.len() * 4 < plain.2.len(),
        "{} of {} bytes",
        gzipped.len(),
        plain.2.len()
    );
    let mut unzipped = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::GzDecoder::new(&gzipped[..]),
        &mut unzipped,
    )
    .unwrap();
    assert_eq!(unzipped, plain.2);

    let mut query = localize("seed=3&trace=full", "application/json");
    query
        .headers_mut()
        .insert(header::ACCEPT_ENCODING, "gzip".parse().unwrap());
    let (status, headers, _) = send(&state, query).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_ENCODING], "gzip");

    let (status, headers, _) = send(&state, get_gzip("/images/0/thumbnail")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_TYPE], "image/jpeg");
    assert!(!headers.contains_key(header::CONTENT_ENCODING));

    let mut config = Config::default();
    config.server.compression = false;
    let state = state_with(true, config);
    let (_, headers, _) = send(&state, get_gzip("/openapi.json")).await;
    assert!(!headers.contains_key(header::CONTENT_ENCODING));
}

/// A preflight from a page at `origin` asking to POST an image.
fn preflight(origin: &str) -> Request<Body> {
    Request::options("/localize")
        .header(header::ORIGIN, origin)
        .header(header::ACCESS_CONTROL_REQUEST_METHOD, "POST")
        .header(header::ACCESS_CONTROL_REQUEST_HEADERS, "content-type")
        .body(Body::empty())
        .unwrap()
}

/// A query posted by a page at `origin`.
fn localize_from(origin: &str) -> Request<Body> {
    let mut request = localize("seed=3", "application/json");
    let origin = origin.parse().unwrap();
    request.headers_mut().insert(header::ORIGIN, origin);
    request
}

#[tokio::test]
async fn pages_on_the_configured_origins_may_call_the_api_and_no_others() {
    let allowed = "https://robots.example";
    let mut config = Config::default();
    config.server.cors_origins = vec![allowed.into()];
    let state = state_with(true, config);

    let (status, headers, _) = send(&state, preflight(allowed)).await;
    assert!(status.is_success(), "{status}");
    assert_eq!(headers[header::ACCESS_CONTROL_ALLOW_ORIGIN], allowed);
    let methods = headers[header::ACCESS_CONTROL_ALLOW_METHODS]
        .to_str()
        .unwrap();
    assert!(methods.contains("POST"), "{methods}");
    let (_, headers, _) = send(&state, preflight("https://elsewhere.example")).await;
    assert!(!headers.contains_key(header::ACCESS_CONTROL_ALLOW_ORIGIN));

    // the answer itself, and an error, are marked for the page, its
    // request id readable
    let (status, headers, _) = send(&state, localize_from(allowed)).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::ACCESS_CONTROL_ALLOW_ORIGIN], allowed);
    let exposed = headers[header::ACCESS_CONTROL_EXPOSE_HEADERS]
        .to_str()
        .unwrap();
    assert!(exposed.contains("x-request-id"), "{exposed}");
    let bad = Request::post("/localize?top_n=0")
        .header(header::ORIGIN, allowed)
        .body(Body::from("not an image"))
        .unwrap();
    let (status, headers, _) = send(&state, bad).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert_eq!(headers[header::ACCESS_CONTROL_ALLOW_ORIGIN], allowed);

    // by default no page elsewhere may
    let state = self::state(true);
    let (_, headers, _) = send(&state, preflight(allowed)).await;
    assert!(!headers.contains_key(header::ACCESS_CONTROL_ALLOW_ORIGIN));
    let (_, headers, _) = send(&state, localize_from(allowed)).await;
    assert!(!headers.contains_key(header::ACCESS_CONTROL_ALLOW_ORIGIN));
}

/// An answer's `tiles` without `saved_ms` (a time), which is checked: some
/// time when tiles were left, none when every tile was extracted.
fn tiles_but_time(answer: &serde_json::Value) -> serde_json::Value {
    let mut tiles = answer["tiles"].clone();
    let saved = tiles["saved_ms"].as_f64().unwrap();
    match tiles["extracted"].as_u64() < tiles["total"].as_u64() {
        true => assert!(saved > 0.0, "{tiles}"),
        false => assert_eq!(saved, 0.0, "{tiles}"),
    }
    tiles.as_object_mut().unwrap().remove("saved_ms");
    tiles
}

#[tokio::test]
async fn the_trace_follows_the_race_to_the_stop_and_the_full_search_to_the_end() {
    let state = state(true);
    let answer = |q: &'static str| {
        let state = state.clone();
        async move {
            let (status, _, body) = send(&state, localize(q, "application/json")).await;
            assert_eq!(status, StatusCode::OK, "{q}");
            serde_json::from_slice::<serde_json::Value>(&body).unwrap()
        }
    };
    // unverified: the search stops where the rule fires
    let plain = answer("seed=3&rule=peak-mean&threshold=1&tiles=2x2&verify=false").await;
    assert!(plain.get("trace").is_none(), "no trace unless asked");
    let traced =
        answer("seed=3&rule=peak-mean&threshold=1&tiles=2x2&trace=full&verify=false").await;
    // tracing changes nothing of the answer (but the times: the time saved
    // is an estimate from the tiles' times)
    for key in ["candidates", "features", "stop"] {
        assert_eq!(plain[key], traced[key], "{key}");
    }
    assert_eq!(tiles_but_time(&plain), tiles_but_time(&traced));
    let t = &traced["trace"];
    let points = t["points"].as_array().unwrap();
    assert!(!points.is_empty() && points.len() <= 257);
    let stop = traced["stop"]["at_feature"].as_u64().unwrap();
    assert_eq!(points.last().unwrap()["features"].as_u64().unwrap(), stop);
    let last = points.last().unwrap();
    assert_eq!(traced["stop"]["kind"], "rule");
    assert!(last["statistic"].as_f64().unwrap() > last["threshold"].as_f64().unwrap());
    assert_eq!(last["threshold"].as_f64().unwrap(), 1.0);
    // before the stop the statistic had not passed the threshold
    for p in &points[..points.len() - 1] {
        assert!(p["statistic"].as_f64().unwrap() <= 1.0, "{p}");
        assert!(p["leader_votes"].as_f64() >= p["runner_up_votes"].as_f64());
    }
    let full = &t["full"];
    let n = full["features"].as_u64().unwrap();
    assert!(n > stop, "the full search votes every feature");
    assert_eq!(full["stop"]["kind"], "exhausted");
    assert_eq!(
        full["points"].as_array().unwrap().last().unwrap()["features"].as_u64(),
        Some(n)
    );
    // the same features in the same order: the two races agree up to the stop
    let full_at: std::collections::HashMap<u64, &serde_json::Value> = full["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["features"].as_u64().unwrap(), p))
        .collect();
    let mut shared = 0;
    for p in points {
        if let Some(q) = full_at.get(&p["features"].as_u64().unwrap()) {
            assert_eq!(p["leader_votes"], q["leader_votes"]);
            assert_eq!(p["runner_up_votes"], q["runner_up_votes"]);
            shared += 1;
        }
    }
    assert!(shared > 0);
    let tile_ends = t["tile_ends"].as_array().unwrap();
    assert_eq!(
        tile_ends.len() as u64,
        traced["tiles"]["extracted"].as_u64().unwrap()
    );
    assert!(!full["candidates"].as_array().unwrap().is_empty());
    // verified: the rule fires at the same feature, and the search votes the
    // rest of that tile before it stops, at the tile's end
    let verified = answer("seed=3&rule=peak-mean&threshold=1&tiles=2x2&trace=full").await;
    assert_eq!(verified["stop"]["kind"], "rule");
    assert_eq!(tiles_but_time(&verified), tiles_but_time(&traced));
    let ends: Vec<u64> = verified["trace"]["tile_ends"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_u64().unwrap())
        .collect();
    let at = verified["stop"]["at_feature"].as_u64().unwrap();
    assert_eq!(Some(&at), ends.last(), "{ends:?}");
    assert!(at >= stop);
    assert!(
        verified["stop"]["detail"]
            .as_str()
            .unwrap()
            .contains("the rest of the tile")
            || at == stop,
        "{}",
        verified["stop"]
    );
}

#[tokio::test]
async fn the_protobuf_answer_carries_the_trace() {
    let state = state(true);
    let q = "seed=5&trace=full&verify=true";
    let (status, _, json) = send(&state, localize(q, "application/json")).await;
    assert_eq!(status, StatusCode::OK);
    let json: serde_json::Value = serde_json::from_slice(&json).unwrap();
    let (status, _, bytes) = send(&state, localize(q, "application/x-protobuf")).await;
    assert_eq!(status, StatusCode::OK);
    let t = pb::Localization::decode(bytes.as_slice())
        .unwrap()
        .trace
        .unwrap();
    let j = &json["trace"];
    assert_eq!(t.points.len(), j["points"].as_array().unwrap().len());
    assert_eq!(t.every as u64, j["every"].as_u64().unwrap());
    assert_eq!(t.warm_up as u64, j["warm_up"].as_u64().unwrap());
    assert_eq!(t.frame_side, 640);
    let last = t.points.last().unwrap();
    assert_eq!(
        last.features as u64,
        json["stop"]["at_feature"].as_u64().unwrap()
    );
    let full = t.full.unwrap();
    assert_eq!(full.features, j["full"]["features"].as_u64().unwrap());
    assert_eq!(
        full.candidates.len(),
        j["full"]["candidates"].as_array().unwrap().len()
    );
    // verified: the top candidate's inliers as lines, as many as in JSON
    assert!(!t.matches.is_empty());
    assert_eq!(
        t.matches[0].lines.len(),
        j["matches"][0]["lines"].as_array().unwrap().len()
    );
    assert!(t.matches[0].lines.len() >= 4);
}

/// The fields of each message of `proto/localize.proto`: message name →
/// (field name → field type), read from the schema's text.
fn proto_messages() -> std::collections::HashMap<String, std::collections::HashMap<String, String>>
{
    let text = std::fs::read_to_string(root().join("proto/localize.proto")).unwrap();
    let mut messages = std::collections::HashMap::new();
    let mut current: Option<(String, std::collections::HashMap<String, String>)> = None;
    for line in text.lines().map(str::trim) {
        if line.starts_with("//") || line.is_empty() {
            continue;
        }
        if let Some(rest) = line.strip_prefix("message ") {
            let name = rest.trim_end_matches('{').trim().to_owned();
            current = Some((name, Default::default()));
        } else if line == "}" {
            if let Some((name, fields)) = current.take() {
                messages.insert(name, fields);
            }
        } else if let Some((_, fields)) = &mut current
            && let Some((decl, _number)) = line.split_once('=')
        {
            let words: Vec<&str> = decl
                .split_whitespace()
                .filter(|w| !matches!(*w, "optional" | "repeated"))
                .collect();
            // `TYPE name`, or `map<K, V> name`
            if let (Some(kind), Some(name)) = (words.first(), words.last()) {
                fields.insert((*name).to_owned(), (*kind).to_owned());
            }
        }
    }
    messages
}

/// The schema a JSON property refers to (directly, as array items, or as
/// the non-null side of a nullable), if any.
fn referenced(property: &serde_json::Value) -> Option<String> {
    let r = property
        .get("$ref")
        .or_else(|| property.get("items").and_then(|i| i.get("$ref")))
        .or_else(|| {
            property
                .get("oneOf")
                .and_then(|o| o.as_array())
                .and_then(|o| o.iter().find_map(|v| v.get("$ref")))
        })?;
    r.as_str()
        .and_then(|s| s.rsplit('/').next())
        .map(str::to_owned)
}

#[test]
fn protobuf_schema_has_every_field_of_the_json_answer() {
    let api: serde_json::Value = serde_json::from_str(openapi::json()).unwrap();
    let schemas = &api["components"]["schemas"];
    let messages = proto_messages();
    // (OpenAPI schema, proto message), walked from the answer down
    let mut todo = vec![("Localization".to_owned(), "Localization".to_owned())];
    let mut seen = std::collections::HashSet::new();
    let mut missing = Vec::new();
    while let Some((schema, message)) = todo.pop() {
        if !seen.insert(schema.clone()) {
            continue;
        }
        let fields = messages
            .get(&message)
            .unwrap_or_else(|| panic!("proto has no message {message} for schema {schema}"));
        let properties = schemas[&schema]["properties"].as_object().unwrap();
        for (name, property) in properties {
            match fields.get(name) {
                None => missing.push(format!("{message}.{name} (schema {schema})")),
                Some(kind) => {
                    if let Some(child) = referenced(property) {
                        todo.push((child, kind.clone()));
                    }
                }
            }
        }
    }
    assert!(seen.contains("SequenceAnswer") && seen.contains("FilteredCandidate"));
    assert!(
        missing.is_empty(),
        "fields of the JSON answer missing from proto/localize.proto: {missing:?}"
    );
}

#[tokio::test]
async fn protobuf_answer_carries_the_sequence_block() {
    let state = state(true);
    // the same two frames, as JSON in one sequence and as protobuf in another
    for frame in 0..2 {
        let frame_of = |name: &str, accept: &'static str| {
            let request = localize(&format!("seed=3&sequence={name}&frame={frame}"), accept);
            let state = state.clone();
            async move {
                let (status, _, body) = send(&state, request).await;
                assert_eq!(status, StatusCode::OK);
                body
            }
        };
        let json: serde_json::Value =
            serde_json::from_slice(&frame_of("j", "application/json").await).unwrap();
        let bytes = frame_of("p", "application/x-protobuf").await;
        let pb = pb::Localization::decode(bytes.as_slice()).unwrap();
        let (s, j) = (pb.sequence.expect("a sequence block"), &json["sequence"]);
        assert_eq!(s.name, "p");
        assert_eq!(s.frame, j["frame"].as_u64().unwrap());
        assert_eq!(s.frames, j["frames"].as_u64().unwrap());
        assert_eq!(s.restart.as_deref(), j["restart"].as_str());
        assert_eq!(s.restart.is_some(), frame == 0);
        let filtered = j["candidates"].as_array().unwrap();
        assert!(!s.candidates.is_empty());
        assert_eq!(s.candidates.len(), filtered.len());
        for (p, j) in s.candidates.iter().zip(filtered) {
            assert_eq!(p.rank as u64, j["rank"].as_u64().unwrap());
            assert_eq!(p.id as u64, j["id"].as_u64().unwrap());
            assert_eq!(p.name, j["name"].as_str().unwrap());
            assert!((p.probability - j["probability"].as_f64().unwrap()).abs() < 1e-12);
        }
        // the frame's own candidates carry their probability too
        for (p, j) in pb
            .candidates
            .iter()
            .zip(json["candidates"].as_array().unwrap())
        {
            let want = j["probability"].as_f64().expect("a probability");
            assert!((p.probability.expect("a probability") - want).abs() < 1e-12);
        }
    }
}

#[tokio::test]
async fn a_single_query_by_the_posterior_rule_weighs_votes_at_the_configured_kappa() {
    // the top candidate's probability given the votes alone, at κ
    let top = |kappa: f64| async move {
        let mut config = Config::default();
        config.sequence.kappa = kappa;
        let state = state_with(true, config);
        let (status, _, body) = send(
            &state,
            localize("seed=3&rule=posterior&threshold=0.01", "application/json"),
        )
        .await;
        assert_eq!(status, StatusCode::OK);
        let json: serde_json::Value = serde_json::from_slice(&body).unwrap();
        json["candidates"][0]["probability"]
            .as_f64()
            .expect("a posterior query's candidates carry probabilities")
    };
    let (weak, strong) = (top(0.05).await, top(2.0).await);
    assert!(
        weak < strong,
        "a smaller κ trusts the votes less: {weak} vs {strong}"
    );
}

#[tokio::test]
async fn the_auto_plan_tries_the_coarse_pass_and_learns_which_costs_less() {
    // loaded as the service loads it, with the learned plan
    let mut config = Config::default();
    let (v, m) = files();
    config.files.vocabulary = v.clone();
    config.files.map = m.clone();
    config.bootstrap.enabled = false;
    config.server.workers = 1;
    config.search.tiles = "2x2+24,auto".into();
    let localizer = bowloc::server::bootstrap::load(&config, &Default::default()).unwrap();
    let state = AppState::new(config).unwrap();
    state.set_localizer(localizer);
    let trials = 2 * bowloc::features::CoarseChoice::TRIAL;
    let mut coarse = 0;
    for seed in 0..trials {
        let (status, _, body) = send(
            &state,
            localize(&format!("seed={seed}"), "application/json"),
        )
        .await;
        assert_eq!(status, StatusCode::OK);
        let answer: serde_json::Value = serde_json::from_slice(&body).unwrap();
        let grid = answer["tiles"]["grid"].as_str().unwrap();
        assert!(grid.starts_with("2x2+24"), "{grid}");
        coarse += grid.ends_with(",coarse") as u64;
    }
    // the trials split evenly between the two plans
    assert_eq!(coarse, trials / 2);
    // a grid asked for is used as asked
    let (status, _, body) = send(
        &state,
        localize("seed=1&tiles=3x3%2B16", "application/json"),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let answer: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(answer["tiles"]["grid"], "3x3+16");
}

#[tokio::test]
async fn a_frame_of_a_sequence_warms_up_as_the_map_images_say() {
    // the map's 12 images: a quarter of their median feature count, at most 100
    let (_, m) = files();
    let map = bowloc::index::MapIndex::open(m, true).unwrap();
    let counts: Vec<usize> = (0..map.images() as u32)
        .map(|j| map.geometry(j).len())
        .collect();
    let auto = bowloc::calibrate::auto_warmup(&counts);
    assert!(
        auto > 0 && auto < 100,
        "rtabmap-loop's small frames: {auto}"
    );
    let warm_up = |config: Config, sequence: &'static str| async move {
        let state = state_with(true, config);
        let q = format!("seed=3&sequence={sequence}&frame=0&trace=true");
        let (status, _, body) = send(&state, localize(&q, "application/json")).await;
        assert_eq!(status, StatusCode::OK);
        let json: serde_json::Value = serde_json::from_slice(&body).unwrap();
        json["trace"]["warm_up"].as_u64().unwrap() as usize
    };
    assert_eq!(warm_up(Config::default(), "auto").await, auto);
    let mut config = Config::default();
    config.sequence.min_features = bowloc::calibrate::Warmup::Features(7);
    assert_eq!(warm_up(config, "fixed").await, 7);
}

/// The service's configuration with a learned plan, on a copy of the map
/// in a folder of its own (so its plan file is the caller's alone).
fn learned_plan_config() -> (tempfile::TempDir, Config) {
    let dir = tempfile::tempdir().unwrap();
    let (v, m) = files();
    let map = dir.path().join("m.bowmap");
    std::fs::copy(m, &map).unwrap();
    let mut config = Config::default();
    config.files.vocabulary = v.clone();
    config.files.map = map;
    config.bootstrap.enabled = false;
    config.server.workers = 1;
    config.search.tiles = "2x2+24,auto".into();
    (dir, config)
}

#[tokio::test]
async fn a_restart_goes_on_from_the_kept_plan_when_nothing_it_was_learned_on_changed() {
    use bowloc::server::plan_memory::{PlanMemory, Restored, path_for};
    let (dir, base) = learned_plan_config();
    let map = base.files.map.clone();
    let config = || base.clone();
    let serve = |config: Config| {
        let localizer = bowloc::server::bootstrap::load(&config, &Default::default()).unwrap();
        let state = AppState::new(config).unwrap();
        state.set_localizer(localizer);
        state
    };
    let learned = |state: &Arc<AppState>| {
        let localizer = state.localizer().unwrap();
        localizer.coarse_choice.as_ref().unwrap().learned()
    };
    let first = serve(config());
    let trials = 2 * bowloc::features::CoarseChoice::TRIAL;
    for seed in 0..trials + 4 {
        let query = format!("seed={seed}");
        let (status, _, _) = send(&first, localize(&query, "application/json")).await;
        assert_eq!(status, StatusCode::OK);
    }
    let kept = learned(&first);
    assert_eq!(kept.requests, trials + 4);
    assert!(!path_for(&map).exists());
    first.keep_plan().await;
    let text = std::fs::read_to_string(path_for(&map)).unwrap();
    let saved: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(saved["learned"]["requests"], trials + 4, "{text}");
    let tile_cost = |state: &Arc<AppState>| {
        let cost = state.localizer().unwrap().tile_cost().learnt();
        serde_json::to_value(cost).unwrap()
    };
    let costs = tile_cost(&first);
    assert_eq!(saved["tile_costs"], costs, "{text}");

    // /map says what was learned, where it is kept, and that it was not
    // resumed
    let plan_status = |state: &Arc<AppState>| {
        let state = state.clone();
        async move {
            let map = Request::get("/map").body(Body::empty()).unwrap();
            let (status, _, body) = send(&state, map).await;
            assert_eq!(status, StatusCode::OK);
            let info: serde_json::Value = serde_json::from_slice(&body).unwrap();
            info["extraction_plan"].clone()
        }
    };
    let plan = plan_status(&first).await;
    assert_eq!(plan["requests"], trials + 4, "{plan}");
    assert_eq!(plan["resumed_from"], serde_json::Value::Null, "{plan}");
    assert_eq!(plan["file"], path_for(&map).display().to_string(), "{plan}");
    let plans = plan["plans"].as_array().unwrap();
    assert_eq!(plans.len(), 2, "{plan}");
    assert_eq!(
        (plans[0]["plan"].as_str(), plans[1]["plan"].as_str()),
        (Some("tiles"), Some("coarse"))
    );
    let answered: u64 = plans.iter().map(|p| p["requests"].as_u64().unwrap()).sum();
    assert_eq!(answered, trials + 4, "{plan}");
    assert!(
        plans
            .iter()
            .all(|p| p["typical_ms"].as_f64().unwrap() > 0.0),
        "{plan}"
    );
    assert!(plan["preferred"].is_string(), "{plan}");

    // the same map, machine and settings: no trials, and the tiles priced
    // as before from the first request on
    let second = serve(config());
    assert_eq!(learned(&second), kept);
    assert_eq!(tile_cost(&second), costs);
    let first_tiles = |state: &Arc<AppState>| {
        let cost = state.localizer().unwrap();
        cost.tile_cost().tiles_to_beat_the_pass(false)
    };
    assert!(first_tiles(&second).is_some());
    assert_eq!(first_tiles(&second), first_tiles(&first));
    assert_eq!(plan_status(&second).await["resumed_from"], trials + 4);
    let (status, _, _) = send(&second, localize("seed=99", "application/json")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(learned(&second).requests, trials + 5);

    // other settings: the trials again, the file as it was
    let mut other = config();
    other.search.top_n = 3;
    let third = serve(other.clone());
    assert_eq!(learned(&third).requests, 0);
    assert_eq!(first_tiles(&third), None);
    let memory = PlanMemory::of(&other).unwrap();
    let localizer = bowloc::server::bootstrap::load(&other, &Default::default()).unwrap();
    assert_eq!(
        memory.restore(&localizer),
        Restored::Ignored("learned for other settings".into())
    );
    // the kept file edited by `edit`, restored into a fresh localizer
    let restore_edited = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut saved: serde_json::Value = serde_json::from_str(&text).unwrap();
        edit(&mut saved);
        std::fs::write(path_for(&map), saved.to_string()).unwrap();
        let memory = PlanMemory::of(&config()).unwrap();
        let localizer = bowloc::server::bootstrap::load(&config(), &Default::default()).unwrap();
        (memory.restore(&localizer), localizer)
    };
    // another map at the same path
    let (restored, _) =
        restore_edited(&|saved| saved["context"]["map"] = "0123456789abcdef".into());
    assert_eq!(
        restored,
        Restored::Ignored("learned for another map".into())
    );
    // a file written before tile costs were kept: the plan resumes, the
    // tile costs are learnt afresh
    let (restored, older) = restore_edited(&|saved| {
        saved.as_object_mut().unwrap().remove("tile_costs");
    });
    assert_eq!(restored, Restored::Resumed(kept));
    assert_eq!(older.tile_cost().tiles_to_beat_the_pass(false), None);
    // tile costs no server learns: the whole file is ignored
    let (restored, localizer) = restore_edited(&|saved| saved["tile_costs"]["xx"] = 0.0.into());
    assert_eq!(
        restored,
        Restored::Ignored("its tile costs are not ones a server learns".into())
    );
    assert_eq!(
        localizer.coarse_choice.as_ref().unwrap().learned().requests,
        0
    );
    // a damaged file: the trials, and the service answers
    std::fs::write(path_for(&map), &text[..text.len() / 2]).unwrap();
    let damaged = serve(config());
    assert_eq!(learned(&damaged).requests, 0);
    let (status, _, _) = send(&damaged, localize("seed=1", "application/json")).await;
    assert_eq!(status, StatusCode::OK);
    // a file that cannot be written: no panic, nothing kept, and the
    // service answers
    let blocked = PlanMemory::at(PathBuf::from("/dev/null/m.bowmap.plan.json"), &config());
    let localizer = bowloc::server::bootstrap::load(&config(), &Default::default()).unwrap();
    let choice = localizer.coarse_choice.as_ref().unwrap();
    choice.record(choice.choose(), 10.0, true);
    let beside = PlanMemory::at(dir.path().join("other.plan.json"), &config());
    assert!(beside.save(&localizer), "a plan with a request is kept");
    assert!(!beside.save(&localizer), "and not written again unchanged");
    assert!(!blocked.save(&localizer));
    assert!(!blocked.save(&localizer));
    // a plan not to be kept has no memory
    let mut forget = config();
    forget.search.remember_plan = false;
    assert!(PlanMemory::of(&forget).is_none());
    let mut fixed = config();
    fixed.search.tiles = "2x2+24".into();
    assert!(PlanMemory::of(&fixed).is_none());
    // a fixed plan has nothing to say
    assert_eq!(plan_status(&serve(fixed)).await, serde_json::Value::Null);
}

#[tokio::test]
async fn a_compaction_while_serving_is_written_into_the_kept_plan() {
    use bowloc::live::Change;
    use bowloc::server::plan_memory::{PlanMemory, Restored, path_for};
    let (_dir, mut config) = learned_plan_config();
    let map = config.files.map.clone();
    // a write token: the map is opened with its change log
    config.auth.write_token = Some("a-write-token-long-enough-0123456789".into());
    let localizer = bowloc::server::bootstrap::load(&config, &Default::default()).unwrap();
    let memory = PlanMemory::of(&config).unwrap();
    let choice = localizer.coarse_choice.as_ref().unwrap();
    choice.record(choice.choose(), 10.0, true);
    assert!(memory.save(&localizer));
    let read = || -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(path_for(&map)).unwrap()).unwrap()
    };
    let before = read()["context"]["map"].clone();
    // a change and a compaction: a new map file, no new request
    let name = {
        use bowloc::index::MapRead;
        localizer.map.snapshot().image(0).name.to_owned()
    };
    localizer.map.apply(Change::Remove { name }).unwrap();
    assert!(localizer.map.compact().unwrap().is_some());
    assert!(memory.save(&localizer), "the new map file is recorded");
    let after = read()["context"]["map"].clone();
    assert_ne!(before, after);
    assert_eq!(read()["learned"]["requests"], 1);
    // and a restart on the compacted map goes on from the plan
    drop(localizer);
    let reopened = bowloc::server::bootstrap::load(&config, &Default::default()).unwrap();
    let memory = PlanMemory::of(&config).unwrap();
    assert!(matches!(memory.restore(&reopened), Restored::Resumed(l) if l.requests == 1));
}

/// HTTP/2 (prior knowledge) and HTTP/1.1 on one port: requests in flight
/// at once on one HTTP/2 connection all answered, the connection sent
/// GOAWAY once idle for the header timeout, and the server stops.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn http2_multiplexes_requests_beside_http1_and_idle_connections_end() {
    use axum::body::Bytes;
    use bowloc::server::connections;
    use http_body_util::{BodyExt, Full};
    use hyper_util::rt::{TokioExecutor, TokioIo};
    use std::time::{Duration, Instant};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::net::{TcpListener, TcpStream};

    let state = state(true);
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    let mut settings = connections::Settings::of(&state.config);
    assert!(settings.http2, "HTTP/2 is on by default");
    settings.header_timeout = Duration::from_millis(300);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(connections::serve(
        listener,
        router(state.clone()),
        settings,
        async {
            let _ = stopped.await;
        },
    ));

    let stream = TcpStream::connect(address).await.unwrap();
    let (sender, connection) =
        hyper::client::conn::http2::handshake(TokioExecutor::new(), TokioIo::new(stream))
            .await
            .unwrap();
    let connection = tokio::spawn(connection);
    let image =
        Bytes::from(std::fs::read(common::dataset("rtabmap-loop").join("images/5.jpg")).unwrap());
    let requests: Vec<_> = (1..=3)
        .map(|seed| {
            let mut sender = sender.clone();
            let request = Request::post(format!("http://bowloc/localize?seed={seed}"))
                .header(header::CONTENT_TYPE, "image/jpeg")
                .body(Full::new(image.clone()))
                .unwrap();
            tokio::spawn(async move {
                let response = sender.send_request(request).await.unwrap();
                let (version, status) = (response.version(), response.status());
                let body = response.into_body().collect().await.unwrap().to_bytes();
                (version, status, body)
            })
        })
        .collect();
    for request in requests {
        let (version, status, body) = request.await.unwrap();
        assert_eq!(
            (version, status),
            (axum::http::Version::HTTP_2, StatusCode::OK)
        );
        let answer: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert!(
            !answer["candidates"].as_array().unwrap().is_empty(),
            "{answer}"
        );
    }
    // the client keeps the connection (its sender) open
    let answered = Instant::now();

    // HTTP/1.1 on the same port meanwhile
    let mut http1 = TcpStream::connect(address).await.unwrap();
    http1
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: bowloc\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut reply = String::new();
    http1.read_to_string(&mut reply).await.unwrap();
    assert!(reply.starts_with("HTTP/1.1 200"), "{reply}");

    // idle for the header timeout: GOAWAY, the client acknowledges, it ends
    tokio::time::timeout(Duration::from_secs(5), connection)
        .await
        .expect("an idle HTTP/2 connection is ended")
        .unwrap()
        .unwrap();
    let idle = answered.elapsed();
    assert!(idle >= Duration::from_millis(250), "ended after {idle:?}");
    drop(sender);

    let _ = stop.send(());
    tokio::time::timeout(Duration::from_secs(5), server)
        .await
        .expect("the server stops")
        .unwrap();
}

//! Prometheus metrics: the recorder (installed once per process), the names
//! and help texts of every metric the service exports, and small functions
//! the handlers call to record them. Names follow Prometheus conventions:
//! `bowloc_` prefix, base units (`_seconds`), `_total` for counters. Labelled
//! counters whose labels are known in advance are exported at 0 from the
//! start. The process's own metrics (`process_resident_memory_bytes`,
//! `process_open_fds`, `process_cpu_seconds_total`, …) are read at each
//! scrape.

use crate::index::MapRead;
use crate::report::Localization;
use metrics::{
    Unit, counter, describe_counter, describe_gauge, describe_histogram, gauge, histogram,
};
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::sync::OnceLock;
use std::time::Duration;

pub const HTTP_REQUESTS: &str = "bowloc_http_requests_total";
pub const HTTP_DURATION: &str = "bowloc_http_request_duration_seconds";
pub const HTTP_IN_FLIGHT: &str = "bowloc_http_requests_in_flight";
pub const HTTP_ERRORS: &str = "bowloc_http_errors_total";
pub const REJECTED: &str = "bowloc_rejected_requests_total";
pub const CONNECTIONS: &str = "bowloc_http_connections_open";
pub const CONNECTION_ERRORS: &str = "bowloc_http_connection_errors_total";
pub const LOCALIZE_DURATION: &str = "bowloc_localize_duration_seconds";
pub const STAGE_DURATION: &str = "bowloc_localize_stage_duration_seconds";
pub const RATIO_USED: &str = "bowloc_localize_features_used_ratio";
pub const QUERY_FEATURES: &str = "bowloc_localize_query_features";
pub const TILES_RATIO: &str = "bowloc_localize_tiles_extracted_ratio";
pub const EXTRACTION_SAVED: &str = "bowloc_localize_extraction_saved_seconds";
pub const TILES_AHEAD: &str = "bowloc_localize_tiles_ahead_total";
pub const STOPS: &str = "bowloc_localize_stops_total";
pub const VERIFY_DURATION: &str = "bowloc_verify_duration_seconds";
pub const VERIFY_INLIERS: &str = "bowloc_verify_top_inliers";
pub const VERIFIED: &str = "bowloc_verify_answers_total";
pub const ORB_PASS: &str = "bowloc_orb_pass_queries_total";
pub const WORKERS: &str = "bowloc_workers";
pub const WORKERS_BUSY: &str = "bowloc_workers_busy";
pub const QUEUE_WAITING: &str = "bowloc_queue_waiting";
pub const QUEUE_CAPACITY: &str = "bowloc_queue_capacity";
pub const READY: &str = "bowloc_ready";
pub const MAP_IMAGES: &str = "bowloc_map_images";
pub const MAP_WORDS: &str = "bowloc_map_words";
pub const MAP_POSTINGS: &str = "bowloc_map_postings";
pub const BUILD_INFO: &str = "bowloc_build_info";
pub const SEQUENCES: &str = "bowloc_sequences_live";
pub const PLAN_COST: &str = "bowloc_extraction_plan_typical_seconds";
pub const PLAN_REQUESTS: &str = "bowloc_extraction_plan_requests_total";
pub const KEYPOINT_COST: &str = "bowloc_tile_keypoint_seconds";
pub const FIRST_TILES_COST: &str = "bowloc_tile_first_tiles_seconds";
pub const SEQUENCE_EVICTIONS: &str = "bowloc_sequence_evictions_total";
pub const SEQUENCE_RESTARTS: &str = "bowloc_sequence_restarts_total";

/// The process's recorder. Installed by the first caller; later callers (a
/// test building several routers) share it.
pub fn install() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let latency = [
                0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
            ];
            let fraction = [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0];
            let features = [
                0.0, 50.0, 100.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0,
            ];
            let inliers = [0.0, 4.0, 8.0, 12.0, 16.0, 24.0, 32.0, 50.0, 100.0, 200.0];
            let handle = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), &latency)
                .and_then(|b| b.set_buckets_for_metric(Matcher::Full(RATIO_USED.into()), &fraction))
                .and_then(|b| {
                    b.set_buckets_for_metric(Matcher::Full(TILES_RATIO.into()), &fraction)
                })
                .and_then(|b| {
                    b.set_buckets_for_metric(Matcher::Full(QUERY_FEATURES.into()), &features)
                })
                .and_then(|b| {
                    b.set_buckets_for_metric(Matcher::Full(VERIFY_INLIERS.into()), &inliers)
                })
                .expect("bucket lists are not empty")
                .install_recorder()
                .expect("no other metrics recorder is installed");
            describe();
            zero_counters();
            process().describe();
            gauge!(BUILD_INFO, "version" => env!("CARGO_PKG_VERSION")).set(1.0);
            handle
        })
        .clone()
}

fn describe() {
    describe_counter!(
        HTTP_REQUESTS,
        "HTTP requests answered, by route, method and status."
    );
    describe_histogram!(
        HTTP_DURATION,
        Unit::Seconds,
        "Time to answer an HTTP request, by route."
    );
    describe_gauge!(HTTP_IN_FLIGHT, "HTTP requests being answered now.");
    describe_counter!(
        HTTP_ERRORS,
        "Requests answered with an error, by status and error code."
    );
    describe_counter!(
        REJECTED,
        "Requests refused with 503 without being answered, by error code (reason): overloaded, queue_timeout, deadline_exceeded, not_ready, shutting_down."
    );
    describe_gauge!(CONNECTIONS, "TCP connections open now.");
    describe_counter!(
        CONNECTION_ERRORS,
        "Connections that ended in an error before reaching a route, by kind: malformed_request (answered 400 or 414 by the HTTP layer), headers_too_large (431 from the HTTP layer), header_timeout (headers not complete within server.header_timeout_ms, idle connections included), incomplete_request, io, accept."
    );
    describe_histogram!(
        LOCALIZE_DURATION,
        Unit::Seconds,
        "Time of a localization on its worker, all stages."
    );
    describe_histogram!(
        STAGE_DURATION,
        Unit::Seconds,
        "Time per stage of a localization: decode, extract, quantize and vote, and the ORB pass (orb_pass) when it ran."
    );
    describe_histogram!(
        RATIO_USED,
        "Ratio of a query's features used before the search stopped (0 to 1)."
    );
    describe_histogram!(QUERY_FEATURES, "Features extracted from a query image.");
    describe_histogram!(
        TILES_RATIO,
        "Ratio of a query's tiles extracted before the search stopped (streaming extraction)."
    );
    describe_histogram!(
        EXTRACTION_SAVED,
        Unit::Seconds,
        "Extraction time saved by stopping before the last tile: what the tiles left were expected to take (the answer's tiles.saved_ms)."
    );
    describe_counter!(
        TILES_AHEAD,
        "Tiles extracted ahead of their turn on a core that would otherwise idle (server.tiles_ahead), by whether the search used them (used=false: it stopped before)."
    );
    describe_counter!(
        STOPS,
        "Searches by why they stopped: rule, exhausted or deadline."
    );
    describe_histogram!(
        VERIFY_DURATION,
        Unit::Seconds,
        "Time of geometric verification (matching and model fits of the top k candidates), for queries verified."
    );
    describe_histogram!(
        VERIFY_INLIERS,
        "Inliers of the best candidate after verification."
    );
    describe_counter!(
        VERIFIED,
        "Verified queries by whether the best candidate was verified (true/false)."
    );
    describe_counter!(
        ORB_PASS,
        "Queries the ORB pass looked at first, by whether it answered them without SIFT (true/false)."
    );
    describe_gauge!(WORKERS, "Worker threads for CPU work.");
    describe_gauge!(WORKERS_BUSY, "Workers running a query now.");
    describe_gauge!(QUEUE_WAITING, "Requests waiting for a free worker.");
    describe_gauge!(
        QUEUE_CAPACITY,
        "Requests that may wait before new ones are refused."
    );
    describe_gauge!(
        READY,
        "1 once the map is loaded and the service takes traffic."
    );
    describe_gauge!(MAP_IMAGES, "Images in the loaded map.");
    describe_gauge!(MAP_WORDS, "Visual words of the loaded vocabulary.");
    describe_gauge!(
        MAP_POSTINGS,
        "(word, image) entries of the loaded map's inverted index."
    );
    describe_gauge!(BUILD_INFO, "Always 1; the version is a label.");
    describe_gauge!(SEQUENCES, "Sequences kept now (/localize?sequence=NAME).");
    describe_gauge!(
        PLAN_COST,
        Unit::Seconds,
        "Typical request time (geometric mean, without decoding) of streaming extraction with and without the coarse pass, as the learned choice (search.tiles ending in ,auto) sees it."
    );
    describe_counter!(
        PLAN_REQUESTS,
        "Requests whose extraction plan the learned choice (search.tiles ending in ,auto) drew, by plan: tiles alone or the coarse pass first."
    );
    describe_gauge!(
        KEYPOINT_COST,
        Unit::Seconds,
        "What one keypoint adds to a tile's time (extraction, quantization, votes, checks), as the service has learnt it from the requests served; a time budget prices the next tile with it."
    );
    describe_gauge!(
        FIRST_TILES_COST,
        Unit::Seconds,
        format!(
            "What the first {} tiles of a request in the configured grid have taken lately together, each place in the order at its own mean, extracted one at a time; a time budget under it starts with the coarse pass (with a spare core, two at a time, under the longer tile of each pair).",
            crate::search::budget::TILES_TO_BEAT_THE_PASS
        )
    );
    describe_counter!(
        SEQUENCE_EVICTIONS,
        "Sequences dropped, by reason: capacity (least recently used beyond sequence.max_sequences) or idle."
    );
    describe_counter!(
        SEQUENCE_RESTARTS,
        "Frames that started a sequence afresh, by reason: first, out_of_order, gap."
    );
}

/// Sequences kept now.
pub fn sequences_live(n: usize) {
    gauge!(SEQUENCES).set(n as f64);
}

/// A sequence was dropped (`capacity` or `idle`).
pub fn sequence_evicted(reason: &'static str) {
    counter!(SEQUENCE_EVICTIONS, "reason" => reason).increment(1);
}

/// A frame started its sequence afresh.
pub fn sequence_restarted(reason: &'static str) {
    counter!(SEQUENCE_RESTARTS, "reason" => reason).increment(1);
}

/// One answered HTTP request.
pub fn request(route: &str, method: &str, status: u16, elapsed: Duration) {
    counter!(
        HTTP_REQUESTS,
        "route" => route.to_owned(),
        "method" => method.to_owned(),
        "status" => status.to_string()
    )
    .increment(1);
    histogram!(HTTP_DURATION, "route" => route.to_owned()).record(elapsed.as_secs_f64());
}

/// Requests in flight went up (`+1`) or down (`-1`).
pub fn in_flight(delta: f64) {
    gauge!(HTTP_IN_FLIGHT).increment(delta);
}

/// Kinds of [`CONNECTION_ERRORS`].
pub const CONNECTION_ERROR_KINDS: [&str; 6] = [
    "malformed_request",
    "headers_too_large",
    "header_timeout",
    "incomplete_request",
    "io",
    "accept",
];

/// The labelled counters whose labels are known, at 0.
fn zero_counters() {
    for &(status, code) in super::errors::CODES {
        counter!(HTTP_ERRORS, "status" => status.to_string(), "code" => code).absolute(0);
        if status == 503 {
            counter!(REJECTED, "reason" => code).absolute(0);
        }
    }
    for kind in CONNECTION_ERROR_KINDS {
        counter!(CONNECTION_ERRORS, "kind" => kind).absolute(0);
    }
    use crate::search::StopKind;
    for kind in StopKind::ALL {
        counter!(STOPS, "kind" => kind.name()).absolute(0);
    }
    for flag in ["true", "false"] {
        counter!(VERIFIED, "verified" => flag).absolute(0);
        counter!(ORB_PASS, "answered" => flag).absolute(0);
    }
    for plan in crate::features::CoarseChoice::PLANS {
        counter!(PLAN_REQUESTS, "plan" => plan).absolute(0);
    }
    for reason in ["capacity", "idle"] {
        counter!(SEQUENCE_EVICTIONS, "reason" => reason).absolute(0);
    }
    for reason in ["first", "out_of_order", "gap"] {
        counter!(SEQUENCE_RESTARTS, "reason" => reason).absolute(0);
    }
    gauge!(SEQUENCES).set(0.0);
}

/// The collector of the process's own metrics.
fn process() -> &'static metrics_process::Collector {
    static COLLECTOR: OnceLock<metrics_process::Collector> = OnceLock::new();
    COLLECTOR.get_or_init(metrics_process::Collector::default)
}

/// Read the process's memory, open files and CPU time (before a scrape).
pub fn collect_process() {
    process().collect();
}

/// The exposition text of every metric. `process_cpu_seconds_total` is
/// recorded as a gauge, because the `metrics` crate's counters hold whole
/// numbers and CPU time is fractional seconds; it only ever grows, so it is
/// typed a counter here, as Prometheus' own clients export it.
pub fn render(handle: &PrometheusHandle) -> String {
    retype_as_counter(handle.render(), PROCESS_CPU_SECONDS)
}

const PROCESS_CPU_SECONDS: &str = "process_cpu_seconds_total";

fn retype_as_counter(text: String, name: &str) -> String {
    text.replacen(
        &format!("# TYPE {name} gauge\n"),
        &format!("# TYPE {name} counter\n"),
        1,
    )
}

/// A request answered with an error; a 503 is also a rejection.
pub fn error(status: u16, code: &'static str) {
    counter!(HTTP_ERRORS, "status" => status.to_string(), "code" => code).increment(1);
    if status == 503 {
        counter!(REJECTED, "reason" => code).increment(1);
    }
}

/// TCP connections open went up (`+1`) or down (`-1`).
pub fn connections(delta: f64) {
    gauge!(CONNECTIONS).increment(delta);
}

/// A connection ended in an error of this kind (one of
/// [`CONNECTION_ERROR_KINDS`]).
pub fn connection_error(kind: &'static str) {
    counter!(CONNECTION_ERRORS, "kind" => kind).increment(1);
}

/// A localization answered.
pub fn localized(answer: &Localization) {
    let t = &answer.timings_ms;
    for (stage, ms) in [
        ("decode", t.decode),
        ("extract", t.extract),
        ("quantize", t.quantize),
        ("vote", t.vote),
    ] {
        histogram!(STAGE_DURATION, "stage" => stage).record(ms / 1e3);
    }
    histogram!(LOCALIZE_DURATION).record(t.total / 1e3);
    histogram!(RATIO_USED).record(answer.features.fraction);
    histogram!(QUERY_FEATURES).record(answer.features.total as f64);
    let tiles = &answer.tiles;
    if tiles.total > 0 && tiles.extracted > 0 {
        histogram!(TILES_RATIO).record(tiles.extracted as f64 / tiles.total as f64);
        histogram!(EXTRACTION_SAVED).record(tiles.saved_ms / 1e3);
    }
    let (ahead, unused) = (tiles.ahead.extracted as u64, u64::from(tiles.ahead.unused));
    if ahead > 0 {
        counter!(TILES_AHEAD, "used" => "true").increment(ahead - unused);
        counter!(TILES_AHEAD, "used" => "false").increment(unused);
    }
    counter!(STOPS, "kind" => answer.stop.kind.name()).increment(1);
    if let Some(verified) = answer.verified {
        histogram!(VERIFY_DURATION).record(t.verify / 1e3);
        let top = answer.candidates.first().and_then(|c| c.inliers);
        histogram!(VERIFY_INLIERS).record(top.unwrap_or(0) as f64);
        counter!(VERIFIED, "verified" => verified.to_string()).increment(1);
    }
    if let Some(pass) = answer.orb_pass {
        histogram!(STAGE_DURATION, "stage" => "orb_pass").record(t.orb_pass / 1e3);
        counter!(ORB_PASS, "answered" => pass.answered.to_string()).increment(1);
    }
}

/// The plan the learned coarse pass drew for a request, and what it has
/// measured of each plan.
pub fn coarse_choice(choice: &crate::features::CoarseChoice, plan: &crate::pipeline::Plan) {
    if plan.learned() {
        let drawn = crate::features::CoarseChoice::plan_name(plan.grid.coarse);
        counter!(PLAN_REQUESTS, "plan" => drawn).increment(1);
    }
    plan_costs(choice);
}

/// What the learned coarse pass has measured of each plan: its typical
/// request (set once a plan has been measured).
pub fn plan_costs(choice: &crate::features::CoarseChoice) {
    for (plan, arm) in choice.learned().plans() {
        if arm.samples > 0 {
            gauge!(PLAN_COST, "plan" => plan).set(arm.typical_ms() / 1e3);
        }
    }
}

/// What tiles cost, as the localizer has learnt it: a keypoint, and the
/// first tiles a time budget plans on.
pub fn tile_cost(cost: &crate::search::budget::TileCostModel) {
    gauge!(KEYPOINT_COST).set(cost.per_keypoint().as_secs_f64());
    if let Some(first) = cost.tiles_to_beat_the_pass(false) {
        gauge!(FIRST_TILES_COST).set(first.as_secs_f64());
    }
}

/// The worker pool's size and occupancy.
pub fn pool(workers: usize, busy: usize, waiting: usize, capacity: usize) {
    gauge!(WORKERS).set(workers as f64);
    gauge!(WORKERS_BUSY).set(busy as f64);
    gauge!(QUEUE_WAITING).set(waiting as f64);
    gauge!(QUEUE_CAPACITY).set(capacity as f64);
}

/// The map is loaded.
pub fn map_loaded(map: &dyn MapRead) {
    let m = map.meta();
    gauge!(MAP_IMAGES).set(m.images as f64);
    gauge!(MAP_WORDS).set(m.words as f64);
    gauge!(MAP_POSTINGS).set(m.postings as f64);
}

pub fn ready(ready: bool) {
    gauge!(READY).set(if ready { 1.0 } else { 0.0 });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_seconds_are_typed_a_counter_and_keep_their_fraction() {
        let text = "# HELP process_cpu_seconds_total Total CPU time.\n\
                    # TYPE process_cpu_seconds_total gauge\n\
                    process_cpu_seconds_total 1.25\n\
                    # TYPE process_open_fds gauge\n\
                    process_open_fds 12\n";
        let out = retype_as_counter(text.to_string(), PROCESS_CPU_SECONDS);
        assert!(out.contains("# TYPE process_cpu_seconds_total counter\n"));
        assert!(out.contains("process_cpu_seconds_total 1.25\n"));
        assert!(out.contains("# TYPE process_open_fds gauge\n"));
        // a text without it is left alone
        let other = "# TYPE process_open_fds gauge\nprocess_open_fds 12\n";
        assert_eq!(
            retype_as_counter(other.to_string(), PROCESS_CPU_SECONDS),
            other
        );
    }
}

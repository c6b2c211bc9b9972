//! The service's configuration: its shape and built-in defaults (which
//! `config/default.toml` documents key by key), loading it from the TOML file
//! and `BOWLOC_` environment variables with figment, and checking every value
//! before start-up goes on. Command-line flags are applied by the caller with
//! [`Config::apply`].

use crate::geometry::verify::VerifyParams;
use crate::quantize::QuantizerKind;
use crate::search::{RuleSpec, SearchOptions, SpareCore};
use crate::sequence::{Motion, SequenceModel, TopologyKind};
use figment::Figment;
use figment::providers::{Env, Format, Serialized, Toml};
use serde::{Deserialize, Serialize};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Environment variables with this prefix override keys: `BOWLOC_SEARCH__TOP_N=3`
/// sets `search.top_n` (`__` separates a section from its key).
pub const ENV_PREFIX: &str = "BOWLOC_";

/// The configuration file `bowloc serve` reads when none is named, relative
/// to the working directory (the repository's, which documents every key).
pub const DEFAULT_FILE: &str = "config/default.toml";

/// Everything `bowloc serve` reads at start-up.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub server: ServerConfig,
    pub files: FilesConfig,
    pub search: SearchDefaults,
    pub limits: Limits,
    pub bootstrap: BootstrapConfig,
    /// Geometric verification of the top vote candidates.
    pub verify: VerifyParams,
    /// Sequences of frames (`/localize?sequence=NAME`).
    pub sequence: SequenceConfig,
    /// Who may change the map.
    pub auth: AuthConfig,
    /// The map's changes: compaction and size cap.
    pub changes: ChangesConfig,
    /// The ORB pass: a cheap first look before SIFT, from the map's ORB side.
    pub orb_pass: crate::orb_pass::OrbPassParams,
}

/// Sequences: their bounds, the map's topology and the filter's model
/// (docs/service.md, "Sequences").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SequenceConfig {
    /// Sequences kept at once; beyond, the least recently used is dropped.
    pub max_sequences: usize,
    /// A sequence without a frame for this long is dropped.
    pub idle_ms: u64,
    /// Which map images neighbour: `auto` (poses x, y when the map has
    /// them, else order), `order`, `poses` or `none`.
    pub topology: TopologyKind,
    /// Rule of a frame that names none (its parameter in `threshold`).
    pub rule: String,
    pub threshold: Option<f64>,
    /// Warm-up of that rule: a number of features, or `auto`
    /// ([`crate::calibrate::auto_warmup`] of the map images' feature counts).
    pub min_features: crate::calibrate::Warmup,
    /// Evidence weight κ: votes h(j) after t features count as κ·h(j)/√t.
    pub kappa: f64,
    /// Map images each sequence's belief tracks.
    pub track: usize,
    /// A gap of more than this many frames restarts a sequence.
    pub max_gap: u64,
    /// The leader's place for the rule `posterior`: images within this
    /// many ids (order topology).
    pub window: u32,
    /// Motion per frame: spread σ, expected move along the order, farthest
    /// move from it, and the chance of a jump anywhere.
    pub sigma: f64,
    pub drift: f64,
    pub reach: f64,
    pub teleport: f64,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        let m = SequenceModel::default();
        Self {
            max_sequences: 10_000,
            idle_ms: 600_000,
            topology: TopologyKind::Auto,
            rule: "posterior".into(),
            threshold: Some(0.7),
            min_features: crate::calibrate::Warmup::Auto,
            kappa: m.kappa,
            track: m.track,
            max_gap: m.max_gap,
            window: m.window,
            sigma: m.motion.sigma,
            drift: m.motion.drift,
            reach: m.motion.reach,
            teleport: m.motion.teleport,
        }
    }
}

impl SequenceConfig {
    /// The filter's model.
    pub fn model(&self) -> SequenceModel {
        SequenceModel {
            motion: Motion {
                sigma: self.sigma,
                drift: self.drift,
                reach: self.reach,
                teleport: self.teleport,
            },
            kappa: self.kappa,
            track: self.track,
            max_gap: self.max_gap,
            window: self.window,
        }
    }

    /// The rule of a frame that names none.
    pub fn rule(&self) -> Result<RuleSpec, String> {
        RuleSpec::new(&self.rule, self.threshold)
    }

    pub fn idle(&self) -> Duration {
        Duration::from_millis(self.idle_ms)
    }
}

/// The token the write endpoints require (`Authorization: Bearer TOKEN`);
/// without one they are disabled.
#[derive(Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AuthConfig {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub write_token: Option<String>,
}

impl std::fmt::Debug for AuthConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // never print the token
        let token = self.write_token.as_ref().map(|_| "…");
        f.debug_struct("AuthConfig")
            .field("write_token", &token)
            .finish()
    }
}

/// Least length of a write token.
pub const MIN_TOKEN_LEN: usize = 16;

/// When the change log is folded into the map file, and how large the map
/// may grow.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChangesConfig {
    /// Compact this often (seconds) when there are changes; 0 = never on a schedule.
    pub compact_interval_s: u64,
    /// Compact once the change log holds this many bytes; 0 = never on size.
    pub compact_log_bytes: u64,
    /// Most images the map may hold; an add beyond is refused.
    pub max_images: usize,
}

impl Default for ChangesConfig {
    fn default() -> Self {
        Self {
            compact_interval_s: 3600,
            compact_log_bytes: 64 << 20,
            max_images: 1_000_000,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServerConfig {
    /// Address and port to listen on.
    pub listen: SocketAddr,
    /// Threads doing CPU work (decode, SIFT, quantize, vote); 0 = one per core.
    pub workers: usize,
    /// OpenCV threads each worker's SIFT extraction may fan out to.
    pub opencv_threads: usize,
    /// While a core would idle, a streamed query extracts its next tile
    /// together with the one after it, on that core.
    pub tiles_ahead: bool,
    /// Before the service is ready, each worker answers a synthetic query
    /// ([`crate::pipeline::Localizer::warm_up`]), so that the first requests
    /// do not pay for a thread's first extraction.
    pub warm_up: bool,
    pub log_format: LogFormat,
    /// Connections open at once; beyond, new ones wait in the listen backlog.
    pub max_connections: usize,
    /// Time a connection may take to send a request's headers, also while
    /// idle between requests.
    pub header_timeout_ms: u64,
    /// Longest pause while a request body arrives.
    pub body_timeout_ms: u64,
    /// After SIGTERM, time requests in flight have to finish.
    pub drain_ms: u64,
    /// Origins of web pages elsewhere that may call the API from a
    /// browser ([`super::cors`]); `["*"]` lets every origin in.
    pub cors_origins: Vec<String>,
    /// Answers gzip-compressed for clients that accept it (JSON, protobuf,
    /// the metrics and the page; never the JPEG thumbnails).
    pub compression: bool,
    /// HTTP/2 without TLS beside HTTP/1.1 on the same port, for clients
    /// that start with HTTP/2's preface ([`super::connections`]).
    pub http2: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    Human,
    Json,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FilesConfig {
    pub vocabulary: PathBuf,
    pub map: PathBuf,
    /// Recompute every checksum when loading.
    pub verify: bool,
    /// The folder the map's image names are relative to (the dataset it
    /// was built from): `GET /images/{id}/thumbnail` reads image `id` from
    /// it. Empty: no thumbnails (404).
    pub images: PathBuf,
}

/// Search settings used when a request does not give them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SearchDefaults {
    pub rule: String,
    /// Parameter of `rule`, when it takes one (`bowloc rules` names each).
    /// Absent: the built-in rule's own when `rule` is the built-in one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// Also stop when the answer is verified with this many inliers at the
    /// query's scale (a vote rule only). 0: no such check. Absent: the
    /// built-in rule's own when `rule` is the built-in one, else none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub or_verified: Option<u32>,
    pub top_n: usize,
    pub min_features: usize,
    pub block: usize,
    pub min_score: f32,
    /// Candidates less distinct than this are dropped from answers (0: none).
    pub min_distinct: f32,
    /// `exact` or `tree` (approximate, for vocabularies of 50 000 words and more).
    pub quantizer: String,
    /// Groups the tree quantizer searches per descriptor.
    pub tree_probes: usize,
    /// Streaming extraction: `COLSxROWS+MARGIN` tiles extracted one by one
    /// until the rule stops the search; `1x1` extracts the whole image first;
    /// a `,coarse` suffix extracts the whole image at half size first; an
    /// `,auto` suffix learns for the map whether to ([`crate::features::CoarseChoice`]).
    pub tiles: String,
    /// With `,auto`, keep what the service learned of each plan in a file
    /// beside the map (`<map>.plan.json`), so a restart on the same map,
    /// machine and settings goes on from it instead of trying both plans
    /// again ([`super::plan_memory`]).
    pub remember_plan: bool,
    /// The order tiles are extracted in: `richest` (most FAST corners first),
    /// `spread` (the richest, then the farthest from those taken)
    /// or `random`.
    pub tile_order: crate::search::TileOrder,
    /// Weigh votes by the features' Hamming signatures (false: plain tf-idf).
    pub hamming: bool,
    /// Images on each side, along the map's order, that count as one place
    /// when a candidate's distinctness is measured (0: each image alone).
    pub place_window: u32,
    /// A time budget in milliseconds from the start of decoding: a streamed
    /// query's next tile is extracted only when it is expected to end within
    /// it (the first tile always). Absent: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub budget_ms: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Limits {
    /// Largest request body.
    pub body_bytes: usize,
    /// Largest image (width × height), checked from the header before decoding.
    pub pixels: u64,
    /// Keep at most this many strongest features of a query (0 = all).
    pub max_features: u32,
    /// Largest `top_n` a request may ask for.
    pub max_top_n: usize,
    /// Requests that may wait for a worker; beyond that the answer is 503.
    pub queue: usize,
    /// Time a request may take, queueing included.
    pub deadline_ms: u64,
    /// Most header fields of a request (431 beyond).
    pub headers: usize,
    /// Most bytes of a request's header fields, names and values (431 beyond).
    pub header_bytes: usize,
}

/// Building a default vocabulary and map from a dataset when the configured
/// files are missing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BootstrapConfig {
    pub enabled: bool,
    /// A dataset folder in the shared layout (its `map.txt` is used).
    pub dataset: PathBuf,
    /// Visual words K.
    pub words: usize,
    /// k-means seed.
    pub seed: u64,
}

/// The cores this process may use, read once (the standard library reads
/// the cgroup's quota from files each time it is asked, and every request
/// asks).
fn machine_cores() -> usize {
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            workers: 0,
            opencv_threads: 1,
            tiles_ahead: true,
            warm_up: true,
            log_format: LogFormat::Human,
            max_connections: 256,
            header_timeout_ms: 10_000,
            body_timeout_ms: 10_000,
            drain_ms: 12_000,
            cors_origins: Vec::new(),
            compression: true,
            http2: true,
        }
    }
}

impl Default for FilesConfig {
    fn default() -> Self {
        Self {
            vocabulary: PathBuf::from("data/default/vocab.bowvoc"),
            map: PathBuf::from("data/default/map.bowmap"),
            verify: true,
            images: PathBuf::from("../shared/datasets/gardens-point"),
        }
    }
}

impl Default for SearchDefaults {
    fn default() -> Self {
        // The same defaults as every front end's.
        let o = SearchOptions::recommended();
        Self {
            // the built-in rule's, by default_rule(): a file naming another
            // rule need not unset them
            threshold: None,
            or_verified: None,
            rule: o.rule.name,
            top_n: o.top_n,
            min_features: o.min_features,
            block: o.block,
            min_score: o.min_score,
            min_distinct: o.min_distinct,
            quantizer: "exact".into(),
            tree_probes: 16,
            tiles: crate::features::TilePlan {
                grid: crate::features::TileGrid::DEFAULT,
                learn_coarse: true,
            }
            .to_string(),
            remember_plan: true,
            tile_order: o.tile_order,
            hamming: o.hamming.is_some(),
            place_window: o.place_window,
            budget_ms: None,
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            body_bytes: 10 * 1024 * 1024,
            pixels: 40_000_000,
            max_features: 4000,
            max_top_n: 100,
            queue: 32,
            deadline_ms: 10_000,
            headers: 100,
            header_bytes: 64 * 1024,
        }
    }
}

impl Default for BootstrapConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            dataset: PathBuf::from("../shared/datasets/gardens-point"),
            words: 2000,
            seed: 1,
        }
    }
}

/// Values given on the command line; each one set replaces the configured one.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    pub listen: Option<SocketAddr>,
    pub vocabulary: Option<PathBuf>,
    pub map: Option<PathBuf>,
    pub workers: Option<usize>,
    pub log_format: Option<LogFormat>,
}

/// A configuration that cannot be used, naming the key at fault and, when
/// known, where its value came from.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct ConfigError {
    /// The key (or keys, `a / b`) at fault, when one is.
    pub key: Option<String>,
    pub message: String,
}

impl ConfigError {
    fn new(message: String) -> Self {
        Self { key: None, message }
    }

    fn at(key: &str, why: impl std::fmt::Display) -> Self {
        Self {
            key: Some(key.to_owned()),
            message: format!("{key}: {why}"),
        }
    }

    /// Say where the values of the keys at fault came from (the file, or
    /// the environment variable by its name), as `figment` recorded it.
    fn with_sources(mut self, figment: &Figment) -> Self {
        let Some(keys) = &self.key else { return self };
        let sources: Vec<String> = keys
            .split(" / ")
            .filter_map(|key| {
                let m = figment.find_metadata(key)?;
                let path: Vec<&str> = key.split('.').collect();
                source(m, &path).map(|from| format!("{key} from {from}"))
            })
            .collect();
        if !sources.is_empty() {
            self.message = format!("{} ({})", self.message, sources.join(", "));
        }
        self
    }
}

/// Where a value came from: the file, or the environment variables under
/// `path` by their full names; `None` for a built-in default.
fn source(m: &figment::Metadata, path: &[&str]) -> Option<String> {
    if m.name.contains("environment") {
        let upper: Vec<String> = path.iter().map(|p| p.to_ascii_uppercase()).collect();
        let name = format!("{ENV_PREFIX}{}", upper.join("__"));
        // A section named alone (an unknown one) stands for every variable
        // below it: name those in full.
        let mut full: Vec<String> = std::env::vars_os()
            .filter_map(|(k, _)| k.into_string().ok())
            .filter(|k| {
                k.eq_ignore_ascii_case(&name)
                    || k.to_ascii_uppercase().starts_with(&format!("{name}__"))
            })
            .collect();
        full.sort();
        if full.is_empty() {
            full.push(name);
        }
        let noun = if full.len() == 1 {
            "variable"
        } else {
            "variables"
        };
        return Some(format!("environment {noun} {}", full.join(", ")));
    }
    match &m.source {
        Some(figment::Source::Code(_)) => None,
        Some(s) => Some(s.to_string()),
        None => Some(m.name.to_string()),
    }
}

/// One configuration error: the key, what is wrong, and where the value came
/// from (the file, or the environment variable by its name).
fn describe(e: figment::Error) -> String {
    let mut path: Vec<&str> = e.path.iter().map(String::as_str).collect();
    if let figment::error::Kind::UnknownField(name, _) = &e.kind {
        // the unknown key itself, so its source is named in full
        if path.last() != Some(&name.as_str()) {
            path.push(name);
        }
    }
    let key = e.path.join(".").to_ascii_lowercase();
    let from = e
        .metadata
        .as_ref()
        .and_then(|m| source(m, &path))
        .unwrap_or_else(|| "configuration".into());
    if key.is_empty() {
        format!("{} ({from})", e.kind)
    } else {
        format!("{key}: {} ({from})", e.kind)
    }
}

/// The configuration key [`crate::features::KEEP_BUFFERS_VAR`] would be
/// read as: not one, it is set for the process before any configuration.
fn keep_buffers_key() -> String {
    crate::features::KEEP_BUFFERS_VAR
        .trim_start_matches(ENV_PREFIX)
        .to_lowercase()
}

impl Config {
    /// Built-in defaults, then the TOML file at `path`, then `BOWLOC_`
    /// environment variables (but the process's own,
    /// [`KEEP_BUFFERS_VAR`](crate::features::KEEP_BUFFERS_VAR)); checked.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        if path.is_dir() {
            return Err(ConfigError::new(format!(
                "{}: is a directory, not a configuration file",
                path.display()
            )));
        }
        if !path.is_file() {
            let place = match std::env::current_dir() {
                Ok(dir) if path.is_relative() => {
                    format!(" in the working directory {}", dir.display())
                }
                _ => String::new(),
            };
            return Err(ConfigError::new(format!(
                "{}: configuration file not found{place}",
                path.display()
            )));
        }
        Self::extract(Some(path))
    }

    /// Built-in defaults (the values [`DEFAULT_FILE`] documents), then
    /// `BOWLOC_` environment variables; checked. What `bowloc serve` runs on
    /// where no configuration file is named and none is at [`DEFAULT_FILE`].
    pub fn load_without_file() -> Result<Self, ConfigError> {
        Self::extract(None)
    }

    fn extract(path: Option<&Path>) -> Result<Self, ConfigError> {
        let mut figment = Figment::from(Serialized::defaults(Config::default()));
        if let Some(path) = path {
            figment = figment.merge(Toml::file_exact(path));
        }
        let figment = figment.merge(
            Env::prefixed(ENV_PREFIX)
                .ignore(&[keep_buffers_key().as_str()])
                .split("__"),
        );
        let config: Config = figment.extract().map_err(|e| {
            let all: Vec<String> = e.into_iter().map(describe).collect();
            ConfigError::new(format!("invalid configuration: {}", all.join("; ")))
        })?;
        config.check().map_err(|e| e.with_sources(&figment))?;
        Ok(config)
    }

    /// Apply command-line values, then check again.
    pub fn apply(mut self, o: &Overrides) -> Result<Self, ConfigError> {
        if let Some(v) = o.listen {
            self.server.listen = v;
        }
        if let Some(v) = &o.vocabulary {
            self.files.vocabulary = v.clone();
        }
        if let Some(v) = &o.map {
            self.files.map = v.clone();
        }
        if let Some(v) = o.workers {
            self.server.workers = v;
        }
        if let Some(v) = o.log_format {
            self.server.log_format = v;
        }
        self.check()?;
        Ok(self)
    }

    /// Values serde accepts but the service cannot work with.
    pub fn check(&self) -> Result<(), ConfigError> {
        let bad = |key: &str, why: String| Err(ConfigError::at(key, why));
        let s = &self.search;
        if let Err(e) = self.default_rule() {
            return bad("search.rule / search.threshold / search.or_verified", e);
        }
        if let Err(e) = self.quantizer() {
            return bad("search.quantizer / search.tree_probes", e);
        }
        if let Err(e) = self.tiles() {
            return bad("search.tiles", e);
        }
        if s.top_n == 0 || s.top_n > self.limits.max_top_n {
            return bad(
                "search.top_n",
                format!(
                    "must lie in 1..=limits.max_top_n ({}), got {}",
                    self.limits.max_top_n, s.top_n
                ),
            );
        }
        if s.block == 0 {
            return bad("search.block", "must be at least 1".into());
        }
        if !(s.min_score.is_finite() && s.min_score >= 0.0) {
            return bad(
                "search.min_score",
                format!("must be a finite number ≥ 0, got {}", s.min_score),
            );
        }
        if let Err(e) = SearchOptions::check_min_distinct(s.min_distinct.into()) {
            return bad("search.min_distinct", e);
        }
        if let Err(e) = SearchOptions::check_place_window(s.place_window) {
            return bad("search.place_window", e);
        }
        if let Some(Err(e)) = s.budget_ms.map(crate::search::budget::check_ms) {
            return bad("search.budget_ms", e);
        }
        if self.server.opencv_threads == 0 {
            return bad("server.opencv_threads", "must be at least 1".into());
        }
        let l = &self.limits;
        if l.body_bytes == 0 {
            return bad("limits.body_bytes", "must be at least 1".into());
        }
        if l.pixels == 0 {
            return bad("limits.pixels", "must be at least 1".into());
        }
        if l.max_top_n == 0 {
            return bad("limits.max_top_n", "must be at least 1".into());
        }
        if l.deadline_ms == 0 {
            return bad("limits.deadline_ms", "must be at least 1".into());
        }
        for (key, value) in [
            ("server.max_connections", self.server.max_connections as u64),
            ("server.header_timeout_ms", self.server.header_timeout_ms),
            ("server.body_timeout_ms", self.server.body_timeout_ms),
            ("limits.headers", l.headers as u64),
        ] {
            if value == 0 {
                return bad(key, "must be at least 1".into());
            }
        }
        if l.header_bytes < 1024 {
            return bad(
                "limits.header_bytes",
                format!("must be at least 1024, got {}", l.header_bytes),
            );
        }
        if let Err(e) = super::cors::check(&self.server.cors_origins) {
            return bad("server.cors_origins", e);
        }
        if self.server.workers > 4096 {
            return bad(
                "server.workers",
                format!(
                    "{} threads is more than any machine needs",
                    self.server.workers
                ),
            );
        }
        if let Err(e) = self.verify.validate() {
            return bad("verify", e);
        }
        if let Err(e) = self.orb_pass.validate() {
            return bad("orb_pass", e);
        }
        let q = &self.sequence;
        if let Err(e) = q.model().check() {
            return bad("sequence", e);
        }
        if let Err(e) = q.rule() {
            return bad("sequence.rule / sequence.threshold", e);
        }
        if q.max_sequences == 0 || q.idle_ms == 0 {
            return bad(
                "sequence.max_sequences / sequence.idle_ms",
                "must be at least 1".into(),
            );
        }
        if let Some(t) = &self.auth.write_token
            && (t.len() < MIN_TOKEN_LEN || !t.bytes().all(|b| b.is_ascii_graphic()))
        {
            return bad(
                "auth.write_token",
                format!(
                    "must be at least {MIN_TOKEN_LEN} printable ASCII characters without spaces"
                ),
            );
        }
        if self.changes.max_images == 0 {
            return bad("changes.max_images", "must be at least 1".into());
        }
        if self.bootstrap.enabled && self.bootstrap.words < 2 {
            return bad("bootstrap.words", "must be at least 2".into());
        }
        Ok(())
    }

    /// The quantizer queries use.
    pub fn quantizer(&self) -> Result<QuantizerKind, String> {
        match (self.search.quantizer.as_str(), self.search.tree_probes) {
            ("exact", _) => Ok(QuantizerKind::Exact),
            ("tree", 0) => Err("tree_probes must be at least 1".into()),
            ("tree", probes) => Ok(QuantizerKind::Tree { probes }),
            (other, _) => Err(format!(
                "unknown quantizer `{other}`; use `exact` or `tree`"
            )),
        }
    }

    /// The tile grid of streaming extraction, and whether its coarse pass
    /// is learned (`,auto`).
    pub fn tiles(&self) -> Result<crate::features::TilePlan, String> {
        self.search.tiles.parse()
    }

    /// The search a request gets when it asks for nothing: the default rule
    /// and the `search` section's settings (a request's seed, deadline,
    /// prior and spare core are its own).
    pub fn search_options(&self) -> Result<crate::search::SearchOptions, String> {
        let s = &self.search;
        Ok(crate::search::SearchOptions {
            rule: self.default_rule()?,
            top_n: s.top_n,
            seed: 0,
            block: s.block,
            min_features: s.min_features,
            min_score: s.min_score,
            min_distinct: s.min_distinct,
            deadline: None,
            // checked with the configuration
            budget: s
                .budget_ms
                .and_then(|ms| crate::search::budget::check_ms(ms).ok()),
            prior: None,
            hamming: s.hamming.then_some(crate::search::HammingWeights::DEFAULT),
            place_window: s.place_window,
            tile_order: s.tile_order,
            // the service votes in a random order
            given_order: false,
            // set per request, when its answer is verified
            finish_tile: false,
            // set per request, from the pool's load
            spare_core: None,
            orb_pass: self.orb_pass.enabled,
        })
    }

    /// The map's ORB side: `orb_pass.file`, else `MAP.orbpass` beside the
    /// map.
    pub fn orb_pass_file(&self) -> std::path::PathBuf {
        match self.orb_pass.file.as_os_str().is_empty() {
            true => crate::orb_pass::file::path_beside(&self.files.map),
            false => self.orb_pass.file.clone(),
        }
    }

    /// The default rule with its parameter and verified stop: those given,
    /// else the built-in rule's own when `search.rule` names it.
    pub fn default_rule(&self) -> Result<RuleSpec, String> {
        let s = &self.search;
        let builtin = SearchOptions::recommended().rule;
        let is_builtin = s.rule == builtin.name;
        let threshold = s.threshold.or(is_builtin.then_some(builtin.parameter));
        let rule = RuleSpec::new(&s.rule, threshold)?;
        if rule.parameter_name().is_none() && s.threshold.is_some() {
            return Err(format!("rule `{}` takes no parameter", rule.name));
        }
        let or_verified = s.or_verified.or(builtin.or_verified.filter(|_| is_builtin));
        rule.or_verified(or_verified.map(f64::from))
            .map_err(|e| format!("{e} (or_verified = 0 turns the check off)"))
    }

    /// Whether a core would idle now, when `admitted` jobs run or wait on
    /// the pool: each takes `opencv_threads` of the machine's cores. `None`
    /// when `server.tiles_ahead` is off.
    pub fn spare_core(
        &self,
        admitted: impl Fn() -> usize + Send + Sync + 'static,
    ) -> Option<SpareCore> {
        let cores = machine_cores();
        let each = self.server.opencv_threads.max(1);
        self.server
            .tiles_ahead
            .then(|| SpareCore::new(move || admitted() * each < cores))
    }

    /// Worker threads: the configured count, or one per core.
    pub fn worker_count(&self) -> usize {
        match self.server.workers {
            0 => machine_cores(),
            n => n,
        }
    }

    pub fn deadline(&self) -> Duration {
        Duration::from_millis(self.limits.deadline_ms)
    }

    /// After SIGTERM, how long requests in flight may still take.
    pub fn drain(&self) -> Duration {
        Duration::from_millis(self.server.drain_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use figment::Jail;

    /// Load `toml` with the variables `env` set (figment's Jail restores the
    /// environment and serializes the tests that use it).
    #[allow(clippy::result_large_err)] // figment's error type, in a test
    fn load_str(toml: &str, env: &[(&str, &str)]) -> Result<Config, String> {
        let mut out = None;
        Jail::expect_with(|jail| {
            jail.create_file("c.toml", toml)?;
            for (k, v) in env {
                jail.set_env(k, v);
            }
            out = Some(Config::load(Path::new("c.toml")).map_err(|e| e.to_string()));
            Ok(())
        });
        out.unwrap()
    }

    fn shipped() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(DEFAULT_FILE)
    }

    #[test]
    fn shipped_file_equals_the_built_in_defaults() {
        let text = std::fs::read_to_string(shipped()).unwrap();
        assert_eq!(load_str(&text, &[]).unwrap(), Config::default());
    }

    #[test]
    #[allow(clippy::result_large_err)] // figment's error type, in a test
    fn without_a_file_the_defaults_and_the_environment_apply_and_are_checked() {
        Jail::expect_with(|jail| {
            assert_eq!(Config::load_without_file().unwrap(), Config::default());
            jail.set_env("BOWLOC_SEARCH__TOP_N", "3");
            assert_eq!(Config::load_without_file().unwrap().search.top_n, 3);
            jail.set_env("BOWLOC_SEARCH__TOP_N", "0");
            let e = Config::load_without_file().unwrap_err().to_string();
            assert!(e.contains("BOWLOC_SEARCH__TOP_N"), "{e}");
            Ok(())
        });
    }

    #[test]
    #[allow(clippy::result_large_err)] // figment's error type, in a test
    fn a_missing_file_is_named_with_the_working_directory_when_relative() {
        Jail::expect_with(|jail| {
            let e = Config::load(Path::new("nothere.toml"))
                .unwrap_err()
                .to_string();
            let dir = jail.directory().canonicalize().unwrap();
            assert!(
                e.starts_with("nothere.toml: configuration file not found"),
                "{e}"
            );
            assert!(e.contains(&dir.display().to_string()), "{e}");
            let e = Config::load(&dir.join("nothere.toml"))
                .unwrap_err()
                .to_string();
            assert!(!e.contains("working directory"), "{e}");
            Ok(())
        });
    }

    #[test]
    fn cors_origins_come_from_the_file_or_the_environment_and_are_checked() {
        let c = load_str(
            "[server]\ncors_origins = [\"https://robots.example\"]\n",
            &[],
        )
        .unwrap();
        assert_eq!(c.server.cors_origins, ["https://robots.example"]);
        let env = [(
            "BOWLOC_SERVER__CORS_ORIGINS",
            "[\"http://10.0.0.7:3000\", \"https://robots.example\"]",
        )];
        let c = load_str("", &env).unwrap();
        assert_eq!(
            c.server.cors_origins,
            ["http://10.0.0.7:3000", "https://robots.example"]
        );
        let e = load_str(
            "[server]\ncors_origins = [\"https://robots.example/\"]\n",
            &[],
        )
        .unwrap_err();
        assert!(
            e.contains("server.cors_origins") && e.contains("no path"),
            "{e}"
        );
    }

    #[test]
    fn every_verification_model_and_estimator_can_be_configured_by_name() {
        use crate::geometry::verify::{Estimator, Model};
        // the file's names (serde's) are the ones the CLI and errors list
        for model in Model::ALL {
            let name = model.name();
            let c = load_str(&format!("[verify]\nmodel = \"{name}\"\n"), &[]).unwrap();
            assert_eq!(c.verify.model, model);
            assert_eq!(name.parse::<Model>(), Ok(model));
        }
        for estimator in Estimator::ALL {
            let name = estimator.name();
            let c = load_str(&format!("[verify]\nestimator = \"{name}\"\n"), &[]).unwrap();
            assert_eq!(c.verify.estimator, estimator);
            assert_eq!(name.parse::<Estimator>(), Ok(estimator));
        }
        let e = "projective".parse::<Model>().unwrap_err();
        assert!(
            e.contains("similarity, homography, fundamental, affine"),
            "{e}"
        );
    }

    #[test]
    fn a_sequence_warm_up_is_auto_or_a_number_of_features() {
        use crate::calibrate::Warmup;
        let warmup = |toml: &str, env: &[(&str, &str)]| {
            load_str(&format!("[sequence]\n{toml}"), env).map(|c| c.sequence.min_features)
        };
        assert_eq!(warmup("", &[]), Ok(Warmup::Auto));
        assert_eq!(warmup("min_features = 40", &[]), Ok(Warmup::Features(40)));
        assert_eq!(warmup("min_features = \"auto\"", &[]), Ok(Warmup::Auto));
        let env = [("BOWLOC_SEQUENCE__MIN_FEATURES", "60")];
        assert_eq!(warmup("", &env), Ok(Warmup::Features(60)));
        let e = warmup("min_features = \"soon\"", &[]).unwrap_err();
        assert!(e.contains("neither a number of features nor `auto`"), "{e}");
        assert!(warmup("min_features = -3", &[]).is_err());
    }

    #[test]
    fn shipped_file_names_every_key() {
        // Every key of the defaults appears in the file (optional keys that
        // default to nothing are documented as comments).
        let text = std::fs::read_to_string(shipped()).unwrap();
        let file: toml::Table = text.parse().unwrap();
        let defaults = toml::Table::try_from(Config::default()).unwrap();
        for (section, keys) in &defaults {
            let keys = keys.as_table().unwrap();
            let in_file = file
                .get(section)
                .and_then(|s| s.as_table())
                .unwrap_or_else(|| panic!("section [{section}] missing"));
            for key in keys.keys() {
                assert!(in_file.contains_key(key), "{section}.{key} missing");
            }
        }
    }

    #[test]
    fn shipped_file_names_every_rule_and_parameter() {
        let text = std::fs::read_to_string(shipped()).unwrap();
        // the comments as one line: the lists may wrap
        let comments = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix('#'))
            .map(str::trim)
            .collect::<Vec<_>>()
            .join(" ");
        // the registry's rules, all of them and in its order
        let rules = crate::search::stop::rule_names().join(", ");
        assert!(
            comments.contains(&rules),
            "config/default.toml must list the rules as `{rules}`"
        );
        let parameters = crate::search::stop::parameter_names().join(", ");
        assert!(
            comments.contains(&parameters),
            "config/default.toml must list the parameters as `{parameters}`"
        );
        // the built-in rule's parameter and warm-up, as its comments state them
        use crate::search::SearchOptions as S;
        for stated in [
            format!("threshold = {:?}", S::RECOMMENDED_PARAMETER),
            format!(
                "`{}` at z = {} after {} features",
                S::RECOMMENDED_RULE,
                S::RECOMMENDED_PARAMETER,
                S::RECOMMENDED_WARMUP
            ),
        ] {
            assert!(
                comments.contains(&stated),
                "config/default.toml must say `{stated}`"
            );
        }
        // every tile order, quoted
        for order in crate::search::TileOrder::ALL {
            let quoted = format!("\"{}\"", order.name());
            assert!(
                comments.contains(&quoted),
                "config/default.toml must describe the tile order {quoted}"
            );
        }
        // every verification order, model and estimator, quoted
        use crate::geometry::verify::{Estimator, Model, Order, Rerank};
        let names = (Order::ALL.iter().map(|o| o.name()))
            .chain(Rerank::ALL.iter().map(|r| r.name()))
            .chain(Model::ALL.iter().map(|m| m.name()))
            .chain(Estimator::ALL.iter().map(|e| e.name()));
        for name in names {
            let quoted = format!("\"{name}\"");
            assert!(
                comments.contains(&quoted),
                "config/default.toml must describe the verification setting {quoted}"
            );
        }
    }

    #[test]
    fn environment_overrides_the_file() {
        let c = load_str(
            "[search]\ntop_n = 3\n",
            &[
                ("BOWLOC_SEARCH__TOP_N", "7"),
                ("BOWLOC_SERVER__LISTEN", "0.0.0.0:9000"),
            ],
        )
        .unwrap();
        assert_eq!(c.search.top_n, 7);
        assert_eq!(c.server.listen, "0.0.0.0:9000".parse().unwrap());
        assert_eq!(
            load_str("[search]\ntop_n = 3\n", &[]).unwrap().search.top_n,
            3
        );
    }

    #[test]
    fn unknown_keys_are_errors_naming_the_key() {
        let e = load_str("[search]\ntop_m = 3\n", &[]).unwrap_err();
        assert!(e.contains("top_m"), "{e}");
        let e = load_str("[serch]\n", &[]).unwrap_err();
        assert!(e.contains("serch"), "{e}");
        let e = load_str("", &[("BOWLOC_LIMITS__BODY", "1")]).unwrap_err();
        assert!(e.contains("body"), "{e}");
    }

    #[test]
    fn bad_values_name_the_key() {
        let cases = [
            ("[server]\nlisten = \"nowhere\"\n", "listen"),
            ("[server]\nlog_format = \"xml\"\n", "log_format"),
            ("[limits]\nqueue = -1\n", "queue"),
            ("[search]\ntop_n = 0\n", "search.top_n"),
            ("[search]\ntop_n = 101\n", "search.top_n"),
            ("[search]\nblock = 0\n", "search.block"),
            ("[search]\nplace_window = 1001\n", "search.place_window"),
            ("[search]\nbudget_ms = 0\n", "search.budget_ms"),
            ("[search]\nbudget_ms = -5\n", "search.budget_ms"),
            ("[limits]\ndeadline_ms = 0\n", "limits.deadline_ms"),
            ("[server]\nmax_connections = 0\n", "server.max_connections"),
            (
                "[server]\nheader_timeout_ms = 0\n",
                "server.header_timeout_ms",
            ),
            ("[server]\nbody_timeout_ms = 0\n", "server.body_timeout_ms"),
            ("[limits]\nheaders = 0\n", "limits.headers"),
            ("[limits]\nheader_bytes = 100\n", "limits.header_bytes"),
            ("[search]\nrule = \"fastest\"\n", "fastest"),
            ("[search]\nrule = \"fixed\"\n", "needs its fraction"),
            (
                "[search]\nrule = \"none\"\nthreshold = 0.5\n",
                "takes no parameter",
            ),
            ("[search]\nquantizer = \"fast\"\n", "search.quantizer"),
            ("[verify]\ntop_k = 0\n", "top_k"),
            ("[verify]\nmodel = \"projective\"\n", "model"),
            ("[verify]\nconfidence = 1.5\n", "confidence"),
            ("[verify]\nstop_log_scale = -0.1\n", "stop_log_scale"),
            (
                "[search]\nquantizer = \"tree\"\ntree_probes = 0\n",
                "tree_probes",
            ),
            (
                "[search]\nrule = \"hoeffding\"\nthreshold = 2.0\n",
                "search.rule",
            ),
        ];
        for (toml, expected) in cases {
            let e = load_str(toml, &[]).unwrap_err();
            assert!(e.contains(expected), "{toml:?}: {e}");
        }
    }

    #[test]
    fn errors_name_the_source_of_the_value() {
        // a value the checks refuse, from the environment
        let e = load_str("", &[("BOWLOC_SEARCH__RULE", "relativ")]).unwrap_err();
        assert!(
            e.contains("search.rule from environment variable BOWLOC_SEARCH__RULE"),
            "{e}"
        );
        // the same from the file
        let e = load_str("[search]\nrule = \"relativ\"\n", &[]).unwrap_err();
        assert!(
            e.contains("search.rule from") && e.contains("c.toml"),
            "{e}"
        );
        // an unknown section from the environment, named in full
        let e = load_str("", &[("BOWLOC_SERVR__LISTEN", "0.0.0.0:1")]).unwrap_err();
        assert!(
            e.contains("servr") && e.contains("BOWLOC_SERVR__LISTEN"),
            "{e}"
        );
        // a value the checks refuse from the defaults names no source
        let e = load_str("[search]\ntop_n = 0\n", &[("BOWLOC_LIMITS__QUEUE", "3")]).unwrap_err();
        assert!(!e.contains("BOWLOC_LIMITS__QUEUE"), "{e}");
    }

    #[test]
    fn a_rule_with_its_parameter_loads() {
        let c = load_str("[search]\nrule = \"hoeffding\"\nthreshold = 0.05\n", &[]).unwrap();
        assert_eq!(c.default_rule().unwrap().parameter, 0.05);
    }

    #[test]
    fn or_verified_joins_the_default_rule_and_is_checked() {
        let c = load_str("[search]\nor_verified = 16\n", &[]).unwrap();
        let rule = c.default_rule().unwrap();
        assert_eq!(
            (rule.name.as_str(), rule.or_verified),
            ("place-z", Some(16))
        );
        assert!(rule.geometric());
        // the built-in rule's own, off with 0, none for another rule
        assert_eq!(
            Config::default().default_rule().unwrap(),
            SearchOptions::recommended().rule
        );
        assert_eq!(
            Config::default().default_rule().unwrap().or_verified,
            Some(12)
        );
        let off = load_str("[search]\nor_verified = 0\n", &[]).unwrap();
        assert_eq!(off.default_rule().unwrap().or_verified, None);
        for (other, given) in [
            ("none", ""),
            ("verified", "threshold = 12\n"),
            ("hoeffding", "threshold = 0.05\n"),
            ("relative", "threshold = 2.5\n"),
        ] {
            let c = load_str(&format!("[search]\nrule = \"{other}\"\n{given}"), &[]).unwrap();
            let rule = c.default_rule().unwrap();
            assert_eq!((rule.name.as_str(), rule.or_verified), (other, None));
        }
        for bad in [
            "[search]\nrule = \"none\"\nor_verified = 16\n",
            "[search]\nor_verified = 2\n",
        ] {
            let e = load_str(bad, &[]).unwrap_err().to_string();
            assert!(e.contains("search.or_verified"), "{bad}: {e}");
        }
    }

    #[test]
    fn missing_file_is_an_error() {
        let e = Config::load(Path::new("/nonexistent/bowloc.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not found"), "{e}");
        let dir = std::env::temp_dir();
        let e = Config::load(&dir).unwrap_err().to_string();
        assert!(
            e.ends_with(": is a directory, not a configuration file"),
            "{e}"
        );
    }

    #[test]
    fn flags_override_and_are_checked() {
        let c = Config::default()
            .apply(&Overrides {
                workers: Some(3),
                log_format: Some(LogFormat::Json),
                ..Default::default()
            })
            .unwrap();
        assert_eq!(c.worker_count(), 3);
        assert_eq!(c.server.log_format, LogFormat::Json);
        assert!(
            Config::default()
                .apply(&Overrides {
                    workers: Some(1 << 20),
                    ..Default::default()
                })
                .is_err()
        );
    }
}

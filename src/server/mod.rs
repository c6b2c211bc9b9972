//! The HTTP service (`bowloc serve`): an axum router over a shared state
//! holding the configuration, the worker pool and — once loaded — the
//! memory-mapped vocabulary and map. Start-up binds the listener first (so
//! `/healthz` answers while the map is loaded or bootstrapped, `/readyz` once
//! it is), and SIGTERM / SIGINT stop it gracefully: new connections are
//! refused, requests in flight finish, and [`run`] returns.
//!
//! - [`config`]: configuration (file, environment, flags) and its checks;
//! - [`cors`]: which pages on other origins may call the API;
//! - [`connections`]: accepting and serving connections (cap, timeouts,
//!   drain), and what the HTTP layer answers by itself;
//! - [`bootstrap`]: building a missing default map, then loading;
//! - [`localize`]: `POST /localize` and its parameters;
//! - [`body`]: the image of a request body (raw or multipart), read within
//!   its limits, for `/localize` and `POST /images`;
//! - [`sequences`]: the per-sequence state of `/localize?sequence=NAME`
//!   (bounded, one lock each) and `DELETE /sequences/{name}`;
//! - [`images`]: the map's images (add, remove, list), compaction, and the
//!   write token;
//! - [`status`]: health, readiness, `/map`, `/metrics`, `/openapi.json`;
//! - [`page`]: the page for people at `GET /`, its script and style;
//! - [`thumbnails`]: `GET /images/{id}/thumbnail`, map images for the page;
//! - [`workers`]: the bounded pool for CPU work;
//! - [`plan_memory`]: the learned extraction plan kept across restarts;
//! - [`errors`]: error answers as JSON;
//! - [`middleware`]: request ids, request logs and metrics, panics;
//! - [`native_stderr`]: with a JSON log, what the native libraries write to
//!   stderr, logged as events tied to the requests that caused them;
//! - [`metrics`], [`openapi`], [`proto`]: the exported metrics, the API
//!   document and the protobuf answer.

pub mod body;
pub mod bootstrap;
pub mod config;
pub mod connections;
pub mod cors;
pub mod errors;
pub mod images;
pub mod localize;
pub mod metrics;
pub mod middleware;
pub mod native_stderr;
pub mod openapi;
pub mod page;
pub mod plan_memory;
pub mod proto;
pub mod sequences;
pub mod status;
pub mod thumbnails;
pub mod workers;

use crate::index::MapRead;
use crate::pipeline::Localizer;
use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::routing::{delete, get, post, put};
use config::Config;
use errors::ApiError;
use localize::Defaults;
use metrics_exporter_prometheus::PrometheusHandle;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use tokio::net::TcpListener;
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::RequestBodyTimeoutLayer;
use workers::WorkerPool;

/// What every handler shares.
pub struct AppState {
    pub config: Config,
    pub defaults: Defaults,
    pub pool: WorkerPool,
    pub metrics: PrometheusHandle,
    /// Live sequences of frames.
    pub sequences: sequences::Sequences,
    localizer: OnceLock<Arc<Localizer>>,
    /// The loaded map's topology for sequences (or why the configured one
    /// does not fit the map).
    topology: OnceLock<Result<crate::sequence::Topology, String>>,
    /// What loading (or bootstrapping) the map is doing now.
    loading: bootstrap::Progress,
    /// Map images made small for the page.
    thumbnails: thumbnails::ThumbnailCache,
    shutting_down: AtomicBool,
    /// Image ids being written now.
    writing: images::Writing,
    /// A compaction is running or about to.
    compacting: Arc<AtomicBool>,
    /// Where the learned extraction plan is kept (`None`: it is not).
    plan_memory: Option<Arc<plan_memory::PlanMemory>>,
}

impl AppState {
    /// State for `config` (already checked), with no map loaded yet.
    pub fn new(config: Config) -> anyhow::Result<Arc<Self>> {
        let defaults = Defaults {
            options: config.search_options().map_err(anyhow::Error::msg)?,
            max_top_n: config.limits.max_top_n,
        };
        let pool = WorkerPool::new(config.worker_count(), config.limits.queue);
        let metrics = metrics::install();
        metrics::ready(false);
        let sequences =
            sequences::Sequences::new(config.sequence.max_sequences, config.sequence.idle());
        Ok(Arc::new(Self {
            defaults,
            pool,
            metrics,
            sequences,
            localizer: OnceLock::new(),
            topology: OnceLock::new(),
            loading: bootstrap::Progress::default(),
            thumbnails: thumbnails::ThumbnailCache::default(),
            shutting_down: AtomicBool::new(false),
            writing: images::Writing::default(),
            compacting: Arc::new(AtomicBool::new(false)),
            plan_memory: plan_memory::PlanMemory::of(&config).map(Arc::new),
            config,
        }))
    }

    /// Make the service ready with this vocabulary and map.
    pub fn set_localizer(&self, localizer: impl Into<Arc<Localizer>>) {
        let localizer: Arc<Localizer> = localizer.into();
        let snapshot = localizer.map.snapshot();
        metrics::map_loaded(&*snapshot);
        let m = snapshot.meta();
        tracing::info!(
            map = %m.name,
            images = m.images,
            words = m.words,
            vocabulary = %m.vocab_hash,
            workers = self.pool.workers(),
            queue = self.pool.queue_capacity(),
            "ready"
        );
        let topology = crate::sequence::Topology::of(
            self.config.sequence.topology,
            snapshot.id_range(),
            snapshot.positions(),
        );
        if let Err(e) = &topology {
            tracing::error!("sequence.topology: {e}; requests with a sequence will be refused");
        }
        let _ = self.topology.set(topology);
        if let (Some(memory), Some(choice)) = (&self.plan_memory, &localizer.coarse_choice) {
            memory.restore_logged(&localizer);
            metrics::plan_costs(choice);
            metrics::tile_cost(localizer.tile_cost());
        }
        if self.localizer.set(localizer).is_ok() {
            metrics::ready(true);
        }
    }

    /// Answer a synthetic query on every worker ([`Localizer::warm_up`]),
    /// as `server.warm_up` asks, so that the first requests do not pay for
    /// what a thread's first extraction maps in and sets up. A failure only
    /// costs those requests the time.
    async fn warm_workers(&self, localizer: &Arc<Localizer>) {
        if !self.config.server.warm_up {
            return;
        }
        self.loading.begin("warming up the workers");
        // one worker also readies the thread of a tile pair on a spare core
        // (one at a time is what a lightly loaded server runs; a warm-up on
        // every worker would keep as many threads' memory)
        let pairs = self
            .config
            .server
            .tiles_ahead
            .then(|| AtomicBool::new(true));
        let localizer = localizer.clone();
        let started = std::time::Instant::now();
        let warmed = self
            .pool
            .on_every_worker(Duration::from_secs(5), move || {
                let pair = pairs
                    .as_ref()
                    .is_some_and(|p| p.swap(false, Ordering::SeqCst));
                localizer.warm_up(pair)
            })
            .await;
        let ms = middleware::log_ms(started.elapsed());
        match warmed.iter().find_map(|w| match w {
            Ok(Ok(_)) => None,
            Ok(Err(e)) => Some(e.to_string()),
            Err(e) => Some(e.to_string()),
        }) {
            None => tracing::info!(workers = warmed.len(), ms, "workers warmed up"),
            Some(e) => tracing::warn!(
                "warming up the workers failed ({e}); the first requests will take longer"
            ),
        }
    }

    /// The loaded localizer, or 503 `not_ready` naming the loading step.
    pub fn localizer(&self) -> Result<Arc<Localizer>, ApiError> {
        self.localizer.get().cloned().ok_or_else(|| {
            let step = self.loading.step();
            ApiError::not_ready(format!("the map is still loading ({step}); retry later"))
                .with_step(step)
        })
    }

    /// Run `job` on the worker pool, started before `deadline`. A full queue
    /// answers 503 `overloaded`, no worker free in time 503 `queue_timeout`,
    /// and a job that panics 500, logged under `what` (its name).
    pub async fn on_worker<T: Send + 'static>(
        &self,
        deadline: std::time::Instant,
        what: &'static str,
        job: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        use workers::PoolError;
        // The job logs in its request's span, and what the native libraries
        // write to stderr meanwhile is tied to its request.
        let span = tracing::Span::current();
        let request_id = middleware::request_id();
        let job = move || {
            let _native = request_id.as_deref().map(native_stderr::section);
            span.in_scope(job)
        };
        self.pool
            .run(Some(tokio::time::Instant::from_std(deadline)), job)
            .await
            .map_err(|e| match e {
                PoolError::QueueFull => ApiError::overloaded(self.pool.queue_capacity()),
                PoolError::TimedOut => ApiError::queue_timeout(),
                PoolError::Panicked(m) => {
                    tracing::error!("{what} panicked: {m}");
                    ApiError::internal(format!("the {what} failed unexpectedly"))
                }
            })?
    }

    /// The map's topology for sequences, or 400 saying why there is none.
    pub fn topology(&self) -> Result<&crate::sequence::Topology, ApiError> {
        match self.topology.get() {
            Some(Ok(t)) => Ok(t),
            Some(Err(e)) => Err(ApiError::invalid_parameter("sequence", e)),
            None => Err(ApiError::not_ready("the map is still loading; retry later")),
        }
    }

    /// After a change: the map's gauges, and a compaction in the background
    /// once the log holds `changes.compact_log_bytes`.
    pub fn after_write(&self, localizer: &Arc<Localizer>) {
        metrics::map_loaded(&*localizer.map.snapshot());
        let threshold = self.config.changes.compact_log_bytes;
        if threshold > 0 && localizer.map.log_bytes() >= threshold {
            self.compact_in_background(localizer, "log size");
        }
    }

    /// Start a compaction on a blocking thread unless one is running.
    pub fn compact_in_background(&self, localizer: &Arc<Localizer>, why: &'static str) {
        if self.compacting.swap(true, Ordering::SeqCst) {
            return;
        }
        let (localizer, flag) = (localizer.clone(), self.compacting.clone());
        tokio::task::spawn_blocking(move || {
            tracing::info!("compacting the map ({why})");
            if let Err(e) = localizer.map.compact() {
                tracing::error!("compaction failed: {e}");
            }
            metrics::map_loaded(&*localizer.map.snapshot());
            flag.store(false, Ordering::SeqCst);
        });
    }

    /// Where the learned extraction plan is kept, when it is.
    pub fn plan_memory(&self) -> Option<&plan_memory::PlanMemory> {
        self.plan_memory.as_deref()
    }

    /// Keep the learned extraction plan in its file, when it changed
    /// (on a blocking thread: the write is synced).
    pub async fn keep_plan(&self) {
        let (Some(memory), Some(localizer)) = (self.plan_memory.clone(), self.localizer.get())
        else {
            return;
        };
        let localizer = localizer.clone();
        let _ = tokio::task::spawn_blocking(move || memory.save(&localizer)).await;
    }

    pub fn begin_shutdown(&self) {
        self.shutting_down.store(true, Ordering::SeqCst);
        metrics::ready(false);
    }

    pub fn is_shutting_down(&self) -> bool {
        self.shutting_down.load(Ordering::SeqCst)
    }
}

/// Every route with its layers.
pub fn router(state: Arc<AppState>) -> Router {
    let compression = state.config.server.compression;
    let routes = routes(state);
    // outermost: what every layer inside answered, compressed
    if compression {
        routes.layer(CompressionLayer::new())
    } else {
        routes
    }
}

/// Every route with its layers but compression.
fn routes(state: Arc<AppState>) -> Router {
    let body_limit = state.config.limits.body_bytes;
    let body_timeout = Duration::from_millis(state.config.server.body_timeout_ms);
    let header_limits = middleware::HeaderLimits {
        fields: state.config.limits.headers,
        bytes: state.config.limits.header_bytes,
    };
    Router::new()
        .route("/localize", post(localize::localize))
        .route("/sequences/{name}", delete(localize::delete_sequence))
        .route("/healthz", get(status::healthz))
        .route("/readyz", get(status::readyz))
        .route("/map", get(status::map))
        .route("/images", get(images::list_images))
        .route(
            "/images/{id}",
            get(images::get_image).merge(
                put(images::put_image)
                    .delete(images::delete_image)
                    .route_layer(axum::middleware::from_fn_with_state(
                        state.clone(),
                        images::require_write_token,
                    )),
            ),
        )
        .route(
            "/map/compact",
            post(images::compact).route_layer(axum::middleware::from_fn_with_state(
                state.clone(),
                images::require_write_token,
            )),
        )
        .route("/metrics", get(status::metrics))
        .route("/openapi.json", get(status::openapi))
        .route("/", get(page::index))
        .route("/page.js", get(page::script))
        .route("/page.css", get(page::style))
        .route("/images/{id}/thumbnail", get(thumbnails::thumbnail))
        .fallback(|| async { ApiError::not_found() })
        .method_not_allowed_fallback(|| async { ApiError::method_not_allowed() })
        .layer(
            ServiceBuilder::new()
                .layer(SetRequestIdLayer::new(
                    middleware::REQUEST_ID,
                    MakeRequestUuid,
                ))
                .layer(PropagateRequestIdLayer::new(middleware::REQUEST_ID))
                .layer(axum::middleware::from_fn(middleware::observe))
                .layer(CatchPanicLayer::custom(middleware::panic_response))
                .option_layer(cors::layer(&state.config.server.cors_origins))
                .layer(axum::middleware::from_fn_with_state(
                    header_limits,
                    middleware::header_limits,
                ))
                .layer(RequestBodyTimeoutLayer::new(body_timeout))
                .layer(DefaultBodyLimit::max(body_limit)),
        )
        .with_state(state)
}

/// Bind the configured address and serve until SIGTERM or SIGINT.
pub async fn run(config: Config) -> anyhow::Result<()> {
    let listener = TcpListener::bind(config.server.listen)
        .await
        .map_err(|e| anyhow::anyhow!("server.listen {}: {e}", config.server.listen))?;
    serve(config, listener, shutdown_signal()).await
}

/// Serve on `listener` until `shutdown` resolves: load (or bootstrap) the map
/// in the background, then take traffic. A map that cannot be loaded stops
/// the service with an error.
pub async fn serve(
    config: Config,
    listener: TcpListener,
    shutdown: impl Future<Output = &'static str> + Send,
) -> anyhow::Result<()> {
    let state = AppState::new(config)?;
    let address = listener.local_addr()?;
    let (stop_tx, mut stop_rx) = tokio::sync::watch::channel(false);
    let app = router(state.clone());
    let mut server = tokio::spawn(connections::serve(
        listener,
        app,
        connections::Settings::of(&state.config),
        async move {
            let _ = stop_rx.wait_for(|stop| *stop).await;
        },
    ));
    tracing::info!("listening on http://{address}");
    let upkeep = {
        let handle = state.metrics.clone();
        let upkeep_state = state.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_secs(5));
            loop {
                tick.tick().await;
                handle.run_upkeep();
                upkeep_state.sequences.sweep();
                upkeep_state.keep_plan().await;
            }
        })
    };
    let mut compactor: Option<tokio::task::JoinHandle<()>> = None;
    let loader_state = state.clone();
    let mut loader = Some(tokio::task::spawn_blocking(move || {
        bootstrap::load(&loader_state.config, &loader_state.loading)
    }));
    tokio::pin!(shutdown);
    let outcome: anyhow::Result<()> = loop {
        tokio::select! {
            loaded = async { loader.as_mut().expect("guarded").await }, if loader.is_some() => {
                loader = None;
                match loaded {
                    Ok(Ok(localizer)) => {
                        // Set once the map is loaded: building one at start-up
                        // runs OpenCV single-threaded under rayon. By default
                        // each worker runs one query on one core and OpenCV
                        // does not fan out too (docs/performance.md).
                        crate::features::set_opencv_threads(state.config.server.opencv_threads);
                        let localizer = Arc::new(localizer);
                        state.warm_workers(&localizer).await;
                        state.set_localizer(localizer);
                        compactor = schedule_compaction(&state);
                    }
                    Ok(Err(e)) => break Err(e.context("cannot load the vocabulary and map")),
                    Err(e) => break Err(anyhow::anyhow!("loading the map failed: {e}")),
                }
            }
            signal = &mut shutdown => {
                tracing::info!("{signal} received: finishing requests in flight, then stopping");
                break Ok(());
            }
            ended = &mut server => {
                break match ended {
                    Ok(()) => Err(anyhow::anyhow!("the server stopped unexpectedly")),
                    Err(e) => Err(anyhow::anyhow!("the server failed: {e}")),
                };
            }
        }
    };
    state.begin_shutdown();
    let _ = stop_tx.send(true);
    // Requests in flight have `server.drain_ms` to finish, workers included.
    let grace = state.config.drain();
    let drained_by = tokio::time::Instant::now() + grace;
    if !server.is_finished() && tokio::time::timeout(grace, &mut server).await.is_err() {
        tracing::warn!(
            "connections still open {} ms after shutdown began; stopping anyway",
            grace.as_millis()
        );
    }
    upkeep.abort();
    if let Some(c) = compactor {
        c.abort();
    }
    let pool = state.pool.clone();
    if !matches!(
        tokio::task::spawn_blocking(move || {
            // idle workers need a moment to take their stop message
            let left = drained_by.saturating_duration_since(tokio::time::Instant::now());
            pool.close(left.max(Duration::from_millis(100)))
        })
        .await,
        Ok(true)
    ) {
        tracing::warn!(
            "workers still busy {} ms after shutdown began; stopping anyway",
            grace.as_millis()
        );
    }
    state.keep_plan().await;
    tracing::info!("stopped");
    outcome
}

/// Compact every `changes.compact_interval_s` seconds while there are
/// changes (none when 0 or when the map takes no changes).
fn schedule_compaction(state: &Arc<AppState>) -> Option<tokio::task::JoinHandle<()>> {
    let every = state.config.changes.compact_interval_s;
    let localizer = state.localizer.get()?.clone();
    if every == 0 || !localizer.map.writable() {
        return None;
    }
    let state = state.clone();
    Some(tokio::spawn(async move {
        let period = Duration::from_secs(every);
        let mut tick = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
        loop {
            tick.tick().await;
            let s = localizer.map.status();
            if s.added > 0 || s.removed > 0 || s.log_records.unwrap_or(0) > 0 {
                state.compact_in_background(&localizer, "schedule");
            }
        }
    }))
}

/// Resolves at SIGTERM or SIGINT, naming it. The handlers are installed
/// when this is called (inside the runtime), not when it is first polled.
pub fn shutdown_signal() -> impl Future<Output = &'static str> + Send {
    use tokio::signal::unix::{SignalKind, signal};
    let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
    let mut int = signal(SignalKind::interrupt()).expect("SIGINT handler");
    async move {
        tokio::select! {
            _ = term.recv() => "SIGTERM",
            _ = int.recv() => "SIGINT",
        }
    }
}

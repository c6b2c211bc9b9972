//! Connections: accepting TCP connections, at most `server.max_connections`
//! open at once, serving HTTP/1.1 on each with hyper (header read timeout,
//! hard header limits), and draining them at shutdown. What hyper answers by
//! itself never reaches the router — a malformed request (400, 414), headers
//! over its hard limits (431, empty body), headers not sent in time (the
//! connection is closed) — so it is logged and counted here instead.

use super::config::Config;
use super::metrics;
use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;

/// The router's header limits (`limits.headers`, `limits.header_bytes`)
/// answer with a JSON 431; hyper's own limits, this many times larger, stop
/// what is far beyond before it is buffered whole.
pub const HARD_LIMIT_FACTOR: usize = 4;

/// hyper's read buffer when nothing asks for more (its default).
const DEFAULT_MAX_BUF: usize = 8192 + 4096 * 100;

/// How connections are served.
#[derive(Debug, Clone)]
pub struct Settings {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub max_headers: usize,
    pub max_header_bytes: usize,
}

impl Settings {
    pub fn of(config: &Config) -> Self {
        Self {
            max_connections: config.server.max_connections,
            header_timeout: Duration::from_millis(config.server.header_timeout_ms),
            max_headers: config.limits.headers.saturating_mul(HARD_LIMIT_FACTOR),
            max_header_bytes: config.limits.header_bytes.saturating_mul(HARD_LIMIT_FACTOR),
        }
    }

    fn builder(&self) -> http1::Builder {
        let mut b = http1::Builder::new();
        b.timer(TokioTimer::new())
            .header_read_timeout(self.header_timeout)
            .max_headers(self.max_headers)
            .max_header_size(self.max_header_bytes)
            .max_buf_size(DEFAULT_MAX_BUF.max(self.max_header_bytes + 8192));
        b
    }
}

/// Serve `app` on `listener` until `stop` resolves; then stop accepting
/// (the listener is closed, so new connections are refused), let the
/// connections finish their requests in flight and close, and return.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    settings: Settings,
    stop: impl Future<Output = ()>,
) {
    let builder = settings.builder();
    let slots = Arc::new(Semaphore::new(settings.max_connections));
    let graceful = GracefulShutdown::new();
    tokio::pin!(stop);
    loop {
        // A free slot first: beyond the cap, connections wait in the backlog.
        let slot = tokio::select! {
            slot = slots.clone().acquire_owned() => slot.expect("the semaphore is never closed"),
            () = &mut stop => break,
        };
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    // e.g. out of file descriptors: wait rather than spin
                    tracing::warn!("accepting a connection failed: {e}");
                    metrics::connection_error("accept");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            () = &mut stop => break,
        };
        let _ = stream.set_nodelay(true);
        let conn =
            builder.serve_connection(TokioIo::new(stream), TowerToHyperService::new(app.clone()));
        let conn = graceful.watch(conn);
        metrics::connections(1.0);
        tokio::spawn(async move {
            if let Err(e) = conn.await {
                ended_with(&e, peer);
            }
            metrics::connections(-1.0);
            drop(slot);
        });
    }
    drop(listener);
    graceful.shutdown().await;
}

/// What a connection that ended in an error is counted as.
pub fn error_kind(e: &hyper::Error) -> &'static str {
    if e.is_parse_too_large() {
        "headers_too_large"
    } else if e.is_parse() || e.is_parse_status() {
        "malformed_request"
    } else if e.is_timeout() {
        "header_timeout"
    } else if e.is_incomplete_message() {
        "incomplete_request"
    } else {
        "io"
    }
}

/// Log and count a connection that ended in an error.
fn ended_with(e: &hyper::Error, peer: SocketAddr) {
    let kind = error_kind(e);
    metrics::connection_error(kind);
    match kind {
        "headers_too_large" => tracing::info!(
            %peer,
            kind,
            "connection answered 431 by the HTTP layer and closed: {e}"
        ),
        "malformed_request" => tracing::info!(
            %peer,
            kind,
            "connection answered 400 by the HTTP layer and closed: {e}"
        ),
        _ => tracing::debug!(%peer, kind, "connection closed: {e}"),
    }
}

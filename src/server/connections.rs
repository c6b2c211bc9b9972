//! Connections: accepting TCP connections, at most `server.max_connections`
//! open at once, telling HTTP/2 without TLS (its preface first) from
//! HTTP/1.1 by the first bytes, serving each with hyper (header read
//! timeout, hard header limits; an idle HTTP/2 connection is sent GOAWAY),
//! and draining them at shutdown. What hyper answers by itself never
//! reaches the router — a malformed request (400, 414), headers over its
//! hard limits (431, empty body), headers not sent in time (the connection
//! is closed) — so it is logged and counted here instead.

use super::config::Config;
use super::metrics;
use axum::Router;
use hyper::server::conn::{http1, http2};
use hyper::service::{Service, service_fn};
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulConnection;
use hyper_util::service::TowerToHyperService;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, Semaphore, watch};
use tokio::time::Instant;

/// The router's header limits (`limits.headers`, `limits.header_bytes`)
/// answer with a JSON 431; hyper's own limits, this many times larger, stop
/// what is far beyond before it is buffered whole.
pub const HARD_LIMIT_FACTOR: usize = 4;

/// hyper's read buffer when nothing asks for more (its default).
const DEFAULT_MAX_BUF: usize = 8192 + 4096 * 100;

/// What an HTTP/2 client without TLS sends first (RFC 9113, section 3.4).
pub const HTTP2_PREFACE: &[u8; 24] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";

/// How connections are served.
#[derive(Debug, Clone)]
pub struct Settings {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub max_headers: usize,
    pub max_header_bytes: usize,
    /// HTTP/2 beside HTTP/1.1 (`server.http2`).
    pub http2: bool,
}

impl Settings {
    pub fn of(config: &Config) -> Self {
        Self {
            max_connections: config.server.max_connections,
            header_timeout: Duration::from_millis(config.server.header_timeout_ms),
            max_headers: config.limits.headers.saturating_mul(HARD_LIMIT_FACTOR),
            max_header_bytes: config.limits.header_bytes.saturating_mul(HARD_LIMIT_FACTOR),
            http2: config.server.http2,
        }
    }

    fn http1(&self) -> http1::Builder {
        let mut b = http1::Builder::new();
        b.timer(TokioTimer::new())
            .header_read_timeout(self.header_timeout)
            .max_headers(self.max_headers)
            .max_header_size(self.max_header_bytes)
            .max_buf_size(DEFAULT_MAX_BUF.max(self.max_header_bytes + 8192));
        b
    }

    fn http2(&self) -> http2::Builder<TokioExecutor> {
        let mut b = http2::Builder::new(TokioExecutor::new());
        b.timer(TokioTimer::new())
            .max_header_list_size(u32::try_from(self.max_header_bytes).unwrap_or(u32::MAX));
        b
    }
}

/// The protocol a connection speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    Http1,
    Http2,
}

/// The protocol of a connection whose first bytes are `first`: HTTP/2 when
/// they are its preface, HTTP/1.1 as soon as they differ from it, `None`
/// while they are a part of it (or nothing yet).
pub fn protocol_of(first: &[u8]) -> Option<Protocol> {
    let n = first.len().min(HTTP2_PREFACE.len());
    if first[..n] != HTTP2_PREFACE[..n] {
        Some(Protocol::Http1)
    } else if n == HTTP2_PREFACE.len() {
        Some(Protocol::Http2)
    } else {
        None
    }
}

/// Why a connection was closed before its protocol was known.
enum Unsniffed {
    /// Closed by the client, or a read error.
    Closed,
    /// No telling bytes within the header timeout.
    Timeout,
}

/// Peek (without reading) at the first bytes until they tell the protocol,
/// for at most `within`. An HTTP/1.1 request tells at its first or second
/// byte; an HTTP/2 preface usually arrives in one piece.
async fn sniff(stream: &TcpStream, within: Duration) -> Result<Protocol, Unsniffed> {
    let deadline = Instant::now() + within;
    let mut first = [0u8; HTTP2_PREFACE.len()];
    loop {
        match tokio::time::timeout_at(deadline, stream.peek(&mut first)).await {
            Err(_) => return Err(Unsniffed::Timeout),
            Ok(Ok(0) | Err(_)) => return Err(Unsniffed::Closed),
            Ok(Ok(n)) => {
                if let Some(protocol) = protocol_of(&first[..n]) {
                    return Ok(protocol);
                }
            }
        }
        // a part of the preface: the rest is on its way
        if Instant::now() + PREFACE_POLL >= deadline {
            return Err(Unsniffed::Timeout);
        }
        tokio::time::sleep(PREFACE_POLL).await;
    }
}

/// How often the first bytes are looked at again while they are an
/// unfinished HTTP/2 preface.
const PREFACE_POLL: Duration = Duration::from_millis(2);

/// How long an HTTP/2 connection sent GOAWAY, with no request in flight,
/// has to end: the client acknowledges the GOAWAY's ping, which takes a
/// round trip; one that never does is closed after this.
const GOAWAY_GRACE: Duration = Duration::from_secs(1);

/// Requests in flight on an HTTP/2 connection, and since when it has had
/// none.
struct Activity {
    state: Mutex<InFlightState>,
    none_in_flight: Notify,
}

struct InFlightState {
    requests: usize,
    idle_since: Instant,
}

impl Activity {
    fn new() -> Self {
        Self {
            state: Mutex::new(InFlightState {
                requests: 0,
                idle_since: Instant::now(),
            }),
            none_in_flight: Notify::new(),
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, InFlightState> {
        self.state.lock().expect("not poisoned")
    }

    /// A request began; the guard ends it.
    fn begin(self: &Arc<Self>) -> InFlight {
        self.state().requests += 1;
        InFlight(self.clone())
    }

    /// Resolves once the connection has had no request in flight for
    /// `quiet`, counted from now at the earliest.
    async fn quiet_for(&self, quiet: Duration) {
        let from = Instant::now();
        loop {
            let ended = self.none_in_flight.notified();
            let left = {
                let state = self.state();
                (state.requests == 0)
                    .then(|| quiet.saturating_sub(from.max(state.idle_since).elapsed()))
            };
            match left {
                None => ended.await,
                Some(left) if left.is_zero() => return,
                Some(left) => tokio::time::sleep(left).await,
            }
        }
    }
}

/// A request in flight on an HTTP/2 connection.
struct InFlight(Arc<Activity>);

impl Drop for InFlight {
    fn drop(&mut self) {
        let mut state = self.0.state();
        state.requests -= 1;
        state.idle_since = Instant::now();
        if state.requests == 0 {
            self.0.none_in_flight.notify_waiters();
        }
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
    let settings = Arc::new(settings);
    let slots = Arc::new(Semaphore::new(settings.max_connections));
    let (stopping, stop_rx) = watch::channel(false);
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
        metrics::connections(1.0);
        let (settings, app, stop_rx) = (settings.clone(), app.clone(), stop_rx.clone());
        tokio::spawn(async move {
            let protocol = if settings.http2 {
                // a connection still silent when the server stops is closed
                let mut stopped = stop_rx.clone();
                tokio::select! {
                    protocol = sniff(&stream, settings.header_timeout) => protocol,
                    _ = stopped.wait_for(|stop| *stop) => Err(Unsniffed::Closed),
                }
            } else {
                Ok(Protocol::Http1)
            };
            let ended = match protocol {
                Ok(Protocol::Http1) => {
                    let conn = settings
                        .http1()
                        .serve_connection(TokioIo::new(stream), TowerToHyperService::new(app));
                    // idle HTTP/1.1 connections end at hyper's header timeout
                    until_done(conn, None, stop_rx).await
                }
                Ok(Protocol::Http2) => serve_http2(stream, app, &settings, stop_rx).await,
                Err(Unsniffed::Timeout) => {
                    // the part of a preface that came, read so that the
                    // connection closes as usual rather than by a reset
                    let _ = stream.try_read(&mut [0u8; HTTP2_PREFACE.len()]);
                    metrics::connection_error("header_timeout");
                    tracing::debug!(%peer, kind = "header_timeout", "connection closed: no request");
                    Ok(())
                }
                Err(Unsniffed::Closed) => Ok(()),
            };
            if let Err(e) = ended {
                ended_with(&e, peer);
            }
            metrics::connections(-1.0);
            drop(slot);
        });
    }
    drop(listener);
    let _ = stopping.send(true);
    // every connection holds a slot until it ends
    let all = u32::try_from(settings.max_connections).unwrap_or(u32::MAX);
    let _ = slots.acquire_many(all).await;
}

/// Serve an HTTP/2 connection until it ends; GOAWAY once it has had no
/// request in flight for the header timeout, or once the server stops
/// (the requests in flight still finish).
async fn serve_http2(
    stream: TcpStream,
    app: Router,
    settings: &Settings,
    stopping: watch::Receiver<bool>,
) -> Result<(), hyper::Error> {
    let activity = Arc::new(Activity::new());
    let service = TowerToHyperService::new(app);
    let counted = activity.clone();
    let service = service_fn(move |request| {
        let in_flight = counted.begin();
        let answer = service.call(request);
        async move {
            let answer = answer.await;
            drop(in_flight);
            answer
        }
    });
    let conn = settings
        .http2()
        .serve_connection(TokioIo::new(stream), service);
    until_done(conn, Some((&activity, settings.header_timeout)), stopping).await
}

/// Run `conn` to its end; once the server stops, or (HTTP/2, `idle` given)
/// once it has had no request in flight for the duration given with its
/// activity, shut it down gracefully (HTTP/1.1: close after the answer in
/// flight; HTTP/2: GOAWAY, the streams open still answered) and let it
/// finish, an HTTP/2 one within [`GOAWAY_GRACE`] of its last answer.
async fn until_done<C>(
    conn: C,
    idle: Option<(&Activity, Duration)>,
    mut stopping: watch::Receiver<bool>,
) -> Result<(), hyper::Error>
where
    C: GracefulConnection<Error = hyper::Error>,
{
    tokio::pin!(conn);
    let idle_for = async {
        match idle {
            Some((activity, timeout)) => activity.quiet_for(timeout).await,
            // HTTP/1.1: hyper's header timeout closes idle connections
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        ended = conn.as_mut() => return ended,
        () = idle_for => {}
        _ = stopping.wait_for(|stop| *stop) => {}
    }
    conn.as_mut().graceful_shutdown();
    match idle {
        None => conn.await,
        Some((activity, _)) => tokio::select! {
            ended = conn => ended,
            () = activity.quiet_for(GOAWAY_GRACE) => Ok(()),
        },
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_bytes_tell_the_protocol() {
        assert_eq!(protocol_of(b""), None);
        assert_eq!(protocol_of(b"P"), None);
        assert_eq!(protocol_of(b"PRI * HTTP/2.0\r\n"), None);
        assert_eq!(protocol_of(HTTP2_PREFACE), Some(Protocol::Http2));
        // the preface and the client's first frame in one segment
        let mut more = HTTP2_PREFACE.to_vec();
        more.extend_from_slice(&[0, 0, 0, 4, 0, 0, 0, 0, 0]);
        assert_eq!(protocol_of(&more), Some(Protocol::Http2));
        // HTTP/1.1 tells at its first or second byte, PRI with another
        // version at the first that differs
        assert_eq!(protocol_of(b"G"), Some(Protocol::Http1));
        assert_eq!(protocol_of(b"PO"), Some(Protocol::Http1));
        assert_eq!(
            protocol_of(b"PUT /images/a HTTP/1.1\r\n"),
            Some(Protocol::Http1)
        );
        assert_eq!(protocol_of(b"PATCH"), Some(Protocol::Http1));
        assert_eq!(
            protocol_of(b"PRI * HTTP/1.1\r\n\r\n"),
            Some(Protocol::Http1)
        );
        assert_eq!(protocol_of(b"GARBAGE\r\n\r\n"), Some(Protocol::Http1));
    }
}

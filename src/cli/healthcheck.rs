//! `bowloc healthcheck`: ask a running service's `/readyz` (or another path)
//! and exit 0 when it answers 200 — the container's HEALTHCHECK, without an
//! HTTP client in the image.

use clap::Args;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

#[derive(Args)]
pub struct HealthcheckArgs {
    /// Address of the service.
    #[arg(long, default_value = "127.0.0.1:8080")]
    address: SocketAddr,
    /// Path to ask: `/readyz` (the map is loaded and requests are taken) or
    /// `/healthz` (the process answers).
    #[arg(long, default_value = "/readyz")]
    path: String,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 3)]
    timeout: u64,
}

pub fn run(a: HealthcheckArgs) -> anyhow::Result<()> {
    let timeout = Duration::from_secs(a.timeout.max(1));
    let mut stream = TcpStream::connect_timeout(&a.address, timeout)?;
    stream.set_read_timeout(Some(timeout))?;
    stream.set_write_timeout(Some(timeout))?;
    anyhow::ensure!(
        a.path.starts_with('/') && !a.path.contains(char::is_whitespace),
        "--path must start with / and hold no spaces, got `{}`",
        a.path
    );
    write!(
        stream,
        "GET {} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
        a.path, a.address
    )?;
    let mut head = [0u8; 64];
    let n = stream.read(&mut head)?;
    let line = String::from_utf8_lossy(&head[..n]);
    let status = line.split_whitespace().nth(1).unwrap_or("");
    anyhow::ensure!(
        status == "200",
        "{}: {} answered `{}`",
        a.address,
        a.path,
        line.lines().next().unwrap_or("")
    );
    Ok(())
}

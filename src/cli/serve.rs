//! `bowloc serve`: read the configuration (file, environment, flags), set up
//! logging and OpenCV for a server process, and run the HTTP service until
//! SIGTERM / SIGINT. `bowloc openapi` prints the service's API document.

use super::LogFormatArg;
use bowloc::server::config::{Config, Overrides};
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args)]
pub struct ServeArgs {
    /// Configuration file (every key is documented in config/default.toml).
    #[arg(long, default_value = "config/default.toml")]
    config: PathBuf,
    /// Address to listen on (server.listen); port 0 picks a free port.
    #[arg(long)]
    listen: Option<SocketAddr>,
    /// Vocabulary file (files.vocabulary).
    #[arg(long)]
    vocab: Option<PathBuf>,
    /// Map file (files.map).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Worker threads for CPU work, 0 = one per core (server.workers).
    #[arg(long)]
    workers: Option<usize>,
    /// Log format (server.log_format).
    #[arg(long, value_enum)]
    log_format: Option<LogFormatArg>,
}

/// Load the configuration; errors name the key at fault.
pub fn config(a: &ServeArgs) -> anyhow::Result<Config> {
    let overrides = Overrides {
        listen: a.listen,
        vocabulary: a.vocab.clone(),
        map: a.map.clone(),
        workers: a.workers,
        log_format: a.log_format.map(Into::into),
    };
    Ok(Config::load(&a.config)?.apply(&overrides)?)
}

pub fn run(config: Config) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("bowloc-http")
        .build()?;
    let result = runtime.block_on(bowloc::server::run(config));
    // A bootstrap still running after a signal is abandoned, not awaited.
    runtime.shutdown_timeout(Duration::from_millis(100));
    result
}

/// `bowloc openapi`: print the API document (kept in docs/openapi.json).
pub fn print_openapi() -> anyhow::Result<()> {
    out!("{}", bowloc::server::openapi::json())?;
    Ok(())
}

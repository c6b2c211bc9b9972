//! `bowloc serve`: read the configuration (file, environment, flags), set up
//! logging and OpenCV for a server process, and run the HTTP service until
//! SIGTERM / SIGINT. `bowloc openapi` prints the service's API document.

use super::LogFormatArg;
use bowloc::server::config::{Config, DEFAULT_FILE, Overrides};
use clap::Args;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

#[derive(Args)]
pub struct ServeArgs {
    /// Configuration file (every key is documented in config/default.toml).
    /// Without it: config/default.toml when the working directory has one,
    /// else the built-in defaults, which are that file's values.
    #[arg(long)]
    config: Option<PathBuf>,
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

/// Load the configuration; errors name the key at fault. With it, where it
/// came from, for the start-up log: the file, or the built-in defaults.
pub fn config(a: &ServeArgs) -> anyhow::Result<(Config, String)> {
    let overrides = Overrides {
        listen: a.listen,
        vocabulary: a.vocab.clone(),
        map: a.map.clone(),
        workers: a.workers,
        log_format: a.log_format.map(Into::into),
    };
    let default_file = Path::new(DEFAULT_FILE);
    let (config, source) = match &a.config {
        Some(path) => (Config::load(path)?, path.display().to_string()),
        None if default_file.is_file() => (Config::load(default_file)?, DEFAULT_FILE.to_owned()),
        None => (
            Config::load_without_file()?,
            format!("the built-in defaults (no {DEFAULT_FILE} in the working directory)"),
        ),
    };
    Ok((config.apply(&overrides)?, source))
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

//! Command-line front end: argument parsing and one module per subcommand.

#[macro_use]
mod out;

mod args;
mod calibrate;
mod eval;
mod healthcheck;
mod map;
mod query;
mod serve;
mod shards;
mod vocab;

use bowloc::server::config::LogFormat;
use bowloc::server::native_stderr;
use clap::{Parser, Subcommand, ValueEnum};
use std::io::IsTerminal;
use std::process::ExitCode;
use tracing_subscriber::fmt::writer::BoxMakeWriter;

#[derive(Parser)]
#[command(
    name = "bowloc",
    version,
    about = "Visual place recognition with early-stopping bag-of-words search"
)]
struct Cli {
    /// Log filter (e.g. `info`, `bowloc=debug`); also RUST_LOG.
    #[arg(long, global = true, default_value = "info", env = "RUST_LOG")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a visual vocabulary (k-means over SIFT descriptors).
    #[command(subcommand)]
    Vocab(vocab::VocabCommand),
    /// Build a map index from images; add, remove and list its images.
    #[command(subcommand)]
    Map(map::MapCommand),
    /// Localize images against a map and print the results as JSON.
    Query(query::QueryArgs),
    /// Evaluate the stopping rules on a dataset (the paper's tables and plots).
    Eval(Box<eval::EvalArgs>),
    /// Simulate the search on a map split into shards: same answers as one
    /// machine, and the messages per query (docs/scale.md).
    Shards(shards::ShardsArgs),
    /// Choose stopping-rule parameters for a map without ground truth.
    Calibrate(calibrate::CalibrateArgs),
    /// Serve localization over HTTP (see config/default.toml).
    Serve(serve::ServeArgs),
    /// Print the HTTP API's OpenAPI document (as in docs/openapi.json).
    Openapi,
    /// Print the stopping rules and their parameters (the table of
    /// docs/service.md), from the registry every front end reads.
    Rules,
    /// Exit 0 when a running service answers 200 on /readyz (or --path).
    Healthcheck(healthcheck::HealthcheckArgs),
}

/// `--log-format` values.
#[derive(Clone, Copy, ValueEnum)]
pub enum LogFormatArg {
    Human,
    Json,
}

impl From<LogFormatArg> for LogFormat {
    fn from(f: LogFormatArg) -> Self {
        match f {
            LogFormatArg::Human => LogFormat::Human,
            LogFormatArg::Json => LogFormat::Json,
        }
    }
}

/// Log to `out` (stderr unless a server captures it), as text (coloured on
/// a terminal) or as JSON lines.
fn init_logging(filter: &str, format: LogFormat, out: BoxMakeWriter) {
    let filter = tracing_subscriber::EnvFilter::try_new(filter)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(out);
    match format {
        LogFormat::Human => builder.with_ansi(std::io::stderr().is_terminal()).init(),
        LogFormat::Json => builder.json().flatten_event(true).init(),
    }
}

pub fn run() -> ExitCode {
    let cli = Cli::parse();
    if bowloc::features::keep_image_buffers() == bowloc::features::Buffers::Refused {
        eprintln!(
            "warning: malloc kept its own thresholds; image buffers may be mapped anew per image"
        );
    }
    let result = match cli.command {
        Command::Serve(a) => serve::config(&a).and_then(|(config, source)| {
            let format = config.server.log_format;
            // A JSON log takes the native libraries' stderr lines in as
            // events, so that every line of it parses.
            let captured = match format {
                LogFormat::Json => Some(native_stderr::capture()),
                LogFormat::Human => None,
            };
            let out = match &captured {
                Some(Ok(c)) => c.log_writer(),
                _ => BoxMakeWriter::new(std::io::stderr),
            };
            init_logging(&cli.log, format, out);
            if let Some(Err(e)) = &captured {
                tracing::warn!("the native libraries' messages stay on stderr: {e}");
            }
            tracing::info!("configuration: {source}, then BOWLOC_ environment variables and flags");
            let served = serve::run(config);
            // stderr is itself again before an error is printed on it
            drop(captured);
            served
        }),
        command => {
            init_logging(
                &cli.log,
                LogFormat::Human,
                BoxMakeWriter::new(std::io::stderr),
            );
            match command {
                Command::Vocab(c) => vocab::run(c),
                Command::Map(c) => map::run(c),
                Command::Query(a) => query::run(a),
                Command::Eval(a) => eval::run(*a),
                Command::Shards(a) => shards::run(a),
                Command::Calibrate(a) => calibrate::run(a),
                Command::Openapi => serve::print_openapi(),
                Command::Rules => {
                    out!("{}", bowloc::search::stop::rules_markdown())
                }
                Command::Healthcheck(a) => healthcheck::run(a),
                Command::Serve(_) => unreachable!("handled above"),
            }
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // `bowloc … | head`: the reader has what it wanted
        Err(e) if out::reader_gone(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

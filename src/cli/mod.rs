//! Command-line front end: argument parsing and one module per subcommand.

mod args;
mod calibrate;
mod eval;
mod map;
mod query;
mod vocab;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

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
    /// Build a map index from images.
    #[command(subcommand)]
    Map(map::MapCommand),
    /// Localize images against a map and print the results as JSON.
    Query(query::QueryArgs),
    /// Evaluate the stopping rules on a dataset (the paper's tables and plots).
    Eval(Box<eval::EvalArgs>),
    /// Choose stopping-rule parameters for a map without ground truth.
    Calibrate(calibrate::CalibrateArgs),
}

pub fn run() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_new(&cli.log)
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Vocab(c) => vocab::run(c),
        Command::Map(c) => map::run(c),
        Command::Query(a) => query::run(a),
        Command::Eval(a) => eval::run(*a),
        Command::Calibrate(a) => calibrate::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

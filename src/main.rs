//! The `bowloc` command: builds vocabularies and maps, answers queries, serves
//! HTTP and evaluates. Each subcommand lives in `cli/`.

mod cli;

fn main() -> std::process::ExitCode {
    cli::run()
}

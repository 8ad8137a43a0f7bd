//! The `ortm` command-line tool: a thin layer over the `ortm` library (argument parsing,
//! progress bars, messages). Each subcommand lives in `src/cli/`.

mod bench;
mod cli;
mod view;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

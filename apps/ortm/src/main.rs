//! The `ortm` command-line tool: a thin layer over the `ortm` library. `src/cli/` holds the
//! subcommands (arguments, progress bars and printing only; the work is the library's),
//! `src/view/` the interactive viewer, `src/bench/` benchmark data, `src/output.rs` the files
//! both write for people (PNG frames and screenshots).

mod bench;
mod cli;
mod output;
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

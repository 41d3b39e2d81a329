//! `balancer`: studies the request balancer alone by replaying request traces on simulated
//! workers. The algorithm lives in the library; this binary reads traces, runs
//! configurations in parallel and writes CSV, JSON and PNG reports.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    match cli::run(cli::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

//! `visnode`: the visualization node's command line. All work lives in the library; this file
//! only parses flags and turns errors into exit codes.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Boards and frames allocate and free large buffers every frame, as workers do.
    backend::keep_large_allocations();
    backend::ensure_runtime_dir();
    let cli = visnode::cli::Cli::parse();
    match visnode::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

//! The visualization node: the machine with the good GPU. Today it inspects scenes (what will
//! be drawn as geometry, what as reliefboards); rendering and benchmarking come next.
//!
//! Start at [`run`], which dispatches the subcommands of [`cli::Cli`].
//!
//! **Architecture invariant:** the scene model and preprocessing live in the `scene` crate;
//! this crate only drives them and presents their results.
#![warn(missing_docs)]

pub mod cli;
mod inspect;
mod progress;
mod topview;

pub use inspect::{InspectReport, inspect};

/// Runs one command line.
pub fn run(cli: cli::Cli) -> anyhow::Result<()> {
    match cli.command {
        Some(cli::Command::Inspect(args)) => inspect::run(&args),
        // No subcommand: `inspect` with its defaults, as clap parses them.
        None => match <cli::Cli as clap::Parser>::parse_from(["visnode", "inspect"]).command {
            Some(cli::Command::Inspect(args)) => inspect::run(&args),
            None => unreachable!("\"inspect\" parses as the inspect subcommand"),
        },
    }
}

/// The peak resident memory of this process in bytes (Linux `VmHWM`), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kilobytes: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kilobytes * 1024)
}

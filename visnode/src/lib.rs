//! The visualization node: the machine with the good GPU. It draws every frame with wgpu,
//! geometry near the viewer and reliefboards beyond, and asks the workers for boards without
//! ever waiting for them.
//!
//! Start at [`run`], which dispatches the subcommands of [`cli::Cli`]. The frame loop is
//! [`Viewer`]: [`plan`] decides what is drawn how and which boards to request, the
//! [`far_field`] draws what lies beyond the near zone (worker boards, or the alternatives a
//! user would pick alone), [`workers`] sends the requests through the balancer and collects
//! the answers, [`render`] draws.
//! [`bench`] measures it all against a geometry-only reference.
//!
//! **Architecture invariant:** the scene model and preprocessing live in the `scene` crate,
//! board rendering in `backend`, load balancing in `balancer`; this crate drives them. The
//! frame never blocks on a worker unless `--sync` asks it to.
#![warn(missing_docs)]

pub mod bench;
pub mod board;
pub mod camera;
pub mod cli;
pub mod cluster;
pub mod far_field;
pub mod gui;
pub mod image_error;
mod inspect;
pub mod plan;
mod plots;
mod progress;
pub mod render;
pub mod setup;
pub mod timeline;
mod topview;
pub mod viewer;
pub mod workers;

pub use inspect::{InspectReport, inspect};
pub use viewer::{FrameReport, GeometryLod, Viewer, ViewerOptions};

/// Runs one command line.
pub fn run(cli: cli::Cli) -> anyhow::Result<()> {
    match cli.command {
        Some(cli::Command::Inspect(args)) => inspect::run(&args),
        Some(cli::Command::Bench(args)) => bench::run(&args),
        Some(cli::Command::View(args)) => gui::run(&args),
        Some(cli::Command::Cluster(args)) => cluster::run(&args),
        None => gui::run(&cli::ViewArgs::defaults()),
    }
}

/// The peak resident memory of this process in bytes (Linux `VmHWM`), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    peak_memory_of("self")
}

/// The peak resident memory of process `pid` (or `self`) in bytes, if known.
pub fn peak_memory_of(pid: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kilobytes: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kilobytes * 1024)
}

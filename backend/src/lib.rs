//! The backend worker: keeps replicas of objects and turns a request (object, view
//! direction, resolution) into a reliefboard, in software, as fast as the machine allows.
//!
//! Start at [`render_maps`] (the rasteriser: one pass over the triangles into a visibility
//! buffer, then one pass over the pixels), then [`EncodedBoard`] (the compact wire form) and
//! [`Grid`] (the displaced grid the node draws from the maps; [`Board`] holds it at full
//! resolution for reports). [`WorkerService`] serves them over
//! gRPC ([`serve`]).
//!
//! **Architecture invariant:** depends on `scene` (and `proto` for the service), never on
//! `visnode` or `balancer`; needs no GPU. The rasteriser allocates nothing per triangle.
#![warn(missing_docs)]

mod board;
mod encode;
mod error;
#[cfg(feature = "gpu-reference")]
mod gpu;
mod object;
mod raster;
mod render_queue;
mod service;
mod shared;
pub mod simplify;

pub use board::{Board, Grid};
pub use encode::{DecodeError, EncodedBoard};
pub use error::RenderError;
#[cfg(feature = "gpu-reference")]
pub use gpu::{
    GpuError, GpuMaps, GpuObject, GpuReference, SKIP_GPU_TESTS_VARIABLE, no_adapter_in_test,
};
pub use object::{MeshRef, PreparedObject, RenderVertex};
pub use raster::{
    Basis, Maps, SPLIT_WORK, Stages, coverage_counts, render_maps, render_mesh, render_mesh_timed,
    threads_worth,
};
pub use service::{
    MAX_MESSAGE_BYTES, Security, WorkerConfig, WorkerService, default_threads, is_loopback,
    lowest_cpu_priority, serve,
};
pub use simplify::{Level, LodChain, MAX_ERROR_PIXELS};

/// The largest map side any request may ask for (a worker may configure a smaller one).
pub const MAX_MAP_SIZE: u32 = 4096;

/// The largest encoded board a client accepts: above the raw size of a `MAX_MAP_SIZE` board
/// (4096² texels of at most 10 bytes each, 160 MiB), so a worker cannot make a client
/// allocate without bound.
pub const MAX_BOARD_BYTES: usize = 192 << 20;

/// A board allocates a few buffers of 0.25–1 MiB and frees them when it is sent. glibc serves
/// allocations over 128 KiB with fresh `mmap`s and unmaps them on free, so every board paid
/// page faults on all of them (0.2–0.4 ms of a 4 ms dragon board). Raising the thresholds
/// keeps that memory in the heap for the next board; the worker's peak memory does not grow,
/// since the same buffers are reused. Call it first thing in `main`, before threads start.
pub fn keep_large_allocations() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is called before any thread
    // exists, and invalid values are rejected by returning 0 (ignored: it is only tuning).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

/// Mesa's window-system code prints "error: XDG_RUNTIME_DIR is invalid or not set in the
/// environment." on every run where the variable is missing (containers, CI, ssh sessions),
/// although headless rendering needs no runtime directory. Give the process a private one
/// (mode 0700, as the XDG specification asks), so nothing misleading is printed. Call it
/// first thing in `main`, before threads start.
pub fn ensure_runtime_dir() {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let usable = |dir: &std::path::Path| {
            std::fs::metadata(dir)
                .is_ok_and(|m| m.is_dir() && m.permissions().mode() & 0o777 == 0o700)
        };
        if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|dir| usable(dir.as_ref())) {
            return;
        }
        // One per user, reused by every run (the owner of /proc/self is this process's user).
        use std::os::unix::fs::MetadataExt;
        let user = std::fs::metadata("/proc/self").map_or(std::process::id(), |m| m.uid());
        let dir = std::env::temp_dir().join(format!("reliefboard-runtime-{user}"));
        let created = std::fs::create_dir_all(&dir)
            .and_then(|()| std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)));
        if created.is_ok() {
            // SAFETY: called at the start of `main`, before any other thread exists that
            // could read the environment concurrently.
            unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
        }
    }
}

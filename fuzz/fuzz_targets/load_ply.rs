//! Any bytes as a .ply file (and gzipped, when they start like gzip): an error or a scene,
//! never a panic, a hang or unbounded memory.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = scene::load_bytes("fuzz.ply", bytes, &options());
});

/// Limits small enough that libFuzzer's memory limit (2 GB) is never the one that stops an input.
fn options() -> scene::LoadOptions {
    scene::LoadOptions {
        limits: scene::LoadLimits {
            max_inflated_bytes: 64 << 20,
            max_triangles: 2_000_000,
            max_node_instances: 100_000,
        },
        ..scene::LoadOptions::default()
    }
}

//! What the fuzz targets share.

/// Load limits small enough that libFuzzer's memory limit (2 GB) is never the one that stops
/// an input: a file past them must be refused by the loader, with an error.
pub fn load_options() -> scene::LoadOptions {
    scene::LoadOptions {
        limits: scene::LoadLimits {
            max_inflated_bytes: 64 << 20,
            max_triangles: 2_000_000,
            max_node_instances: 100_000,
        },
        ..scene::LoadOptions::default()
    }
}

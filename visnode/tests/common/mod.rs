//! Helpers the visnode test files share (each includes this with `mod common;`).
#![allow(dead_code)] // each test file uses its own subset

use std::path::PathBuf;

/// A mesh of the repository's `testdata/`.
pub fn test_mesh(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../testdata")
        .join(name)
}

/// The Stanford bunny (`testdata/bunny.ply`) as one object.
pub fn bunny() -> scene::Object {
    let scene = scene::load_file(&test_mesh("bunny.ply"), &scene::LoadOptions::default()).unwrap();
    scene::merge_objects("bunny", &scene.objects)
}

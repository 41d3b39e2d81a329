//! Any bytes as a glTF document: the first byte picks .glb or .gltf, the rest is the file.
//! An error or a scene, never a panic, a hang or unbounded memory (node DAGs, cycles,
//! shared accessors).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let Some((&kind, file)) = bytes.split_first() else {
        return;
    };
    let name = if kind & 1 == 0 {
        "fuzz.glb"
    } else {
        "fuzz.gltf"
    };
    let _ = scene::load_bytes(name, file, &reliefboard_fuzz::load_options());
});

//! Any bytes as a .obj file (and gzipped, when they start like gzip): an error or a scene,
//! never a panic, a hang or unbounded memory.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = scene::load_bytes("fuzz.obj", bytes, &reliefboard_fuzz::load_options());
});

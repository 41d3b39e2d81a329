//! Property tests: no byte sequence makes a loader panic, whatever the format. Inputs are
//! random bytes and valid files with random bytes overwritten, cut or inserted.

mod common;

use proptest::prelude::*;

fn load_bytes(name: &str, bytes: &[u8]) {
    let dir = common::temp_dir(&format!(
        "fuzz-{}",
        std::thread::current()
            .name()
            .unwrap_or("t")
            .replace("::", "-")
    ));
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    // Ok or Err are both fine; a panic fails the test.
    let _ = scene::load_file(&path, &scene::LoadOptions::default());
}

fn seeds() -> Vec<(&'static str, Vec<u8>)> {
    let teapot = scene::load_file(
        &common::test_mesh("teapot.ply"),
        &scene::LoadOptions::default(),
    )
    .unwrap();
    let (mut ply, mut obj, mut glb) = (Vec::new(), Vec::new(), Vec::new());
    scene::write_ply(&teapot.objects, &mut ply).unwrap();
    scene::write_obj(&teapot.objects, &mut obj).unwrap();
    scene::write_glb(&teapot.objects, &mut glb).unwrap();
    let ascii = std::fs::read(common::test_mesh("airplane.ply")).unwrap();
    vec![
        ("m.ply", ply),
        ("m.obj", obj),
        ("m.glb", glb),
        ("a.ply", ascii),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048), format in 0usize..5) {
        let name = ["x.ply", "x.obj", "x.glb", "x.gltf", "x.ply.gz"][format];
        load_bytes(name, &bytes);
        let mut with_header = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        with_header.extend_from_slice(&bytes);
        load_bytes("h.ply", &with_header);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in 0usize..4,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let seeds = seeds();
        let (name, mut bytes) = seeds[which].clone();
        for (at, value, kind) in edits {
            let index = at.index(bytes.len());
            match kind {
                0 => bytes[index] = value,
                1 => bytes.insert(index, value),
                _ => { bytes.remove(index); }
            }
        }
        load_bytes(name, &bytes);
        let keep = cut.index(bytes.len());
        load_bytes(name, &bytes[..keep]);
    }
}

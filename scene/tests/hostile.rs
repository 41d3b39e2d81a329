//! Small files that describe enormous work: each is refused with a clear error, quickly and
//! without allocating what it asks for, or loads exactly what it holds.

mod common;

use std::io::Write;

use base64::Engine;
use scene::{LoadLimits, LoadOptions, Problem, SceneError, load_file};

fn load_with(name: &str, bytes: &[u8], limits: LoadLimits) -> Result<scene::Scene, SceneError> {
    let dir = common::temp_dir(&format!("hostile-{}", name.replace('.', "-")));
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    load_file(
        &path,
        &LoadOptions {
            limits,
            ..LoadOptions::default()
        },
    )
}

fn problem_of(result: Result<scene::Scene, SceneError>) -> (String, Problem) {
    match result {
        Err(SceneError::Invalid {
            location, problem, ..
        }) => (location, problem),
        Err(other) => panic!("expected an Invalid error, got {other}"),
        Ok(scene) => panic!(
            "expected an error, loaded {} triangles",
            scene.triangle_count()
        ),
    }
}

/// A glTF document with one triangle mesh (positions and u16 indices in a data URI) used by
/// `nodes`, and `primitives` copies of its primitive.
fn gltf(nodes: serde_json::Value, primitives: usize) -> Vec<u8> {
    let mut buffer = Vec::new();
    for value in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        buffer.extend_from_slice(&value.to_le_bytes());
    }
    for index in [0u16, 1, 2, 0] {
        buffer.extend_from_slice(&index.to_le_bytes());
    }
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&buffer)
    );
    let primitive = serde_json::json!({"attributes": {"POSITION": 0}, "indices": 1});
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": nodes,
        "meshes": [{"primitives": vec![primitive; primitives]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "buffers": [{"byteLength": buffer.len(), "uri": uri}]
    })
    .to_string()
    .into_bytes()
}

#[test]
fn a_gltf_node_dag_is_refused_by_its_instance_count() {
    // Node i has children i+1 and i+2: 64 nodes, about 2^45 paths from the root. Reported by
    // a user: `visnode inspect` grew to 8.4 GB in 30 s and never finished.
    let nodes: Vec<serde_json::Value> = (0..64)
        .map(|i| {
            let children: Vec<usize> = [i + 1, i + 2].into_iter().filter(|&c| c < 64).collect();
            serde_json::json!({"mesh": 0, "children": children})
        })
        .collect();
    let file = gltf(nodes.into(), 1);
    assert!(file.len() < 4096, "{} bytes", file.len());
    let (location, problem) = problem_of(load_with("dag.gltf", &file, LoadLimits::default()));
    assert!(location.starts_with("node "), "{location}");
    let message = problem.to_string();
    assert!(
        message.contains("more than 1000000 node instances"),
        "{message}"
    );
}

#[test]
fn a_gltf_node_cycle_is_named() {
    let nodes = serde_json::json!([
        {"mesh": 0, "children": [1]},
        {"mesh": 0, "children": [2]},
        {"mesh": 0, "children": [0]}
    ]);
    let (location, problem) = problem_of(load_with(
        "cycle.gltf",
        &gltf(nodes, 1),
        LoadLimits::default(),
    ));
    assert_eq!(location, "node 0");
    assert_eq!(
        problem,
        Problem::Malformed("the node is its own ancestor (a cycle)".into())
    );
}

#[test]
fn gltf_instances_and_shared_accessors_count_against_the_triangle_limit() {
    let limits = LoadLimits {
        max_triangles: 1000,
        ..LoadLimits::default()
    };
    // A thousand primitives reading the same three indices: 1000 triangles fit exactly.
    let scene = load_with(
        "shared.gltf",
        &gltf(serde_json::json!([{"mesh": 0}]), 1000),
        limits,
    )
    .unwrap();
    assert_eq!(scene.triangle_count(), 1000);
    // One more primitive is refused before it is read.
    let (location, problem) = problem_of(load_with(
        "shared.gltf",
        &gltf(serde_json::json!([{"mesh": 0}]), 1001),
        limits,
    ));
    assert_eq!(location, "mesh 0 in node 0");
    assert!(problem.to_string().contains("more than 1000 triangles"));
    // 600 instances of a two-primitive mesh: the children of one node, each a copy.
    let children: Vec<usize> = (1..=600).collect();
    let mut nodes = vec![serde_json::json!({"children": children})];
    nodes.extend((0..600).map(|_| serde_json::json!({"mesh": 0})));
    let (location, _) = problem_of(load_with("instances.gltf", &gltf(nodes.into(), 2), limits));
    assert_eq!(location, "mesh 0 in node 501");
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

#[test]
fn a_gzip_bomb_stops_at_the_inflate_limit() {
    // A valid PLY header, then 8 MiB of spaces: 8 KiB gzipped.
    let mut ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    ply.resize(8 << 20, b' ');
    let bomb = gzip(&ply);
    assert!(bomb.len() < 64 << 10, "{} bytes", bomb.len());
    let limits = LoadLimits {
        max_inflated_bytes: 1 << 20,
        ..LoadLimits::default()
    };
    let (location, problem) = problem_of(load_with("bomb.ply.gz", &bomb, limits));
    assert_eq!(location, "gzip stream");
    assert_eq!(
        problem,
        Problem::TooLarge("inflates to more than 1 MiB (--max-inflated-mb)".into())
    );
    // Under the limit the same file is read, and fails for what it is: no vertex data.
    let (_, problem) = problem_of(load_with("bomb.ply.gz", &bomb, LoadLimits::default()));
    assert_eq!(problem, Problem::Truncated);
}

#[test]
fn the_triangle_limit_applies_to_every_format() {
    let teapot = std::fs::read(common::test_mesh("teapot.ply")).unwrap();
    let limits = LoadLimits {
        max_triangles: 991,
        ..LoadLimits::default()
    };
    let (location, problem) = problem_of(load_with("teapot.ply", &teapot, limits));
    assert_eq!(location, "faces");
    assert_eq!(
        problem,
        Problem::TooLarge("992 triangles exceed the limit of 991 (--max-triangles)".into())
    );
    let limits = LoadLimits {
        max_triangles: 992,
        ..LoadLimits::default()
    };
    assert_eq!(
        load_with("teapot.ply", &teapot, limits)
            .unwrap()
            .triangle_count(),
        992
    );
}

/// Regression: found by the `load_gltf` fuzzer (fuzz/artifacts/load_gltf/crash-28fba3f4...):
/// a document whose primitive names POSITION accessor 0 while it has no accessors (here
/// because the key is misspelt) made the gltf crate's validation index out of bounds and
/// panic.
#[test]
fn a_gltf_position_accessor_that_does_not_exist_is_an_error() {
    let document = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "azccessors": []
    });
    let (location, problem) = problem_of(load_with(
        "missing-accessor.gltf",
        document.to_string().as_bytes(),
        LoadLimits::default(),
    ));
    assert_eq!(location, "mesh 0, primitive 0");
    assert_eq!(
        problem,
        Problem::Malformed("POSITION names accessor 0, but the file has 0".into())
    );
    // The fuzzer's own input, byte for byte (its first byte chose .gltf).
    let crash = include_bytes!("data/fuzz-load_gltf-crash-28fba3f4.bin");
    let (_, problem) = problem_of(load_with("crash.gltf", &crash[1..], LoadLimits::default()));
    assert!(matches!(problem, Problem::Malformed(_)), "{problem:?}");
}

/// Regression: found by the `load_gltf` fuzzer (fuzz/artifacts/load_gltf/crash-de236477...):
/// a GLB header declaring a length shorter than the header made the gltf crate subtract with
/// overflow (a panic in debug builds).
#[test]
fn a_glb_length_shorter_than_its_header_is_an_error() {
    let crash = include_bytes!("data/fuzz-load_gltf-crash-de236477.bin");
    // The fuzzer's first byte chose .glb; the file declares 11 bytes.
    let (location, problem) =
        problem_of(load_with("crash.glb", &crash[1..], LoadLimits::default()));
    assert_eq!(location, "GLB header");
    assert_eq!(
        problem,
        Problem::Malformed(format!(
            "declared length 11 does not fit the file's {} bytes",
            crash.len() - 1
        ))
    );
}

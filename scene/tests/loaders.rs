//! Loader tests: real meshes in every format agree, bad files give clear errors.

mod common;

use std::io::Write;

use common::{temp_dir, test_mesh, triangle_set};
use scene::{LoadOptions, Problem, SceneError, load_file};

fn load(path: &std::path::Path) -> Result<scene::Scene, SceneError> {
    load_file(path, &LoadOptions::default())
}

/// Writes `bytes` to a file called `name` in a fresh directory and loads it.
fn load_bytes(name: &str, bytes: &[u8]) -> Result<scene::Scene, SceneError> {
    let dir = temp_dir(&format!("bytes-{}", name.replace('.', "-")));
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    load(&path)
}

#[test]
fn shared_meshes_load_with_their_documented_triangle_counts() {
    // Counts from testdata/README.md.
    for (name, triangles) in [
        ("bunny.ply", 3674),
        ("teapot.ply", 992),
        ("airplane.ply", 2452),
    ] {
        let scene = load(&test_mesh(name)).unwrap();
        let total = scene.triangle_count() + scene.degenerate_triangles_dropped;
        assert_eq!(total, triangles, "{name}");
        assert_eq!(scene.objects.len(), 1);
    }
}

#[test]
fn the_same_mesh_saved_as_ply_obj_and_glb_loads_the_same() {
    let original = load(&test_mesh("bunny.ply")).unwrap();
    let expected = triangle_set(&original.objects);
    let dir = temp_dir("round-trip");
    let mut files = Vec::new();
    for (name, write) in [
        (
            "bunny.ply",
            scene::write_ply as fn(&[scene::Object], &mut std::fs::File) -> std::io::Result<()>,
        ),
        ("bunny.obj", scene::write_obj),
        ("bunny.glb", scene::write_glb),
    ] {
        let path = dir.join(name);
        write(
            &original.objects,
            &mut std::fs::File::create(&path).unwrap(),
        )
        .unwrap();
        files.push(path);
    }
    for path in &files {
        let loaded = load(path).unwrap();
        common::assert_same_triangles(
            &triangle_set(&loaded.objects),
            &expected,
            &path.display().to_string(),
        );
        let colors: std::collections::BTreeSet<[u8; 4]> = loaded
            .objects
            .iter()
            .flat_map(|o| o.colors.iter().copied())
            .collect();
        let original_colors: std::collections::BTreeSet<[u8; 4]> =
            original.objects[0].colors.iter().copied().collect();
        assert_eq!(colors, original_colors, "{}", path.display());
    }
}

#[test]
fn gzipped_files_load_directly() {
    let dir = temp_dir("gzip");
    let bytes = std::fs::read(test_mesh("teapot.ply")).unwrap();
    let path = dir.join("teapot.ply.gz");
    let mut encoder = flate2::write::GzEncoder::new(
        std::fs::File::create(&path).unwrap(),
        flate2::Compression::fast(),
    );
    encoder.write_all(&bytes).unwrap();
    encoder.finish().unwrap();
    let plain = load(&test_mesh("teapot.ply")).unwrap();
    let zipped = load(&path).unwrap();
    common::assert_same_triangles(
        &triangle_set(&zipped.objects),
        &triangle_set(&plain.objects),
        "gzip",
    );
}

#[test]
fn obj_groups_become_objects_with_material_colours() {
    let dir = temp_dir("obj-groups");
    std::fs::write(
        dir.join("m.mtl"),
        "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n",
    )
    .unwrap();
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n\
               o first\nusemtl red\nf 1 2 3\n\
               g second\nusemtl blue\nf 2 4 3\nf -3 -1 -2\n";
    std::fs::write(dir.join("two.obj"), obj).unwrap();
    let scene = load(&dir.join("two.obj")).unwrap();
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["first", "second"]);
    assert_eq!(scene.objects[0].colors, vec![[255, 0, 0, 255]; 3]);
    assert!(
        scene.objects[1]
            .colors
            .iter()
            .all(|c| *c == [0, 0, 255, 255])
    );
    assert_eq!(scene.objects[1].triangles.len(), 2);
}

#[test]
fn ascii_and_big_endian_ply_with_quads_and_colours() {
    let ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                 property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n\
                 0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0 9 9 9\n4 0 1 2 3\n";
    let scene = load_bytes("quad.ply", ascii.as_bytes()).unwrap();
    assert_eq!(
        scene.objects[0].triangles.len(),
        2,
        "a quad is fanned into two triangles"
    );
    assert!(scene.objects[0].colors.contains(&[255, 0, 0, 255]));

    let mut big = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
                    element face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
    for v in [[0.0f64, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0]] {
        for c in v {
            big.extend_from_slice(&c.to_be_bytes());
        }
    }
    big.push(3);
    for i in [0u32, 1, 2] {
        big.extend_from_slice(&i.to_be_bytes());
    }
    let scene = load_bytes("big.ply", &big).unwrap();
    let bounds = scene.bounds();
    assert_eq!(bounds.max.to_array(), [2.0, 3.0, 0.0]);
}

/// The problem of a load that must fail, with its location.
fn problem_of(result: Result<scene::Scene, SceneError>) -> (String, Problem) {
    match result {
        Err(SceneError::Invalid {
            location, problem, ..
        }) => (location, problem),
        other => panic!("expected an Invalid error, got {other:?}"),
    }
}

const PLY_HEADER: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

#[test]
fn bad_files_name_the_element_at_fault() {
    let (location, problem) = problem_of(load_bytes(
        "nan.ply",
        format!("{PLY_HEADER}0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n").as_bytes(),
    ));
    assert_eq!(location, "vertex 1");
    assert!(matches!(problem, Problem::NonFiniteCoordinate(v) if v.is_nan()));

    let (location, problem) = problem_of(load_bytes(
        "inf.ply",
        format!("{PLY_HEADER}0 0 0\n1 0 0\n0 inf 0\n3 0 1 2\n").as_bytes(),
    ));
    assert_eq!(location, "vertex 2");
    assert_eq!(problem, Problem::NonFiniteCoordinate(f64::INFINITY));

    let (location, problem) = problem_of(load_bytes(
        "index.ply",
        format!("{PLY_HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").as_bytes(),
    ));
    assert_eq!(location, "face 0");
    assert_eq!(
        problem,
        Problem::IndexOutOfRange {
            index: 7,
            vertex_count: 3
        }
    );

    let (location, problem) = problem_of(load_bytes(
        "two.ply",
        format!("{PLY_HEADER}0 0 0\n1 0 0\n0 1 0\n2 0 1\n").as_bytes(),
    ));
    assert_eq!(location, "face 0");
    assert_eq!(problem, Problem::TooFewVertices(2));

    let (_, problem) = problem_of(load_bytes(
        "short.ply",
        format!("{PLY_HEADER}0 0 0\n1 0 0\n").as_bytes(),
    ));
    assert_eq!(problem, Problem::Truncated);

    let (location, problem) = problem_of(load_bytes(
        "obj-index.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    ));
    assert_eq!(location, "line 4");
    assert_eq!(
        problem,
        Problem::IndexOutOfRange {
            index: 4,
            vertex_count: 3
        }
    );

    let (location, problem) = problem_of(load_bytes("obj-nan.obj", b"v 0 0 0\nv NaN 0 0\n"));
    assert_eq!(location, "line 2");
    assert!(matches!(problem, Problem::NonFiniteCoordinate(_)));

    let (location, problem) = problem_of(load_bytes("obj-face.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n"));
    assert_eq!(location, "line 3");
    assert_eq!(problem, Problem::TooFewVertices(2));

    // A header that promises a billion vertices in a few bytes fails before allocating.
    let huge = "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let (location, problem) = problem_of(load_bytes("huge.ply", huge.as_bytes()));
    assert_eq!((location.as_str(), problem), ("header", Problem::Truncated));
}

#[test]
fn truncated_and_malformed_gltf_is_an_error() {
    let original = load(&test_mesh("teapot.ply")).unwrap();
    let mut glb = Vec::new();
    scene::write_glb(&original.objects, &mut glb).unwrap();
    // Cut the binary chunk short: the declared buffer no longer fits.
    let cut = &glb[..glb.len() - 100];
    assert!(matches!(
        load_bytes("cut.glb", cut),
        Err(SceneError::Invalid { .. })
    ));
    assert!(matches!(
        load_bytes("junk.gltf", b"{\"asset\": 7}"),
        Err(SceneError::Invalid { .. })
    ));
}

#[test]
fn empty_and_all_degenerate_files_are_refused() {
    let empty = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    assert!(matches!(
        load_bytes("empty.ply", empty.as_bytes()),
        Err(SceneError::Empty { .. })
    ));
    // Three collinear points: the only triangle has zero area.
    let flat = format!("{PLY_HEADER}0 0 0\n1 1 1\n2 2 2\n3 0 1 2\n");
    match load_bytes("flat.ply", flat.as_bytes()) {
        Err(SceneError::Empty { why, .. }) => assert!(why.contains("zero area"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        load_bytes("mesh.stl", b"solid"),
        Err(SceneError::UnsupportedFormat { .. })
    ));
}

#[test]
fn a_million_identical_points_is_a_clear_error() {
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 333333\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for _ in 0..1_000_000 {
        for c in [1.5f32, 2.5, 3.5] {
            ply.extend_from_slice(&c.to_le_bytes());
        }
    }
    for f in 0..333_333i32 {
        ply.push(3);
        for i in 0..3 {
            ply.extend_from_slice(&(3 * f + i).to_le_bytes());
        }
    }
    match load_bytes("points.ply", &ply) {
        Err(SceneError::Empty { why, .. }) => {
            assert!(why.contains("333333 triangles have zero area"), "{why}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 3\n\
               property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n3 0 1 2\n3 0 1 3\n3 0 0 2\n";
    let scene = load_bytes("some-flat.ply", ply.as_bytes()).unwrap();
    assert_eq!(scene.triangle_count(), 1);
    assert_eq!(scene.degenerate_triangles_dropped, 2);
}

#[test]
fn gltf_nodes_apply_their_transforms_and_base_colour() {
    // One triangle mesh used by a parent node (translated by 10 in x) and its child (scaled
    // by 2, then mirrored in z), with a red material. Buffer: positions (3 x vec3 f32) then
    // indices (3 x u16), embedded as a data URI.
    let mut buffer = Vec::new();
    for value in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        buffer.extend_from_slice(&value.to_le_bytes());
    }
    for index in [0u16, 1, 2] {
        buffer.extend_from_slice(&index.to_le_bytes());
    }
    buffer.extend_from_slice(&[0, 0]);
    use base64::Engine;
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&buffer)
    );
    let document = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "parent", "mesh": 0, "translation": [10.0, 0.0, 0.0], "children": [1]},
            {"name": "child", "mesh": 0, "scale": [2.0, 2.0, -2.0]}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, 1.0]}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "buffers": [{"byteLength": buffer.len(), "uri": uri}]
    });
    let scene = load_bytes("nodes.gltf", document.to_string().as_bytes()).unwrap();
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["parent", "child"]);
    let corners = |object: &scene::Object| -> Vec<[f64; 3]> {
        object.triangles[0]
            .iter()
            .map(|&v| object.world_position(v).to_array())
            .collect()
    };
    assert_eq!(
        corners(&scene.objects[0]),
        [[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]
    );
    // The child inherits the translation; its mirror flips the winding back to front-facing.
    assert_eq!(
        corners(&scene.objects[1]),
        [[10.0, 0.0, 0.0], [10.0, 2.0, 0.0], [12.0, 0.0, 0.0]]
    );
    assert!(
        scene
            .objects
            .iter()
            .all(|o| o.colors.iter().all(|c| *c == [255, 0, 0, 255]))
    );
}

#[test]
fn forest_meshes_are_copied_into_the_forest() {
    let options = LoadOptions {
        triangles: 400_000,
        forest_meshes: vec![test_mesh("bunny.ply")],
        ..LoadOptions::default()
    };
    let forest = scene::load_scene("forest", &options).unwrap();
    let bunnies: Vec<&scene::Object> = forest
        .objects
        .iter()
        .filter(|o| o.name.starts_with("bunny"))
        .collect();
    assert_eq!(
        bunnies.len(),
        2,
        "every other of the four objects is a copy"
    );
    // Scaled so the longest side is 5-8 m, then turned about the vertical, which keeps the
    // height: height / original height = scale.
    let original = load(&test_mesh("bunny.ply")).unwrap().bounds().size();
    let (low, high) = (5.0 / original.max_element(), 8.0 / original.max_element());
    for bunny in &bunnies {
        assert_eq!(bunny.triangles.len(), 3674, "a full copy, not an instance");
        let scale = bunny.bounds().size().y / original.y;
        assert!(
            scale >= low - 1e-6 && scale <= high + 1e-6,
            "scaled to tree size: {scale} not in {low}..{high}"
        );
    }
    assert_ne!(bunnies[0].origin, bunnies[1].origin);
}

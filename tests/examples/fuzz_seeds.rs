//! Writes the fuzzers' seed corpora (`fuzz/seeds/TARGET/`) from the test meshes:
//! `cargo run -p integration-tests --example fuzz_seeds -- fuzz/seeds`.

use std::path::{Path, PathBuf};

use prost::Message;

fn main() -> anyhow::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fuzz/seeds".into()),
    );
    let testdata = Path::new(env!("CARGO_MANIFEST_DIR")).join("../testdata");
    let load = |name: &str| scene::load_file(&testdata.join(name), &scene::LoadOptions::default());
    let teapot = load("teapot.ply")?;
    let write = |target: &str, name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let dir = out.join(target);
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join(name), bytes)?;
        Ok(())
    };
    // The loaders: the real files, and the teapot written back in each format.
    for name in ["teapot.ply", "airplane.ply"] {
        write("load_ply", name, &std::fs::read(testdata.join(name))?)?;
    }
    let (mut ply, mut obj, mut glb) = (Vec::new(), Vec::new(), Vec::new());
    scene::write_ply(&teapot.objects, &mut ply)?;
    scene::write_obj(&teapot.objects, &mut obj)?;
    scene::write_glb(&teapot.objects, &mut glb)?;
    write("load_ply", "teapot-binary.ply", &ply)?;
    write("load_obj", "teapot.obj", &obj)?;
    // The glTF target's first byte picks the format: even = .glb.
    write(
        "load_gltf",
        "teapot.glb",
        &[[0u8].as_slice(), &glb].concat(),
    )?;
    // One triangle, instanced by a parent node and its child, with a data-URI buffer.
    let json = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],
"nodes":[{"mesh":0,"translation":[1,0,0],"children":[1]},{"mesh":0,"scale":[2,2,2]}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"buffers":[{"byteLength":44,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA="}]}"#;
    write(
        "load_gltf",
        "triangle.gltf",
        &[b"\x01".as_slice(), json.as_bytes()].concat(),
    )?;
    // A store stream: u16 length, then the chunk.
    let mut stream = Vec::new();
    let airplane = load("airplane.ply")?;
    for chunk in proto::object_to_chunks(3, &airplane.objects[0]) {
        let bytes = chunk.encode_to_vec();
        stream.extend((bytes.len().min(u16::MAX as usize) as u16).to_le_bytes());
        stream.extend(bytes);
    }
    write("assemble_object", "airplane.bin", &stream)?;
    // A board, as a worker sends it.
    let object = backend::PreparedObject::new(&teapot.objects[0])?;
    let maps = backend::render_maps(&object, glam::DVec3::new(0.3, -0.2, -1.0), 48, 1)?;
    write(
        "decode_board",
        "teapot-48.bin",
        &backend::EncodedBoard::encode(&maps).bytes,
    )?;
    println!("wrote seeds under {}", out.display());
    Ok(())
}

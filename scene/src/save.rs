//! Writers for the formats the loaders read, so tools can export what they make (boards,
//! clusters) and tests can round-trip meshes through every loader.

use std::io::{self, Write};

use crate::object::Object;

/// Writes objects as one binary little-endian PLY with vertex colours (world coordinates).
pub fn write_ply(objects: &[Object], out: &mut impl Write) -> io::Result<()> {
    let vertices: usize = objects.iter().map(|o| o.positions.len()).sum();
    let faces: usize = objects.iter().map(|o| o.triangles.len()).sum();
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment written by reliefboard\nelement vertex {vertices}\n\
         property double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n\
         element face {faces}\nproperty list uchar uint vertex_indices\nend_header\n"
    )?;
    for object in objects {
        for (index, color) in object.colors.iter().enumerate() {
            for value in object.world_position(index as u32).to_array() {
                out.write_all(&value.to_le_bytes())?;
            }
            out.write_all(color)?;
        }
    }
    let mut first = 0u32;
    for object in objects {
        for triangle in &object.triangles {
            out.write_all(&[3])?;
            for index in triangle {
                out.write_all(&(first + index).to_le_bytes())?;
            }
        }
        first += object.positions.len() as u32;
    }
    Ok(())
}

/// Writes objects as OBJ, one `o` per object, vertex colours as `v x y z r g b`.
pub fn write_obj(objects: &[Object], out: &mut impl Write) -> io::Result<()> {
    writeln!(out, "# written by reliefboard")?;
    let mut first = 1u64;
    for object in objects {
        writeln!(out, "o {}", object.name)?;
        for (index, color) in object.colors.iter().enumerate() {
            let p = object.world_position(index as u32);
            let c = color.map(|c| c as f64 / 255.0);
            writeln!(out, "v {} {} {} {} {} {}", p.x, p.y, p.z, c[0], c[1], c[2])?;
        }
        for [a, b, c] in &object.triangles {
            writeln!(
                out,
                "f {} {} {}",
                first + *a as u64,
                first + *b as u64,
                first + *c as u64
            )?;
        }
        first += object.positions.len() as u64;
    }
    Ok(())
}

/// Writes objects as glTF 2.0 binary (`.glb`): one node per object, translated to the
/// object's origin, with `COLOR_0`.
pub fn write_glb(objects: &[Object], out: &mut impl Write) -> io::Result<()> {
    let mut binary: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    for object in objects {
        let mut view = |binary: &mut Vec<u8>, data: &[u8], target: u32| {
            while !binary.len().is_multiple_of(4) {
                binary.push(0);
            }
            views.push(serde_json::json!({"buffer": 0, "byteOffset": binary.len(), "byteLength": data.len(), "target": target}));
            binary.extend_from_slice(data);
            views.len() - 1
        };
        let positions: Vec<u8> = object
            .positions
            .iter()
            .flat_map(|p| p.to_array())
            .flat_map(f32::to_le_bytes)
            .collect();
        let colors: Vec<u8> = object.colors.iter().flatten().copied().collect();
        let indices: Vec<u8> = object
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let local =
            crate::geometry::Aabb::from_points(object.positions.iter().map(|p| p.as_dvec3()));
        let (position_view, color_view, index_view) = (
            view(&mut binary, &positions, 34962),
            view(&mut binary, &colors, 34962),
            view(&mut binary, &indices, 34963),
        );
        let first = accessors.len();
        accessors.push(serde_json::json!({"bufferView": position_view, "componentType": 5126, "count": object.positions.len(), "type": "VEC3",
            "min": [local.min.x as f32, local.min.y as f32, local.min.z as f32], "max": [local.max.x as f32, local.max.y as f32, local.max.z as f32]}));
        accessors.push(serde_json::json!({"bufferView": color_view, "componentType": 5121, "normalized": true, "count": object.colors.len(), "type": "VEC4"}));
        accessors.push(serde_json::json!({"bufferView": index_view, "componentType": 5125, "count": object.triangles.len() * 3, "type": "SCALAR"}));
        meshes.push(serde_json::json!({"primitives": [{"attributes": {"POSITION": first, "COLOR_0": first + 1}, "indices": first + 2}]}));
        nodes.push(serde_json::json!({"name": object.name, "mesh": meshes.len() - 1, "translation": object.origin.to_array()}));
    }
    while !binary.len().is_multiple_of(4) {
        binary.push(0);
    }
    let document = serde_json::json!({
        "asset": {"version": "2.0", "generator": "reliefboard"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes, "meshes": meshes, "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": binary.len()}],
    });
    let mut json = serde_json::to_vec(&document).map_err(io::Error::other)?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + binary.len();
    out.write_all(b"glTF")?;
    out.write_all(&2u32.to_le_bytes())?;
    out.write_all(&(total as u32).to_le_bytes())?;
    out.write_all(&(json.len() as u32).to_le_bytes())?;
    out.write_all(b"JSON")?;
    out.write_all(&json)?;
    out.write_all(&(binary.len() as u32).to_le_bytes())?;
    out.write_all(b"BIN\0")?;
    out.write_all(&binary)?;
    Ok(())
}

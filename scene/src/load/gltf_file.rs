//! glTF 2.0 (`.gltf` with embedded or external buffers, `.glb`): every node with a mesh in the
//! default scene becomes one object, in world space (its transform times its parents'), with
//! the material's base colour times any `COLOR_0` vertex colour. Textures are not read.
//!
//! The `gltf` crate validates the JSON but trusts the binary layout (and debug-asserts on
//! mismatched accessor types), so every accessor is checked here before it is read.
//!
//! A few bytes of JSON can describe an enormous scene: a node graph where each node has two
//! children that are the next nodes (a DAG: 2^64 paths through 64 nodes), a cycle, or a
//! million nodes instancing one large mesh. The walk refuses cycles, counts every node
//! instance and every triangle before reading it, and stops at [`LoadLimits`].

use std::path::Path;

use base64::Engine;
use glam::{DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use super::{LoadLimits, finite, invalid};
use crate::error::{Problem, SceneError};
use crate::object::ObjectBuilder;

/// Deeper node hierarchies are refused (the recursion's bound).
const MAX_NODE_DEPTH: usize = 64;

pub(super) fn parse(
    path: &str,
    bytes: &[u8],
    directory: Option<&Path>,
    limits: &LoadLimits,
) -> Result<Vec<ObjectBuilder>, SceneError> {
    let malformed =
        |error: gltf::Error| invalid(path, "document", Problem::Malformed(error.to_string()));
    check_glb_header(path, bytes)?;
    let unchecked = gltf::Gltf::from_slice_without_validation(bytes).map_err(malformed)?;
    check_position_accessors(path, unchecked.document.as_json())?;
    let document = gltf::Gltf {
        document: gltf::Document::from_json(unchecked.document.into_json()).map_err(malformed)?,
        blob: unchecked.blob,
    };
    let buffers = load_buffers(path, &document, directory)?;
    let mut objects = Vec::new();
    let roots: Vec<gltf::Node> = match document
        .default_scene()
        .or_else(|| document.scenes().next())
    {
        Some(scene) => scene.nodes().collect(),
        // No scene: every node that is no other node's child is a root.
        None => {
            let children: std::collections::HashSet<usize> = document
                .nodes()
                .flat_map(|n| n.children().map(|c| c.index()))
                .collect();
            document
                .nodes()
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    };
    let mut walk = Walk {
        path,
        buffers: &buffers,
        limits,
        ancestors: Vec::new(),
        instances: 0,
        triangles: 0,
        vertices: 0,
        objects: &mut objects,
    };
    for root in roots {
        walk.visit(&root, DMat4::IDENTITY)?;
    }
    Ok(objects)
}

/// Regression (found by the `load_gltf` fuzzer): gltf 1.4.1 subtracts the 12-byte header
/// from a GLB's declared length unchecked, which panics (debug builds) or wraps around
/// (release) when the declared length is shorter than the header itself.
fn check_glb_header(path: &str, bytes: &[u8]) -> Result<(), SceneError> {
    if let Some(length) = bytes
        .strip_prefix(b"glTF")
        .and_then(|rest| rest.get(4..8))
        .map(|length| u32::from_le_bytes([length[0], length[1], length[2], length[3]]))
        && (length < 12 || length as usize > bytes.len())
    {
        return Err(invalid(
            path,
            "GLB header",
            Problem::Malformed(format!(
                "declared length {length} does not fit the file's {} bytes",
                bytes.len()
            )),
        ));
    }
    Ok(())
}

/// Regression (found by the `load_gltf` fuzzer): gltf-json 1.4.1's validation reads every
/// primitive's POSITION accessor by index before checking that the index exists, and panics
/// on one that does not. Checked here first, so such a file is an error.
fn check_position_accessors(path: &str, json: &gltf::json::Root) -> Result<(), SceneError> {
    use gltf::json::validation::Checked;
    for (mesh_index, mesh) in json.meshes.iter().enumerate() {
        for (primitive_index, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive
                .attributes
                .get(&Checked::Valid(gltf::json::mesh::Semantic::Positions));
            if let Some(accessor) = position
                && accessor.value() >= json.accessors.len()
            {
                return Err(invalid(
                    path,
                    format!("mesh {mesh_index}, primitive {primitive_index}"),
                    Problem::Malformed(format!(
                        "POSITION names accessor {}, but the file has {}",
                        accessor.value(),
                        json.accessors.len()
                    )),
                ));
            }
        }
    }
    Ok(())
}

/// The state of one walk over the node graph: what bounds it.
struct Walk<'a> {
    path: &'a str,
    buffers: &'a [Vec<u8>],
    limits: &'a LoadLimits,
    /// The nodes from the root to the current one: a child among them is a cycle.
    ancestors: Vec<usize>,
    /// Node instances visited so far (a node reached along two paths counts twice).
    instances: u64,
    /// Triangles and vertices accepted so far, counted before they are read.
    triangles: u64,
    vertices: u64,
    objects: &'a mut Vec<ObjectBuilder>,
}

impl Walk<'_> {
    fn visit(&mut self, node: &gltf::Node, parent: DMat4) -> Result<(), SceneError> {
        let path = self.path;
        let at = || format!("node {}", node.index());
        if self.ancestors.contains(&node.index()) {
            return Err(invalid(
                path,
                at(),
                Problem::Malformed("the node is its own ancestor (a cycle)".into()),
            ));
        }
        if self.ancestors.len() >= MAX_NODE_DEPTH {
            return Err(invalid(
                path,
                at(),
                Problem::TooLarge(format!("node hierarchy deeper than {MAX_NODE_DEPTH}")),
            ));
        }
        self.instances += 1;
        if self.instances > self.limits.max_node_instances {
            return Err(invalid(
                path,
                at(),
                Problem::TooLarge(format!(
                    "more than {} node instances (nodes reached along many paths)",
                    self.limits.max_node_instances
                )),
            ));
        }
        self.ancestors.push(node.index());
        let result = self.visit_inner(node, parent);
        self.ancestors.pop();
        result
    }

    fn visit_inner(&mut self, node: &gltf::Node, parent: DMat4) -> Result<(), SceneError> {
        let (path, buffers) = (self.path, self.buffers);
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if !world.is_finite() {
            return Err(invalid(
                path,
                format!("node {}", node.index()),
                Problem::Malformed("transform is not finite".into()),
            ));
        }
        if let Some(mesh) = node.mesh() {
            let name = node
                .name()
                .or(mesh.name())
                .map(str::to_string)
                .unwrap_or_else(|| format!("node {}", node.index()));
            let mut builder = ObjectBuilder::new(name);
            for primitive in mesh.primitives() {
                self.triangles += upper_triangle_count(&primitive);
                self.vertices += primitive
                    .get(&gltf::Semantic::Positions)
                    .map_or(0, |positions| positions.count() as u64);
                // Vertices are bounded too: a primitive may index 3 of a million vertices.
                if self.triangles > self.limits.max_triangles
                    || self.vertices > self.limits.max_triangles.saturating_mul(3)
                {
                    return Err(invalid(
                        path,
                        format!("mesh {} in node {}", mesh.index(), node.index()),
                        Problem::TooLarge(format!(
                            "the scene's node instances hold more than {} triangles or three times as many vertices (--max-triangles)",
                            self.limits.max_triangles
                        )),
                    ));
                }
                read_primitive(path, &primitive, world, buffers, &mut builder)?;
            }
            self.objects.push(builder);
        }
        for child in node.children() {
            self.visit(&child, world)?;
        }
        Ok(())
    }
}

/// At most how many triangles a primitive yields, from its accessors' declared counts (read
/// before any data, so the limit holds before anything is allocated).
fn upper_triangle_count(primitive: &gltf::Primitive) -> u64 {
    if !matches!(
        primitive.mode(),
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return 0;
    }
    let count = primitive
        .indices()
        .or_else(|| primitive.get(&gltf::Semantic::Positions))
        .map_or(0, |accessor| accessor.count() as u64);
    match primitive.mode() {
        Mode::Triangles => count / 3,
        _ => count.saturating_sub(2),
    }
}

fn read_primitive(
    path: &str,
    primitive: &gltf::Primitive,
    world: DMat4,
    buffers: &[Vec<u8>],
    builder: &mut ObjectBuilder,
) -> Result<(), SceneError> {
    let location = format!("mesh primitive {}", primitive.index());
    if !matches!(
        primitive.mode(),
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return Ok(()); // Points and lines have no surface to draw as a board.
    }
    let Some(positions) = primitive.get(&gltf::Semantic::Positions) else {
        return Err(invalid(
            path,
            location,
            Problem::Malformed("no POSITION attribute".into()),
        ));
    };
    check_accessor(
        path,
        &positions,
        &[DataType::F32],
        &[Dimensions::Vec3],
        buffers,
    )?;
    let colors = primitive.get(&gltf::Semantic::Colors(0));
    if let Some(colors) = &colors {
        check_accessor(
            path,
            colors,
            &[DataType::F32, DataType::U8, DataType::U16],
            &[Dimensions::Vec3, Dimensions::Vec4],
            buffers,
        )?;
    }
    if let Some(indices) = primitive.indices() {
        check_accessor(
            path,
            &indices,
            &[DataType::U8, DataType::U16, DataType::U32],
            &[Dimensions::Scalar],
            buffers,
        )?;
    }
    let reader = primitive.reader(|buffer| buffers.get(buffer.index()).map(Vec::as_slice));
    let base = primitive
        .material()
        .pbr_metallic_roughness()
        .base_color_factor();
    let base = base.map(|c| {
        if c.is_finite() {
            c.clamp(0.0, 1.0)
        } else {
            1.0
        }
    });

    let first = builder.vertex_count() as u32;
    let vertex_colors: Vec<[u8; 4]> = match reader.read_colors(0) {
        Some(colors) => colors.into_rgba_u8().collect(),
        None => Vec::new(),
    };
    let Some(read_positions) = reader.read_positions() else {
        return Err(invalid(
            path,
            location,
            Problem::Malformed("POSITION cannot be read".into()),
        ));
    };
    for (vertex, position) in read_positions.enumerate() {
        let world_position = world.transform_point3(DVec3::from_array(position.map(f64::from)));
        for value in world_position.to_array() {
            finite(path, || format!("{location}, vertex {vertex}"), value)?;
        }
        let vertex_color = vertex_colors.get(vertex).copied().unwrap_or([255; 4]);
        let color: [u8; 4] =
            std::array::from_fn(|c| (vertex_color[c] as f32 * base[c]).round() as u8);
        builder.vertex(world_position, color);
    }
    let vertex_count = builder.vertex_count() - first as usize;
    let indices: Vec<u32> = match reader.read_indices() {
        Some(indices) => indices.into_u32().collect(),
        None => (0..vertex_count as u32).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= vertex_count) {
        return Err(invalid(
            path,
            location,
            Problem::IndexOutOfRange {
                index: bad as i64,
                vertex_count,
            },
        ));
    }
    // A transform that mirrors flips the winding; undo it so front faces stay front faces.
    let mirrored = world.determinant() < 0.0;
    let mut add = |a: u32, b: u32, c: u32| {
        let (b, c) = if mirrored { (c, b) } else { (b, c) };
        builder.triangle(first + a, first + b, first + c);
    };
    match primitive.mode() {
        Mode::Triangles => indices.chunks_exact(3).for_each(|t| add(t[0], t[1], t[2])),
        Mode::TriangleStrip => {
            for (i, t) in indices.windows(3).enumerate() {
                if i % 2 == 0 {
                    add(t[0], t[1], t[2])
                } else {
                    add(t[1], t[0], t[2])
                }
            }
        }
        _ => {
            for pair in indices.get(1..).unwrap_or(&[]).windows(2) {
                add(indices[0], pair[0], pair[1]);
            }
        }
    }
    Ok(())
}

/// Checks that an accessor has an expected type and lies inside its buffer.
fn check_accessor(
    path: &str,
    accessor: &gltf::Accessor,
    data_types: &[DataType],
    dimensions: &[Dimensions],
    buffers: &[Vec<u8>],
) -> Result<(), SceneError> {
    let location = format!("accessor {}", accessor.index());
    let malformed =
        |message: &str| invalid(path, location.clone(), Problem::Malformed(message.into()));
    if !data_types.contains(&accessor.data_type()) || !dimensions.contains(&accessor.dimensions()) {
        return Err(malformed("unexpected component type or dimensions"));
    }
    if accessor.sparse().is_some() {
        return Err(malformed("sparse accessors are not supported"));
    }
    let Some(view) = accessor.view() else {
        return Err(malformed("accessor has no buffer view"));
    };
    if accessor.count() == 0 {
        return Err(malformed("accessor is empty"));
    }
    let element_size = accessor.size();
    let stride = view.stride().unwrap_or(element_size);
    if stride < element_size {
        return Err(malformed("byte stride smaller than an element"));
    }
    let buffer_length = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let view_end = view.offset().checked_add(view.length());
    let accessor_end = (accessor.count() - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(element_size))
        .and_then(|n| n.checked_add(accessor.offset()));
    match (view_end, accessor_end) {
        (Some(view_end), Some(accessor_end))
            if view_end <= buffer_length && accessor_end <= view.length() =>
        {
            Ok(())
        }
        _ => Err(invalid(path, location, Problem::Truncated)),
    }
}

fn load_buffers(
    path: &str,
    document: &gltf::Gltf,
    directory: Option<&Path>,
) -> Result<Vec<Vec<u8>>, SceneError> {
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let location = format!("buffer {}", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => document.blob.clone().ok_or_else(|| {
                invalid(
                    path,
                    location.clone(),
                    Problem::Malformed("GLB has no binary chunk".into()),
                )
            })?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let encoded = uri
                    .split_once(";base64,")
                    .map(|(_, data)| data)
                    .ok_or_else(|| {
                        invalid(
                            path,
                            location.clone(),
                            Problem::Malformed("only base64 data URIs are supported".into()),
                        )
                    })?;
                base64::engine::general_purpose::STANDARD
                    .decode(encoded)
                    .map_err(|error| {
                        invalid(
                            path,
                            location.clone(),
                            Problem::Malformed(format!("bad base64: {error}")),
                        )
                    })?
            }
            gltf::buffer::Source::Uri(uri) => {
                let Some(directory) = directory else {
                    return Err(invalid(
                        path,
                        location,
                        Problem::Malformed(format!(
                            "external buffer {uri:?} cannot be read from memory"
                        )),
                    ));
                };
                let file = directory.join(uri);
                std::fs::read(&file).map_err(|source| SceneError::Io {
                    path: file.display().to_string(),
                    source,
                })?
            }
        };
        if data.len() < buffer.length() {
            return Err(invalid(path, location, Problem::Truncated));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

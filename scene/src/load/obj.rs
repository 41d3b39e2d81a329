//! Wavefront OBJ: `v` (with the common `v x y z r g b` colour extension), `f` with any of the
//! `v`, `v/vt`, `v//vn`, `v/vt/vn` forms and negative (relative) indices, `o` and `g` starting
//! a new object, `usemtl` with the diffuse colour (`Kd`) of materials from `mtllib` files.
//! Other statements are ignored, as the format allows.

use std::collections::HashMap;
use std::path::Path;

use glam::DVec3;

use super::{DEFAULT_COLOR, finite, invalid};
use crate::error::{Problem, SceneError};
use crate::object::ObjectBuilder;

/// Parses an OBJ file; `directory` is where `mtllib` files are looked up.
pub(super) fn parse(
    path: &str,
    bytes: &[u8],
    directory: Option<&Path>,
) -> Result<Vec<ObjectBuilder>, SceneError> {
    let text = std::str::from_utf8(bytes).map_err(|error| {
        invalid(
            path,
            format!("byte {}", error.valid_up_to()),
            Problem::Malformed("not text".into()),
        )
    })?;
    let stem = super::file_stem(path);

    let mut positions: Vec<DVec3> = Vec::new();
    let mut vertex_colors: Vec<Option<[u8; 4]>> = Vec::new();
    let mut materials: HashMap<String, [u8; 4]> = HashMap::new();
    let mut current_color: Option<[u8; 4]> = None;
    let mut objects = Vec::new();
    let mut current = ObjectInProgress::new(stem.clone());
    let mut polygon = Vec::new();

    for (line_index, raw_line) in text.lines().enumerate() {
        let line_number = line_index + 1;
        let location = || format!("line {line_number}");
        let line = raw_line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        match keyword {
            "v" => {
                let values: Vec<&str> = words.collect();
                if values.len() < 3 {
                    return Err(invalid(
                        path,
                        location(),
                        Problem::Malformed("a vertex needs x, y and z".into()),
                    ));
                }
                let mut numbers = [0.0f64; 6];
                for (slot, word) in numbers.iter_mut().zip(values.iter().take(6)) {
                    *slot = word.parse().map_err(|_| {
                        invalid(
                            path,
                            location(),
                            Problem::Malformed(format!("{word:?} is not a number")),
                        )
                    })?;
                }
                for &value in &numbers[..3] {
                    finite(path, location, value)?;
                }
                positions.push(DVec3::new(numbers[0], numbers[1], numbers[2]));
                vertex_colors.push((values.len() >= 6).then(|| {
                    let channel = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                    [
                        channel(numbers[3]),
                        channel(numbers[4]),
                        channel(numbers[5]),
                        255,
                    ]
                }));
            }
            "f" => {
                polygon.clear();
                for word in words {
                    let index_text = word.split('/').next().unwrap_or("");
                    let index: i64 = index_text.parse().map_err(|_| {
                        invalid(
                            path,
                            location(),
                            Problem::Malformed(format!("bad face index {word:?}")),
                        )
                    })?;
                    let vertex_count = positions.len();
                    // OBJ counts from 1; negative indices count back from the last vertex.
                    let resolved = if index > 0 {
                        index - 1
                    } else {
                        vertex_count as i64 + index
                    };
                    if index == 0 || resolved < 0 || resolved >= vertex_count as i64 {
                        return Err(invalid(
                            path,
                            location(),
                            Problem::IndexOutOfRange {
                                index,
                                vertex_count,
                            },
                        ));
                    }
                    polygon.push(resolved as u32);
                }
                if polygon.len() < 3 {
                    return Err(invalid(
                        path,
                        location(),
                        Problem::TooFewVertices(polygon.len()),
                    ));
                }
                let locals: Vec<u32> = polygon
                    .iter()
                    .map(|&global| {
                        let vertex_color = vertex_colors[global as usize];
                        let color = current_color.or(vertex_color).unwrap_or(DEFAULT_COLOR);
                        current.vertex(global, color, positions[global as usize])
                    })
                    .collect();
                for pair in locals[1..].windows(2) {
                    current.builder.triangle(locals[0], pair[0], pair[1]);
                }
            }
            "o" | "g" => {
                let name = words.collect::<Vec<_>>().join(" ");
                let name = if name.is_empty() { stem.clone() } else { name };
                let finished = std::mem::replace(&mut current, ObjectInProgress::new(name));
                if finished.builder.triangle_count() > 0 {
                    objects.push(finished.builder);
                }
            }
            "usemtl" => {
                let name = words.collect::<Vec<_>>().join(" ");
                current_color = materials.get(&name).copied();
            }
            "mtllib" => {
                for file in words {
                    if let Some(directory) = directory {
                        // A missing material library leaves the default colour: the
                        // geometry is still worth drawing.
                        if let Ok(text) = std::fs::read_to_string(directory.join(file)) {
                            materials.extend(parse_mtl(&text));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    if current.builder.triangle_count() > 0 {
        objects.push(current.builder);
    }
    Ok(objects)
}

/// One object's builder with the map from file vertex (and colour) to object vertex.
struct ObjectInProgress {
    builder: ObjectBuilder,
    local_index: HashMap<(u32, [u8; 4]), u32>,
}

impl ObjectInProgress {
    fn new(name: String) -> ObjectInProgress {
        ObjectInProgress {
            builder: ObjectBuilder::new(name),
            local_index: HashMap::new(),
        }
    }

    fn vertex(&mut self, global: u32, color: [u8; 4], position: DVec3) -> u32 {
        let builder = &mut self.builder;
        *self
            .local_index
            .entry((global, color))
            .or_insert_with(|| builder.vertex(position, color))
    }
}

/// Reads `newmtl` names and their `Kd` diffuse colours; everything else is ignored.
fn parse_mtl(text: &str) -> HashMap<String, [u8; 4]> {
    let mut materials = HashMap::new();
    let mut name: Option<String> = None;
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("newmtl") => name = Some(words.collect::<Vec<_>>().join(" ")),
            Some("Kd") => {
                let values: Vec<f64> = words.filter_map(|w| w.parse().ok()).collect();
                if let (Some(name), [r, g, b, ..]) = (&name, values.as_slice()) {
                    let channel = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                    materials.insert(name.clone(), [channel(*r), channel(*g), channel(*b), 255]);
                }
            }
            _ => {}
        }
    }
    materials
}

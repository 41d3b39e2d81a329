//! PLY (Stanford polygon format): ASCII and binary (both byte orders), vertices with optional
//! colours, faces as index lists (polygons are fanned into triangles), unknown elements and
//! properties skipped.

use glam::DVec3;

use super::{DEFAULT_COLOR, finite, invalid};
use crate::error::{Problem, SceneError};
use crate::object::ObjectBuilder;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    /// For a list, the type of the count.
    count: Option<Scalar>,
    value: Scalar,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

impl Element {
    /// The fewest bytes (binary) or characters (ASCII) one instance can take: a bound that
    /// lets a header's counts be checked against the file's size before allocating.
    fn min_size(&self, encoding: Encoding) -> usize {
        let min = self
            .properties
            .iter()
            .map(|p| match (encoding, p.count) {
                (Encoding::Ascii, _) => 2,
                (_, Some(count)) => count.size(),
                (_, None) => p.value.size(),
            })
            .sum::<usize>();
        min.max(1)
    }
}

/// Parses a PLY file into one object.
pub(super) fn parse(path: &str, bytes: &[u8]) -> Result<Vec<ObjectBuilder>, SceneError> {
    let (encoding, elements, body_start) = parse_header(path, bytes)?;
    let body = &bytes[body_start..];
    // A header may claim any count; the body bounds what can really be there.
    let min_body: usize = elements
        .iter()
        .map(|e| e.count.saturating_mul(e.min_size(encoding)))
        .fold(0usize, |a, b| a.saturating_add(b));
    if min_body > body.len() {
        return Err(invalid(path, "header", Problem::Truncated));
    }
    let mut reader = match encoding {
        Encoding::Ascii => Reader::Ascii(AsciiReader::new(body)),
        Encoding::BinaryLittleEndian => Reader::Binary {
            bytes: body,
            at: 0,
            little: true,
        },
        Encoding::BinaryBigEndian => Reader::Binary {
            bytes: body,
            at: 0,
            little: false,
        },
    };

    let stem = super::file_stem(path);
    let mut builder = ObjectBuilder::new(stem);
    let mut vertex_count = 0usize;
    let mut saw_vertices = false;
    let mut polygon = Vec::new();
    for element in &elements {
        match element.name.as_str() {
            "vertex" => {
                saw_vertices = true;
                vertex_count = element.count;
                read_vertices(path, element, &mut reader, &mut builder)?;
            }
            "face" => {
                if !saw_vertices {
                    return Err(invalid(
                        path,
                        "header",
                        Problem::Malformed("faces come before vertices".into()),
                    ));
                }
                let list = element
                    .properties
                    .iter()
                    .position(|p| {
                        p.count.is_some()
                            && (p.name == "vertex_indices" || p.name == "vertex_index")
                    })
                    .ok_or_else(|| {
                        invalid(
                            path,
                            "header",
                            Problem::Malformed("face element has no vertex_indices list".into()),
                        )
                    })?;
                builder.reserve(0, element.count);
                for face in 0..element.count {
                    reader.start_line(path)?;
                    for (index, property) in element.properties.iter().enumerate() {
                        if index != list {
                            skip_property(path, property, &mut reader)?;
                            continue;
                        }
                        let count = reader.read(path, property.count.unwrap_or(Scalar::U8))?;
                        if !(0.0..=1e6).contains(&count) {
                            return Err(invalid(
                                path,
                                format!("face {face}"),
                                Problem::Malformed(format!("implausible vertex count {count}")),
                            ));
                        }
                        polygon.clear();
                        for _ in 0..count as usize {
                            let value = reader.read(path, property.value)?;
                            polygon.push(value);
                        }
                    }
                    add_polygon(path, face, &polygon, vertex_count, &mut builder)?;
                }
            }
            _ => {
                for _ in 0..element.count {
                    reader.start_line(path)?;
                    for property in &element.properties {
                        skip_property(path, property, &mut reader)?;
                    }
                }
            }
        }
    }
    Ok(vec![builder])
}

fn read_vertices(
    path: &str,
    element: &Element,
    reader: &mut Reader<'_>,
    builder: &mut ObjectBuilder,
) -> Result<(), SceneError> {
    let find = |names: &[&str]| {
        element
            .properties
            .iter()
            .position(|p| names.contains(&p.name.as_str()))
    };
    let axes = [find(&["x"]), find(&["y"]), find(&["z"])];
    let [Some(x), Some(y), Some(z)] = axes else {
        return Err(invalid(
            path,
            "header",
            Problem::Malformed("vertex element lacks x, y or z".into()),
        ));
    };
    let channels = [
        find(&["red", "diffuse_red", "r"]),
        find(&["green", "diffuse_green", "g"]),
        find(&["blue", "diffuse_blue", "b"]),
        find(&["alpha", "diffuse_alpha", "a"]),
    ];
    builder.reserve(element.count, 0);
    let mut values = vec![0.0f64; element.properties.len()];
    for vertex in 0..element.count {
        reader.start_line(path)?;
        for (slot, property) in values.iter_mut().zip(&element.properties) {
            if property.count.is_some() {
                skip_property(path, property, reader)?;
            } else {
                *slot = reader.read(path, property.value)?;
            }
        }
        let mut position = [0.0; 3];
        for (axis, &index) in [x, y, z].iter().enumerate() {
            position[axis] = finite(path, || format!("vertex {vertex}"), values[index])?;
        }
        let mut color = DEFAULT_COLOR;
        for (channel, index) in channels.iter().enumerate() {
            if let Some(index) = *index {
                let value = values[index];
                let scaled = if element.properties[index].value.is_integer() {
                    value
                } else {
                    value * 255.0
                };
                // NaN clamps to 0, so a bad colour is never an error.
                color[channel] = scaled.clamp(0.0, 255.0) as u8;
            }
        }
        builder.vertex(DVec3::from_array(position), color);
    }
    Ok(())
}

/// Fans a polygon into triangles after checking its indices.
pub(super) fn add_polygon(
    path: &str,
    face: usize,
    polygon: &[f64],
    vertex_count: usize,
    builder: &mut ObjectBuilder,
) -> Result<(), SceneError> {
    if polygon.len() < 3 {
        return Err(invalid(
            path,
            format!("face {face}"),
            Problem::TooFewVertices(polygon.len()),
        ));
    }
    let mut indices = [0u32; 3];
    let mut checked = Vec::with_capacity(polygon.len());
    for &value in polygon {
        if value.fract() != 0.0 || value < 0.0 || value >= vertex_count as f64 {
            return Err(invalid(
                path,
                format!("face {face}"),
                Problem::IndexOutOfRange {
                    index: value as i64,
                    vertex_count,
                },
            ));
        }
        checked.push(value as u32);
    }
    indices[0] = checked[0];
    for pair in checked[1..].windows(2) {
        indices[1] = pair[0];
        indices[2] = pair[1];
        builder.triangle(indices[0], indices[1], indices[2]);
    }
    Ok(())
}

fn skip_property(
    path: &str,
    property: &Property,
    reader: &mut Reader<'_>,
) -> Result<(), SceneError> {
    match property.count {
        None => {
            reader.read(path, property.value)?;
        }
        Some(count_type) => {
            let count = reader.read(path, count_type)?;
            if !(0.0..=1e6).contains(&count) {
                return Err(invalid(
                    path,
                    format!("property {}", property.name),
                    Problem::Malformed(format!("implausible list length {count}")),
                ));
            }
            for _ in 0..count as usize {
                reader.read(path, property.value)?;
            }
        }
    }
    Ok(())
}

fn parse_header(path: &str, bytes: &[u8]) -> Result<(Encoding, Vec<Element>, usize), SceneError> {
    let malformed = |line: usize, message: String| {
        invalid(
            path,
            format!("header line {line}"),
            Problem::Malformed(message),
        )
    };
    let mut at = 0usize;
    let mut line_number = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(end) = bytes[at..].iter().position(|&b| b == b'\n') else {
            return Err(invalid(path, "header", Problem::Truncated));
        };
        let line = std::str::from_utf8(&bytes[at..at + end])
            .map_err(|_| malformed(line_number + 1, "not text".into()))?
            .trim_end_matches('\r')
            .trim();
        at += end + 1;
        line_number += 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        if line_number == 1 {
            if line != "ply" {
                return Err(malformed(
                    1,
                    "a PLY file starts with the line \"ply\"".into(),
                ));
            }
            continue;
        }
        match words.as_slice() {
            [] => {}
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", kind, _version] => {
                encoding = Some(match *kind {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => {
                        return Err(malformed(line_number, format!("unknown format {other:?}")));
                    }
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse::<usize>()
                    .map_err(|_| malformed(line_number, format!("bad element count {count:?}")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, value, name] => {
                let (Some(count), Some(value)) = (Scalar::parse(count), Scalar::parse(value))
                else {
                    return Err(malformed(
                        line_number,
                        format!("unknown property type in {line:?}"),
                    ));
                };
                if !count.is_integer() {
                    return Err(malformed(
                        line_number,
                        "a list count must be an integer type".into(),
                    ));
                }
                let element = elements
                    .last_mut()
                    .ok_or_else(|| malformed(line_number, "property before any element".into()))?;
                element.properties.push(Property {
                    name: name.to_string(),
                    count: Some(count),
                    value,
                });
            }
            ["property", kind, name] => {
                let value = Scalar::parse(kind).ok_or_else(|| {
                    malformed(line_number, format!("unknown property type {kind:?}"))
                })?;
                let element = elements
                    .last_mut()
                    .ok_or_else(|| malformed(line_number, "property before any element".into()))?;
                element.properties.push(Property {
                    name: name.to_string(),
                    count: None,
                    value,
                });
            }
            ["end_header"] => break,
            _ => return Err(malformed(line_number, format!("unexpected {line:?}"))),
        }
    }
    let encoding = encoding
        .ok_or_else(|| invalid(path, "header", Problem::Malformed("no format line".into())))?;
    Ok((encoding, elements, at))
}

enum Reader<'a> {
    Ascii(AsciiReader<'a>),
    Binary {
        bytes: &'a [u8],
        at: usize,
        little: bool,
    },
}

impl Reader<'_> {
    /// ASCII PLY has one element per line; binary has no lines.
    fn start_line(&mut self, path: &str) -> Result<(), SceneError> {
        match self {
            Reader::Ascii(ascii) => ascii.next_line(path),
            Reader::Binary { .. } => Ok(()),
        }
    }

    fn read(&mut self, path: &str, scalar: Scalar) -> Result<f64, SceneError> {
        match self {
            Reader::Ascii(ascii) => ascii.read(path),
            Reader::Binary { bytes, at, little } => {
                let size = scalar.size();
                let Some(raw) = bytes.get(*at..*at + size) else {
                    return Err(invalid(
                        path,
                        format!("byte {at} of the body"),
                        Problem::Truncated,
                    ));
                };
                *at += size;
                let mut buffer = [0u8; 8];
                buffer[..size].copy_from_slice(raw);
                if !*little {
                    buffer[..size].reverse();
                }
                Ok(match scalar {
                    Scalar::I8 => buffer[0] as i8 as f64,
                    Scalar::U8 => buffer[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([buffer[0], buffer[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([buffer[0], buffer[1]]) as f64,
                    Scalar::I32 => {
                        i32::from_le_bytes(buffer[..4].try_into().unwrap_or_default()) as f64
                    }
                    Scalar::U32 => {
                        u32::from_le_bytes(buffer[..4].try_into().unwrap_or_default()) as f64
                    }
                    Scalar::F32 => {
                        f32::from_le_bytes(buffer[..4].try_into().unwrap_or_default()) as f64
                    }
                    Scalar::F64 => f64::from_le_bytes(buffer),
                })
            }
        }
    }
}

struct AsciiReader<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    words: std::str::SplitWhitespace<'a>,
    line_number: usize,
    valid_utf8: Result<(), usize>,
}

impl<'a> AsciiReader<'a> {
    fn new(body: &'a [u8]) -> AsciiReader<'a> {
        // Invalid UTF-8 can only be an error, and only where it is reached.
        let (text, valid_utf8) = match std::str::from_utf8(body) {
            Ok(text) => (text, Ok(())),
            Err(error) => {
                let valid = &body[..error.valid_up_to()];
                (
                    std::str::from_utf8(valid).unwrap_or(""),
                    Err(error.valid_up_to()),
                )
            }
        };
        AsciiReader {
            lines: text.lines().enumerate(),
            words: "".split_whitespace(),
            line_number: 0,
            valid_utf8,
        }
    }

    fn next_line(&mut self, path: &str) -> Result<(), SceneError> {
        loop {
            match self.lines.next() {
                Some((number, line)) => {
                    self.line_number = number + 1;
                    if !line.trim().is_empty() {
                        self.words = line.split_whitespace();
                        return Ok(());
                    }
                }
                None => {
                    return Err(match self.valid_utf8 {
                        Ok(()) => invalid(path, "body", Problem::Truncated),
                        Err(byte) => invalid(
                            path,
                            format!("body byte {byte}"),
                            Problem::Malformed("not text".into()),
                        ),
                    });
                }
            }
        }
    }

    fn read(&mut self, path: &str) -> Result<f64, SceneError> {
        let word = self.words.next().ok_or_else(|| {
            invalid(
                path,
                format!("body line {}", self.line_number),
                Problem::Malformed("too few values on the line".into()),
            )
        })?;
        word.parse::<f64>().map_err(|_| {
            invalid(
                path,
                format!("body line {}", self.line_number),
                Problem::Malformed(format!("{word:?} is not a number")),
            )
        })
    }
}

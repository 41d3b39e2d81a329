//! Mesh loaders. Each reads the whole file into memory (gunzipping it when it starts with the
//! gzip magic bytes) and validates every element before it reaches an [`ObjectBuilder`], so a
//! bad file gives an error that names the file and the element, never a panic.
//!
//! PLY and OBJ are parsed here rather than with `ply-rs` or `tobj`: both formats are small,
//! and owning the parser is what lets every error name its line, vertex or face and lets the
//! counts in a header be checked against the bytes that are really there before allocating.
//! glTF is not small, so it goes through the `gltf` crate, with the accessor bounds it does
//! not check verified first.

mod gltf_file;
mod obj;
mod ply;

use std::io::Read;
use std::path::{Path, PathBuf};

use indicatif::ProgressBar;

use crate::builtin::BuiltinScene;
use crate::error::{Problem, SceneError};
use crate::object::{Object, ObjectBuilder, Scene};

/// How to load a scene: the built-in generators' size and seed, and where progress goes.
#[derive(Debug, Clone)]
pub struct LoadOptions {
    /// Triangle target of a built-in scene.
    pub triangles: u64,
    /// Seed of a built-in scene.
    pub seed: u64,
    /// Meshes copied (not instanced) into the built-in forest beside its trees.
    pub forest_meshes: Vec<PathBuf>,
    /// Progress of reading and generating.
    pub progress: ProgressBar,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            triangles: 1_000_000,
            seed: 1,
            forest_meshes: Vec::new(),
            progress: ProgressBar::hidden(),
        }
    }
}

/// Loads a scene from a mesh file path, or generates a built-in scene by name (`forest`,
/// `plant`). A name that is both an existing file and a built-in scene loads the file.
pub fn load_scene(spec: &str, options: &LoadOptions) -> Result<Scene, SceneError> {
    let path = Path::new(spec);
    if path.exists() {
        return load_file(path, options);
    }
    match BuiltinScene::from_name(spec) {
        Some(builtin) => builtin.generate(options),
        None => Err(SceneError::UnknownScene(spec.to_string())),
    }
}

/// Loads a mesh file: `.ply`, `.obj`, `.gltf` or `.glb`, each optionally gzipped (`.gz`).
pub fn load_file(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let name = path.display().to_string();
    let bytes = read_maybe_gzipped(path, &options.progress)?;
    let lower = name.to_ascii_lowercase();
    let stem = lower.strip_suffix(".gz").unwrap_or(&lower);
    let objects = if stem.ends_with(".ply") {
        ply::parse(&name, &bytes)?
    } else if stem.ends_with(".obj") {
        obj::parse(&name, &bytes, path.parent())?
    } else if stem.ends_with(".gltf") || stem.ends_with(".glb") {
        gltf_file::parse(&name, &bytes, path.parent())?
    } else {
        return Err(SceneError::UnsupportedFormat { path: name });
    };
    finish_scene(name, objects)
}

/// Turns builders into a scene, dropping zero-area triangles and empty objects, and refusing
/// a scene with no triangle left.
pub(crate) fn finish_scene(
    source: String,
    builders: Vec<ObjectBuilder>,
) -> Result<Scene, SceneError> {
    let mut scene = Scene {
        source: source.clone(),
        ..Default::default()
    };
    let mut faces_before = 0u64;
    for builder in builders {
        faces_before += builder.triangle_count() as u64;
        let (object, dropped) = builder.finish();
        scene.degenerate_triangles_dropped += dropped;
        if !object.triangles.is_empty() {
            scene.objects.push(compact(object));
        }
    }
    if scene.objects.is_empty() {
        let why = if faces_before == 0 {
            "it has no faces".to_string()
        } else {
            format!("all {faces_before} triangles have zero area")
        };
        return Err(SceneError::Empty {
            source_name: source,
            why,
        });
    }
    Ok(scene)
}

/// Drops vertices no triangle uses (left behind by dropped triangles or unused file vertices).
fn compact(mut object: Object) -> Object {
    let mut new_index = vec![u32::MAX; object.positions.len()];
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    for triangle in &mut object.triangles {
        for index in triangle.iter_mut() {
            let slot = &mut new_index[*index as usize];
            if *slot == u32::MAX {
                *slot = positions.len() as u32;
                positions.push(object.positions[*index as usize]);
                colors.push(object.colors[*index as usize]);
            }
            *index = *slot;
        }
    }
    object.positions = positions;
    object.colors = colors;
    object
}

fn read_maybe_gzipped(path: &Path, progress: &ProgressBar) -> Result<Vec<u8>, SceneError> {
    let io_error = |source| SceneError::Io {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io_error)?;
    let length = file.metadata().map_err(io_error)?.len();
    progress.set_length(length);
    progress.set_message(format!("reading {}", path.display()));
    let mut raw = Vec::with_capacity(length as usize);
    progress
        .wrap_read(file)
        .read_to_end(&mut raw)
        .map_err(io_error)?;
    if raw.starts_with(&[0x1f, 0x8b]) {
        let mut unzipped = Vec::new();
        flate2::read::MultiGzDecoder::new(&raw[..])
            .read_to_end(&mut unzipped)
            .map_err(|error| SceneError::Invalid {
                path: path.display().to_string(),
                location: "gzip stream".into(),
                problem: Problem::Malformed(format!("cannot decompress: {error}")),
            })?;
        return Ok(unzipped);
    }
    Ok(raw)
}

/// Checks a coordinate read from a file.
pub(crate) fn finite(
    path: &str,
    location: impl FnOnce() -> String,
    value: f64,
) -> Result<f64, SceneError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(invalid(
            path,
            location(),
            Problem::NonFiniteCoordinate(value),
        ))
    }
}

pub(crate) fn invalid(path: &str, location: impl Into<String>, problem: Problem) -> SceneError {
    SceneError::Invalid {
        path: path.to_string(),
        location: location.into(),
        problem,
    }
}

/// The file name up to its first dot: the name of a file's single object.
pub(crate) fn file_stem(path: &str) -> String {
    Path::new(path)
        .file_name()
        .and_then(|name| name.to_string_lossy().split('.').next().map(str::to_string))
        .filter(|stem| !stem.is_empty())
        .unwrap_or_else(|| "mesh".into())
}

/// Grey for meshes that carry no colour.
pub(crate) const DEFAULT_COLOR: [u8; 4] = [200, 200, 200, 255];

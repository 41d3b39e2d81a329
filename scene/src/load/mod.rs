//! Mesh loaders. Each reads the whole file into memory (gunzipping it when it starts with the
//! gzip magic bytes) and validates every element before it reaches an [`ObjectBuilder`], so a
//! bad file gives an error that names the file and the element, never a panic.
//!
//! The work a file can cause is bounded by [`LoadLimits`]: PLY and OBJ produce at most a few
//! triangles per byte read, so only decompression and glTF's reuse (nodes instancing meshes,
//! node graphs that are DAGs or cycles, accessors shared by many primitives) can amplify a
//! small file; both are capped before anything is allocated.
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

use crate::progress::Progress;

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
    pub progress: Progress,
    /// Bounds on the work one file may cause.
    pub limits: LoadLimits,
}

/// Bounds on what one mesh file may expand to, so a small hostile file (a gzip bomb, a glTF
/// node DAG) is refused with a clear error instead of exhausting memory or time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadLimits {
    /// Largest size a gzipped file may inflate to.
    pub max_inflated_bytes: u64,
    /// Most triangles a file may produce (glTF instancing multiplies a mesh's triangles).
    pub max_triangles: u64,
    /// Most glTF node instances visited (a node reached along several paths counts each time).
    pub max_node_instances: u64,
}

impl LoadLimits {
    /// 512 MiB inflated: five times the largest real gzipped scan we know of under 20 MB.
    pub const DEFAULT_MAX_INFLATED_BYTES: u64 = 512 << 20;
    /// 20 M triangles, twice the built-in forest: about 0.8 GB while loading (40 bytes a
    /// triangle in the builders), so a refused file stays well under 2 GB.
    pub const DEFAULT_MAX_TRIANGLES: u64 = 20_000_000;
    /// A million node instances: far more than hand-built or exported scenes use.
    pub const DEFAULT_MAX_NODE_INSTANCES: u64 = 1_000_000;
}

impl Default for LoadLimits {
    fn default() -> Self {
        LoadLimits {
            max_inflated_bytes: Self::DEFAULT_MAX_INFLATED_BYTES,
            max_triangles: Self::DEFAULT_MAX_TRIANGLES,
            max_node_instances: Self::DEFAULT_MAX_NODE_INSTANCES,
        }
    }
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            triangles: 1_000_000,
            seed: 1,
            forest_meshes: Vec::new(),
            progress: Progress::hidden(),
            limits: LoadLimits::default(),
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
    let io_error = |source| SceneError::Io {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io_error)?;
    let length = file.metadata().map_err(io_error)?.len();
    options.progress.set_length(length);
    options
        .progress
        .set_message(&format!("reading {}", path.display()));
    let mut raw = Vec::with_capacity(length as usize);
    options
        .progress
        .wrap_read(file)
        .read_to_end(&mut raw)
        .map_err(io_error)?;
    parse(&path.display().to_string(), raw, path.parent(), options)
}

/// Loads a mesh from memory, its format taken from `name`'s extension as [`load_file`] does.
/// Files a glTF document names (external buffers, materials) are not read: there is no
/// folder to read them from.
pub fn load_bytes(name: &str, bytes: &[u8], options: &LoadOptions) -> Result<Scene, SceneError> {
    parse(name, bytes.to_vec(), None, options)
}

/// Parses a file's bytes (gunzipping them first when they are gzipped); `directory` is where
/// a glTF's external buffers are, if anywhere.
fn parse(
    name: &str,
    raw: Vec<u8>,
    directory: Option<&Path>,
    options: &LoadOptions,
) -> Result<Scene, SceneError> {
    let name = name.to_string();
    let bytes = inflate_if_gzipped(&name, raw, &options.limits)?;
    let lower = name.to_ascii_lowercase();
    let stem = lower.strip_suffix(".gz").unwrap_or(&lower);
    let objects = if stem.ends_with(".ply") {
        ply::parse(&name, &bytes)?
    } else if stem.ends_with(".obj") {
        obj::parse(&name, &bytes, directory)?
    } else if stem.ends_with(".gltf") || stem.ends_with(".glb") {
        gltf_file::parse(&name, &bytes, directory, &options.limits)?
    } else {
        return Err(SceneError::UnsupportedFormat { path: name });
    };
    drop(bytes);
    let triangles: u64 = objects.iter().map(|o| o.triangle_count() as u64).sum();
    if triangles > options.limits.max_triangles {
        return Err(invalid(
            &name,
            "faces",
            Problem::TooLarge(format!(
                "{triangles} triangles exceed the limit of {} (--max-triangles)",
                options.limits.max_triangles
            )),
        ));
    }
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
    let mut seams = Vec::new();
    for triangle in &mut object.triangles {
        for index in triangle.iter_mut() {
            let slot = &mut new_index[*index as usize];
            if *slot == u32::MAX {
                *slot = positions.len() as u32;
                positions.push(object.positions[*index as usize]);
                colors.push(object.colors[*index as usize]);
                seams.push(object.seams[*index as usize]);
            }
            *index = *slot;
        }
    }
    object.positions = positions;
    object.colors = colors;
    object.seams = seams;
    object
}

/// Inflates a file's bytes when they start with gzip's magic bytes: streamed, and stopped
/// with an error once past `limits.max_inflated_bytes`, so a small bomb never fills memory.
fn inflate_if_gzipped(
    name: &str,
    raw: Vec<u8>,
    limits: &LoadLimits,
) -> Result<Vec<u8>, SceneError> {
    if !raw.starts_with(&[0x1f, 0x8b]) {
        return Ok(raw);
    }
    let mut unzipped = Vec::new();
    flate2::read::MultiGzDecoder::new(&raw[..])
        .take(limits.max_inflated_bytes.saturating_add(1))
        .read_to_end(&mut unzipped)
        .map_err(|error| {
            invalid(
                name,
                "gzip stream",
                Problem::Malformed(format!("cannot decompress: {error}")),
            )
        })?;
    if unzipped.len() as u64 > limits.max_inflated_bytes {
        return Err(invalid(
            name,
            "gzip stream",
            Problem::TooLarge(format!(
                "inflates to more than {} MiB (--max-inflated-mb)",
                limits.max_inflated_bytes >> 20
            )),
        ));
    }
    Ok(unzipped)
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

//! The on-disk cache of Phases I and III: for each object that was cut, the group of every
//! triangle. The key hashes the objects' geometry and every parameter that changes the result,
//! so a changed input or parameter misses the cache instead of reading a stale answer.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use xxhash_rust::xxh3::Xxh3;

use crate::object::Object;

/// Bump when the clustering's result for the same input changes.
const FORMAT_VERSION: u64 = 1;
const MAGIC: &[u8; 8] = b"RBCLUST1";

/// What Phases I and III computed, as stored.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct CachedClustering {
    /// Per cut object, per triangle: its group, or `u32::MAX` when dropped as a duplicate.
    #[serde(skip)]
    pub group_of_triangle: Vec<Vec<u32>>,
    pub group_count: u32,
    pub duplicate_faces: u64,
    pub welded_vertices: u64,
    pub connected_components: u64,
    pub cut_components: u64,
    pub base_clusters: u64,
    pub joins: u64,
}

/// A hash of the objects' geometry and the parameters.
pub(crate) fn key(objects: &[&Object], parameters: &[f64]) -> u128 {
    let mut hasher = Xxh3::new();
    hasher.update(&FORMAT_VERSION.to_le_bytes());
    for value in parameters {
        hasher.update(&value.to_le_bytes());
    }
    for object in objects {
        hasher.update(&(object.positions.len() as u64).to_le_bytes());
        for value in object.origin.to_array() {
            hasher.update(&value.to_le_bytes());
        }
        for position in &object.positions {
            for value in position.to_array() {
                hasher.update(&value.to_le_bytes());
            }
        }
        for triangle in &object.triangles {
            for index in triangle {
                hasher.update(&index.to_le_bytes());
            }
        }
    }
    hasher.digest128()
}

pub(crate) fn path(directory: &Path, key: u128) -> PathBuf {
    directory.join(format!("clusters-{key:032x}.bin"))
}

/// Reads a cache file; any problem (missing, truncated, other version) is a miss.
pub(crate) fn read(path: &Path, objects: &[&Object]) -> Option<CachedClustering> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .read_to_end(&mut bytes)
        .ok()?;
    let rest = bytes.strip_prefix(MAGIC)?;
    let (length, rest) = rest.split_first_chunk::<8>()?;
    let length = u64::from_le_bytes(*length) as usize;
    let (header, mut rest) = (rest.get(..length)?, rest.get(length..)?);
    let mut cached: CachedClustering = serde_json::from_slice(header).ok()?;
    // Every group holds at least one triangle: a larger count is a damaged or forged file,
    // and would allocate a builder per group before anything else is read.
    let triangles: u64 = objects.iter().map(|o| o.triangles.len() as u64).sum();
    if u64::from(cached.group_count) > triangles {
        return None;
    }
    for object in objects {
        let size = object.triangles.len() * 4;
        let (groups, tail) = (rest.get(..size)?, rest.get(size..)?);
        let groups: Vec<u32> = groups
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if groups
            .iter()
            .any(|&g| g != u32::MAX && g >= cached.group_count)
        {
            return None;
        }
        cached.group_of_triangle.push(groups);
        rest = tail;
    }
    rest.is_empty().then_some(cached)
}

/// Writes a cache file atomically (a temporary file renamed into place), so a crash or a
/// concurrent run never leaves half a file under the real name.
pub(crate) fn write(path: &Path, cached: &CachedClustering) -> std::io::Result<()> {
    if let Some(directory) = path.parent() {
        std::fs::create_dir_all(directory)?;
    }
    let temporary = path.with_extension(format!("tmp{}", std::process::id()));
    {
        let mut out = std::io::BufWriter::new(std::fs::File::create(&temporary)?);
        let header = serde_json::to_vec(cached).map_err(std::io::Error::other)?;
        out.write_all(MAGIC)?;
        out.write_all(&(header.len() as u64).to_le_bytes())?;
        out.write_all(&header)?;
        for groups in &cached.group_of_triangle {
            for group in groups {
                out.write_all(&group.to_le_bytes())?;
            }
        }
        out.flush()?;
    }
    std::fs::rename(&temporary, path)
}

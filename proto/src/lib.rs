//! The wire protocol between the visualization node and the backend workers: the generated
//! gRPC code (tonic, prost) for `proto/reliefboard.proto`, and conversions between scene
//! objects and the chunks they travel in.
//!
//! **Architecture invariant:** depends on the `scene` crate only; knows nothing of how boards
//! are rendered or balanced.

#[allow(missing_docs, clippy::all)]
mod generated {
    tonic::include_proto!("reliefboard.v1");
}

pub use generated::worker_client::WorkerClient;
pub use generated::worker_server::{Worker, WorkerServer};
pub use generated::{
    BoardChunk, ObjectChunk, PauseControl, PauseEvent, RenderRequest, StatusRequest, StoreReply,
    WorkerStatus,
};

use glam::{DVec3, Vec3};

/// Bytes of geometry per chunk: well under tonic's 4 MiB default message limit.
pub const CHUNK_BYTES: usize = 1 << 20;

/// Splits an object into chunks for `StoreObject`.
pub fn object_to_chunks(object_id: u32, object: &scene::Object) -> Vec<ObjectChunk> {
    // Vertices and triangles go in separate chunks; each chunk holds about CHUNK_BYTES.
    let vertices_per_chunk = CHUNK_BYTES / 16;
    let triangles_per_chunk = CHUNK_BYTES / 12;
    let mut chunks = vec![ObjectChunk {
        object_id,
        name: object.name.clone(),
        origin_x: object.origin.x,
        origin_y: object.origin.y,
        origin_z: object.origin.z,
        total_vertices: object.positions.len() as u64,
        total_triangles: object.triangles.len() as u64,
        ..ObjectChunk::default()
    }];
    for ((positions, colors), seams) in object
        .positions
        .chunks(vertices_per_chunk)
        .zip(object.colors.chunks(vertices_per_chunk))
        .zip(object.seams.chunks(vertices_per_chunk))
    {
        chunks.push(ObjectChunk {
            object_id,
            positions: positions
                .iter()
                .flat_map(|p| p.to_array())
                .flat_map(f32::to_le_bytes)
                .collect(),
            colors: colors.iter().flatten().copied().collect(),
            seams: if seams.contains(&true) {
                seams.iter().map(|&s| s as u8).collect()
            } else {
                Vec::new()
            },
            ..ObjectChunk::default()
        });
    }
    for triangles in object.triangles.chunks(triangles_per_chunk) {
        chunks.push(ObjectChunk {
            object_id,
            triangles: triangles
                .iter()
                .flatten()
                .flat_map(|i| i.to_le_bytes())
                .collect(),
            ..ObjectChunk::default()
        });
    }
    chunks
}

/// Why received chunks are not an object.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AssembleError {
    /// More vertices or triangles than the receiver accepts.
    #[error(
        "object too large: {vertices} vertices and {triangles} triangles, limit {limit} of each"
    )]
    TooLarge {
        /// Declared vertices.
        vertices: u64,
        /// Declared triangles.
        triangles: u64,
        /// The receiver's limit.
        limit: u64,
    },
    /// The chunks do not add up to what the header declared, or are malformed.
    #[error("malformed object chunks: {0}")]
    Malformed(String),
}

/// Reassembles an object from chunks, checking every size against the declared totals and a
/// limit before allocating.
#[derive(Debug)]
pub struct ObjectAssembler {
    object_id: Option<u32>,
    name: String,
    origin: DVec3,
    declared: (u64, u64),
    positions: Vec<Vec3>,
    colors: Vec<[u8; 4]>,
    triangles: Vec<[u32; 3]>,
    seams: Vec<bool>,
    limit: u64,
}

impl ObjectAssembler {
    /// A new assembler accepting at most `limit` vertices and `limit` triangles.
    pub fn new(limit: u64) -> ObjectAssembler {
        ObjectAssembler {
            object_id: None,
            name: String::new(),
            origin: DVec3::ZERO,
            declared: (0, 0),
            positions: Vec::new(),
            colors: Vec::new(),
            triangles: Vec::new(),
            seams: Vec::new(),
            limit,
        }
    }

    /// Adds one chunk.
    pub fn push(&mut self, chunk: ObjectChunk) -> Result<(), AssembleError> {
        let malformed = |m: &str| Err(AssembleError::Malformed(m.to_string()));
        match self.object_id {
            None => {
                let (vertices, triangles) = (chunk.total_vertices, chunk.total_triangles);
                if vertices > self.limit || triangles > self.limit {
                    return Err(AssembleError::TooLarge {
                        vertices,
                        triangles,
                        limit: self.limit,
                    });
                }
                let origin = DVec3::new(chunk.origin_x, chunk.origin_y, chunk.origin_z);
                if !origin.is_finite() {
                    return malformed("origin is not finite");
                }
                self.object_id = Some(chunk.object_id);
                self.name = chunk.name.clone();
                self.origin = origin;
                self.declared = (vertices, triangles);
                self.positions.reserve(vertices as usize);
                self.colors.reserve(vertices as usize);
                self.seams.reserve(vertices as usize);
                self.triangles.reserve(triangles as usize);
            }
            Some(id) if id != chunk.object_id => {
                return malformed("chunks of two objects in one stream");
            }
            Some(_) => {}
        }
        if !chunk.positions.len().is_multiple_of(12)
            || !chunk.colors.len().is_multiple_of(4)
            || !chunk.triangles.len().is_multiple_of(12)
        {
            return malformed("partial element in a chunk");
        }
        if chunk.positions.len() / 12 != chunk.colors.len() / 4 {
            return malformed("positions and colours differ in count");
        }
        if !chunk.seams.is_empty() && chunk.seams.len() != chunk.positions.len() / 12 {
            return malformed("seam flags and positions differ in count");
        }
        if chunk.seams.iter().any(|&s| s > 1) {
            return malformed("a seam flag is neither 0 nor 1");
        }
        if (self.positions.len() + chunk.positions.len() / 12) as u64 > self.declared.0
            || (self.triangles.len() + chunk.triangles.len() / 12) as u64 > self.declared.1
        {
            return malformed("more data than the header declared");
        }
        for p in chunk.positions.chunks_exact(12) {
            let v = Vec3::new(f32_at(p, 0), f32_at(p, 4), f32_at(p, 8));
            if !v.is_finite() {
                return malformed("vertex position is not finite");
            }
            self.positions.push(v);
        }
        if chunk.seams.is_empty() {
            self.seams
                .extend(std::iter::repeat_n(false, chunk.positions.len() / 12));
        } else {
            self.seams.extend(chunk.seams.iter().map(|&s| s == 1));
        }
        self.colors.extend(
            chunk
                .colors
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]]),
        );
        self.triangles.extend(
            chunk
                .triangles
                .chunks_exact(12)
                .map(|t| [u32_at(t, 0), u32_at(t, 4), u32_at(t, 8)]),
        );
        Ok(())
    }

    /// The object, once every declared element arrived.
    pub fn finish(self) -> Result<(u32, scene::Object), AssembleError> {
        let Some(object_id) = self.object_id else {
            return Err(AssembleError::Malformed("no chunk received".into()));
        };
        if self.positions.len() as u64 != self.declared.0
            || self.triangles.len() as u64 != self.declared.1
        {
            return Err(AssembleError::Malformed(
                "fewer elements than the header declared".into(),
            ));
        }
        let vertex_count = self.positions.len() as u32;
        if self.triangles.iter().flatten().any(|&i| i >= vertex_count) {
            return Err(AssembleError::Malformed(
                "triangle index out of range".into(),
            ));
        }
        Ok((
            object_id,
            scene::Object {
                name: self.name,
                origin: self.origin,
                positions: self.positions,
                colors: self.colors,
                triangles: self.triangles,
                seams: self.seams,
            },
        ))
    }
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` quads, with the vertices of its right end marked as a cut when `cut`.
    fn strip(n: u32, cut: bool) -> scene::Object {
        let mut b = scene::ObjectBuilder::new("strip");
        for i in 0..=n {
            for y in [0.0, 1.0] {
                let v = b.vertex(DVec3::new(i as f64, y, 0.0), [9, 8, 7, 255]);
                if cut && i == n {
                    b.mark_seam(v);
                }
            }
        }
        for i in 0..n {
            b.triangle(2 * i, 2 * i + 2, 2 * i + 3);
            b.triangle(2 * i, 2 * i + 3, 2 * i + 1);
        }
        b.finish().0
    }

    fn assemble(chunks: Vec<ObjectChunk>) -> Result<scene::Object, AssembleError> {
        let mut assembler = ObjectAssembler::new(1 << 20);
        for chunk in chunks {
            assembler.push(chunk)?;
        }
        assembler.finish().map(|(_, object)| object)
    }

    #[test]
    fn seams_travel_with_their_vertices_across_chunks() {
        // More vertices than one chunk holds, so the cut's vertices are in the last chunk
        // and the chunks before carry no seam bytes at all.
        let n = (CHUNK_BYTES / 16) as u32;
        let object = strip(n, true);
        let chunks = object_to_chunks(4, &object);
        let with_seams: Vec<usize> = chunks
            .iter()
            .enumerate()
            .filter(|(_, c)| !c.seams.is_empty())
            .map(|(i, _)| i)
            .collect();
        // Chunk 0 is the header; vertex chunks 1 and 2 hold n vertices each, 3 the last two.
        assert_eq!(
            with_seams,
            vec![3],
            "only the chunk with the cut's vertices has seams"
        );
        let back = assemble(chunks).unwrap();
        assert_eq!(back, object);
        assert_eq!(back.seams.iter().filter(|&&s| s).count(), 2);
        // An uncut object sends no seam bytes and arrives with none marked.
        let plain = strip(3, false);
        let chunks = object_to_chunks(5, &plain);
        assert!(chunks.iter().all(|c| c.seams.is_empty()));
        assert_eq!(assemble(chunks).unwrap(), plain);
    }

    #[test]
    fn seam_flags_of_the_wrong_count_or_value_are_refused() {
        let object = strip(3, true);
        for (what, bad) in [
            ("count", vec![0u8; 3]),
            ("value", vec![0, 0, 0, 0, 0, 0, 2, 1]),
        ] {
            let mut chunks = object_to_chunks(6, &object);
            chunks[1].seams = bad;
            assert!(
                matches!(assemble(chunks), Err(AssembleError::Malformed(_))),
                "a wrong seam {what} is refused"
            );
        }
    }
}

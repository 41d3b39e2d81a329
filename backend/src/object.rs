//! An object made ready for rendering, once, when a worker stores it: vertex normals, the
//! bounding sphere, and a memory layout for the rasteriser.

use std::sync::OnceLock;

use rustc_hash::FxHashMap as HashMap;

use glam::{DVec3, Vec3};

use crate::error::RenderError;
use crate::simplify::{Level, MAX_ERROR_PIXELS};

/// One vertex with everything the per-pixel pass reads, together: one cache line instead of
/// three separate arrays (position, normal, colour).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderVertex {
    /// Position relative to the object's origin.
    pub position: Vec3,
    /// Area-weighted unit normal (object space).
    pub normal: Vec3,
    /// Unlit RGBA8 colour.
    pub color: [u8; 4],
    /// On a cut between pieces of one mesh: a board grows past its edge there
    /// (`raster::grow_seams`), so the boards of neighbouring pieces overlap instead of
    /// leaving a crack between them.
    pub seam: bool,
}

/// An object as a worker keeps it.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedObject {
    /// The object's name.
    pub name: String,
    /// World position of the local origin.
    pub origin: DVec3,
    /// Vertices, numbered in the order the triangles first use them, so walking the
    /// triangles walks the vertices nearly in order.
    pub vertices: Vec<RenderVertex>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Centre of the bounds, relative to `origin`.
    pub local_center: Vec3,
    /// Half the bounds' diagonal: the radius of the sphere the maps frame.
    pub radius: f64,
    /// Simplified versions, finest first, with their errors; unset until
    /// [`PreparedObject::build_levels`] (a worker builds them after it has stored an object,
    /// rendering from the full mesh meanwhile).
    levels: OnceLock<Vec<Level>>,
}

/// The vertices and triangles one render reads: the full mesh or one of its levels.
#[derive(Debug, Clone, Copy)]
pub struct MeshRef<'a> {
    /// Vertices.
    pub vertices: &'a [RenderVertex],
    /// Triangles, indices into `vertices`.
    pub triangles: &'a [[u32; 3]],
    /// Largest distance from the full mesh's surface, object units (0 for the full mesh).
    pub error: f64,
}

impl PreparedObject {
    /// Computes normals and the bounding sphere and lays the vertices out for rendering.
    pub fn new(object: &scene::Object) -> Result<PreparedObject, RenderError> {
        let bounds = scene::Aabb::from_points(object.positions.iter().map(|p| p.as_dvec3()));
        let radius = bounds.diagonal() * 0.5;
        if object.triangles.is_empty() || !(radius > 0.0) || !radius.is_finite() {
            return Err(RenderError::EmptyObject(object.name.clone()));
        }
        let (corners, normals) = corner_normals(object);
        // Vertices split where creases give one position several normals, renumbered in the
        // order the triangles first use them.
        let mut index_of: HashMap<(u32, [u32; 3]), u32> = HashMap::default();
        let mut vertices = Vec::with_capacity(object.positions.len());
        let triangles: Vec<[u32; 3]> = corners
            .iter()
            .map(|corner| {
                corner.map(|(v, normal)| {
                    *index_of
                        .entry((v, normals[normal as usize].to_array().map(f32::to_bits)))
                        .or_insert_with(|| {
                            vertices.push(RenderVertex {
                                position: object.positions[v as usize],
                                normal: normals[normal as usize],
                                color: object.colors[v as usize],
                                seam: object.seams[v as usize],
                            });
                            (vertices.len() - 1) as u32
                        })
                })
            })
            .collect();
        // Crease splits can push the count past `positions.len()`, and the doubling that
        // follows would keep up to half the vertices' memory unused for the object's life.
        vertices.shrink_to_fit();
        Ok(PreparedObject {
            name: object.name.clone(),
            origin: object.origin,
            vertices,
            triangles,
            local_center: bounds.center().as_vec3(),
            radius,
            levels: OnceLock::new(),
        })
    }

    /// Builds the simplified levels unless they are built (about 0.1 s per 100 k triangles,
    /// seconds for foliage, whose levels are checked by rendering): a caller that finds
    /// another building them waits for those.
    pub fn build_levels(&self) {
        self.levels.get_or_init(|| crate::simplify::levels(self));
    }

    /// The object with its simplified levels built.
    pub fn with_levels(self) -> PreparedObject {
        self.build_levels();
        self
    }

    /// The simplified levels, finest first; empty until they are built.
    pub fn levels(&self) -> &[Level] {
        self.levels.get().map_or(&[], Vec::as_slice)
    }

    /// Whether [`PreparedObject::build_levels`] has run.
    pub fn has_levels(&self) -> bool {
        self.levels.get().is_some()
    }

    /// The full mesh.
    pub fn full_mesh(&self) -> MeshRef<'_> {
        MeshRef {
            vertices: &self.vertices,
            triangles: &self.triangles,
            error: 0.0,
        }
    }

    /// What a board of `size` pixels is rendered from: the coarsest level allowed at that
    /// size ([`PreparedObject::allows`]), else the full mesh.
    pub fn mesh_for_size(&self, size: u32) -> MeshRef<'_> {
        self.levels()
            .iter()
            .rev()
            .find(|level| self.allows(level, size))
            .map_or_else(|| self.full_mesh(), Level::mesh)
    }

    /// Whether a board of `size` pixels may be rendered from `level` (one of this object's):
    /// its error within [`MAX_ERROR_PIXELS`] of a pixel (a pixel is `2 r / size` object
    /// units) and its silhouette kept at this size ([`crate::Level::smallest_size`]).
    pub fn allows(&self, level: &Level, size: u32) -> bool {
        let bound = MAX_ERROR_PIXELS * 2.0 * self.radius / size.max(1) as f64;
        // A board below the smallest checked side takes what a board of that side would.
        let checked = size.max(crate::simplify::SMALLEST_CHECK);
        level.error <= bound && level.smallest_size <= checked
    }

    /// World position of the bounding sphere's centre.
    pub fn world_center(&self) -> DVec3 {
        self.origin + self.local_center.as_dvec3()
    }

    /// What an object of `vertices` and `triangles` will hold once prepared, from the sizes it
    /// declares (crease splits can add vertices; the store checks the real size again):
    /// a worker admits a store with it before anything is allocated. The arrays received
    /// meanwhile are bounded by the element limit times the concurrent stores.
    pub fn admission_bytes(vertices: u64, triangles: u64) -> u64 {
        booked_bytes(vertices, triangles)
    }

    /// Bytes booked for this object against a worker's memory limit, its levels included
    /// whether built yet or not: the same figure over the object's life, so that the book
    /// balances when the object is replaced.
    pub fn memory_bytes(&self) -> usize {
        booked_bytes(self.vertices.len() as u64, self.triangles.len() as u64) as usize
            + self.name.len()
    }
}

/// Twice a mesh of `vertices` and `triangles`: the levels, each about half the one before
/// (foliage's together at most the full mesh's triangles), add at most about as much again.
fn booked_bytes(vertices: u64, triangles: u64) -> u64 {
    vertices
        .saturating_mul(std::mem::size_of::<RenderVertex>() as u64)
        .saturating_add(triangles.saturating_mul(12))
        .saturating_mul(2)
}

/// Faces meeting at a vertex at more than this angle keep their own normals there: a box's
/// edges stay sharp, a sphere's facets blend.
pub const CREASE_ANGLE_DEGREES: f32 = 60.0;

/// The normal at every corner of every triangle: the area-weighted sum of the normals of the
/// faces around the corner's vertex that lie within the crease angle of the corner's own face.
/// Returns, per triangle, (vertex, normal index) for each corner, and the distinct normals.
fn corner_normals(object: &scene::Object) -> (Vec<[(u32, u32); 3]>, Vec<Vec3>) {
    let positions = &object.positions;
    // Twice the area times the unit normal, per face.
    let weighted: Vec<Vec3> = object
        .triangles
        .iter()
        .map(|&[a, b, c]| {
            let (pa, pb, pc) = (
                positions[a as usize],
                positions[b as usize],
                positions[c as usize],
            );
            (pb - pa).cross(pc - pa)
        })
        .collect();
    let unit: Vec<Vec3> = weighted.iter().map(|w| w.normalize_or_zero()).collect();
    // The faces around each vertex (compressed rows).
    let mut start = vec![0u32; positions.len() + 1];
    for triangle in &object.triangles {
        for &v in triangle {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..positions.len() {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut faces = vec![0u32; start[positions.len()] as usize];
    for (face, triangle) in object.triangles.iter().enumerate() {
        for &v in triangle {
            faces[fill[v as usize] as usize] = face as u32;
            fill[v as usize] += 1;
        }
    }
    let cos_crease = CREASE_ANGLE_DEGREES.to_radians().cos();
    let mut normals = Vec::new();
    let corners = object
        .triangles
        .iter()
        .enumerate()
        .map(|(face, triangle)| {
            triangle.map(|v| {
                let around = &faces[start[v as usize] as usize..start[v as usize + 1] as usize];
                // Summed in the same order for every corner of a smooth vertex, so they agree
                // to the bit and stay one vertex.
                let sum: Vec3 = around
                    .iter()
                    .filter(|&&other| unit[other as usize].dot(unit[face]) >= cos_crease)
                    .map(|&other| weighted[other as usize])
                    .sum();
                normals.push(sum.normalize_or_zero());
                (v, (normals.len() - 1) as u32)
            })
        })
        .collect();
    (corners, normals)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_board_takes_the_coarsest_level_within_its_error_bound_and_silhouette_size() {
        let mut builder = scene::ObjectBuilder::new("quad");
        for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            builder.vertex(DVec3::new(x, y, 0.0), [255; 4]);
        }
        builder.triangle(0, 1, 2);
        builder.triangle(0, 2, 3);
        let object = PreparedObject::new(&builder.finish().0).unwrap();
        let pixel = |size: f64| 2.0 * object.radius / size;
        // Coarser down the list: A keeps the silhouette from 32 pixels, B only from 64, and
        // C (checked at no size) is within half a pixel only below 10 pixels.
        let level = |triangles: usize, error: f64, smallest_size: u32| Level {
            error,
            smallest_size,
            vertices: object.vertices.clone(),
            triangles: vec![[0, 1, 2]; triangles],
        };
        let chain = vec![
            level(30, 0.4 * pixel(256.0), 32),
            level(20, 0.4 * pixel(128.0), 64),
            level(10, 0.4 * pixel(8.0), 0),
        ];
        let levels = object.levels.set(chain);
        assert!(levels.is_ok());
        let chosen = |size: u32| object.mesh_for_size(size).triangles.len();
        assert_eq!(
            chosen(512),
            2,
            "no level within half a pixel: the full mesh"
        );
        assert_eq!(chosen(256), 30);
        assert_eq!(chosen(128), 20);
        assert_eq!(chosen(64), 20);
        assert_eq!(chosen(32), 30, "B loses the silhouette at 32 pixels");
        assert_eq!(
            chosen(16),
            30,
            "a board below 32 pixels takes what 32 would"
        );
        assert_eq!(chosen(8), 10, "C within half a pixel");
        assert_eq!(chosen(11), 30, "C beyond half a pixel");
    }
}

//! An object made ready for rendering, once, when a worker stores it: vertex normals, the
//! bounding sphere, and a memory layout for the rasteriser.

use glam::{DVec3, Vec3};

use crate::error::RenderError;

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
}

impl PreparedObject {
    /// Computes normals and the bounding sphere and lays the vertices out for rendering.
    pub fn new(object: &scene::Object) -> Result<PreparedObject, RenderError> {
        let bounds = scene::Aabb::from_points(object.positions.iter().map(|p| p.as_dvec3()));
        let radius = bounds.diagonal() * 0.5;
        if object.triangles.is_empty() || !(radius > 0.0) || !radius.is_finite() {
            return Err(RenderError::EmptyObject(object.name.clone()));
        }
        // Renumber vertices by first use.
        let mut new_index = vec![u32::MAX; object.positions.len()];
        let mut order = Vec::with_capacity(object.positions.len());
        let triangles: Vec<[u32; 3]> = object
            .triangles
            .iter()
            .map(|triangle| {
                triangle.map(|v| {
                    let slot = &mut new_index[v as usize];
                    if *slot == u32::MAX {
                        *slot = order.len() as u32;
                        order.push(v);
                    }
                    *slot
                })
            })
            .collect();
        let mut vertices: Vec<RenderVertex> = order
            .iter()
            .map(|&v| RenderVertex {
                position: object.positions[v as usize],
                normal: Vec3::ZERO,
                color: object.colors[v as usize],
            })
            .collect();
        for &[a, b, c] in &triangles {
            let (pa, pb, pc) = (
                vertices[a as usize].position,
                vertices[b as usize].position,
                vertices[c as usize].position,
            );
            // The cross product's length is twice the area: summing it weights by area.
            let weighted = (pb - pa).cross(pc - pa);
            for v in [a, b, c] {
                vertices[v as usize].normal += weighted;
            }
        }
        for vertex in &mut vertices {
            vertex.normal = vertex.normal.normalize_or_zero();
        }
        Ok(PreparedObject {
            name: object.name.clone(),
            origin: object.origin,
            vertices,
            triangles,
            local_center: bounds.center().as_vec3(),
            radius,
        })
    }

    /// World position of the bounding sphere's centre.
    pub fn world_center(&self) -> DVec3 {
        self.origin + self.local_center.as_dvec3()
    }

    /// Bytes this object takes in memory (for a worker's memory limit).
    pub fn memory_bytes(&self) -> usize {
        self.vertices.len() * std::mem::size_of::<RenderVertex>()
            + self.triangles.len() * 12
            + self.name.len()
    }
}

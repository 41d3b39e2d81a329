//! The reliefboard: a regular grid in the plane facing the view, one vertex per covered map
//! pixel, pushed along the view by that pixel's depth, coloured and given its normal.

use glam::{DVec3, Vec3};

use crate::raster::Maps;

/// A triangle of the grid is cut (left out) when the depths of its corners differ by more
/// than this many pixel widths: a branch in front of a trunk leaves a gap instead of a
/// stretched skin. A surface must be steeper than atan(4) ≈ 76° to the view plane before
/// it is cut; steeper than that, the skin is mostly stretching anyway.
pub const DEPTH_JUMP_PIXELS: f32 = 4.0;

/// One vertex of a board, in map coordinates: `x`, `y` in [-1, 1], `z` the view depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardVertex {
    /// Map position and depth.
    pub position: Vec3,
    /// Unlit colour.
    pub color: [u8; 4],
    /// Object-space normal.
    pub normal: Vec3,
}

/// A reliefboard: the maps and the displaced grid made from them.
#[derive(Debug, Clone, PartialEq)]
pub struct Board {
    /// The maps it was made from (and carries, for texturing).
    pub maps: Maps,
    /// Covered pixels as vertices.
    pub vertices: Vec<BoardVertex>,
    /// Grid triangles between covered, depth-continuous neighbours.
    pub triangles: Vec<[u32; 3]>,
    /// Smallest and largest depth over covered pixels.
    pub depth_range: [f32; 2],
}

impl Board {
    /// Builds the grid: a vertex per covered pixel, two triangles per 2×2 block whose corners
    /// are covered and depth-continuous (see [`DEPTH_JUMP_PIXELS`]).
    pub fn from_maps(maps: Maps) -> Board {
        let size = maps.size as usize;
        let pixel = 2.0 / maps.size as f32;
        let mut index_of = vec![u32::MAX; size * size];
        let mut vertices = Vec::new();
        let mut range = [f32::INFINITY, f32::NEG_INFINITY];
        for row in 0..size {
            for column in 0..size {
                let at = row * size + column;
                if !maps.stencil[at] {
                    continue;
                }
                let z = maps.depth[at];
                range = [range[0].min(z), range[1].max(z)];
                index_of[at] = vertices.len() as u32;
                vertices.push(BoardVertex {
                    position: Vec3::new(
                        (column as f32 + 0.5) * pixel - 1.0,
                        1.0 - (row as f32 + 0.5) * pixel,
                        z,
                    ),
                    color: maps.color[at],
                    normal: Vec3::from_array(maps.normal[at]),
                });
            }
        }
        let limit = DEPTH_JUMP_PIXELS * pixel;
        let continuous = |corners: [u32; 3]| {
            if corners.contains(&u32::MAX) {
                return false;
            }
            let z = corners.map(|v| vertices[v as usize].position.z);
            z[0].max(z[1]).max(z[2]) - z[0].min(z[1]).min(z[2]) <= limit
        };
        let mut triangles = Vec::new();
        for row in 0..size.saturating_sub(1) {
            for column in 0..size - 1 {
                let top_left = index_of[row * size + column];
                let top_right = index_of[row * size + column + 1];
                let bottom_left = index_of[(row + 1) * size + column];
                let bottom_right = index_of[(row + 1) * size + column + 1];
                // Counter-clockwise as seen from the viewer (x right, y up).
                for corners in [
                    [top_left, bottom_left, bottom_right],
                    [top_left, bottom_right, top_right],
                ] {
                    if continuous(corners) {
                        triangles.push(corners);
                    }
                }
            }
        }
        if vertices.is_empty() {
            range = [0.0, 0.0];
        }
        Board {
            maps,
            vertices,
            triangles,
            depth_range: range,
        }
    }

    /// The board as a mesh in world space, for export (`reliefboard.ply`).
    pub fn world_mesh(&self) -> scene::Object {
        let basis = &self.maps.basis;
        let mut builder = scene::ObjectBuilder::new("reliefboard");
        for v in &self.vertices {
            let p = v.position.as_dvec3();
            builder.vertex(basis.world_point(p.x, p.y, p.z), v.color);
        }
        for &[a, b, c] in &self.triangles {
            builder.triangle(a, b, c);
        }
        builder.finish().0
    }

    /// World position of the board's centre.
    pub fn center(&self) -> DVec3 {
        self.maps.basis.center
    }
}

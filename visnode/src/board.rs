//! A received reliefboard made ready for the GPU, off the frame thread: texel arrays for the
//! depth, colour and normal maps, and the *proxy grid*, the displaced grid actually drawn.
//!
//! The proxy grid may be coarser than the maps (`grid_cells` cells per side): its vertices sit
//! at the nearest depth of the covered pixels around them, and the fragment shader takes
//! colour, normal, silhouette (stencil) and depth per pixel from the maps. So a coarse grid
//! keeps the map's silhouette and per-pixel occlusion, and only the parallax between grid
//! vertices is approximated. A grid of one cell per pixel is the full board of
//! `backend::Board`; a 1-cell grid at depth 0 is a plain billboard.

use backend::{Basis, Maps};
use glam::DVec3;

/// Depth texel value of an uncovered pixel (view depth lies in [-1, 1]).
pub const UNCOVERED_DEPTH: f32 = 2.0;

/// How the board's geometry is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoardShape {
    /// A displaced grid of at most this many cells per side (at least one pixel per cell).
    Relief {
        /// Cells per side.
        grid_cells: u32,
    },
    /// A flat quad through the object's centre: the plain billboard.
    Billboard,
}

/// Everything the renderer uploads for one board.
#[derive(Debug, Clone)]
pub struct BoardData {
    /// Where the maps sit in the world.
    pub basis: Basis,
    /// The direction the board was made from.
    pub direction: DVec3,
    /// Map side.
    pub size: u32,
    /// View depth per texel, [`UNCOVERED_DEPTH`] where uncovered.
    pub depth: Vec<f32>,
    /// RGBA8 colour, alpha 255 where covered and 0 elsewhere (alpha is the stencil).
    pub color: Vec<[u8; 4]>,
    /// Normal as signed bytes (xyz, w unused).
    pub normal: Vec<[i8; 4]>,
    /// Proxy vertices in map coordinates (x, y in [-1, 1], z view depth).
    pub vertices: Vec<[f32; 3]>,
    /// Proxy triangles.
    pub indices: Vec<u32>,
    /// Whether the board is flat (billboard): the shader then ignores the depth map.
    pub flat: bool,
}

impl BoardData {
    /// Prepares decoded maps for drawing with `shape`.
    pub fn new(maps: &Maps, direction: DVec3, shape: BoardShape) -> BoardData {
        let size = maps.size;
        let pixels = (size * size) as usize;
        let mut depth = vec![UNCOVERED_DEPTH; pixels];
        let mut color = vec![[0u8; 4]; pixels];
        let mut normal = vec![[0i8; 4]; pixels];
        for i in 0..pixels {
            if maps.stencil[i] {
                depth[i] = maps.depth[i];
                let c = maps.color[i];
                color[i] = [c[0], c[1], c[2], 255];
                let n = maps.normal[i];
                normal[i] = [snorm(n[0]), snorm(n[1]), snorm(n[2]), 0];
            }
        }
        let (vertices, indices, flat) = match shape {
            BoardShape::Billboard => (
                vec![
                    [-1.0, -1.0, 0.0],
                    [1.0, -1.0, 0.0],
                    [1.0, 1.0, 0.0],
                    [-1.0, 1.0, 0.0],
                ],
                vec![0, 1, 2, 0, 2, 3],
                true,
            ),
            BoardShape::Relief { grid_cells } => {
                let (v, i) = proxy_grid(maps, grid_cells);
                (v, i, false)
            }
        };
        BoardData {
            basis: maps.basis,
            direction,
            size,
            depth,
            color,
            normal,
            vertices,
            indices,
            flat,
        }
    }

    /// Bytes this board takes on the GPU.
    pub fn gpu_bytes(&self) -> usize {
        self.depth.len() * 12 + self.vertices.len() * 12 + self.indices.len() * 4
    }
}

/// A unit-range value as a signed normalised byte (normals in maps and vertices).
pub(crate) fn snorm(value: f32) -> i8 {
    (value.clamp(-1.0, 1.0) * 127.0).round() as i8
}

/// The displaced proxy grid: `cells × cells` cells (fewer when the map is smaller), a cell
/// kept when any of its pixels is covered, each vertex on the surface at its corner (the mean
/// depth of the covered pixels touching it; on the silhouette, the nearest depth around it).
pub fn proxy_grid(maps: &Maps, grid_cells: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let size = maps.size as usize;
    let step = size.div_ceil(grid_cells.max(1) as usize).max(1);
    let cells = size.div_ceil(step);
    // Nearest depth per cell, +inf where the cell is empty.
    let mut nearest = vec![f32::INFINITY; cells * cells];
    for row in 0..size {
        for column in 0..size {
            let at = row * size + column;
            if maps.stencil[at] {
                let cell = (row / step) * cells + column / step;
                nearest[cell] = nearest[cell].min(maps.depth[at]);
            }
        }
    }
    let corners = cells + 1;
    let mut index_of = vec![u32::MAX; corners * corners];
    let mut vertices = Vec::new();
    let pixel = 2.0 / size as f32;
    for row in 0..corners {
        for column in 0..corners {
            // The surface at the corner: the mean depth of the covered pixels touching it;
            // where none do (a silhouette corner), the nearest depth of the cells around it.
            let (r, c) = ((row * step).min(size), (column * step).min(size));
            let (mut sum, mut count) = (0.0f32, 0u32);
            for (pr, pc) in [
                (r.wrapping_sub(1), c.wrapping_sub(1)),
                (r.wrapping_sub(1), c),
                (r, c.wrapping_sub(1)),
                (r, c),
            ] {
                if pr < size && pc < size && maps.stencil[pr * size + pc] {
                    sum += maps.depth[pr * size + pc];
                    count += 1;
                }
            }
            let mut z = if count > 0 {
                sum / count as f32
            } else {
                f32::INFINITY
            };
            let mut touches_kept_cell = false;
            for (cell_row, cell_column) in [
                (row.wrapping_sub(1), column.wrapping_sub(1)),
                (row.wrapping_sub(1), column),
                (row, column.wrapping_sub(1)),
                (row, column),
            ] {
                if cell_row < cells && cell_column < cells {
                    let cell = nearest[cell_row * cells + cell_column];
                    touches_kept_cell |= cell.is_finite();
                    if count == 0 {
                        z = z.min(cell);
                    }
                }
            }
            if touches_kept_cell {
                index_of[row * corners + column] = vertices.len() as u32;
                vertices.push([c as f32 * pixel - 1.0, 1.0 - r as f32 * pixel, z]);
            }
        }
    }
    let mut indices = Vec::new();
    for row in 0..cells {
        for column in 0..cells {
            if !nearest[row * cells + column].is_finite() {
                continue;
            }
            let corner = |r: usize, c: usize| index_of[r * corners + c];
            let (top_left, top_right) = (corner(row, column), corner(row, column + 1));
            let (bottom_left, bottom_right) =
                (corner(row + 1, column), corner(row + 1, column + 1));
            // Counter-clockwise as seen from the board's viewer (x right, y up).
            indices.extend_from_slice(&[top_left, bottom_left, bottom_right]);
            indices.extend_from_slice(&[top_left, bottom_right, top_right]);
        }
    }
    (vertices, indices)
}

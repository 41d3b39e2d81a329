//! A received reliefboard made ready for the GPU, off the frame thread: texel arrays for the
//! depth, colour and normal maps, and the displaced grid actually drawn (`backend::Grid`,
//! `grid_cells` cells a side; the fragment shader takes colour, normal, silhouette and depth
//! per pixel from the maps). A 1-cell grid at depth 0 is a plain billboard.

use backend::{Basis, Maps};
use glam::DVec3;

/// Depth texel value of an uncovered pixel (view depth lies in [-1, 1]).
pub const UNCOVERED_DEPTH: f32 = 2.0;

/// Default of `--board-cell-pixels`: a board's grid has a cell per this many pixels a side.
pub const DEFAULT_CELL_PIXELS: u32 = 8;

/// How the board's geometry is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoardShape {
    /// A displaced grid following the board's size on screen: a cell per `cell_pixels`
    /// pixels of the map (the map is the size the object covers on screen when asked for),
    /// at most `grid_cells` cells a side.
    Relief {
        /// Most cells per side.
        grid_cells: u32,
        /// Map pixels per cell side.
        cell_pixels: u32,
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
    /// The maps as the texture's three RGBA8 layers of `size x size` texels, packed here (off
    /// the frame thread) so an upload only copies: [`MAP_LAYER_COLOR`] (alpha 255 where
    /// covered, 0 elsewhere: the stencil), [`MAP_LAYER_NORMAL`] (xyz biased into [0, 255]
    /// and 0 where uncovered, so filtered over an edge and divided by the filtered alpha
    /// they stay the covered texels'; the shader undoes both), [`MAP_LAYER_DEPTH`] (the
    /// four bytes of the f32 view depth, read back exactly, never filtered; an uncovered
    /// texel next to a covered one holds the nearest of their depths, one farther out
    /// [`UNCOVERED_DEPTH`]).
    pub layers: Vec<u8>,
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
        let drawn = DrawnMaps::new(maps);
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
            BoardShape::Relief {
                grid_cells,
                cell_pixels,
            } => {
                let grid = backend::Grid::new(maps, cells_for(size, grid_cells, cell_pixels));
                (grid.vertices, grid.triangles.into_flattened(), false)
            }
        };
        BoardData {
            basis: maps.basis,
            direction,
            size,
            layers: drawn.pack_layers(),
            vertices,
            indices,
            flat,
        }
    }

    /// Bytes this board holds on the GPU: its maps. Its grid is not held there but copied
    /// in each frame it is drawn, with the other boards' (`Renderer::write_board_grids`).
    pub fn gpu_bytes(&self) -> usize {
        self.layers.len()
    }

    /// Texels per map.
    fn texels(&self) -> usize {
        (self.size * self.size) as usize
    }

    /// The bytes of texel `texel` in map layer `layer`.
    fn texel(&self, layer: usize, texel: usize) -> [u8; 4] {
        let at = (layer * self.texels() + texel) * 4;
        self.layers[at..at + 4].try_into().expect("four bytes")
    }

    /// The view depth of `texel`.
    pub fn depth(&self, texel: usize) -> f32 {
        f32::from_ne_bytes(self.texel(MAP_LAYER_DEPTH, texel))
    }

    /// The colour of `texel`, alpha 255 where the object covers it.
    pub fn color(&self, texel: usize) -> [u8; 4] {
        self.texel(MAP_LAYER_COLOR, texel)
    }
}

/// A board's maps as they are drawn (a board's texture layers, an octahedral atlas's views).
pub struct DrawnMaps {
    /// View depth per texel; an uncovered texel next to a covered one (8 neighbours) holds
    /// the nearest of their depths, one farther out [`UNCOVERED_DEPTH`].
    pub depth: Vec<f32>,
    /// RGBA8 colour, alpha 255 where covered and 0 elsewhere (alpha is the stencil).
    pub color: Vec<[u8; 4]>,
    /// Normal as signed bytes (xyz, w unused).
    pub normal: Vec<[i8; 4]>,
}

impl DrawnMaps {
    /// The maps a worker rendered, as drawn.
    pub fn new(maps: &Maps) -> DrawnMaps {
        let pixels = (maps.size * maps.size) as usize;
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
        extend_depth_one_texel(&mut depth, &maps.stencil, maps.size as usize);
        DrawnMaps {
            depth,
            color,
            normal,
        }
    }

    /// The three texture layers of [`BoardData::layers`].
    fn pack_layers(&self) -> Vec<u8> {
        let mut layers = Vec::with_capacity(self.depth.len() * 4 * MAP_LAYERS as usize);
        layers.extend_from_slice(bytemuck::cast_slice(&self.color));
        layers.extend(self.normal.iter().zip(&self.color).flat_map(|(n, c)| {
            let covered = c[3] == 255;
            let unsigned = |v: i8| {
                if covered {
                    (v as i32 + 128).min(255) as u8
                } else {
                    0
                }
            };
            [unsigned(n[0]), unsigned(n[1]), unsigned(n[2]), 0]
        }));
        layers.extend_from_slice(bytemuck::cast_slice(&self.depth));
        layers
    }
}

/// Layers of a board's map texture (see [`BoardData::layers`]; the shader reads them so).
pub const MAP_LAYER_COLOR: usize = 0;
/// See [`MAP_LAYER_COLOR`].
pub const MAP_LAYER_NORMAL: usize = 1;
/// See [`MAP_LAYER_COLOR`].
pub const MAP_LAYER_DEPTH: usize = 2;
/// How many.
pub const MAP_LAYERS: u32 = 3;

/// Gives each uncovered texel next to a covered one the nearest depth among its covered
/// neighbours. The shader cuts the silhouette where the colour's bilinear alpha crosses one
/// half, between texel centres, and may find the nearest texel there uncovered: it takes
/// the depth from this ring. (The stencil is the colour's alpha, unchanged.)
fn extend_depth_one_texel(depth: &mut [f32], stencil: &[bool], size: usize) {
    // The nearest covered depth over each texel's 3×3 neighbourhood, as a minimum along rows
    // and then along columns (six comparisons a texel, in memory order).
    let covered = |at: usize| {
        if stencil[at] {
            depth[at]
        } else {
            UNCOVERED_DEPTH
        }
    };
    let mut rows = vec![UNCOVERED_DEPTH; depth.len()];
    for y in 0..size {
        for x in 0..size {
            let at = y * size + x;
            let mut z = covered(at);
            if x > 0 {
                z = z.min(covered(at - 1));
            }
            if x + 1 < size {
                z = z.min(covered(at + 1));
            }
            rows[at] = z;
        }
    }
    for y in 0..size {
        for x in 0..size {
            let at = y * size + x;
            if stencil[at] {
                continue;
            }
            let mut z = rows[at];
            if y > 0 {
                z = z.min(rows[at - size]);
            }
            if y + 1 < size {
                z = z.min(rows[at + size]);
            }
            depth[at] = z;
        }
    }
}

/// Cells per side of the grid of a board `size` pixels across: one per `cell_pixels`, at
/// least one, at most `grid_cells`. The grid only places texels on screen (silhouette and
/// depth are per pixel), so a cell of a few pixels loses nothing a board that small shows,
/// while a fixed fine grid costs a 16-pixel board as many triangles as a 256-pixel one.
pub fn cells_for(size: u32, grid_cells: u32, cell_pixels: u32) -> u32 {
    size.div_ceil(cell_pixels.max(1))
        .clamp(1, grid_cells.max(1))
}

/// A unit-range value as a signed normalised byte (normals in maps and vertices).
pub(crate) fn snorm(value: f32) -> i8 {
    (value.clamp(-1.0, 1.0) * 127.0).round() as i8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uncovered_texels_beside_the_silhouette_take_the_nearest_covered_depth() {
        // A 6×6 map covering a 2×2 block at depths 0.1, 0.2 (top row) and 0.3, 0.4.
        let size = 6usize;
        let mut maps = Maps {
            size: size as u32,
            basis: Basis::new(DVec3::NEG_Z, DVec3::ZERO, 1.0).unwrap(),
            depth: vec![f32::NAN; size * size],
            stencil: vec![false; size * size],
            color: vec![[0; 4]; size * size],
            normal: vec![[0.0; 3]; size * size],
        };
        for (at, z) in [(14, 0.1), (15, 0.2), (20, 0.3), (21, 0.4)] {
            maps.depth[at] = z;
            maps.stencil[at] = true;
            maps.color[at] = [10, 20, 30, 255];
            maps.normal[at] = [0.0, 0.0, 1.0];
        }
        let board = BoardData::new(&maps, DVec3::NEG_Z, BoardShape::Billboard);
        for y in 0..size {
            for x in 0..size {
                let at = y * size + x;
                // The 4×4 block around the covered 2×2 (rows and columns 1 to 4) is the ring.
                let expected = match (y, x) {
                    _ if maps.stencil[at] => maps.depth[at],
                    (1..=4, 1..=4) => {
                        let mut nearest = UNCOVERED_DEPTH;
                        for (cy, cx) in [(2usize, 2usize), (2, 3), (3, 2), (3, 3)] {
                            if cy.abs_diff(y) <= 1 && cx.abs_diff(x) <= 1 {
                                nearest = nearest.min(maps.depth[cy * size + cx]);
                            }
                        }
                        nearest
                    }
                    _ => UNCOVERED_DEPTH,
                };
                assert_eq!(board.depth(at), expected, "texel ({x}, {y})");
                // The stencil stays the colour's alpha: the ring is not covered.
                assert_eq!(
                    board.color(at)[3] == 255,
                    maps.stencil[at],
                    "texel ({x}, {y})"
                );
            }
        }
        assert_eq!(board.depth(7), 0.1, "the corner beside the nearest texel");
        assert_eq!(board.depth(4 * size + 4), 0.4);
    }
}

//! The reliefboard's displaced grid, one definition for both sides: the visualization node
//! draws it (`--board-grid` cells a side, over the full maps), `backend render` reports and
//! exports it at one cell per pixel.
//!
//! The grid lies in the plane facing the view, each vertex pushed along the view to the
//! surface at its corner. The fragment shader takes colour, normal, silhouette (stencil) and
//! depth per pixel from the maps, so a grid coarser than the maps keeps the silhouette and the
//! per-pixel occlusion, and only the parallax between its vertices is approximated. That is
//! also why no cell is cut where the depth jumps (a branch in front of a trunk): the pixels
//! on both sides are drawn at their own depth, and a cut cell would drop covered pixels.

use glam::{DVec3, Vec3};

use crate::raster::Maps;

/// A displaced grid in map coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Grid {
    /// Vertices: `x`, `y` in [-1, 1] (x right, y up), `z` the view depth of the surface at
    /// the corner.
    pub vertices: Vec<[f32; 3]>,
    /// Two triangles per cell that holds a covered pixel, counter-clockwise as seen from the
    /// board's viewer.
    pub triangles: Vec<[u32; 3]>,
}

impl Grid {
    /// `cells × cells` cells over the maps (fewer when the maps are smaller: a cell is at
    /// least one pixel), a cell kept when any of its pixels is covered. A vertex sits at the
    /// mean depth of the covered pixels touching its corner; on the silhouette, where none
    /// does, at the nearest depth of the kept cells around it.
    pub fn new(maps: &Maps, cells: u32) -> Grid {
        let size = maps.size as usize;
        let step = size.div_ceil(cells.max(1) as usize).max(1);
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
        let mut triangles = Vec::new();
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
                triangles.push([top_left, bottom_left, bottom_right]);
                triangles.push([top_left, bottom_right, top_right]);
            }
        }
        Grid {
            vertices,
            triangles,
        }
    }
}

/// A reliefboard at full resolution: the maps and their grid at one cell per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Board {
    /// The maps it was made from (and carries, for texturing).
    pub maps: Maps,
    /// The grid, one cell per pixel.
    pub grid: Grid,
    /// Smallest and largest depth over covered pixels (0, 0 when none is).
    pub depth_range: [f32; 2],
}

impl Board {
    /// The board of `maps`, its grid at one cell per pixel.
    pub fn from_maps(maps: Maps) -> Board {
        let range = maps
            .depth
            .iter()
            .zip(&maps.stencil)
            .filter(|(_, covered)| **covered)
            .fold(
                [f32::INFINITY, f32::NEG_INFINITY],
                |[near, far], (&z, _)| [near.min(z), far.max(z)],
            );
        let depth_range = if range[0] <= range[1] {
            range
        } else {
            [0.0, 0.0] // nothing covered
        };
        Board {
            grid: Grid::new(&maps, maps.size),
            maps,
            depth_range,
        }
    }

    /// The board as a mesh in world space, for export (`reliefboard.ply`): each vertex
    /// coloured as a covered pixel touching its corner.
    pub fn world_mesh(&self) -> scene::Object {
        let basis = &self.maps.basis;
        let size = self.maps.size as usize;
        let mut builder = scene::ObjectBuilder::new("reliefboard");
        for &[x, y, z] in &self.grid.vertices {
            let column = ((x + 1.0) * 0.5 * size as f32).round() as usize;
            let row = ((1.0 - y) * 0.5 * size as f32).round() as usize;
            let color = [(0, 0), (0, 1), (1, 0), (1, 1)]
                .iter()
                .map(|(dr, dc)| (row.wrapping_sub(*dr), column.wrapping_sub(*dc)))
                .find(|&(r, c)| r < size && c < size && self.maps.stencil[r * size + c])
                .map_or([0, 0, 0, 255], |(r, c)| self.maps.color[r * size + c]);
            let p = Vec3::new(x, y, z).as_dvec3();
            builder.vertex(basis.world_point(p.x, p.y, p.z), color);
        }
        for &[a, b, c] in &self.grid.triangles {
            builder.triangle(a, b, c);
        }
        builder.finish().0
    }

    /// World position of the board's centre.
    pub fn center(&self) -> DVec3 {
        self.maps.basis.center
    }
}

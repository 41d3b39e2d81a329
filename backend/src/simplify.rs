//! Simplified versions of an object, built with meshoptimizer (crate `meshopt`, the
//! simplifier most engines ship): a chain of levels, each about half the one before, with
//! the object-space error of each. The worker renders a board from the coarsest level its
//! pixels cannot tell from the full mesh; the visualization node's `--impostor lod` draws
//! the same chain as the alternative a single-machine user would build.

use crate::object::{MeshRef, PreparedObject, RenderVertex};

/// Levels stop when a halving keeps more than this share of the triangles (the simplifier is
/// stuck on topology) ...
pub const STUCK_SHARE: f64 = 0.9;
/// ... or below this many triangles.
pub const MIN_TRIANGLES: usize = 16;
/// At most this many levels below the full mesh (1/2^8 of it).
pub const MAX_LEVELS: usize = 8;

/// An object's coarser levels: index lists into the full mesh's vertices, each about half the
/// one before, with their accumulated object-space error.
#[derive(Debug, Clone, PartialEq)]
pub struct LodChain {
    /// Triangles of each coarser level, finest first (level 0, the full mesh, is not here).
    pub levels: Vec<Vec<[u32; 3]>>,
    /// Object-space error of level `i` (0 for the full mesh), non-decreasing.
    pub errors: Vec<f64>,
}

impl Default for LodChain {
    /// The full mesh alone.
    fn default() -> LodChain {
        LodChain {
            levels: Vec::new(),
            errors: vec![0.0],
        }
    }
}

impl LodChain {
    /// Simplifies `vertices`/`triangles` by repeated halving, each level from the one before
    /// (the error of a level adds the errors of the steps that made it, as meshoptimizer
    /// advises). Vertices at one position with different normals (creases) are seams the
    /// simplifier keeps together.
    pub fn build(vertices: &[RenderVertex], triangles: &[[u32; 3]]) -> LodChain {
        LodChain::build_while(vertices, triangles, |_, _| true)
    }

    /// As [`LodChain::build`], but hands each new level (its triangles and error) to `keep`
    /// and stops at the first one it refuses, which is left out: a level the worker cannot
    /// use is not worth simplifying further.
    pub fn build_while(
        vertices: &[RenderVertex],
        triangles: &[[u32; 3]],
        mut keep: impl FnMut(&[[u32; 3]], f64) -> bool,
    ) -> LodChain {
        let positions: Vec<[f32; 3]> = vertices.iter().map(|v| v.position.to_array()).collect();
        let Ok(adapter) = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&positions), 12, 0)
        else {
            return LodChain::default();
        };
        // The factor from meshoptimizer's relative error to object units.
        let scale = meshopt::simplify_scale(&adapter) as f64;
        let mut chain = LodChain::default();
        let mut current: Vec<u32> = bytemuck::cast_slice(triangles).to_vec();
        while chain.levels.len() < MAX_LEVELS && current.len() / 3 > MIN_TRIANGLES {
            let target = (current.len() / 6) * 3;
            let mut relative = 0.0f32;
            // Permissive: collapses may cross the crease splits (one position, several
            // normals); without it the dragon's chain stops at 15 k triangles with a
            // twentyfold error jump, with it halving goes on to 782.
            let next = meshopt::simplify(
                &current,
                &adapter,
                target,
                f32::MAX,
                meshopt::SimplifyOptions::Permissive,
                Some(&mut relative),
            );
            if next.is_empty() || next.len() as f64 > current.len() as f64 * STUCK_SHARE {
                break;
            }
            let error = chain.errors.last().copied().unwrap_or(0.0) + relative as f64 * scale;
            let level: Vec<[u32; 3]> = next.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
            if !keep(&level, error) {
                break;
            }
            chain.levels.push(level);
            chain.errors.push(error);
            current = next;
        }
        chain
    }

    /// Whether every index names one of `vertices` vertices (a cached chain must, to be
    /// drawn).
    pub fn fits(&self, vertices: usize) -> bool {
        self.levels
            .iter()
            .flatten()
            .flatten()
            .all(|&i| (i as usize) < vertices)
    }
}

/// One coarser version of a prepared object, with its own compact vertex array (only the
/// vertices its triangles use, in the order they first use them) so rendering it touches
/// nothing of the full mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// Largest distance of this level's surface from the full mesh's, in object units.
    pub error: f64,
    /// Vertices.
    pub vertices: Vec<RenderVertex>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
}

impl Level {
    /// This level as one render reads it.
    pub fn mesh(&self) -> MeshRef<'_> {
        MeshRef {
            vertices: &self.vertices,
            triangles: &self.triangles,
            error: self.error,
        }
    }
}

/// A board of side N pixels frames the object's bounding sphere, so one pixel is
/// `2 r / N` object units; a level whose error stays under half a pixel draws nearly the
/// same maps as the full mesh. Where the error misjudges the silhouette, the stencil check
/// in [`levels`] catches it (on the dragon it keeps the mean stencil IoU at 0.98 or more at
/// 32 to 256 pixels; a quarter pixel, tried first, rendered twice the triangles at 64 and
/// 256 for mean IoU 0.996 and 0.999 instead of 0.984 and 0.998).
pub const MAX_ERROR_PIXELS: f64 = 0.5;

/// Stencil intersection over union a level must keep against the full mesh, averaged over
/// [`CHECK_DIRECTIONS`], at the sizes it is chosen for.
pub const MIN_STENCIL_IOU: f64 = 0.98;
/// Views a level is checked from (spread over the sphere).
const CHECK_DIRECTIONS: usize = 3;
/// The smallest board side checked: smaller boards are mostly edge.
const SMALLEST_CHECK: u32 = 32;
/// The largest board side checked (larger boards use the finer levels anyway).
const LARGEST_CHECK: u32 = 256;

/// The levels of `object`'s chain, each compacted, with errors a board can trust:
/// meshoptimizer's error measures how far the surface moved, not what vanished, and on
/// foliage it underrates whole leaves collapsed away (a tree's first halving, 0.13 px by its
/// error, kept stencil IoU 0.85 at 32 pixels). So each level is rendered against the full
/// mesh at the largest size it would be chosen for and at [`SMALLEST_CHECK`]: a level that
/// fails at its largest size is kept for half that size (its error raised to match), one
/// that fails at the smallest is dropped with every coarser level.
pub fn levels(object: &PreparedObject) -> Vec<Level> {
    let pixel = |size: u32| MAX_ERROR_PIXELS * 2.0 * object.radius / size as f64;
    let mut full_stencils: rustc_hash::FxHashMap<u32, Vec<Vec<bool>>> = Default::default();
    let mut checked = Vec::new();
    // Built one level at a time: a level that fails at the smallest size ends the chain, so
    // the coarser ones (which would fail too) are never simplified.
    LodChain::build_while(&object.vertices, &object.triangles, |triangles, error| {
        let mut level = compact(object, triangles, error);
        loop {
            // The largest side at which this level would be chosen.
            let largest = if level.error > 0.0 {
                (MAX_ERROR_PIXELS * 2.0 * object.radius / level.error).floor()
            } else {
                f64::INFINITY
            };
            let largest = largest.min(LARGEST_CHECK as f64) as u32;
            if largest < SMALLEST_CHECK {
                // Only boards below the smallest check choose it; there they are mostly edge.
                checked.push(level);
                return true;
            }
            let mut passes = |size: u32| -> bool {
                let full = full_stencils
                    .entry(size)
                    .or_insert_with(|| stencils(object, object.full_mesh(), size));
                let mine = stencils(object, level.mesh(), size);
                mean_iou(full, &mine) >= MIN_STENCIL_IOU
            };
            if !passes(SMALLEST_CHECK) {
                return false;
            }
            if largest == SMALLEST_CHECK || passes(largest) {
                checked.push(level);
                return true;
            }
            // Chosen from here on only up to half its former largest side.
            level.error = pixel(largest / 2) * (1.0 + 1e-9);
        }
    });
    checked
}

/// The stencil of `mesh` at `size` from each check direction.
fn stencils(object: &PreparedObject, mesh: MeshRef<'_>, size: u32) -> Vec<Vec<bool>> {
    check_directions()
        .map(|direction| {
            crate::raster::render_mesh(object, mesh, direction, size, 1)
                .map(|maps| maps.stencil)
                .unwrap_or_default()
        })
        .collect()
}

/// Views from three unrelated directions, none along an axis.
fn check_directions() -> impl Iterator<Item = glam::DVec3> {
    [[0.31, -0.42, -0.85], [-0.77, 0.21, 0.6], [0.5, 0.8, -0.33]]
        .into_iter()
        .take(CHECK_DIRECTIONS)
        .map(|d| glam::DVec3::from_array(d).normalize())
}

/// Intersection over union of two stencils (1 where both are empty): how far a board's
/// silhouette matches another's.
pub fn stencil_iou(a: &[bool], b: &[bool]) -> f64 {
    let (mut both, mut either) = (0usize, 0usize);
    for (x, y) in a.iter().zip(b) {
        both += (*x && *y) as usize;
        either += (*x || *y) as usize;
    }
    if either == 0 {
        1.0
    } else {
        both as f64 / either as f64
    }
}

/// Mean over views of [`stencil_iou`].
fn mean_iou(a: &[Vec<bool>], b: &[Vec<bool>]) -> f64 {
    let each = a.iter().zip(b).map(|(a, b)| stencil_iou(a, b));
    each.sum::<f64>() / a.len().max(1) as f64
}

/// A level of `object`'s chain with its own compact vertex array.
fn compact(object: &PreparedObject, triangles: &[[u32; 3]], error: f64) -> Level {
    let mut new_index = vec![u32::MAX; object.vertices.len()];
    let mut vertices = Vec::new();
    let triangles = triangles
        .iter()
        .map(|triangle| {
            triangle.map(|v| {
                if new_index[v as usize] == u32::MAX {
                    new_index[v as usize] = vertices.len() as u32;
                    vertices.push(object.vertices[v as usize]);
                }
                new_index[v as usize]
            })
        })
        .collect();
    Level {
        error,
        vertices,
        triangles,
    }
}

//! Simplified versions of an object, built with meshoptimizer (crate `meshopt`, the
//! simplifier most engines ship): a chain of levels, each about half the one before, with
//! the object-space error of each. Foliage and other aggregate detail, which mesh
//! simplification can only delete, is thinned stochastically instead ([`Aggregate`]). The
//! worker renders a board from the coarsest level its pixels cannot tell from the full mesh;
//! the visualization node's `--impostor lod` draws the meshoptimizer chain as the
//! alternative a single-machine user would build.

use rustc_hash::FxHashMap;

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
    /// The smallest checked board side whose silhouette this level keeps: a smaller board
    /// (of [`SMALLEST_CHECK`] pixels or more) is rendered from a finer level. A silhouette is a
    /// larger share of a smaller board, so a level can lose it at 32 pixels and keep it at 64.
    pub smallest_size: u32,
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

/// Stencil intersection over union a mesh level must keep against the full mesh in each of
/// `Silhouette::views`, at the sizes it is chosen for.
pub const MIN_STENCIL_IOU: f64 = 0.98;
/// The smallest board side checked: smaller boards are mostly edge.
pub const SMALLEST_CHECK: u32 = 32;
/// The largest board side checked (larger boards use the finer levels anyway).
const LARGEST_CHECK: u32 = 256;

/// The levels a worker renders boards from, each compacted, with errors a board can trust.
/// Aggregate detail (foliage, [`Aggregate`]) is thinned stochastically; anything else is
/// simplified by meshoptimizer. Every level is checked against the full mesh
/// (`check_level`); the first that fails at every size ends the chain, so coarser ones
/// (which would fail too) are never built.
pub fn levels(object: &PreparedObject) -> Vec<Level> {
    let mut references = FxHashMap::default();
    let mut checked: Vec<Level> = Vec::new();
    // Checks `level`, keeps it if it passes, and says whether it did.
    let mut keep = |checked: &mut Vec<Level>, level: Level, silhouette: Silhouette| {
        match check_level(object, &mut references, level, silhouette) {
            Some(mut level) => {
                // Errors stay non-decreasing, as the choice by size needs, even where the
                // check raised an earlier level's.
                level.error = level.error.max(checked.last().map_or(0.0, |l| l.error));
                checked.push(level);
                true
            }
            None => false,
        }
    };
    match Aggregate::find(object) {
        Some(aggregate) => {
            // The levels together hold at most the full mesh's triangles, as a worker's
            // admission of an object assumes (the large parts repeat in every level).
            let mut room = object.triangles.len();
            for step in 1..=MAX_LEVELS as u32 {
                let Some(mut level) = aggregate.level(object, step) else {
                    break;
                };
                let Some(left) = room.checked_sub(level.triangles.len()) else {
                    break;
                };
                room = left;
                // Tried first at the largest size the finer level held at, not above.
                level.error = checked.last().map_or(0.0, |l| l.error);
                if !keep(&mut checked, level, Silhouette::Statistic) {
                    break;
                }
            }
        }
        None => {
            LodChain::build_while(&object.vertices, &object.triangles, |triangles, error| {
                keep(
                    &mut checked,
                    compact(object, triangles, error),
                    Silhouette::Curve,
                )
            });
        }
    }
    checked
}

/// What a level's stencils must keep against the full mesh's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Silhouette {
    /// A surface's silhouette is a curve a coarser mesh can follow: stencil IoU at least
    /// [`MIN_STENCIL_IOU`] in every view.
    Curve,
    /// Aggregate detail's is a statistic that no level with fewer parts matches pixel for
    /// pixel (a tree's half-leaves level: IoU 0.95 at every size, coverage within 1%): mean
    /// stencil IoU at least the full mesh's own against itself moved half a pixel (a tree's: 0.84 at
    /// 32 pixels to 0.95 at 256; the dragon's 0.85 to 0.98), and the same number of covered
    /// pixels within [`COVERAGE_TOLERANCE`].
    Statistic,
}

impl Silhouette {
    /// The views a level is checked from, spread over the sphere and none along an axis
    /// (where a modelled object lines its edges up). A curve's every view must pass: three
    /// views, averaged, let the dragon's worst fall to IoU 0.962 (32 pixels) and 0.974 (64)
    /// of the 32 views `backend bench` measures; six, each to pass, keep 0.98 in all of them
    /// (a Fibonacci lattice about the z axis, turned a radian off the bench's, about y). A
    /// statistic is judged by its mean over three unrelated views: its outcome hangs on
    /// which, and these keep a tree's figures as measured.
    fn views(self) -> Vec<glam::DVec3> {
        match self {
            Silhouette::Curve => {
                let n = 6;
                (0..n)
                    .map(|i| {
                        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                        let theta = std::f64::consts::PI * (3.0 - 5f64.sqrt()) * i as f64 + 1.0;
                        let r = (1.0 - z * z).sqrt();
                        glam::DVec3::new(r * theta.sin(), r * theta.cos(), z)
                    })
                    .collect()
            }
            Silhouette::Statistic => [[0.31, -0.42, -0.85], [-0.77, 0.21, 0.6], [0.5, 0.8, -0.33]]
                .into_iter()
                .map(|d| glam::DVec3::from_array(d).normalize())
                .collect(),
        }
    }
}

/// How far an aggregate level's covered pixels may differ in number from the full mesh's.
pub const COVERAGE_TOLERANCE: f64 = 0.02;

/// The full mesh's stencils at one size, and what a level's must keep of them.
struct Reference {
    stencils: Vec<Vec<bool>>,
    /// The least stencil IoU a level must keep: in every view for a curve, on average for a
    /// statistic.
    min_iou: f64,
    /// For a statistic, the full mesh's covered pixels, which a level must keep in number.
    covered: Option<usize>,
}

impl Reference {
    fn new(object: &PreparedObject, size: u32, silhouette: Silhouette) -> Reference {
        let stencils = stencils(object, object.full_mesh(), size, silhouette);
        match silhouette {
            Silhouette::Curve => Reference {
                stencils,
                min_iou: MIN_STENCIL_IOU,
                covered: None,
            },
            Silhouette::Statistic => {
                let mut moved = object.clone();
                // Half a pixel (a pixel is 2 r / size) along each view's image x axis.
                let moved_stencils: Vec<Vec<bool>> = silhouette
                    .views()
                    .into_iter()
                    .map(|direction| {
                        let (right, _) = scene::view_axes(direction);
                        let half_pixel = right * object.radius / size as f64;
                        moved.local_center = object.local_center - half_pixel.as_vec3();
                        crate::raster::render_mesh_ungrown(
                            &moved,
                            moved.full_mesh(),
                            direction,
                            size,
                        )
                        .map(|maps| maps.stencil)
                        .unwrap_or_default()
                    })
                    .collect();
                Reference {
                    min_iou: mean_iou(&stencils, &moved_stencils),
                    covered: Some(stencils.iter().flatten().filter(|s| **s).count()),
                    stencils,
                }
            }
        }
    }

    /// Whether `mine` (a level's stencils) keep this silhouette.
    fn kept_by(&self, mine: &[Vec<bool>]) -> bool {
        let covered = || mine.iter().flatten().filter(|s| **s).count() as f64;
        match self.covered {
            None => self
                .stencils
                .iter()
                .zip(mine)
                .all(|(full, level)| stencil_iou(full, level) >= self.min_iou),
            Some(full) => {
                mean_iou(&self.stencils, mine) >= self.min_iou
                    && (covered() - full as f64).abs() <= COVERAGE_TOLERANCE * full as f64
            }
        }
    }
}

/// `level` with an error and a smallest size a board can trust, or `None` where it loses
/// the silhouette at every checked size it would be chosen for. meshoptimizer's error
/// measures how far the surface moved, not what vanished, and on foliage it underrates whole
/// leaves collapsed away (a tree's first halving, 0.13 px by its error, kept stencil IoU 0.85
/// at 32 pixels). So a level is rendered against the full mesh at the smallest size it keeps
/// the silhouette at (from [`SMALLEST_CHECK`], doubling) and at the largest size it would be
/// chosen for: one that fails at its largest size is kept for half that size (its error
/// raised to match).
fn check_level(
    object: &PreparedObject,
    references: &mut FxHashMap<u32, Reference>,
    mut level: Level,
    silhouette: Silhouette,
) -> Option<Level> {
    let pixel = |size: u32| MAX_ERROR_PIXELS * 2.0 * object.radius / size as f64;
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
            level.smallest_size = 0;
            return Some(level);
        }
        let mut passes = |size: u32| -> bool {
            let reference = references
                .entry(size)
                .or_insert_with(|| Reference::new(object, size, silhouette));
            reference.kept_by(&stencils(object, level.mesh(), size, silhouette))
        };
        let smallest = smallest_passing(largest, &mut passes)?;
        if smallest == largest || passes(largest) {
            level.smallest_size = smallest;
            return Some(level);
        }
        // Chosen from here on only up to half its former largest side.
        level.error = pixel(largest / 2) * (1.0 + 1e-9);
    }
}

/// The first of [`SMALLEST_CHECK`], twice that, four times ... up to `largest` (itself
/// tried last) at which `passes`, or `None`.
fn smallest_passing(largest: u32, mut passes: impl FnMut(u32) -> bool) -> Option<u32> {
    let mut size = SMALLEST_CHECK;
    loop {
        if passes(size) {
            return Some(size);
        }
        if size >= largest {
            return None;
        }
        size = (size * 2).min(largest);
    }
}

/// An object made mostly of many small separate parts (leaves, needles, grass blades):
/// aggregate detail, which mesh simplification cannot reduce without deleting whole parts
/// (meshoptimizer only collapses leaves away, and the canopy thins). It is thinned the way
/// Cook et al. simplify aggregate detail stochastically ("Stochastic Simplification of
/// Aggregate Detail", SIGGRAPH 2007): a level keeps a random fraction `u` of the small parts,
/// each scaled about its centre so its area grows by `1 / u`, which keeps the chance that a
/// pixel sees a part (and so the canopy's coverage) while drawing `u` of the triangles.
/// Larger parts (trunk, branches) stay whole.
#[derive(Debug)]
pub struct Aggregate {
    /// The small parts' triangles (indices into the full mesh), in the random order in which
    /// levels drop them: level `k` keeps the first `2^-k` of them.
    parts: Vec<Vec<[u32; 3]>>,
    /// Each part's centre (object space), in the same order.
    centers: Vec<glam::Vec3>,
    /// Triangles of the large parts, kept in every level.
    large: Vec<[u32; 3]>,
}

/// A part is small when its radius is at most this share of the object's.
pub const SMALL_PART_SHARE: f64 = 0.05;
/// An object is aggregate detail when its small parts hold at least this share of its
/// triangles ...
pub const AGGREGATE_TRIANGLE_SHARE: f64 = 0.5;
/// ... and there are at least this many of them (fewer are not a statistic).
pub const AGGREGATE_MIN_PARTS: usize = 256;

impl Aggregate {
    /// The object's parts (triangles connected through shared positions: crease splits do
    /// not part a mesh) if it is aggregate detail.
    pub fn find(object: &PreparedObject) -> Option<Aggregate> {
        let triangles = &object.triangles;
        let mut by_position: FxHashMap<[u32; 3], u32> = FxHashMap::default();
        let node: Vec<u32> = object
            .vertices
            .iter()
            .map(|v| {
                let next = by_position.len() as u32;
                // + 0.0 turns -0.0 into 0.0: one position, one node.
                *by_position
                    .entry((v.position + glam::Vec3::ZERO).to_array().map(f32::to_bits))
                    .or_insert(next)
            })
            .collect();
        let mut sets = scene::UnionFind::new(by_position.len());
        for t in triangles {
            let [a, b, c] = t.map(|v| node[v as usize]);
            sets.union(a, b);
            sets.union(a, c);
        }
        let mut part_of: FxHashMap<u32, usize> = FxHashMap::default();
        let mut parts: Vec<Vec<[u32; 3]>> = Vec::new();
        for t in triangles {
            let r = sets.find(node[t[0] as usize]);
            let next = parts.len();
            let part = *part_of.entry(r).or_insert(next);
            if part == next {
                parts.push(Vec::new());
            }
            parts[part].push(*t);
        }
        let small_radius = SMALL_PART_SHARE * object.radius;
        let (mut small, mut large) = (Vec::new(), Vec::new());
        for part in parts {
            let bounds = scene::Aabb::from_points(
                part.iter()
                    .flatten()
                    .map(|&v| object.vertices[v as usize].position.as_dvec3()),
            );
            let radius = bounds.diagonal() * 0.5;
            if radius <= small_radius {
                small.push((bounds.center().as_vec3(), part));
            } else {
                large.extend(part);
            }
        }
        let small_triangles: usize = small.iter().map(|(_, p)| p.len()).sum();
        if small.len() < AGGREGATE_MIN_PARTS
            || (small_triangles as f64) < AGGREGATE_TRIANGLE_SHARE * triangles.len() as f64
        {
            return None;
        }
        // A fixed random order (a hash of each part's index), so the same
        // object always gives the same levels, and each level's parts are the next one's
        // plus more: a board does not flicker between sizes.
        let mut keyed: Vec<_> = small.into_iter().enumerate().collect();
        keyed.sort_unstable_by_key(|(index, _)| splitmix(*index as u64));
        let (centers, parts) = keyed.into_iter().map(|(_, part)| part).unzip();
        Some(Aggregate {
            parts,
            centers,
            large,
        })
    }

    /// Level `step`: the first `2^-step` of the small parts, each grown by `2^(step/2)`
    /// about its centre, and the large parts; `None` once fewer than
    /// [`MIN_TRIANGLES`] would remain or the kept parts would be too few to stand for the rest.
    pub fn level(&self, object: &PreparedObject, step: u32) -> Option<Level> {
        let kept = self.parts.len() >> step;
        if kept < AGGREGATE_MIN_PARTS / 4 {
            return None;
        }
        let grow = 2f32.powf(step as f32 * 0.5);
        // A grown part stays inside the bounding sphere, which frames every board: a vertex
        // grown out of it is pulled back onto it (depth is z over that sphere, in [-1, 1]).
        let (center_of_all, radius) = (object.local_center, object.radius as f32);
        let inside = |p: glam::Vec3| {
            let offset = p - center_of_all;
            let length = offset.length();
            if length > radius {
                center_of_all + offset * (radius / length)
            } else {
                p
            }
        };
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        let mut new_index = FxHashMap::default();
        let mut add = |triangle: &[u32; 3], scaled_about: Option<glam::Vec3>| {
            triangle.map(|v| {
                *new_index.entry(v).or_insert_with(|| {
                    let mut vertex = object.vertices[v as usize];
                    if let Some(center) = scaled_about {
                        vertex.position = inside(center + (vertex.position - center) * grow);
                    }
                    vertices.push(vertex);
                    (vertices.len() - 1) as u32
                })
            })
        };
        for t in &self.large {
            triangles.push(add(t, None));
        }
        for (part, center) in self.parts[..kept].iter().zip(&self.centers) {
            for t in part {
                triangles.push(add(t, Some(*center)));
            }
        }
        if triangles.len() <= MIN_TRIANGLES {
            return None;
        }
        // Kept for the object's life: no room left over from growing.
        vertices.shrink_to_fit();
        triangles.shrink_to_fit();
        Some(Level {
            // No distance bounds what a thinned aggregate changes: the silhouette check
            // finds the sizes it holds at.
            error: 0.0,
            smallest_size: 0,
            vertices,
            triangles,
        })
    }
}

/// A well-mixed 64-bit hash (splitmix64's finaliser).
fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The stencil of `mesh` at `size` from each of the views `silhouette` is checked from.
fn stencils(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    size: u32,
    silhouette: Silhouette,
) -> Vec<Vec<bool>> {
    silhouette
        .views()
        .into_iter()
        .map(|direction| {
            crate::raster::render_mesh_ungrown(object, mesh, direction, size)
                .map(|maps| maps.stencil)
                .unwrap_or_default()
        })
        .collect()
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

/// A level of `object`'s chain with its own compact vertex array, each corner whose normal
/// is more than 60° off its triangle's given the triangle's ([`TURN_COSINE`]).
///
/// Where meshoptimizer folds a thin part onto one plane (the plant's 0.4 m walls, from
/// afar), the folded triangles keep corners of the faces at right angles to them, and
/// shading smoothly between those normals smears one face's light across another. A
/// board is drawn from the level, so its normal map would carry the smear; a turned
/// corner is a copy of the vertex with the triangle's normal. The viewer's LOD chain keeps
/// meshoptimizer's buffers (copies there slowed the plant's relief orbit on lavapipe,
/// README) and applies the same rule per pixel (the shader's `level_fs`).
fn compact(object: &PreparedObject, triangles: &[[u32; 3]], error: f64) -> Level {
    // Keyed by the full-mesh vertex and, for a turned corner, its (rounded) normal.
    let mut new_index: FxHashMap<(u32, Option<[i32; 3]>), u32> = FxHashMap::default();
    let mut vertices = Vec::new();
    let triangles = triangles
        .iter()
        .map(|&triangle| {
            let [a, b, c] = triangle.map(|v| object.vertices[v as usize].position);
            let face = (b - a).cross(c - a).normalize_or_zero();
            triangle.map(|v| {
                let mut vertex = object.vertices[v as usize];
                // A degenerate triangle (no face) covers no pixel: its corners stay.
                let turn = face != glam::Vec3::ZERO && vertex.normal.dot(face) < TURN_COSINE;
                if turn {
                    vertex.normal = face;
                }
                // Coplanar triangles share a turned corner (normals equal within 1e-4).
                let key = turn.then(|| (face * 1e4).round().as_ivec3().to_array());
                *new_index.entry((v, key)).or_insert_with(|| {
                    vertices.push(vertex);
                    (vertices.len() - 1) as u32
                })
            })
        })
        .collect();
    vertices.shrink_to_fit();
    Level {
        error,
        smallest_size: 0,
        vertices,
        triangles,
    }
}

/// A level's corner whose vertex normal is further than this (its cosine) from its
/// triangle's normal, 60°, is drawn with the triangle's ([`compact`]): a smooth surface's
/// coarse triangles stay well inside it, a fold is at right angles.
const TURN_COSINE: f32 = 0.5;

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// `n` small square leaves (two triangles each) scattered in a cube, and, if `trunk`,
    /// a large box through it.
    fn leaves(n: usize, trunk: bool) -> PreparedObject {
        let mut b = scene::ObjectBuilder::new("leaves");
        let mut state = 12345u64;
        let mut random = || {
            state = splitmix(state);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..n {
            let center = DVec3::new(random(), random(), random()) * 0.55;
            let u = DVec3::new(random(), random(), random()).normalize() * 0.01;
            let v = u.any_orthonormal_vector() * 0.01;
            // Corners centre ∓ u ∓ v: the leaf's tips at ±(u + v) and ±(v - u).
            scene::shapes::leaf(&mut b, center, u + v, v - u, [40, 120, 30, 255]);
        }
        if trunk {
            let half = DVec3::new(0.1, 1.0, 0.1);
            scene::shapes::cuboid(&mut b, DVec3::ZERO, half, 1, [90, 60, 40, 255]);
        }
        PreparedObject::new(&b.finish().0).unwrap()
    }

    #[test]
    fn many_small_parts_are_aggregate_detail_and_one_surface_is_not() {
        let aggregate = Aggregate::find(&leaves(1000, true)).expect("1000 leaves");
        assert_eq!(aggregate.parts.len(), 1000);
        assert!(aggregate.parts.iter().all(|p| p.len() == 2));
        assert_eq!(aggregate.large.len(), 12, "the trunk, a box, stays whole");
        // Too few parts to be a statistic.
        assert!(Aggregate::find(&leaves(100, false)).is_none());
        // One closed surface, split at its creases into several vertices per position.
        let mut b = scene::ObjectBuilder::new("box");
        scene::shapes::cuboid(&mut b, DVec3::ZERO, DVec3::ONE, 1, [1, 2, 3, 255]);
        assert!(Aggregate::find(&PreparedObject::new(&b.finish().0).unwrap()).is_none());
    }

    #[test]
    fn an_aggregate_level_keeps_a_nested_random_share_of_the_parts_with_their_area() {
        let object = leaves(4000, true);
        let aggregate = Aggregate::find(&object).unwrap();
        let area = |vertices: &[RenderVertex], triangles: &[[u32; 3]]| -> f64 {
            triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|v| vertices[v as usize].position.as_dvec3());
                    (b - a).cross(c - a).length() * 0.5
                })
                .sum()
        };
        let full = area(&object.vertices, &object.triangles);
        let mut previous: Option<Level> = None;
        for step in 1..=3 {
            let level = aggregate.level(&object, step).unwrap();
            assert_eq!(
                level.triangles.len(),
                12 + 2 * (4000 >> step),
                "step {step}"
            );
            let kept = area(&level.vertices, &level.triangles);
            assert!(
                (kept / full - 1.0).abs() < 0.03,
                "step {step}: area {kept} of {full}"
            );
            // Each level's leaves are among the finer level's (the same order, fewer).
            if let Some(previous) = &previous {
                // A leaf grows about the centre of its bounds, which stays put.
                let centers = |l: &Level| -> Vec<DVec3> {
                    l.triangles[12..]
                        .chunks(2)
                        .map(|leaf| {
                            let corners = leaf.iter().flatten();
                            scene::Aabb::from_points(
                                corners.map(|&v| l.vertices[v as usize].position.as_dvec3()),
                            )
                            .center()
                        })
                        .collect()
                };
                let (fine, coarse) = (centers(previous), centers(&level));
                for (f, c) in fine.iter().zip(&coarse) {
                    assert!((*f - *c).length() < 1e-5);
                }
            }
            previous = Some(level);
        }
    }

    #[test]
    fn grown_parts_stay_inside_the_bounding_sphere_that_frames_every_board() {
        // Leaves at the corners of the bounds, a tip pointing out along the diagonal: that
        // tip is the bounds' corner, on the bounding sphere, and grown about the leaf's centre
        // it would leave the sphere (a board's depth is z over that sphere: a worker's board
        // with depth below -1 is refused by the node as corrupt).
        let mut b = scene::ObjectBuilder::new("corner leaves");
        for i in 0..1024u64 {
            let corner = DVec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            let inside = (splitmix(i) >> 11) as f64 / (1u64 << 53) as f64;
            // Every other leaf at a corner, the rest inside.
            let center = corner * if i & 8 == 0 { 0.5 } else { 0.4 * inside };
            let tip = corner.normalize() * 0.02;
            scene::shapes::leaf(
                &mut b,
                center,
                tip,
                tip.any_orthonormal_vector() * 0.02,
                [40, 120, 30, 255],
            );
        }
        let object = PreparedObject::new(&b.finish().0).unwrap();
        let aggregate = Aggregate::find(&object).unwrap();
        let center = object.local_center;
        let radius = object.radius as f32 * (1.0 + 1e-6);
        assert!(
            object
                .vertices
                .iter()
                .all(|v| (v.position - center).length() <= radius)
        );
        for step in 1..=2 {
            let level = aggregate.level(&object, step).unwrap();
            let farthest = level
                .vertices
                .iter()
                .map(|v| (v.position - center).length())
                .fold(0.0, f32::max);
            assert!(farthest <= radius, "step {step}: {farthest} > {radius}");
        }
    }

    #[test]
    fn a_level_serves_from_the_smallest_checked_size_it_keeps_the_silhouette_at() {
        let tried = |largest: u32, from: u32| {
            let mut sizes = Vec::new();
            let found = smallest_passing(largest, |size| {
                sizes.push(size);
                size >= from
            });
            (found, sizes)
        };
        assert_eq!(tried(256, 0), (Some(32), vec![32]));
        assert_eq!(tried(256, 64), (Some(64), vec![32, 64]));
        // Doubling stops at the largest size it would be chosen for, which is tried too.
        assert_eq!(tried(100, 100), (Some(100), vec![32, 64, 100]));
        assert_eq!(tried(100, 101), (None, vec![32, 64, 100]));
        assert_eq!(tried(32, 64), (None, vec![32]));
    }

    #[test]
    fn a_mesh_level_that_loses_the_silhouette_fails_its_check() {
        // meshoptimizer's first halving of separate leaves collapses whole leaves and calls
        // it a small error (how far the surface moved, not what vanished).
        let object = leaves(20_000, false);
        let raw = LodChain::build(&object.vertices, &object.triangles);
        let pixel_32 = 2.0 * object.radius / 32.0;
        assert!(
            raw.errors[1] <= MAX_ERROR_PIXELS * pixel_32,
            "{:?}",
            raw.errors
        );
        let level = compact(&object, &raw.levels[0], raw.errors[1]);
        let check = |silhouette| {
            check_level(
                &object,
                &mut FxHashMap::default(),
                level.clone(),
                silhouette,
            )
        };
        assert!(check(Silhouette::Curve).is_none());
        // Judged as a statistic it still fails: it loses coverage, not only pixel order.
        assert!(check(Silhouette::Statistic).is_none());
    }

    #[test]
    fn a_wall_folded_onto_one_plane_is_lit_by_its_triangles_not_its_old_faces() {
        // Two walls as the plant builds them (0.4 thick, 12 high, 40 long): from afar a
        // level folds each wall's thickness away, and its triangles then keep corners of the
        // top, bottom and ends, at right angles to them.
        let mut b = scene::ObjectBuilder::new("walls");
        for side in [-1.0, 1.0] {
            let center = DVec3::new(side * 19.6, 6.0, 0.0);
            let half = DVec3::new(0.2, 6.0, 20.0);
            scene::shapes::cuboid(&mut b, center, half, 2, [9, 9, 9, 255]);
        }
        let object = PreparedObject::new(&b.finish().0).unwrap();
        let chain = LodChain::build(&object.vertices, &object.triangles);
        let off = |vertices: &[RenderVertex], triangles: &[[u32; 3]]| {
            let mut off = 0;
            for triangle in triangles {
                let [a, b, c] = triangle.map(|v| vertices[v as usize].position);
                let face = (b - a).cross(c - a).normalize_or_zero();
                off += triangle
                    .iter()
                    .filter(|&&v| vertices[v as usize].normal.dot(face) < TURN_COSINE)
                    .count();
            }
            off
        };
        let folded = chain.errors.len() - 2;
        assert!(chain.errors[folded + 1] > 0.2, "{:?}", chain.errors);
        assert!(
            off(&object.vertices, &chain.levels[folded]) > 0,
            "meshoptimizer folds it"
        );
        for (level, error) in chain.levels.iter().zip(&chain.errors[1..]) {
            let level = compact(&object, level, *error);
            assert_eq!(off(&level.vertices, &level.triangles), 0);
        }
        // A smooth surface's levels keep their corners down to a few hundred triangles (a
        // ball of a few dozen has corners more than 60° off): one vertex per full-mesh vertex.
        let mut b = scene::ObjectBuilder::new("ball");
        scene::shapes::sphere(&mut b, DVec3::ZERO, 1.0, 64, [9, 9, 9, 255]);
        let ball = PreparedObject::new(&b.finish().0).unwrap();
        let chain = LodChain::build(&ball.vertices, &ball.triangles);
        let fine: Vec<_> = chain.levels.iter().filter(|l| l.len() >= 200).collect();
        assert!(fine.len() >= 3);
        for level in fine {
            let compacted = compact(&ball, level, 0.0);
            let used: std::collections::HashSet<u32> = level.iter().flatten().copied().collect();
            assert_eq!(compacted.vertices.len(), used.len());
        }
    }
}

//! The software rasteriser: an object in, the four reliefboard maps out.
//!
//! The object is scaled into the unit sphere and seen orthographically along the request's
//! direction. One pass over the triangles fills a depth buffer and a triangle-id buffer
//! (a *visibility buffer*); a second pass over the pixels interpolates colour and normal of
//! the one triangle each pixel shows. The first pass touches every triangle, the second only
//! visible pixels, so overdraw costs a depth test, not an attribute fetch: Süß needed four
//! GPU passes for the four maps, this needs one pass over the triangles.
//!
//! Coverage is exact: vertices snap to 1/256 pixel, edge functions are evaluated in integers,
//! and pixel centres on an edge belong to exactly one of the triangles sharing it (the
//! top-left rule), so shared edges have neither cracks nor double hits. Depth is affine in
//! screen space for an orthographic view, so a plane equation interpolates it exactly.
//!
//! Threads: triangles are split into one chunk per thread, each chunk rasterised into its own
//! buffers, and the buffers merged by depth. Boards are small (at most `p²` pixels) while
//! objects have hundreds of thousands of mostly sub-pixel triangles, so splitting the
//! triangles balances better than splitting the image into tiles. Projection and the
//! per-pixel pass split their work over the same threads.
//!
//! Where a whole request's time goes, stage by stage, `backend bench` prints ([`Stages`]): on
//! one thread (dec7993) for the dragon's level at 256² the triangle pass 48%, the per-pixel
//! pass and growing at cuts 26%, encoding 26%; for a forest tree's level at 64² (25,328
//! mostly sub-pixel triangles) the triangle pass 72%, projection 11%. The triangle pass is
//! bound by its instructions (about 300 for a triangle whose box holds a pixel centre) and,
//! on foliage, by branches it cannot predict (see [`rasterise_one`]).

use std::hint::select_unpredictable;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::error::RenderError;
use crate::object::{MeshRef, PreparedObject};

/// Sub-pixel precision: coordinates are snapped to 1/256 pixel.
const SUBPIXEL_BITS: i64 = 8;
const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;
/// The id of "no triangle" in the visibility buffer.
const NO_TRIANGLE: u32 = u32::MAX;

/// Rounds half to even, exactly like `f32::round_ties_even`, for |x| < 2²²: adding and
/// subtracting 1.5·2²³ leaves no fraction bits. `round_ties_even` itself is a libm call on
/// x86-64 without SSE4.1 (Rust's baseline), which cost 6% of a board.
#[inline(always)]
fn round_even(x: f32) -> f32 {
    (x + ROUNDING_MAGIC) - ROUNDING_MAGIC
}

/// 1.5·2²³: any |x| < 2²² added to it lands in [2²³, 2²⁴), where an f32 has no fraction bits.
const ROUNDING_MAGIC: f32 = 12_582_912.0;

/// `round_even(x) as i32` for |x| < 2²², read off the sum's mantissa instead of converted:
/// no saturating conversion, which took half the projection's instructions.
#[inline(always)]
fn round_even_to_i32(x: f32) -> i32 {
    (x + ROUNDING_MAGIC).to_bits() as i32 - ROUNDING_MAGIC.to_bits() as i32
}

/// `select_unpredictable` for an f32, through its bits: x86-64's baseline (no SSE4.1 blend)
/// turns a floating-point select into a branch, which on foliage guesses wrong half the time.
#[inline(always)]
fn select_float(condition: bool, if_true: f32, if_false: f32) -> f32 {
    f32::from_bits(select_unpredictable(
        condition,
        if_true.to_bits(),
        if_false.to_bits(),
    ))
}

/// Where the maps sit in the world: the view basis and the unit sphere's placement.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Basis {
    /// World position of the sphere's centre (the object's bounds centre).
    pub center: DVec3,
    /// Radius of the sphere (half the object's bounds diagonal), in world units.
    pub radius: f64,
    /// Image x axis in world space (unit).
    pub right: DVec3,
    /// Image y axis in world space (unit).
    pub up: DVec3,
    /// Viewing direction in world space (unit): from the viewer to the object.
    pub forward: DVec3,
}

impl Basis {
    /// The basis for looking along `direction` at `object`, oriented as a camera would be
    /// ([`scene::view_axes`]). Any direction works, straight up and down included.
    pub fn new(direction: DVec3, center: DVec3, radius: f64) -> Result<Basis, RenderError> {
        if !direction.is_finite() || direction.length_squared() < 1e-24 {
            return Err(RenderError::BadDirection(direction.to_array()));
        }
        let forward = direction.normalize();
        let (right, up) = scene::view_axes(forward);
        Ok(Basis {
            center,
            radius,
            right,
            up,
            forward,
        })
    }

    /// Checks what a board received from elsewhere claims: a finite centre, a finite
    /// positive radius, and unit, orthogonal, right-handed axes (`right × up = -forward`)
    /// within `1e-6`. A board that fails would draw garbage or NaN on the GPU.
    pub fn check(&self) -> Result<(), String> {
        const TOLERANCE: f64 = 1e-6;
        if !self.center.is_finite() {
            return Err(format!("centre {} is not finite", self.center));
        }
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(format!(
                "radius {} is not a finite positive number",
                self.radius
            ));
        }
        let axes = [self.right, self.up, self.forward];
        if axes
            .iter()
            .any(|a| !a.is_finite() || (a.length() - 1.0).abs() > TOLERANCE)
        {
            return Err("an axis is not of unit length".into());
        }
        let orthogonal = self.right.dot(self.up).abs() <= TOLERANCE
            && self.right.dot(self.forward).abs() <= TOLERANCE
            && self.up.dot(self.forward).abs() <= TOLERANCE;
        if !orthogonal || (self.right.cross(self.up) + self.forward).length() > TOLERANCE {
            return Err("the axes are not an orthonormal right-handed basis".into());
        }
        Ok(())
    }

    /// A world point from map coordinates: `x`, `y` in [-1, 1] (right, up) and `z` in
    /// [-1, 1] along the view (-1 nearest).
    pub fn world_point(&self, x: f64, y: f64, z: f64) -> DVec3 {
        self.center + (self.right * x + self.up * y + self.forward * z) * self.radius
    }
}

/// The four maps of one view, `size × size` pixels, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Maps {
    /// Side in pixels.
    pub size: u32,
    /// Where the maps sit in the world.
    pub basis: Basis,
    /// View-space depth `z` in [-1, 1] of each covered pixel (-1 nearest); `NaN` uncovered.
    /// The *distance* map of Süß is `(1 - z) / 2`: higher is nearer.
    pub depth: Vec<f32>,
    /// Whether the object covers the pixel.
    pub stencil: Vec<bool>,
    /// Unlit colour, RGBA8 (sRGB), transparent where uncovered.
    pub color: Vec<[u8; 4]>,
    /// Object-space unit normal facing the viewer, zero where uncovered.
    pub normal: Vec<[f32; 3]>,
}

impl Maps {
    /// The distance map value (`(1 - z) / 2`, higher is nearer) of pixel `index`, 0 where
    /// uncovered.
    pub fn distance(&self, index: usize) -> f32 {
        if self.stencil[index] {
            (1.0 - self.depth[index]) * 0.5
        } else {
            0.0
        }
    }

    /// Number of covered pixels.
    pub fn covered(&self) -> usize {
        self.stencil.iter().filter(|s| **s).count()
    }
}

/// Triangles drawn plus pixels of a board below which splitting it over threads loses: handing
/// a board to a pool and merging the threads' buffers cost more than a second thread saves
/// (`backend bench` prints both, one thread and split, for each board side).
pub const SPLIT_WORK: usize = 16 * 1024;

/// How many of `available` threads a board drawn from `mesh` at `size` is worth splitting over,
/// while `other_boards` wait for or use the same threads: all of them for a large board on
/// an otherwise idle worker (its latency is what the viewer waits for), else one, so that a
/// busy worker spends its cores on whole boards rather than on handing work around.
pub fn threads_worth(mesh: MeshRef<'_>, size: u32, available: usize, other_boards: usize) -> usize {
    let work = mesh.triangles.len() + (size as usize).pow(2);
    if other_boards == 0 && work >= SPLIT_WORK {
        available.max(1)
    } else {
        1
    }
}

/// Renders `object` seen along `direction` into `size × size` maps using up to `threads`
/// threads (of the current rayon pool), from the coarsest of its levels the map's pixels
/// cannot tell from the full mesh ([`PreparedObject::mesh_for_size`]).
pub fn render_maps(
    object: &PreparedObject,
    direction: DVec3,
    size: u32,
    threads: usize,
) -> Result<Maps, RenderError> {
    render_mesh(object, object.mesh_for_size(size), direction, size, threads)
}

/// Renders `mesh` (the full mesh or one of `object`'s levels), framed by `object`'s bounding
/// sphere, into `size × size` maps.
pub fn render_mesh(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    direction: DVec3,
    size: u32,
    threads: usize,
) -> Result<Maps, RenderError> {
    render(object, mesh, direction, size, threads, true).map(|(maps, _)| maps)
}

/// As [`render_mesh`], with the time each stage took (`backend bench` reports them).
pub fn render_mesh_timed(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    direction: DVec3,
    size: u32,
    threads: usize,
) -> Result<(Maps, Stages), RenderError> {
    render(object, mesh, direction, size, threads, true)
}

/// The time one render spent in each of its stages, in the order they run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Stages {
    /// The request checked and the vertices projected to the screen.
    pub projection: Duration,
    /// The triangle pass: depth and triangle-id buffers (and their merge, where split).
    pub triangle_pass: Duration,
    /// The board grown past cuts.
    pub grow_at_cuts: Duration,
    /// The per-pixel pass: colour and normal of the triangle each pixel shows.
    pub per_pixel_pass: Duration,
}

impl std::ops::AddAssign for Stages {
    fn add_assign(&mut self, other: Stages) {
        self.projection += other.projection;
        self.triangle_pass += other.triangle_pass;
        self.grow_at_cuts += other.grow_at_cuts;
        self.per_pixel_pass += other.per_pixel_pass;
    }
}

/// As [`render_mesh`], without growing the board past cuts: the mesh's own silhouette, which
/// a simplified level is checked against the full mesh's by (what grows depends on which
/// cut vertices a level kept, not on how well it keeps the shape).
pub(crate) fn render_mesh_ungrown(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    direction: DVec3,
    size: u32,
) -> Result<Maps, RenderError> {
    render(object, mesh, direction, size, 1, false).map(|(maps, _)| maps)
}

fn render(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    direction: DVec3,
    size: u32,
    threads: usize,
    grow: bool,
) -> Result<(Maps, Stages), RenderError> {
    let threads = threads.max(1);
    // Four clock reads a board (well under a microsecond against a tenth of a millisecond or
    // more): every render is timed rather than keeping a second, timed copy of this one.
    let start = Instant::now();
    let (basis, screen) = setup(object, mesh, direction, size, threads)?;
    let projected = Instant::now();
    let pixels = (size * size) as usize;
    let chunks = threads.min(mesh.triangles.len().max(1));
    let chunk_len = mesh.triangles.len().div_ceil(chunks).max(1);
    let visibility = |(chunk, triangles): (usize, &[[u32; 3]])| {
        let mut depth = vec![f32::INFINITY; pixels];
        let mut ids = vec![NO_TRIANGLE; pixels];
        rasterise(
            &screen,
            triangles,
            (chunk * chunk_len) as u32,
            size,
            |at, z, id, hit| {
                // Selects, not a branch: on foliage whether a hit is nearer is a coin toss.
                // The id's is a conditional move; the compiler still turns the depth's back
                // into a branch (perf's annotation of e50b6a4), and depths kept as ordered
                // integers, which avoid it, were slower (README, "not kept").
                let nearer = hit & (z < depth[at]);
                depth[at] = select_float(nearer, z, depth[at]);
                ids[at] = select_unpredictable(nearer, id, ids[at]);
            },
        );
        (depth, ids)
    };
    // One thread runs on the caller's, without rayon: a small board costs less than handing
    // work to a pool.
    let buffers: Vec<(Vec<f32>, Vec<u32>)> = if threads == 1 {
        vec![visibility((0, mesh.triangles))]
    } else {
        mesh.triangles
            .par_chunks(chunk_len)
            .enumerate()
            .map(visibility)
            .collect()
    };
    let (mut depth, mut ids) = merge(buffers, pixels);
    let drawn = Instant::now();
    if grow {
        grow_seams(
            mesh,
            &screen,
            basis.forward.as_vec3(),
            size,
            &mut depth,
            &mut ids,
        );
    }
    let grown = Instant::now();
    let maps = resolve(mesh, &basis, &screen, size, depth, ids, threads);
    let stages = Stages {
        projection: projected - start,
        triangle_pass: drawn - projected,
        grow_at_cuts: grown - drawn,
        per_pixel_pass: grown.elapsed(),
    };
    Ok((maps, stages))
}

/// A vertex in screen space: fixed-point pixel coordinates and view depth, packed so one
/// cache line serves a triangle's corner.
#[derive(Clone, Copy)]
struct ScreenVertex {
    x: i32,
    y: i32,
    z: f32,
}

/// How many triangles cover each pixel centre, ignoring depth: for testing the fill rule
/// (a closed mesh seen from outside covers each centre inside its silhouette exactly twice,
/// front and back; an open flat mesh exactly once).
#[doc(hidden)]
pub fn coverage_counts(
    object: &PreparedObject,
    direction: DVec3,
    size: u32,
) -> Result<Vec<u32>, RenderError> {
    let mesh = object.full_mesh();
    let (_, screen) = setup(object, mesh, direction, size, 1)?;
    let mut counts = vec![0u32; (size * size) as usize];
    rasterise(&screen, mesh.triangles, 0, size, |at, _, _, hit| {
        counts[at] += hit as u32
    });
    Ok(counts)
}

/// Checks a request and projects the object for it on up to `threads` threads.
fn setup(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    direction: DVec3,
    size: u32,
    threads: usize,
) -> Result<(Basis, Screen), RenderError> {
    if size == 0 || size > crate::MAX_MAP_SIZE {
        return Err(RenderError::BadResolution {
            size,
            max: crate::MAX_MAP_SIZE,
        });
    }
    let basis = Basis::new(direction, object.world_center(), object.radius)?;
    let screen = project(object, mesh, &basis, size, threads);
    Ok((basis, screen))
}

/// Vertices in screen space.
struct Screen {
    vertices: Vec<ScreenVertex>,
}

fn project(
    object: &PreparedObject,
    mesh: MeshRef<'_>,
    basis: &Basis,
    size: u32,
    threads: usize,
) -> Screen {
    // Everything relative to the object's bounds centre, in the object's local frame, so a
    // far-away object keeps its precision: only differences of nearby points appear.
    let scale = 1.0 / object.radius;
    let axes = [basis.right, basis.up, basis.forward].map(|a| (a * scale).as_vec3());
    let center = object.local_center;
    let half = size as f32 * 0.5 * SUBPIXEL as f32;
    // Coordinates stay below 2²² (MAX_MAP_SIZE · SUBPIXEL = 2²⁰), as round_even needs.
    let to_screen = |v: &crate::object::RenderVertex| {
        let q: Vec3 = v.position - center;
        let (sx, sy, sz) = (q.dot(axes[0]), q.dot(axes[1]), q.dot(axes[2]));
        ScreenVertex {
            x: round_even_to_i32((sx + 1.0) * half),
            y: round_even_to_i32((1.0 - sy) * half),
            z: sz,
        }
    };
    // In parallel on the caller's pool when the render has more than one thread.
    let vertices = if threads > 1 {
        mesh.vertices
            .par_iter()
            .with_min_len(16 * 1024)
            .map(to_screen)
            .collect()
    } else {
        mesh.vertices.iter().map(to_screen).collect()
    };
    Screen { vertices }
}

/// The edge function of the edge a→b at point p: positive on the inside of a triangle whose
/// signed area (same formula) is positive.
#[inline]
fn orient(ax: i64, ay: i64, bx: i64, by: i64, px: i64, py: i64) -> i64 {
    (bx - ax) * (py - ay) - (by - ay) * (px - ax)
}

/// The top-left rule for a triangle of positive `orient` area in y-down screen space (its
/// vertices run clockwise on screen): a pixel centre exactly on an edge is inside only for a
/// top edge (horizontal, running right, the interior below it) or a left edge (running up,
/// the interior to its right). Other edges get a bias of -1, which turns `>= 0` into `> 0`.
#[inline]
fn bias(ax: i64, ay: i64, bx: i64, by: i64) -> i64 {
    // Non-short-circuit operators: an edge's direction is a coin toss a branch would lose.
    let top = (ay == by) & (bx > ax);
    let left = by < ay;
    (top | left) as i64 - 1
}

/// Calls `covered(pixel, z, triangle, true)` for every pixel centre a triangle covers, and
/// `covered(pixel, _, triangle, false)` for some it does not (a small triangle's centres are
/// all visited, without branching on which it covers). The renderer passes a depth test;
/// tests pass a counter to check the fill rule.
#[inline(always)]
fn rasterise(
    screen: &Screen,
    triangles: &[[u32; 3]],
    first_id: u32,
    size: u32,
    mut covered: impl FnMut(usize, f32, u32, bool),
) {
    let max = size as i32 - 1;
    // The first and last pixel centre (i + 1/2, in subpixels) at or after `min` / at or
    // before `max`: floor divisions by 256 as arithmetic shifts, in i32 (coordinates stay
    // below 2²⁰).
    let first_centre = |min: i32| (min + (SUBPIXEL / 2 - 1) as i32) >> SUBPIXEL_BITS;
    let last_centre = |max: i32| (max - (SUBPIXEL / 2) as i32) >> SUBPIXEL_BITS;
    let vertices = &screen.vertices;
    // Pixel centres inside a triangle's bounding box, clamped to the image (empty where
    // x0 > x1 or y0 > y1).
    let centres = |[va, vb, vc]: [ScreenVertex; 3]| {
        let x0 = first_centre(va.x.min(vb.x).min(vc.x)).max(0);
        let x1 = last_centre(va.x.max(vb.x).max(vc.x)).min(max);
        let y0 = first_centre(va.y.min(vb.y).min(vc.y)).max(0);
        let y1 = last_centre(va.y.max(vb.y).max(vc.y)).min(max);
        [x0, x1, y0, y1]
    };
    // Most triangles of a detailed object are smaller than a pixel and hold no centre. A
    // first tight loop over a block finds the few that do, with their boxes; the full setup
    // runs only for them (one loop for both kept the setup's state in registers and spilled
    // the test's).
    const BLOCK: usize = 256;
    let mut candidates = [(0u16, [0i32; 4]); BLOCK];
    for (block_index, block) in triangles.chunks(BLOCK).enumerate() {
        let mut found = 0;
        for (offset, triangle) in block.iter().enumerate() {
            let [x0, x1, y0, y1] = centres(triangle.map(|v| vertices[v as usize]));
            candidates[found] = (offset as u16, [x0, x1, y0, y1]);
            found += (x0 <= x1 && y0 <= y1) as usize;
        }
        for &(offset, bounds) in &candidates[..found] {
            let offset = block_index * BLOCK + offset as usize;
            let [va, vb, vc] = triangles[offset].map(|v| vertices[v as usize]);
            rasterise_one(
                va,
                vb,
                vc,
                bounds.map(i64::from),
                first_id + offset as u32,
                size,
                &mut covered,
            );
        }
    }
}

/// Rasterises one triangle whose bounding box holds pixel centres `x0..=x1`, `y0..=y1`.
///
/// The setup does not branch on the triangle, nor does a box of at most 2 × 2 centres: which
/// way a leaf faces, which edges are top-left and which centres a small triangle covers are
/// coin tosses that a branch predictor lost about three times a triangle on a tree (found
/// with callgrind's branch simulation), each costing more than the selects and the few
/// centres tested in vain that replace it.
#[inline(always)]
fn rasterise_one(
    va: ScreenVertex,
    vb: ScreenVertex,
    vc: ScreenVertex,
    [x0, x1, y0, y1]: [i64; 4],
    id: u32,
    size: u32,
    covered: &mut impl FnMut(usize, f32, u32, bool),
) {
    let (ax, ay) = (va.x as i64, va.y as i64);
    let area = orient(ax, ay, vb.x as i64, vb.y as i64, vc.x as i64, vc.y as i64);
    // Two-sided: seen from behind, the same triangle with the other winding.
    let flip = area < 0;
    let pick = |flipped: i32, unflipped: i32| select_unpredictable(flip, flipped, unflipped) as i64;
    let (bx, by) = (pick(vc.x, vb.x), pick(vc.y, vb.y));
    let (cx, cy) = (pick(vb.x, vc.x), pick(vb.y, vc.y));
    let zb = select_float(flip, vc.z, vb.z) - va.z;
    let zc = select_float(flip, vb.z, vc.z) - va.z;
    // Edge functions at the first centre, and their steps.
    let biases = [
        bias(bx, by, cx, cy),
        bias(cx, cy, ax, ay),
        bias(ax, ay, bx, by),
    ];
    let (px, py) = (x0 * SUBPIXEL + SUBPIXEL / 2, y0 * SUBPIXEL + SUBPIXEL / 2);
    let first = [
        orient(bx, by, cx, cy, px, py) + biases[0],
        orient(cx, cy, ax, ay, px, py) + biases[1],
        orient(ax, ay, bx, by, px, py) + biases[2],
    ];
    let step_x = [by - cy, cy - ay, ay - by].map(|d| d * SUBPIXEL);
    let step_y = [cx - bx, ax - cx, bx - ax].map(|d| d * SUBPIXEL);
    let add = |w: [i64; 3], step: [i64; 3]| [w[0] + step[0], w[1] + step[1], w[2] + step[2]];
    let inside = |w: [i64; 3]| (w[0] | w[1] | w[2]) >= 0;
    // An edge-on triangle, or one collapsed by snapping, covers no centre without a test of
    // its own: its edge functions sum to its area, 0, so one is negative, or all are 0 and
    // one edge (running down or left) has a bias of -1. Its plane, infinite, is never used.
    // Depth as a plane: z = z_a + (w_b z_b + w_c z_c - (w_b + w_c) z_a) with barycentric
    // weights w = edge / area, affine in x and y: its value at the first centre, and steps.
    let inv_area = 1.0 / area.abs() as f32;
    let z_at = |w: [i64; 3], bias: [i64; 3]| {
        ((w[1] - bias[1]) as f32 * zb + (w[2] - bias[2]) as f32 * zc) * inv_area
    };
    let z = va.z + z_at(first, biases);
    let (z_x, z_y) = (z_at(step_x, [0; 3]), z_at(step_y, [0; 3]));
    let line = y0 as usize * size as usize + x0 as usize;
    if x1 - x0 <= 1 && y1 - y0 <= 1 {
        // At most 2 × 2 centres (at 64 pixels nearly every leaf of a tree, most holding
        // none): all four, unrolled; one past the box stands on the box's last, in the image.
        let (wide, tall) = (x1 > x0, y1 > y0);
        let (next_x, next_y) = (wide as usize, tall as usize * size as usize);
        let right = add(first, step_x);
        let (below, below_right) = (add(first, step_y), add(right, step_y));
        covered(line, z, id, inside(first));
        covered(line + next_x, z + z_x, id, wide & inside(right));
        covered(line + next_y, z + z_y, id, tall & inside(below));
        let corner = wide & tall & inside(below_right);
        covered(line + next_x + next_y, z + z_x + z_y, id, corner);
        return;
    }
    // A larger triangle covers runs of centres, which a branch predicts well enough, and
    // skips the depth test at the centres it misses. Counted loops over offsets: an
    // inclusive range's bookkeeping cost more than a one-pixel-wide row.
    let (width, height) = ((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize);
    let (mut row, mut row_z, mut row_line) = (first, z, line);
    for _ in 0..height {
        let (mut w, mut z) = (row, row_z);
        for x in 0..width {
            if inside(w) {
                covered(row_line + x, z, id, true);
            }
            w = add(w, step_x);
            z += z_x;
        }
        row = add(row, step_y);
        row_z += z_y;
        row_line += size as usize;
    }
}

/// Grows the board by one pixel past every edge where the object was cut from a larger mesh
/// (an edge between two [`seam`](crate::object::RenderVertex::seam) vertices): each
/// uncovered pixel whose centre lies within a pixel of such an edge of a neighbouring
/// pixel's triangle shows that triangle, at the depth of its plane extended there. Boards of
/// neighbouring pieces are drawn on different texel grids from different directions, and a
/// stencil edge falls up to half a texel from the true cut on each board: without overlap
/// the viewer sees through the crack between them. The mesh's own outline stays exact.
fn grow_seams(
    mesh: MeshRef<'_>,
    screen: &Screen,
    forward: Vec3,
    size: u32,
    depth: &mut [f32],
    ids: &mut [u32],
) {
    let seam = |v: u32| mesh.vertices[v as usize].seam;
    // Whether triangle `id` has a cut edge and faces the view enough to grow (asked once per
    // run of pixels showing the same triangle).
    let may_grow = |id: u32| {
        let corners = mesh.triangles[id as usize];
        if corners.iter().filter(|&&v| seam(v)).count() < 2 {
            return false;
        }
        let [a, b, c] = corners.map(|v| mesh.vertices[v as usize].position);
        (b - a).cross(c - a).normalize_or_zero().dot(forward).abs() >= MIN_SEAM_FACING
    };
    let pixel_of = |v: u32| {
        let s = screen.vertices[v as usize];
        glam::Vec2::new(s.x as f32, s.y as f32) / SUBPIXEL as f32
    };
    // Whether the centre of pixel `at` lies within a pixel of one of triangle `id`'s cut edges.
    let near_cut = |id: u32, at: usize| {
        let corners = mesh.triangles[id as usize];
        let centre = glam::Vec2::new(
            (at as u32 % size) as f32 + 0.5,
            (at as u32 / size) as f32 + 0.5,
        );
        (0..3).any(|k| {
            let (u, v) = (corners[k], corners[(k + 1) % 3]);
            seam(u) && seam(v) && segment_distance(centre, pixel_of(u), pixel_of(v)) <= 1.0
        })
    };
    let n = size as i64;
    // A pixel in view-depth units ([-1, 1] across the board): the extended plane of a
    // sliver triangle is kept within two of its neighbour's depth.
    let pixel = 2.0 / size as f32;
    // From each silhouette pixel of a triangle that may grow into its uncovered neighbours
    // (measured on the dragon's 22 pieces: 0.02 ms of a 0.09 ms board at 64 pixels, 0.18 of
    // 0.90 ms at 256, mostly the cache misses of fetching those triangles' corners).
    let mut grown: Vec<(usize, f32, u32)> = Vec::new();
    let mut last: (u32, bool) = (NO_TRIANGLE, false);
    for at in silhouette_pixels(ids, size as usize) {
        let id = ids[at];
        if id != last.0 {
            last = (id, may_grow(id));
        }
        if !last.1 {
            continue;
        }
        let (x, y) = ((at as u32 % size) as i64, (at as u32 / size) as i64);
        for (dx, dy) in NEIGHBOURS {
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0 || ny < 0 || nx >= n || ny >= n {
                continue;
            }
            let to = (ny * n + nx) as usize;
            if ids[to] != NO_TRIANGLE || !near_cut(id, to) {
                continue;
            }
            let z = plane_depth(mesh, screen, size, id as usize, to)
                .clamp(depth[at] - 2.0 * pixel, depth[at] + 2.0 * pixel)
                .clamp(-1.0, 1.0);
            grown.push((to, z, id));
        }
    }
    // A pixel reached from several triangles shows the nearest.
    grown.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
    grown.dedup_by_key(|g| g.0);
    for (at, z, id) in grown {
        depth[at] = z;
        ids[at] = id;
    }
}

/// The covered pixels with an uncovered one among their eight neighbours, in pixel order.
/// Found 64 pixels at a time on bit rows, so a board without cuts pays a few bit operations
/// per pixel, not a look at each covered pixel's triangle.
fn silhouette_pixels(ids: &[u32], size: usize) -> Vec<usize> {
    let words = size.div_ceil(64);
    // Per row, a bit per uncovered pixel (none beyond the image).
    let mut open = vec![0u64; size * words];
    for (y, row) in ids.chunks_exact(size).enumerate() {
        for (x, &id) in row.iter().enumerate() {
            open[y * words + x / 64] |= ((id == NO_TRIANGLE) as u64) << (x % 64);
        }
    }
    // Per row, a bit per pixel with an uncovered pixel at x - 1, x or x + 1 in that row.
    let mut near = vec![0u64; size * words];
    for y in 0..size {
        let row = &open[y * words..(y + 1) * words];
        for w in 0..words {
            let from_left = row[w] << 1 | if w > 0 { row[w - 1] >> 63 } else { 0 };
            let from_right = row[w] >> 1 | if w + 1 < words { row[w + 1] << 63 } else { 0 };
            near[y * words + w] = row[w] | from_left | from_right;
        }
    }
    let mut pixels = Vec::new();
    for y in 0..size {
        for w in 0..words {
            let mut around = near[y * words + w];
            if y > 0 {
                around |= near[(y - 1) * words + w];
            }
            if y + 1 < size {
                around |= near[(y + 1) * words + w];
            }
            let in_image = match size - w * 64 {
                64.. => u64::MAX,
                left => (1 << left) - 1,
            };
            let mut bits = around & !open[y * words + w] & in_image;
            while bits != 0 {
                pixels.push(y * size + w * 64 + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
    }
    pixels
}

/// The eight neighbours of a pixel.
const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, 0),
    (1, 0),
    (0, -1),
    (0, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (1, 1),
];

/// Distance from `p` to the segment from `a` to `b`.
fn segment_distance(p: glam::Vec2, a: glam::Vec2, b: glam::Vec2) -> f32 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
    p.distance(a + ab * t)
}

/// A cut's triangle grows only where it faces the view within 60°: where a cut meets the
/// mesh's outline its grazing triangles would grow past the silhouette (on the dragon's
/// stills, growing every cut triangle took silhouette error from 54 to 69 and gained
/// nothing; from 0.25 to 0.7, 0.5 did best: 27.79, 27.86, 27.70 dB).
const MIN_SEAM_FACING: f32 = 0.5;

/// The view depth of triangle `id`'s plane at the centre of pixel `at` (outside the
/// triangle too). The same barycentrics as [`shade`]'s, written out again on purpose: one
/// helper for both made every board 10% slower (the dragon's pieces at 256 pixels, 0.80
/// against 0.88 ms, alternated twice), `shade` being the per-pixel hot loop.
fn plane_depth(mesh: MeshRef<'_>, screen: &Screen, size: u32, id: usize, at: usize) -> f32 {
    let [sa, sb, sc] = mesh.triangles[id].map(|v| screen.vertices[v as usize]);
    let (px, py) = (
        ((at as u32 % size) as i64) * SUBPIXEL + SUBPIXEL / 2,
        ((at as u32 / size) as i64) * SUBPIXEL + SUBPIXEL / 2,
    );
    let (ax, ay, bx, by, cx, cy) = (
        sa.x as i64,
        sa.y as i64,
        sb.x as i64,
        sb.y as i64,
        sc.x as i64,
        sc.y as i64,
    );
    let inv_area = 1.0 / orient(ax, ay, bx, by, cx, cy) as f32;
    let wa = orient(bx, by, cx, cy, px, py) as f32 * inv_area;
    let wb = orient(cx, cy, ax, ay, px, py) as f32 * inv_area;
    sa.z * wa + sb.z * wb + sc.z * (1.0 - wa - wb)
}

/// Merges per-thread buffers: nearest depth wins, ties to the lower triangle id.
fn merge(mut buffers: Vec<(Vec<f32>, Vec<u32>)>, pixels: usize) -> (Vec<f32>, Vec<u32>) {
    let Some((mut depth, mut ids)) = buffers.pop() else {
        return (vec![f32::INFINITY; pixels], vec![NO_TRIANGLE; pixels]);
    };
    for (other_depth, other_ids) in buffers {
        for at in 0..pixels {
            let (z, id) = (other_depth[at], other_ids[at]);
            if z < depth[at] || (z == depth[at] && id < ids[at]) {
                depth[at] = z;
                ids[at] = id;
            }
        }
    }
    (depth, ids)
}

/// The per-pixel pass: colour and normal of the visible triangle at each pixel centre, on
/// up to `threads` threads. Pixels are visited in triangle order, so the triangle and vertex
/// data they read come nearly in memory order (measured on the dragon at 256²: 3.6 ms in
/// pixel order, cache misses on every corner).
fn resolve(
    mesh: MeshRef<'_>,
    basis: &Basis,
    screen: &Screen,
    size: u32,
    depth: Vec<f32>,
    ids: Vec<u32>,
    threads: usize,
) -> Maps {
    let pixels = (size * size) as usize;
    let mut visible: Vec<u64> = ids
        .iter()
        .enumerate()
        .filter(|(_, id)| **id != NO_TRIANGLE)
        .map(|(at, id)| (*id as u64) << 32 | at as u64)
        .collect();
    sort_by_triangle(&mut visible, mesh.triangles.len() as u32);
    let mut maps = Maps {
        size,
        basis: *basis,
        depth: vec![f32::NAN; pixels],
        stencil: vec![false; pixels],
        color: vec![[0; 4]; pixels],
        normal: vec![[0.0; 3]; pixels],
    };
    let mut put = |at: usize, color: [u8; 4], normal: [f32; 3]| {
        maps.depth[at] = depth[at];
        maps.stencil[at] = true;
        maps.color[at] = color;
        maps.normal[at] = normal;
    };
    let shade_key = |key: u64| {
        let (id, at) = ((key >> 32) as usize, (key & 0xffff_ffff) as usize);
        let (color, normal) = shade(mesh, screen, size, id, at);
        (at, color, normal)
    };
    if threads <= 1 {
        // One thread (a worker's render pool serves one board a thread): straight into the
        // maps, without the list the threads' results meet in.
        for &key in &visible {
            let (at, color, normal) = shade_key(key);
            put(at, color, normal);
        }
    } else {
        let chunk = visible.len().div_ceil(threads).max(1024);
        let texels: Vec<(usize, [u8; 4], [f32; 3])> = visible
            .par_chunks(chunk)
            .flat_map_iter(|keys| keys.iter().map(|&key| shade_key(key)))
            .collect();
        for (at, color, normal) in texels {
            put(at, color, normal);
        }
    }
    maps
}

/// Sorts `triangle << 32 | pixel` keys by triangle, keeping pixel order within one: a
/// least-significant-digit radix sort over the bytes the triangle ids use (three passes for
/// the dragon), several times faster than a comparison sort on a board's visible pixels.
fn sort_by_triangle(keys: &mut Vec<u64>, triangles: u32) {
    let mut scratch = vec![0u64; keys.len()];
    let mut shift = 32;
    while shift < 64 && (triangles as u64) >> (shift - 32) > 0 {
        let mut starts = [0usize; 256];
        for key in keys.iter() {
            starts[((key >> shift) & 0xff) as usize] += 1;
        }
        let mut total = 0;
        for start in starts.iter_mut() {
            (*start, total) = (total, total + *start);
        }
        for &key in keys.iter() {
            let digit = ((key >> shift) & 0xff) as usize;
            scratch[starts[digit]] = key;
            starts[digit] += 1;
        }
        std::mem::swap(keys, &mut scratch);
        shift += 8;
    }
}

/// Colour and viewer-facing normal of triangle `id` at the centre of pixel `at`.
#[inline]
fn shade(
    mesh: MeshRef<'_>,
    screen: &Screen,
    size: u32,
    id: usize,
    at: usize,
) -> ([u8; 4], [f32; 3]) {
    let [a, b, c] = mesh.triangles[id].map(|v| v as usize);
    let [sa, sb, sc] = [a, b, c].map(|v| screen.vertices[v]);
    let (px, py) = (
        ((at as u32 % size) as i64) * SUBPIXEL + SUBPIXEL / 2,
        ((at as u32 / size) as i64) * SUBPIXEL + SUBPIXEL / 2,
    );
    let area = orient(
        sa.x as i64,
        sa.y as i64,
        sb.x as i64,
        sb.y as i64,
        sc.x as i64,
        sc.y as i64,
    );
    let inv_area = 1.0 / area as f32;
    let wa = orient(sb.x as i64, sb.y as i64, sc.x as i64, sc.y as i64, px, py) as f32 * inv_area;
    let wb = orient(sc.x as i64, sc.y as i64, sa.x as i64, sa.y as i64, px, py) as f32 * inv_area;
    let wc = 1.0 - wa - wb;
    let [va, vb, vc] = [a, b, c].map(|v| &mesh.vertices[v]);
    let color: [u8; 4] = std::array::from_fn(|k| {
        let mix = va.color[k] as f32 * wa + vb.color[k] as f32 * wb + vc.color[k] as f32 * wc;
        round_even(mix).clamp(0.0, 255.0) as u8
    });
    // Counter-clockwise (front-facing) triangles have negative area in y-down screen
    // space; a positive one shows its back, so its normal turns to the viewer.
    let facing = if area > 0 { -1.0 } else { 1.0 };
    let normal = (va.normal * wa + vb.normal * wb + vc.normal * wc) * facing;
    let normal = normal.try_normalize().unwrap_or_else(|| {
        let (pa, pb, pc) = (va.position, vb.position, vc.position);
        (pb - pa).cross(pc - pa).normalize_or_zero() * facing
    });
    (color, normal.to_array())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_even_and_its_integer_are_round_ties_even_below_two_to_the_22() {
        let mut values = vec![0.0f32, 0.5, 1.5, 2.5, -0.5, -1.5, 0.49999997, 1_048_575.5];
        values.extend((0..10_000).map(|i| i as f32 * 0.37 - 1000.0));
        values.extend((0..1000).map(|i| (i as f32 + 0.5) * 1024.0));
        for x in values {
            assert_eq!(round_even(x), x.round_ties_even(), "{x}");
            assert_eq!(round_even_to_i32(x), x.round_ties_even() as i32, "{x}");
        }
    }

    #[test]
    fn sort_by_triangle_orders_by_triangle_then_pixel() {
        // Pixels in order, triangle ids scattered over three bytes.
        let mut keys: Vec<u64> = (0..5000u64)
            .map(|at| ((at * 7919) % 300_000) << 32 | at)
            .collect();
        let mut expected = keys.clone();
        expected.sort_unstable();
        sort_by_triangle(&mut keys, 300_000);
        assert_eq!(keys, expected);
    }
}

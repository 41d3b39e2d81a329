//! `--impostor octahedral`: the other thing a user with one machine would do, baked
//! multi-view impostors (Brucks' ImpostorBaker, Amplify Impostors). Each suitable object is
//! rendered once at load from `views x views` directions spread over the whole sphere by an
//! octahedral map, by the workers' own software rasteriser (colour, normal, depth), into one
//! atlas per object. A frame draws one camera-facing quad per far object; the fragment
//! shader finds the three baked views around the view direction, steps each view's lookup
//! once along the ray by its depth (parallax), blends them by barycentric weight and writes
//! depth. No workers.

use backend::PreparedObject;
use glam::DVec3;
use rayon::prelude::*;

use super::{DrawScene, FarField, Loading};
use crate::plan::Plan;
use crate::render::{DrawItem, GpuOctahedral, Renderer};

use crate::board::DrawnMaps;

/// Bytes per atlas texel: depth (f32), colour (RGBA8), normal (RGBA8 snorm).
pub const TEXEL_BYTES: u64 = 12;
/// The largest view side chosen automatically.
const MAX_VIEW_SIZE: u32 = 64;
/// The smallest view side chosen automatically.
const MIN_VIEW_SIZE: u32 = 8;

/// How the atlases are laid out.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OctahedralParams {
    /// Views per side of the octahedral grid (`views²` views per object).
    pub views: u32,
    /// Side of one view in texels.
    pub view_size: u32,
}

impl OctahedralParams {
    /// GPU bytes of one object's atlas.
    pub fn atlas_bytes(&self) -> u64 {
        let side = (self.views * self.view_size) as u64;
        side * side * TEXEL_BYTES
    }

    /// The view side for `objects` atlases of `views²` views within `budget_bytes`: the
    /// largest power of two up to 64 that fits, and never under 8.
    pub fn within_budget(views: u32, objects: usize, budget_bytes: u64) -> OctahedralParams {
        let mut view_size = MAX_VIEW_SIZE;
        while view_size > MIN_VIEW_SIZE
            && (OctahedralParams { views, view_size }).atlas_bytes() * objects as u64 > budget_bytes
        {
            view_size /= 2;
        }
        OctahedralParams { views, view_size }
    }
}

/// Octahedral encoding of a unit direction into `[-1, 1]²` (y up: the upper hemisphere fills
/// the inner diamond, the lower one the corners). The shader's `oct_encode` is the same.
pub fn encode(direction: DVec3) -> [f64; 2] {
    let n = direction / (direction.x.abs() + direction.y.abs() + direction.z.abs());
    if n.y < 0.0 {
        [(1.0 - n.z.abs()) * sign(n.x), (1.0 - n.x.abs()) * sign(n.z)]
    } else {
        [n.x, n.z]
    }
}

/// The unit direction of a point of `[-1, 1]²`: the inverse of [`encode`].
pub fn decode(u: f64, v: f64) -> DVec3 {
    let y = 1.0 - u.abs() - v.abs();
    let (x, z) = if y < 0.0 {
        ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v))
    } else {
        (u, v)
    };
    DVec3::new(x, y, z).normalize()
}

fn sign(x: f64) -> f64 {
    if x >= 0.0 { 1.0 } else { -1.0 }
}

/// The direction from the object towards the eye of view `(i, j)` of a `views`-sided grid:
/// grid points at `i / (views - 1)` across the square, so the corners and edges are views too.
pub fn view_direction(views: u32, i: u32, j: u32) -> DVec3 {
    let at = |k: u32| k as f64 / (views - 1).max(1) as f64 * 2.0 - 1.0;
    decode(at(i), at(j))
}

/// One object's baked views: tile `(i, j)` of the atlas, at texel `(i, j) * view_size`, is the
/// view from [`view_direction`]`(views, i, j)`, laid out as a board's maps.
#[derive(Debug, Clone)]
pub struct Atlas {
    /// The layout.
    pub params: OctahedralParams,
    /// World centre of the object's bounding sphere.
    pub center: DVec3,
    /// Its radius.
    pub radius: f64,
    /// View depth per texel (`board::UNCOVERED_DEPTH` where uncovered).
    pub depth: Vec<f32>,
    /// RGBA8 colour, alpha 0 where uncovered.
    pub color: Vec<[u8; 4]>,
    /// Normals as signed bytes.
    pub normal: Vec<[i8; 4]>,
}

impl Atlas {
    /// Side of the atlas in texels.
    pub fn side(&self) -> u32 {
        self.params.views * self.params.view_size
    }

    /// Renders every view of `object` with the software rasteriser (one thread per object:
    /// objects are baked in parallel).
    pub fn bake(
        object: &PreparedObject,
        params: OctahedralParams,
    ) -> Result<Atlas, backend::RenderError> {
        let side = (params.views * params.view_size) as usize;
        let s = params.view_size as usize;
        let mut atlas = Atlas {
            params,
            center: object.world_center(),
            radius: object.radius,
            depth: vec![crate::board::UNCOVERED_DEPTH; side * side],
            color: vec![[0; 4]; side * side],
            normal: vec![[0; 4]; side * side],
        };
        for j in 0..params.views {
            for i in 0..params.views {
                // The board's direction runs from the viewer to the object.
                let direction = -view_direction(params.views, i, j);
                let maps = backend::render_maps(object, direction, params.view_size, 1)?;
                let view = DrawnMaps::new(&maps);
                for row in 0..s {
                    let from = row * s;
                    let to = (j as usize * s + row) * side + i as usize * s;
                    atlas.depth[to..to + s].copy_from_slice(&view.depth[from..from + s]);
                    atlas.color[to..to + s].copy_from_slice(&view.color[from..from + s]);
                    atlas.normal[to..to + s].copy_from_slice(&view.normal[from..from + s]);
                }
            }
        }
        Ok(atlas)
    }
}

/// The octahedral far field: each far object as one quad over its baked atlas.
pub struct OctahedralField {
    params: OctahedralParams,
    /// Per object, its atlas on the GPU (suitable objects only).
    impostors: Vec<Option<GpuOctahedral>>,
}

impl OctahedralField {
    /// Atlases of layout `params`, baked at load.
    pub fn new(params: OctahedralParams) -> OctahedralField {
        OctahedralField {
            params,
            impostors: Vec::new(),
        }
    }
}

impl FarField for OctahedralField {
    fn load(
        &mut self,
        renderer: &Renderer,
        batch: Vec<Loading<'_>>,
    ) -> Result<(), backend::RenderError> {
        let params = self.params;
        let atlases: Vec<Atlas> = batch
            .par_iter()
            .map(|loading| Atlas::bake(loading.object, params))
            .collect::<Result<_, _>>()?;
        for (loading, atlas) in batch.iter().zip(&atlases) {
            let id = loading.id as usize;
            if id >= self.impostors.len() {
                self.impostors.resize_with(id + 1, || None);
            }
            self.impostors[id] = Some(renderer.upload_octahedral(atlas));
        }
        Ok(())
    }

    fn no_boards_reason(&self) -> Option<&str> {
        Some("--impostor octahedral: baked impostors, no workers")
    }

    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>) {
        for (id, level) in plan.fallback_with_levels() {
            items.push(match self.impostors.get(id as usize) {
                Some(Some(impostor)) => DrawItem::Octahedral { impostor },
                _ => scene.geometry(id, level),
            });
        }
    }

    fn gpu_bytes(&self) -> u64 {
        self.impostors.iter().flatten().map(|o| o.bytes).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoding_inverts_decoding_over_the_whole_sphere() {
        for i in 0..=20 {
            for j in 0..=20 {
                let (u, v) = (i as f64 / 10.0 - 1.0, j as f64 / 10.0 - 1.0);
                let d = decode(u, v);
                assert!((d.length() - 1.0).abs() < 1e-12);
                let [u2, v2] = encode(d);
                let back = decode(u2, v2);
                assert!(
                    (back - d).length() < 1e-9,
                    "({u}, {v}) -> {d} -> ({u2}, {v2})"
                );
            }
        }
        // The centre is straight up, the corners straight down, the diamond's edge the horizon.
        assert!((decode(0.0, 0.0) - DVec3::Y).length() < 1e-12);
        assert!((decode(1.0, 1.0) - DVec3::NEG_Y).length() < 1e-12);
        assert!(decode(0.5, 0.5).y.abs() < 1e-12);
    }

    #[test]
    fn the_view_size_fits_the_budget() {
        // 16x16 views of 64 texels: a 1024² atlas, 12 MiB per object.
        let one = OctahedralParams::within_budget(16, 1, 1 << 30);
        assert_eq!(one.view_size, 64);
        assert_eq!(one.atlas_bytes(), 1024 * 1024 * 12);
        // 100 objects in 256 MiB: 32 texels (3 MiB each, 300 MiB) are too many, 16 fit.
        let many = OctahedralParams::within_budget(16, 100, 256 << 20);
        assert_eq!(many.view_size, 16);
        // Never under 8, whatever the budget.
        assert_eq!(OctahedralParams::within_budget(16, 100_000, 1).view_size, 8);
    }
}

//! Per-frame planning (Süß §4.3): which objects are drawn as geometry, which as reliefboards,
//! and which boards to request. Pure logic over bounding spheres, so it is tested without a
//! GPU or a worker.
//!
//! 1. Frustum culling by bounding sphere.
//! 2. Unsuitable objects (too large, too simple) are geometry, and as in Süß their
//!    triangles (at the level of detail they are drawn with, when they have levels) count
//!    against the near-zone budget `t_nz`.
//! 3. Suitable objects are taken front to back as geometry until what is left of `t_nz`
//!    would be exceeded, from a min-heap over the visible objects' distances; the rest
//!    follow in the same order. Every list of the plan is front to back, so that the depth
//!    test rejects hidden pixels before they are shaded (O(n log n) for n visible objects: a
//!    few thousand a frame).
//! 4. An object whose level of detail costs less to draw than its board would
//!    ([`PlanParams::triangle_cost_pixels`]) is drawn through that level and asks for no
//!    board: an object simple for its size on screen is cheaper, and exact, as triangles.
//!    Every other visible suitable object is its board while the board is *valid* (the angle
//!    between its creation direction and the current direction is under E), else geometry
//!    (*fallback*, at the level of detail it is drawn with, when it has levels) while the
//!    frame's geometry stays within `t_nz`, else its stale board. An object with no board at
//!    all is always fallback.
//! 5. Updates are decided in pixels (Lawlor): a board is requested when there is none, when
//!    its parallax bound ([`parallax_pixels`]) passes `refresh_pixels`, when its angle passes
//!    ε (Süß's rule, kept for small boards), or when the projected size differs from the
//!    board's by over 30%; never while one is pending. Priority is the error in pixels times
//!    the screen area over the cost (the board's pixels), so the workers' time goes first
//!    where it removes the most error.
//! 6. A pending request is cancelled when its object left the view, or when the board on its
//!    way would be no closer to the current view than the one drawn (superseded: it is asked
//!    for again from here).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::DVec3;
use serde::Serialize;

use crate::camera::View;

/// What the planner knows of an object.
#[derive(Debug, Clone, Copy)]
pub struct ObjectInfo {
    /// Centre of its bounds (the board's sphere centre).
    pub center: DVec3,
    /// Half its bounds' diagonal (the board's sphere radius).
    pub radius: f64,
    /// Its triangles.
    pub triangles: u64,
    /// Whether it may be drawn as a reliefboard.
    pub suitable: bool,
    /// Its largest board side as a multiple of [`PlanParams::map_size`]: 1, or more for the
    /// pieces of a dense mesh cut larger than `sl_c` ([`scene::DenseCut`]).
    pub map_scale: u32,
}

/// The board an object has now.
#[derive(Debug, Clone, Copy)]
pub struct BoardState {
    /// The direction it was made from (viewer to object, unit).
    pub direction: DVec3,
    /// Its map side.
    pub size: u32,
}

/// Parameters of planning.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlanParams {
    /// Near-zone budget in triangles.
    pub t_nz: u64,
    /// Request a new board past this angle (degrees).
    pub epsilon_degrees: f64,
    /// Request a new board when its parallax bound passes this many pixels on screen.
    pub refresh_pixels: f64,
    /// Draw geometry instead of the board past this angle (degrees).
    pub e_degrees: f64,
    /// Request a new board when the projected size differs from the board's by more than this
    /// fraction.
    pub size_change: f64,
    /// Map texels per pixel the object covers on screen: above 1 a board is rendered finer
    /// than the screen shows it, so bilinear sampling between texels blurs less.
    pub texels_per_pixel: f64,
    /// Largest map side.
    pub map_size: u32,
    /// Smallest map side requested.
    pub min_map_size: u32,
    /// Whether boards are used at all (false: geometry only).
    pub impostors: bool,
    /// What one triangle costs to draw, in board pixels shaded: an object beyond the near
    /// zone whose level of detail costs less than its board (triangles times this, against
    /// the board's area on screen) is drawn through the level and asks for no board.
    /// 0: always a board. It is the adapter's own ratio ([`DEFAULT_TRIANGLE_COST_PIXELS`] was
    /// chosen on lavapipe).
    pub triangle_cost_pixels: f64,
}

impl Default for PlanParams {
    fn default() -> Self {
        PlanParams {
            t_nz: scene::PrepareParams::DEFAULT_T_NZ,
            epsilon_degrees: 11.5,
            refresh_pixels: DEFAULT_REFRESH_PIXELS,
            e_degrees: 45.0,
            size_change: 0.3,
            texels_per_pixel: DEFAULT_TEXELS_PER_PIXEL,
            map_size: scene::PrepareParams::DEFAULT_MAP_SIZE,
            min_map_size: 16,
            impostors: true,
            triangle_cost_pixels: DEFAULT_TRIANGLE_COST_PIXELS,
        }
    }
}

/// Default of `--texels-per-pixel`.
pub const DEFAULT_TEXELS_PER_PIXEL: f64 = 1.0;

/// Default pixel tolerance of a board's parallax before it is renewed.
pub const DEFAULT_REFRESH_PIXELS: f64 = 2.0;

/// Default of `--triangle-cost-pixels`: what a level's triangle costs against a board's
/// pixel, chosen by a sweep on lavapipe (README, "Levels where they cost less than boards").
pub const DEFAULT_TRIANGLE_COST_PIXELS: f64 = 16.0;

/// A board the frame wants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WantedBoard {
    /// The object.
    pub object: u32,
    /// From the viewer to the object's centre, unit.
    pub direction: DVec3,
    /// Map side.
    pub size: u32,
    /// Higher first: the error in pixels the board removes times its screen area, over its
    /// cost (its map's pixels).
    pub priority: f64,
}

/// What to draw this frame and what to ask for.
#[derive(Debug, Clone, Default)]
pub struct Plan {
    /// Objects drawn as geometry because they are unsuitable, front to back (by centre).
    pub unsuitable: Vec<u32>,
    /// The level of detail each of `unsuitable` is drawn with (0: its full mesh).
    pub unsuitable_levels: Vec<usize>,
    /// Suitable objects drawn as geometry in the near zone, front to back.
    pub near_zone: Vec<u32>,
    /// Suitable objects beyond the near zone drawn as geometry, front to back: no valid
    /// board, or their level of detail costs less than a board
    /// ([`PlanParams::triangle_cost_pixels`]).
    pub fallback: Vec<u32>,
    /// The level of detail each of `fallback` is drawn with (0: its full mesh).
    pub fallback_levels: Vec<usize>,
    /// Objects drawn as their board, with the board's angle error in degrees, front to back.
    pub boards: Vec<(u32, f64)>,
    /// Boards to request.
    pub requests: Vec<WantedBoard>,
    /// Objects whose pending request is no longer wanted: out of view, or superseded (then
    /// also in `requests`).
    pub cancels: Vec<u32>,
    /// Triangles in `near_zone`.
    pub near_zone_triangles: u64,
    /// Triangles in `unsuitable` (visible ones only), counted against `t_nz`.
    pub unsuitable_triangles: u64,
    /// Triangles in `fallback`, at their levels.
    pub fallback_triangles: u64,
    /// Boards in `boards` drawn past E, because geometry instead would pass `t_nz`.
    pub stale_boards: usize,
    /// Objects in `fallback` because their level costs less than a board.
    pub cheaper_as_levels: usize,
    /// Objects outside the frustum.
    pub culled: usize,
}

impl Plan {
    /// Drops the far objects, the boards and the fallback geometry with all they ask for,
    /// keeping the unsuitable objects and the near zone (`--impostor floor`).
    pub fn drop_far_objects(&mut self) {
        self.fallback.clear();
        self.fallback_levels.clear();
        self.fallback_triangles = 0;
        self.cheaper_as_levels = 0;
        self.boards.clear();
        self.stale_boards = 0;
        self.requests.clear();
        self.cancels.clear();
    }

    /// Draws `id` as geometry beyond the near zone, at `level` of `triangles`; returns them.
    fn fall_back(&mut self, id: u32, (level, triangles): (usize, u64)) -> u64 {
        self.fallback.push(id);
        self.fallback_levels.push(level);
        self.fallback_triangles += triangles;
        triangles
    }

    /// The fallback objects with the level each is drawn with.
    pub fn fallback_with_levels(&self) -> impl Iterator<Item = (u32, usize)> + '_ {
        self.fallback
            .iter()
            .copied()
            .zip(self.fallback_levels.iter().copied())
    }

    /// Every object drawn as geometry.
    pub fn geometry(&self) -> impl Iterator<Item = u32> + '_ {
        self.unsuitable
            .iter()
            .chain(&self.near_zone)
            .chain(&self.fallback)
            .copied()
    }
}

/// Plans one frame. `board` gives an object's current board, `pending` the board on its way
/// (the direction and size asked for), if any. Objects drawn as geometry beyond the near zone
/// count their full triangles ([`plan_with_levels`] when they are drawn through levels of
/// detail).
pub fn plan(
    view: &View,
    objects: &[ObjectInfo],
    params: &PlanParams,
    board: impl Fn(u32) -> Option<BoardState>,
    pending: impl Fn(u32) -> Option<BoardState>,
) -> Plan {
    plan_with_levels(view, objects, params, board, pending, |id| {
        (0, objects[id as usize].triangles)
    })
}

/// [`plan`], with `far_level` giving the level of detail a visible object beyond the near
/// zone is drawn with this frame when drawn as geometry (unsuitable, or fallback), and its
/// triangles, which is what it takes from `t_nz` and what a suitable object's board is
/// weighed against ([`PlanParams::triangle_cost_pixels`]). Near-zone objects are whole.
pub fn plan_with_levels(
    view: &View,
    objects: &[ObjectInfo],
    params: &PlanParams,
    board: impl Fn(u32) -> Option<BoardState>,
    pending: impl Fn(u32) -> Option<BoardState>,
    far_level: impl Fn(u32) -> (usize, u64),
) -> Plan {
    let mut plan = Plan::default();
    // Distance bits of a non-negative f64 order like the f64 itself.
    let mut heap: BinaryHeap<Reverse<(u64, u32)>> = BinaryHeap::new();
    let mut unsuitable = Vec::new();
    for (id, object) in objects.iter().enumerate() {
        let id = id as u32;
        if !view.sees_sphere(object.center, object.radius) {
            plan.culled += 1;
            // A board of an object out of view would only be stored.
            if object.suitable && pending(id).is_some() {
                plan.cancels.push(id);
            }
            continue;
        }
        let distance = (object.center - view.eye).length().to_bits();
        if object.suitable {
            heap.push(Reverse((distance, id)));
        } else {
            unsuitable.push((distance, id));
        }
    }
    // Front to back, so that depth tests reject what nearer geometry hides before it is
    // shaded: on lavapipe the plant's frame without far objects took 0.91 of the time.
    unsuitable.sort_unstable();
    for (_, id) in unsuitable {
        let (level, triangles) = far_level(id);
        plan.unsuitable.push(id);
        plan.unsuitable_levels.push(level);
        plan.unsuitable_triangles += triangles;
    }
    // Geometry that is drawn whatever happens takes its share of the budget first, so
    // the budget bounds what a frame draws (a plant's walls and pipes used to come on top).
    let budget = params.t_nz.saturating_sub(plan.unsuitable_triangles);
    while let Some(Reverse((_, id))) = heap.peek().copied() {
        let triangles = objects[id as usize].triangles;
        if params.impostors && plan.near_zone_triangles + triangles > budget {
            break;
        }
        heap.pop();
        plan.near_zone.push(id);
        plan.near_zone_triangles += triangles;
    }
    // What the frame draws as geometry so far: a board past E falls back to geometry only
    // while this stays within t_nz; past it the stale board is drawn instead, since a slow
    // frame shows a stale image everywhere, and an old board only on its object.
    let mut geometry = plan.unsuitable_triangles + plan.near_zone_triangles;
    // Front to back (a sorted heap of `Reverse` is farthest first): nearer objects take the
    // fallback's share of t_nz first, and their draws come first for the depth test.
    for Reverse((_, id)) in heap.into_sorted_vec().into_iter().rev() {
        let object = &objects[id as usize];
        let Some(direction) = (object.center - view.eye).try_normalize() else {
            geometry += plan.fall_back(id, far_level(id));
            continue;
        };
        let pixels = view.projected_pixels(object.center, object.radius);
        // A dense object's pieces may take their scale times the map size, up to what
        // workers serve by default.
        let largest = params.map_size.saturating_mul(object.map_scale.max(1)).min(
            params
                .map_size
                .max(scene::PrepareParams::MAX_RAISED_MAP_SIZE),
        );
        let size = ((pixels * params.texels_per_pixel).ceil() as u32)
            .clamp(params.min_map_size, largest.max(params.min_map_size));
        let area = pixels * pixels;
        let (level, triangles) = far_level(id);
        if params.triangle_cost_pixels > 0.0
            && triangles as f64 * params.triangle_cost_pixels < area
        {
            geometry += plan.fall_back(id, (level, triangles));
            plan.cheaper_as_levels += 1;
            if pending(id).is_some() {
                plan.cancels.push(id);
            }
            continue;
        }
        let current = board(id);
        let angle = current.map(|b| angle_degrees(b.direction, direction));
        match angle {
            Some(angle) if angle < params.e_degrees => plan.boards.push((id, angle)),
            Some(angle) if geometry + triangles > params.t_nz => {
                plan.boards.push((id, angle));
                plan.stale_boards += 1;
            }
            _ => geometry += plan.fall_back(id, (level, triangles)),
        }
        let error = |b: BoardState| board_error_pixels(b, direction, pixels, size);
        let wanted = match (current, angle) {
            (Some(board), Some(angle)) => {
                let size_off = (size as f64 - board.size as f64).abs() / board.size as f64;
                (angle > params.epsilon_degrees
                    || parallax_pixels(angle, pixels) > params.refresh_pixels
                    || size_off > params.size_change)
                    .then(|| error(board))
            }
            // No board at all: the whole object is missing (drawn as geometry meanwhile).
            _ => Some(pixels.max(1.0)),
        };
        let Some(error_pixels) = wanted else {
            continue;
        };
        match pending(id) {
            None => {}
            // Superseded: the board on its way would be no closer to this view than the
            // board drawn, so it is dropped and asked for again from here. Without a board
            // drawn, any board is better than none: the request stays.
            Some(on_its_way) if current.is_some_and(|b| error(on_its_way) >= error(b)) => {
                plan.cancels.push(id)
            }
            Some(_) => continue,
        }
        plan.requests.push(WantedBoard {
            object: id,
            direction,
            size,
            priority: error_pixels * area / (size as f64 * size as f64),
        });
    }
    plan
}

/// Lawlor's parallax bound for a board made `angle_degrees` away from the current view of an
/// object `pixels` across on screen: relative to the board's plane through its centre, the
/// front and back of its bounding sphere move by up to half its size times the sine of the
/// angle. A displaced board reproduces most of that, but what it could not see (behind a
/// branch, around the side) is missing, so it bounds the board's error too.
pub fn parallax_pixels(angle_degrees: f64, pixels: f64) -> f64 {
    0.5 * pixels * angle_degrees.clamp(0.0, 90.0).to_radians().sin()
}

/// How far, in pixels on screen, `board` is from the board this view wants (`direction`,
/// `size`, `pixels` across): its parallax bound, or the edge's shift from a wrong size.
fn board_error_pixels(board: BoardState, direction: DVec3, pixels: f64, size: u32) -> f64 {
    let size_off = (size as f64 - board.size as f64).abs() / board.size.max(1) as f64;
    parallax_pixels(angle_degrees(board.direction, direction), pixels).max(0.5 * pixels * size_off)
}

/// The angle between two unit vectors, degrees.
pub fn angle_degrees(a: DVec3, b: DVec3) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// `t_nz` when `--t-nz` is not given on a CPU adapter (lavapipe, llvmpipe), or when wgpu
/// finds no adapter at all. On lavapipe relief's frames were fastest and best at 50-100 k on
/// both built-in scenes, orbit and flythrough (README); 1 M, a third of what lavapipe draws in
/// a quarter-second frame, showed older images for a worse picture.
pub const CPU_ADAPTER_T_NZ: u64 = 100_000;

/// The near-zone budget when none is given, for frames drawn on an adapter of kind `adapter`
/// (`None`: wgpu found none): [`CPU_ADAPTER_T_NZ`] on a CPU, else
/// [`scene::PrepareParams::DEFAULT_T_NZ`].
pub fn default_t_nz(adapter: Option<wgpu::DeviceType>) -> u64 {
    match adapter {
        Some(wgpu::DeviceType::Cpu) | None => CPU_ADAPTER_T_NZ,
        Some(_) => scene::PrepareParams::DEFAULT_T_NZ,
    }
}

/// Niski's budget controller: `t_nz` toward a target frame time,
/// `t_new = sqrt(target / time) · t_old`, changed only when the frame time leaves a ±10%
/// band around the target (hysteresis, so it does not oscillate), by at most 2x per frame.
#[derive(Debug, Clone, Copy)]
pub struct BudgetController {
    target_ms: f64,
    t_nz: u64,
}

impl BudgetController {
    /// The smallest budget it sets: at least one object's worth of near zone.
    pub const MIN_T_NZ: u64 = 10_000;

    /// A controller starting at `t_nz`.
    pub fn new(target_ms: f64, t_nz: u64) -> BudgetController {
        BudgetController {
            target_ms: target_ms.max(0.1),
            t_nz: t_nz.max(Self::MIN_T_NZ),
        }
    }

    /// The budget for the next frame after one that took `frame_ms`.
    pub fn update(&mut self, frame_ms: f64) -> u64 {
        if frame_ms.is_finite() && frame_ms > 0.0 {
            let ratio = frame_ms / self.target_ms;
            if !(0.9..=1.1).contains(&ratio) {
                let factor = (1.0 / ratio).sqrt().clamp(0.5, 2.0);
                self.t_nz = ((self.t_nz as f64 * factor) as u64).max(Self::MIN_T_NZ);
            }
        }
        self.t_nz
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// A row of equal objects along -z in front of a camera at the origin looking down -z.
    fn row(count: usize, triangles: u64) -> (View, Vec<ObjectInfo>) {
        let camera = Camera {
            position: DVec3::ZERO,
            target: DVec3::NEG_Z,
            fov_y_degrees: 60.0,
        };
        let objects = (0..count)
            .map(|i| ObjectInfo {
                center: DVec3::new(0.0, 0.0, -10.0 - 5.0 * i as f64),
                radius: 1.0,
                triangles,
                suitable: true,
                map_scale: 1,
            })
            .collect();
        (camera.view([800, 600], 0.1, 1000.0), objects)
    }

    /// Every object's board made `degrees` off the row's view direction (-z), in the x-z
    /// plane.
    fn boards_made_off(degrees: f64) -> impl Fn(u32) -> Option<BoardState> + Copy {
        let direction = DVec3::new(degrees.to_radians().sin(), 0.0, -degrees.to_radians().cos());
        move |_| {
            Some(BoardState {
                direction,
                size: 64,
            })
        }
    }

    fn params(t_nz: u64) -> PlanParams {
        PlanParams {
            t_nz,
            ..PlanParams::default()
        }
    }

    #[test]
    fn near_zone_takes_the_nearest_objects_within_the_budget() {
        let (view, mut objects) = row(6, 1000);
        // Shuffle the input order: the planner must sort by distance, not by id.
        objects.reverse();
        let plan = plan(&view, &objects, &params(2500), |_| None, |_| None);
        // Two objects fit in 2500 triangles; the nearest two are the last two ids.
        let mut near = plan.near_zone.clone();
        near.sort_unstable();
        assert_eq!(near, vec![4, 5]);
        assert_eq!(plan.near_zone_triangles, 2000);
        assert!(plan.near_zone_triangles <= 2500);
        // The rest have no board yet: geometry now, one request each.
        assert_eq!(plan.fallback.len(), 4);
        assert_eq!(plan.requests.len(), 4);
    }

    #[test]
    fn objects_behind_the_camera_are_culled_and_never_requested() {
        let (view, mut objects) = row(2, 1000);
        objects[1].center = DVec3::new(0.0, 0.0, 20.0);
        let plan = plan(&view, &objects, &params(0), |_| None, |_| None);
        assert_eq!(plan.culled, 1);
        assert_eq!(
            plan.requests.iter().map(|r| r.object).collect::<Vec<_>>(),
            vec![0]
        );
    }

    #[test]
    fn geometry_and_boards_come_front_to_back_with_their_levels() {
        let (view, mut objects) = row(6, 1000);
        // Ids from far to near: the order drawn must come from distance, not from ids.
        objects.reverse();
        for object in objects.iter_mut().step_by(2) {
            object.suitable = false;
        }
        // Each object's level is its id, so a level that left its object would show.
        let with_boards = |board: &dyn Fn(u32) -> Option<BoardState>| {
            plan_with_levels(
                &view,
                &objects,
                &params(0),
                board,
                |_| None,
                |id| (id as usize, 1000),
            )
        };
        let without = with_boards(&|_| None);
        assert_eq!(without.unsuitable, vec![4, 2, 0]);
        assert_eq!(without.unsuitable_levels, vec![4, 2, 0]);
        assert_eq!(without.fallback, vec![5, 3, 1]);
        assert_eq!(without.fallback_levels, vec![5, 3, 1]);
        let boards = with_boards(&boards_made_off(0.0));
        let drawn: Vec<u32> = boards.boards.iter().map(|(id, _)| *id).collect();
        assert_eq!(drawn, vec![5, 3, 1]);
    }

    #[test]
    fn unsuitable_objects_are_geometry_whatever_the_budget() {
        let (view, mut objects) = row(3, 1000);
        objects[2].suitable = false;
        let plan = plan(&view, &objects, &params(0), |_| None, |_| None);
        assert_eq!(plan.unsuitable, vec![2]);
        assert!(plan.requests.iter().all(|r| r.object != 2));
    }

    #[test]
    fn unsuitable_triangles_count_against_the_near_zone_budget() {
        let (view, mut objects) = row(6, 1000);
        // The farthest object is unsuitable, 1,500 triangles: geometry, and it leaves 3,500
        // of 5,000 for the near zone, which then holds three objects, not five.
        objects[5].suitable = false;
        objects[5].triangles = 1500;
        let shared = plan(&view, &objects, &params(5000), |_| None, |_| None);
        assert_eq!(shared.unsuitable, vec![5]);
        assert_eq!(shared.unsuitable_triangles, 1500);
        let mut near = shared.near_zone.clone();
        near.sort_unstable();
        assert_eq!(near, vec![0, 1, 2]);
        assert!(shared.near_zone_triangles + shared.unsuitable_triangles <= 5000);
        // Culled unsuitable objects take nothing.
        objects[5].center = DVec3::new(0.0, 0.0, 50.0);
        let culled = plan(&view, &objects, &params(5000), |_| None, |_| None);
        assert_eq!(
            (culled.unsuitable_triangles, culled.near_zone.len()),
            (0, 5)
        );
        // More unsuitable triangles than the budget: no near zone at all.
        objects[5].center = DVec3::new(0.0, 0.0, -40.0);
        objects[5].triangles = 9000;
        let over = plan(&view, &objects, &params(5000), |_| None, |_| None);
        assert!(over.near_zone.is_empty());
        assert_eq!(over.fallback.len(), 5);
    }

    #[test]
    fn unsuitable_objects_count_the_triangles_of_their_level() {
        let (view, mut objects) = row(6, 1000);
        objects[5].suitable = false;
        objects[5].triangles = 4000;
        // At full detail the unsuitable object leaves 1,000 of 5,000: one object near.
        let full = plan(&view, &objects, &params(5000), |_| None, |_| None);
        assert_eq!((full.unsuitable_triangles, full.near_zone.len()), (4000, 1));
        // Drawn through a level of 500 triangles, it leaves room for four.
        let coarse = plan_with_levels(
            &view,
            &objects,
            &params(5000),
            |_| None,
            |_| None,
            |id| if id == 5 { (3, 500) } else { (0, 1000) },
        );
        assert_eq!(
            (coarse.unsuitable_triangles, coarse.near_zone.len()),
            (500, 4)
        );
        assert_eq!(coarse.unsuitable_levels, vec![3]);
    }

    #[test]
    fn fallback_objects_are_drawn_and_counted_at_their_level() {
        let (view, objects) = row(4, 1000);
        // No near zone: every object is fallback (no board yet), each at its level.
        let levels = |id: u32| (id as usize, 1000 >> id);
        let none = plan_with_levels(&view, &objects, &params(0), |_| None, |_| None, levels);
        let mut drawn: Vec<(u32, usize)> = none.fallback_with_levels().collect();
        drawn.sort();
        assert_eq!(drawn, vec![(0, 0), (1, 1), (2, 2), (3, 3)]);
        assert_eq!(none.fallback_triangles, 1000 + 500 + 250 + 125);
        // Boards made 60 degrees off are past E: geometry only while it fits t_nz, counted
        // at the level drawn. The nearest takes 1,000 of 1,900 as the near zone (whole);
        // of the other three none fits whole, all do at their levels (875).
        let stale = boards_made_off(60.0);
        let whole = plan(&view, &objects, &params(1900), stale, |_| None);
        assert_eq!(whole.near_zone, vec![0]);
        assert_eq!((whole.fallback.len(), whole.stale_boards), (0, 3));
        let coarse = plan_with_levels(&view, &objects, &params(1900), stale, |_| None, levels);
        assert_eq!(coarse.near_zone, vec![0]);
        assert_eq!((coarse.fallback.len(), coarse.stale_boards), (3, 0));
        assert_eq!(coarse.fallback_triangles, 875);
    }

    #[test]
    fn a_board_past_e_stays_when_geometry_would_pass_the_budget() {
        let (view, objects) = row(4, 1000);
        // Every object has a board made 60 degrees off: past E, so each wants geometry.
        let board = boards_made_off(60.0);
        // 2,500 triangles allow two objects as geometry (the near zone); the other two keep
        // their boards.
        let stale = plan(&view, &objects, &params(2500), board, |_| None);
        assert_eq!(stale.near_zone.len(), 2);
        assert_eq!((stale.boards.len(), stale.stale_boards), (2, 2));
        assert!(
            stale
                .boards
                .iter()
                .all(|(_, angle)| (angle - 60.0).abs() < 1.0)
        );
        // The second nearest is too large for what is left: the near zone stops at it, and
        // of the three beyond, one more fits as geometry, the others keep their boards.
        let mut uneven = objects.clone();
        uneven[1].triangles = 3000;
        let mixed = plan(&view, &uneven, &params(2500), board, |_| None);
        assert_eq!(mixed.near_zone, vec![0]);
        assert_eq!((mixed.fallback.len(), mixed.stale_boards), (1, 2));
        assert_ne!(mixed.fallback, vec![1], "the large one does not fit");
        // Without a board there is nothing else to draw: geometry, whatever the budget.
        let none = plan(&view, &objects, &params(1000), |_| None, |_| None);
        assert_eq!((none.fallback.len(), none.stale_boards), (3, 0));
        // Every stale board is also asked for again.
        assert_eq!(stale.requests.len(), 2);
    }

    #[test]
    fn a_piece_of_a_dense_object_asks_for_boards_up_to_its_own_scale() {
        // Close enough to cover some 700 pixels: clamped to the map size, or to 4 times it.
        let (view, mut objects) = row(2, 1000);
        objects[1].center = DVec3::new(0.0, 0.0, -1.5);
        objects[0].map_scale = 4;
        objects[0].center = DVec3::new(0.5, 0.0, -1.5);
        // At that size 1,000 triangles cost less than a board: ask for boards anyway.
        let boards_always = PlanParams {
            triangle_cost_pixels: 0.0,
            ..params(0)
        };
        let planned = plan(&view, &objects, &boards_always, |_| None, |_| None);
        let size_of = |id| {
            planned
                .requests
                .iter()
                .find(|r| r.object == id)
                .unwrap()
                .size
        };
        assert_eq!(size_of(1), 256);
        assert!(size_of(0) > 512 && size_of(0) <= 1024, "{}", size_of(0));
    }

    #[test]
    fn boards_are_asked_for_at_their_texels_per_pixel() {
        // The nearest object covers about 104 pixels across (radius 1 at 10 m, 60° over 600
        // pixels): asked for at that size, at twice it, and capped by the map size.
        let (view, objects) = row(1, 1000);
        let size_at = |texels_per_pixel| {
            let params = PlanParams {
                texels_per_pixel,
                map_size: 256,
                triangle_cost_pixels: 0.0,
                ..params(0)
            };
            plan(&view, &objects, &params, |_| None, |_| None).requests[0].size
        };
        let one = size_at(1.0);
        assert!((100..=110).contains(&one), "{one}");
        let two = size_at(2.0);
        assert!(two.abs_diff(2 * one) <= 1, "{two} against {one}");
        assert_eq!(size_at(4.0), 256);
    }

    #[test]
    fn board_angles_decide_drawing_and_requests() {
        let (view, objects) = row(1, 1000);
        let exact = (objects[0].center - view.eye).normalize();
        let size = view.projected_pixels(objects[0].center, 1.0).ceil() as u32;
        let turned = |degrees: f64| BoardState {
            direction: glam::DQuat::from_rotation_y(degrees.to_radians()) * exact,
            size,
        };
        // Süß's angle rule alone (the pixel rule has a test of its own).
        let angle_only = PlanParams {
            refresh_pixels: f64::INFINITY,
            ..params(0)
        };
        // What is pending was asked for from the current view.
        let on_its_way = BoardState {
            direction: exact,
            size,
        };
        let run = |board: BoardState, pending: bool| {
            plan(
                &view,
                &objects,
                &angle_only,
                |_| Some(board),
                |_| pending.then_some(on_its_way),
            )
        };
        // Under ε: drawn, nothing asked.
        let p = run(turned(5.0), false);
        assert_eq!(p.boards.len(), 1);
        assert!((p.boards[0].1 - 5.0).abs() < 1e-6);
        assert!(p.requests.is_empty());
        // Past ε, under E: drawn and refreshed.
        let p = run(turned(20.0), false);
        assert_eq!((p.boards.len(), p.requests.len()), (1, 1));
        // Past E: asked for again; drawn as its stale board, since geometry would pass the
        // budget of 0 (with room left it is geometry: the test after the budget's).
        let p = run(turned(50.0), false);
        assert_eq!(
            (p.boards.len(), p.fallback.len(), p.requests.len()),
            (1, 0, 1)
        );
        assert_eq!(p.stale_boards, 1);
        // Pending: never asked twice.
        let p = run(turned(50.0), true);
        assert!(p.requests.is_empty() && p.cancels.is_empty());
    }

    #[test]
    fn a_board_is_renewed_when_its_parallax_passes_the_pixel_tolerance() {
        // A near object about 104 pixels across and a far one about 10 across.
        let (view, mut objects) = row(2, 1000);
        objects[1].center = DVec3::new(0.0, 0.0, -100.0);
        let pixels: Vec<f64> = objects
            .iter()
            .map(|o| view.projected_pixels(o.center, o.radius))
            .collect();
        assert!(pixels[0] > 100.0 && pixels[1] < 12.0, "{pixels:?}");
        let board_turned = |id: u32, degrees: f64| {
            let exact = (objects[id as usize].center - view.eye).normalize();
            BoardState {
                direction: glam::DQuat::from_rotation_y(degrees.to_radians()) * exact,
                size: (pixels[id as usize].ceil() as u32).max(16),
            }
        };
        let asked = |degrees: f64| {
            let planned = plan(
                &view,
                &objects,
                &params(0),
                |id| Some(board_turned(id, degrees)),
                |_| None,
            );
            let mut ids: Vec<u32> = planned.requests.iter().map(|r| r.object).collect();
            ids.sort_unstable();
            ids
        };
        // 3 degrees, well under ε: the near board is 0.5 * 104 * sin 3° = 2.7 pixels off,
        // past the 2-pixel tolerance; the far one 0.27 pixels off.
        assert!((parallax_pixels(3.0, pixels[0]) - 2.72).abs() < 0.05);
        assert_eq!(asked(3.0), vec![0]);
        // 2 degrees: 1.8 pixels, within the tolerance: nothing.
        assert_eq!(asked(2.0), Vec::<u32>::new());
        // Past ε both are renewed, the larger error first.
        let planned = plan(
            &view,
            &objects,
            &params(0),
            |id| Some(board_turned(id, 15.0)),
            |_| None,
        );
        let priorities: Vec<(u32, f64)> = planned
            .requests
            .iter()
            .map(|r| (r.object, r.priority))
            .collect();
        assert_eq!(priorities.len(), 2);
        let priority_of = |id| priorities.iter().find(|(o, _)| *o == id).unwrap().1;
        assert!(priority_of(0) > 5.0 * priority_of(1), "{priorities:?}");
    }

    #[test]
    fn requests_out_of_view_or_superseded_are_cancelled() {
        let (view, mut objects) = row(3, 1000);
        // Object 2 is behind the camera now.
        objects[2].center = DVec3::new(0.0, 0.0, 20.0);
        let exact = |id: usize| (objects[id].center - view.eye).normalize();
        let turned = |id: usize, degrees: f64| BoardState {
            direction: glam::DQuat::from_rotation_y(degrees.to_radians()) * exact(id),
            size: 64,
        };
        // Object 0 draws a board 20 degrees off and one asked for 30 degrees off is on its
        // way: no better than what is drawn, so it is cancelled and asked for again from
        // here. Object 1 draws one 20 degrees off and one from 1 degree off is coming: kept.
        let planned = plan(
            &view,
            &objects,
            &params(0),
            |id| (id < 2).then(|| turned(id as usize, 20.0)),
            |id| Some(turned(id as usize, if id == 0 { 30.0 } else { 1.0 })),
        );
        let mut cancels = planned.cancels.clone();
        cancels.sort_unstable();
        assert_eq!(cancels, vec![0, 2]);
        let asked: Vec<u32> = planned.requests.iter().map(|r| r.object).collect();
        assert_eq!(asked, vec![0]);
        assert!(planned.requests[0].direction.dot(exact(0)) > 1.0 - 1e-9);
        // Without a board drawn, a board on its way is better than none, however old.
        let first = plan(
            &view,
            &objects,
            &params(0),
            |_| None,
            |id| Some(turned(id as usize, 40.0)),
        );
        assert_eq!((first.cancels, first.requests.len()), (vec![2], 0));
    }

    #[test]
    fn a_size_change_over_thirty_percent_asks_for_a_new_board() {
        let (view, objects) = row(1, 1000);
        let direction = (objects[0].center - view.eye).normalize();
        let size = view.projected_pixels(objects[0].center, 1.0).ceil() as u32;
        let ask = |board_size: u32| {
            let board = BoardState {
                direction,
                size: board_size,
            };
            !plan(&view, &objects, &params(0), |_| Some(board), |_| None)
                .requests
                .is_empty()
        };
        assert!(!ask(size));
        assert!(!ask((size as f64 * 1.2) as u32));
        assert!(ask((size as f64 * 1.5) as u32));
        assert!(ask((size as f64 / 1.5) as u32));
    }

    #[test]
    fn geometry_only_draws_everything_and_asks_nothing() {
        let (view, objects) = row(5, 1000);
        let p = plan(
            &view,
            &objects,
            &PlanParams {
                impostors: false,
                ..params(0)
            },
            |_| None,
            |_| None,
        );
        assert_eq!(p.geometry().count(), 5);
        assert!(p.requests.is_empty());
    }

    #[test]
    fn an_object_whose_level_costs_less_than_its_board_is_drawn_through_it() {
        let (view, objects) = row(2, 10_000);
        let area = |id: usize| view.projected_pixels(objects[id].center, 1.0).powi(2);
        // Object 0's level 2 (100 triangles at 16 pixels each) costs less than its board's
        // area; object 1's level 1 (5,000 triangles) costs more.
        assert!(100.0 * 16.0 < area(0) && 5000.0 * 16.0 > area(1));
        let far_level = |id: u32| if id == 0 { (2, 100) } else { (1, 5000) };
        // `pending`: the object with a request on its way, if any.
        let with_cost = |cost: f64, pending: Option<u32>| {
            let params = PlanParams {
                triangle_cost_pixels: cost,
                ..params(0)
            };
            let pending = |id: u32| boards_made_off(0.0)(id).filter(|_| Some(id) == pending);
            plan_with_levels(&view, &objects, &params, |_| None, pending, far_level)
        };
        let asked = |plan: &Plan| {
            let mut objects: Vec<u32> = plan.requests.iter().map(|r| r.object).collect();
            objects.sort_unstable();
            objects
        };
        let plan = with_cost(16.0, Some(0));
        let mut drawn: Vec<_> = plan.fallback_with_levels().collect();
        drawn.sort_unstable();
        assert_eq!(drawn, vec![(0, 2), (1, 1)]);
        assert_eq!(plan.cheaper_as_levels, 1);
        // Only the object that needs a board asks for one; object 0's request on its way is
        // no longer wanted.
        assert_eq!(asked(&plan), vec![1]);
        assert_eq!(plan.cancels, vec![0]);
        // It counts against the budget like any geometry drawn.
        assert_eq!(plan.fallback_triangles, 5100);
        assert_eq!(asked(&with_cost(16.0, None)), vec![1]);
        // At 0 every object waits for a board, drawn through its level meanwhile: both ask.
        let boards_always = with_cost(0.0, None);
        assert_eq!(boards_always.cheaper_as_levels, 0);
        assert_eq!(boards_always.fallback.len(), 2);
        assert_eq!(asked(&boards_always), vec![0, 1]);
    }

    #[test]
    fn budget_controller_moves_toward_the_target_with_hysteresis() {
        let mut controller = BudgetController::new(100.0, 1_000_000);
        // Inside the ±10% band: unchanged.
        assert_eq!(controller.update(105.0), 1_000_000);
        // Four times too slow: sqrt(1/4) = halve.
        assert_eq!(controller.update(400.0), 500_000);
        // Four times too fast: double.
        assert_eq!(controller.update(25.0), 1_000_000);
        // Never below the floor, whatever the frame time.
        for _ in 0..50 {
            controller.update(1e6);
        }
        assert_eq!(controller.update(1e6), BudgetController::MIN_T_NZ);
    }

    #[test]
    fn a_cpu_adapter_or_none_gets_a_tenth_of_a_gpus_near_zone() {
        use wgpu::DeviceType::*;
        for (adapter, t_nz) in [
            (Some(Cpu), 100_000),
            (None, 100_000),
            (Some(DiscreteGpu), 1_000_000),
            (Some(IntegratedGpu), 1_000_000),
            (Some(VirtualGpu), 1_000_000),
            (Some(Other), 1_000_000),
        ] {
            assert_eq!(default_t_nz(adapter), t_nz, "{adapter:?}");
        }
    }
}

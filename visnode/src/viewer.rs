//! The frame loop shared by the benchmark and the window: plan, let the far field take and
//! request what it needs, draw. Owns the GPU meshes and the far field (boards, levels of
//! detail or baked impostors: [`crate::far_field`]).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::{Camera, View};
use crate::far_field::lod::Levels;
use crate::far_field::{DrawScene, FarField, Loading};
use crate::plan::{ObjectInfo, Plan, PlanParams, plan_with_levels};
use crate::render::{DrawItem, FrameTiming, Mesh, RenderError, Renderer};

/// The near plane as a share of the far one. Reverse-Z with 32-bit float depth keeps a
/// relative precision of about 1e-7 at every distance, so the near plane can sit close
/// enough to walk up to an object in a 10 km scene (1 cm at 10 km).
const NEAR_OVER_FAR: f64 = 1e-6;

/// Tint of near-zone objects when tinting is on (debug view; boards have theirs).
const NEAR_TINT: [f32; 4] = [0.2, 0.4, 1.0, 0.35];
/// No tint.
pub(crate) const NO_TINT: [f32; 4] = [0.0; 4];

/// Default of `--upload-ms`: milliseconds of a frame spent uploading arrived boards.
pub const DEFAULT_UPLOAD_MS: f64 = 4.0;
/// Default of `--still-upload-ms`: while the camera stands still nothing on screen moves, so
/// a frame may spend a 30 Hz frame's time on uploads; the next input waits at most that long.
pub const DEFAULT_STILL_UPLOAD_MS: f64 = 33.0;
/// Default of `--fade-frames`: frames a new board that jumps takes to cross-fade in.
pub const DEFAULT_FADE_FRAMES: u32 = 4;
/// Default of `--fade-pixels`: a board renewed on time (its parallax past `--refresh-pixels`,
/// 2) jumps about that far, too little to see, and a cross-fade draws both boards for
/// `--fade-frames` frames: on a CPU rasterizer that doubles most boards' cost.
pub const DEFAULT_FADE_PIXELS: f64 = 8.0;

/// Everything about one drawn frame.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrameReport {
    /// Frame number.
    pub frame: u64,
    /// CPU and GPU time of the draw.
    pub timing: FrameTiming,
    /// Time spent planning, collecting and uploading boards, in milliseconds.
    pub plan_ms: f64,
    /// Triangles drawn.
    pub triangles: u64,
    /// Objects drawn as boards.
    pub boards: usize,
    /// Objects drawn as geometry (unsuitable, near zone and fallback).
    pub geometry_objects: usize,
    /// Of those, objects drawn through their level because it costs less than a board.
    pub cheaper_as_levels: usize,
    /// Triangles of the near zone.
    pub near_zone_triangles: u64,
    /// Requests issued this frame.
    pub requests_issued: usize,
    /// Requests in flight after this frame, and arrived boards waiting for their upload.
    pub requests_pending: usize,
    /// Requests (or arrived boards waiting for their upload) cancelled this frame: the object
    /// left the view, or the board was superseded.
    pub requests_cancelled: usize,
    /// Arrived boards left for a later frame's uploads (over `--upload-ms`).
    pub uploads_waiting: usize,
    /// Milliseconds spent uploading arrived boards.
    pub upload_ms: f64,
    /// Arrived boards that began a cross-fade this frame (the rest swapped in at once).
    pub boards_faded: usize,
    /// Latencies (issue to arrival, seconds) of boards that arrived this frame.
    pub latencies: Vec<f64>,
    /// Encoded bytes of the boards that arrived this frame.
    pub board_bytes: u64,
    /// Seconds the workers spent rendering the boards that arrived this frame.
    pub worker_render_seconds: f64,
    /// Angle error in degrees of every drawn board.
    pub angle_errors: Vec<f64>,
    /// Objects wanted as boards but with no live replica.
    pub unassignable: usize,
    /// Objects whose board was requested this frame.
    #[serde(skip)]
    pub requested_objects: Vec<u32>,
    /// Objects whose request ended (board or error) this frame.
    #[serde(skip)]
    pub arrived_objects: Vec<u32>,
    /// Objects whose board on its way was cancelled this frame: a request in flight, or a
    /// board that had arrived and waited for its upload.
    #[serde(skip)]
    pub cancelled_objects: Vec<u32>,
}

/// Options of the frame loop.
#[derive(Debug, Clone, Copy)]
pub struct ViewerOptions {
    /// Planning parameters.
    pub plan: PlanParams,
    /// Frames a new board takes to cross-fade in (0: at once).
    pub fade_frames: u32,
    /// A new board cross-fades in only when it differs from the one it replaces by more than
    /// this many pixels (their parallax bound); a closer one swaps in at once.
    pub fade_pixels: f64,
    /// Wait for requested boards before drawing (reproducible runs).
    pub sync: bool,
    /// Tint boards red and near-zone objects blue.
    pub tint: bool,
    /// Issue no new requests.
    pub freeze_requests: bool,
    /// Time a frame spends uploading arrived boards at most (at least one board goes).
    pub upload_budget: std::time::Duration,
    /// The same while the camera stands still (the view is the last frame's), if larger.
    pub still_upload_budget: std::time::Duration,
}

impl ViewerOptions {
    /// What a frame may spend uploading arrived boards: the still camera's budget when
    /// nothing moved since the last frame (`camera_still`), else the moving one's.
    pub fn upload_budget_for(&self, camera_still: bool) -> std::time::Duration {
        if camera_still {
            self.upload_budget.max(self.still_upload_budget)
        } else {
            self.upload_budget
        }
    }
}

impl Default for ViewerOptions {
    fn default() -> Self {
        ViewerOptions {
            plan: PlanParams::default(),
            fade_frames: DEFAULT_FADE_FRAMES,
            fade_pixels: DEFAULT_FADE_PIXELS,
            sync: false,
            tint: false,
            freeze_requests: false,
            upload_budget: std::time::Duration::from_secs_f64(DEFAULT_UPLOAD_MS / 1e3),
            still_upload_budget: std::time::Duration::from_secs_f64(DEFAULT_STILL_UPLOAD_MS / 1e3),
        }
    }
}

/// Levels of detail for the objects drawn as geometry beyond the near zone: those always
/// drawn so (too large or too simple for a board: walls, pipes, terrain) unless
/// `whole_unsuitable`, and, when the far field asks ([`FarField::fallback_through_levels`]),
/// suitable ones without a valid board (new in view, or past E). Chosen per frame within
/// `pixels` of error, so a distant object costs what it shows.
#[derive(Debug, Clone, Default)]
pub struct GeometryLod {
    /// The pixel bound (`--lod-pixels`).
    pub pixels: f64,
    /// Keep the unsuitable objects whole, as Süß does (`--whole-unsuitable`).
    pub whole_unsuitable: bool,
    /// Where the chains are cached (none: built every run).
    pub cache_dir: Option<std::path::PathBuf>,
}

/// The visualization node's state.
pub struct Viewer {
    /// The renderer.
    pub renderer: Renderer,
    objects: Vec<ObjectInfo>,
    meshes: Vec<Mesh>,
    far_field: Box<dyn FarField>,
    /// Levels of detail of the objects drawn as geometry beyond the near zone (none: always
    /// their full meshes).
    far_levels: Option<Levels>,
    /// Options, changeable between frames.
    pub options: ViewerOptions,
    bounds: scene::Aabb,
    /// The height of the always-geometry objects, for paths that keep above them.
    ground: crate::camera::Ground,
    frame: u64,
    /// The last frame's view: a frame with the same one has a still camera.
    last_view: Option<View>,
}

impl Viewer {
    /// Uploads `objects` (each with whether it is suitable), loads the suitable ones into
    /// `far_field` (views baked), and builds the levels `geometry_lod` asks for (when the far
    /// field draws impostors: geometry only stays whole).
    pub fn new(
        renderer: Renderer,
        objects: &[scene::Object],
        suitable: &[bool],
        mut far_field: Box<dyn FarField>,
        options: ViewerOptions,
        geometry_lod: Option<GeometryLod>,
        progress: &indicatif::ProgressBar,
    ) -> anyhow::Result<Viewer> {
        let mut far_levels = geometry_lod
            .filter(|_| far_field.draws_impostors())
            .map(|lod| {
                let fallback = far_field.fallback_through_levels();
                let wanted: Vec<bool> = (0..objects.len())
                    .map(|i| match suitable.get(i) {
                        Some(true) => fallback,
                        _ => !lod.whole_unsuitable,
                    })
                    .collect();
                Levels::new(lod.cache_dir.as_deref(), objects, &wanted, lod.pixels)
            });
        progress.set_length(objects.len() as u64);
        progress.set_position(0);
        progress.set_message("uploading meshes and preparing the far field");
        let mut meshes = Vec::with_capacity(objects.len());
        let mut infos = Vec::with_capacity(objects.len());
        // Normals in parallel, uploads in order, a batch at a time to bound memory (each
        // batch's staging is freed before the next is uploaded).
        for (batch_index, batch) in objects.chunks(32).enumerate() {
            let first = batch_index * 32;
            let prepared: Vec<backend::PreparedObject> = batch
                .par_iter()
                .map(backend::PreparedObject::new)
                .collect::<Result<_, _>>()?;
            let mut uploaded: Vec<Mesh> =
                prepared.iter().map(|o| renderer.upload_mesh(o)).collect();
            for (i, object) in prepared.iter().enumerate() {
                infos.push(ObjectInfo {
                    center: object.world_center(),
                    radius: object.radius,
                    triangles: object.triangles.len() as u64,
                    suitable: suitable.get(first + i).copied().unwrap_or(false),
                    map_scale: 1,
                });
            }
            let suitable = |i: usize| infos[first + i].suitable;
            far_field.load(
                &renderer,
                loading(&prepared, &mut uploaded, first, suitable),
            )?;
            if let Some(levels) = &mut far_levels {
                let batch = loading(&prepared, &mut uploaded, first, |i| levels.wants(first + i));
                levels.load(&renderer, batch);
            }
            meshes.extend(uploaded);
            renderer.finish_uploads()?;
            progress.inc(batch.len() as u64);
        }
        far_field.loaded();
        if let Some(levels) = &mut far_levels {
            levels.loaded();
        }
        let bounds = objects
            .iter()
            .fold(scene::Aabb::EMPTY, |b, o| b.union(o.bounds()));
        let ground: Vec<bool> = (0..objects.len())
            .map(|i| suitable.get(i) != Some(&true))
            .collect();
        let ground = crate::camera::Ground::new(objects, &ground, &bounds);
        Ok(Viewer {
            renderer,
            objects: infos,
            meshes,
            far_field,
            far_levels,
            options,
            bounds,
            ground,
            frame: 0,
            last_view: None,
        })
    }

    /// Lets each object's boards take up to its scale times the map size (pieces of dense
    /// meshes cut larger than `sl_c`: [`scene::PreparedScene::map_scales`]); 1 for any object
    /// not listed.
    pub fn set_map_scales(&mut self, scales: &[u32]) {
        for (info, &scale) in self.objects.iter_mut().zip(scales) {
            info.map_scale = scale.max(1);
        }
    }

    /// The scene's bounds.
    pub fn bounds(&self) -> scene::Aabb {
        self.bounds
    }

    /// `frames` cameras along `kind` over this scene; a flythrough keeps a tenth of the
    /// scene's height above the ground (terrain, floors: the objects always drawn as
    /// geometry), so it never passes under a hill.
    pub fn camera_path(
        &self,
        kind: &crate::camera::PathKind,
        frames: usize,
        fov_y_degrees: f64,
    ) -> anyhow::Result<Vec<Camera>> {
        let mut cameras = crate::camera::camera_path(kind, &self.bounds, frames, fov_y_degrees)?;
        if *kind == crate::camera::PathKind::Flythrough {
            self.ground
                .keep_above(&mut cameras, self.bounds.size().y * 0.1);
        }
        Ok(cameras)
    }

    /// The worker boards, when this far field uses them.
    pub fn boards(&self) -> Option<&crate::far_field::boards::Boards> {
        self.far_field.boards()
    }

    /// The requests, when boards are in use.
    pub fn requests(&self) -> Option<&crate::workers::BoardRequests> {
        self.boards().map(|b| b.requests())
    }

    /// Pauses the workers while the node measures itself off the clock (nothing to pause
    /// without boards).
    pub fn pause_workers(&self) -> crate::workers::WorkersPause {
        match self.requests() {
            Some(requests) => requests.pause_workers(),
            None => crate::workers::WorkersPause::none(),
        }
    }

    /// Boards currently held (on the GPU), and their bytes.
    pub fn boards_held(&self) -> (usize, usize) {
        self.boards().map_or((0, 0), |b| b.held())
    }

    /// GPU bytes spent on the far field: boards held or atlases, and the suitable objects'
    /// coarser levels of detail.
    pub fn far_field_bytes(&self) -> u64 {
        self.far_field.gpu_bytes() + self.level_bytes(true)
    }

    /// GPU bytes of the unsuitable objects' coarser levels (0 without them).
    pub fn unsuitable_lod_bytes(&self) -> u64 {
        self.level_bytes(false)
    }

    /// GPU bytes of the coarser levels of the objects `suitable` or not.
    fn level_bytes(&self, suitable: bool) -> u64 {
        self.meshes
            .iter()
            .zip(&self.objects)
            .filter(|(_, info)| info.suitable == suitable)
            .map(|(mesh, _)| mesh.lod_bytes())
            .sum()
    }

    /// The level `object` is drawn with from `view` as geometry beyond the near zone (0: its
    /// full mesh).
    fn far_level(&self, view: &View, object: u32) -> usize {
        self.far_levels.as_ref().map_or(0, |levels| {
            levels.level(object, &self.objects[object as usize], view)
        })
    }

    /// Why no worker boards are drawn, when none are (geometry only, no worker reachable,
    /// none needed, or another kind of impostor).
    pub fn no_boards_reason(&self) -> Option<&str> {
        self.far_field.no_boards_reason()
    }

    /// The view of `camera` for this viewer's target.
    pub fn view(&self, camera: &Camera, resolution: [u32; 2]) -> View {
        let far = (camera.position - self.bounds.center()).length() + self.bounds.diagonal() + 1.0;
        camera.view(resolution, (far * NEAR_OVER_FAR).max(1e-3), far)
    }

    /// Plans, requests and draws one frame into the offscreen target.
    pub fn frame(
        &mut self,
        camera: &Camera,
        resolution: [u32; 2],
    ) -> Result<FrameReport, RenderError> {
        self.renderer.resize(resolution);
        let view = self.view(camera, resolution);
        let (plan, mut report) = self.prepare_frame(&view);
        report.timing = self.draw(&view, &plan)?;
        report.triangles = report.timing.triangles;
        Ok(report)
    }

    /// Plans the frame and handles requests; what a window's frame does before drawing into
    /// its own surface with [`Viewer::encode`].
    pub fn prepare_frame(&mut self, view: &View) -> (Plan, FrameReport) {
        let start = Instant::now();
        self.frame += 1;
        let mut report = FrameReport {
            frame: self.frame,
            ..FrameReport::default()
        };
        let camera_still = self.last_view == Some(*view);
        self.last_view = Some(*view);
        let options = ViewerOptions {
            upload_budget: self.options.upload_budget_for(camera_still),
            ..self.options
        };
        self.far_field
            .begin_frame(&self.renderer, &options, &mut report);
        let mut plan = self.plan(view);
        if self
            .far_field
            .request(&self.renderer, &plan, &self.options, &mut report)
        {
            plan = self.plan(view);
        }
        report.boards = plan.boards.len();
        report.geometry_objects =
            plan.unsuitable.len() + plan.near_zone.len() + plan.fallback.len();
        report.cheaper_as_levels = plan.cheaper_as_levels;
        report.near_zone_triangles = plan.near_zone_triangles;
        report.angle_errors = plan.boards.iter().map(|(_, a)| *a).collect();
        report.plan_ms = start.elapsed().as_secs_f64() * 1e3;
        (plan, report)
    }

    fn plan(&self, view: &View) -> Plan {
        let mut params = self.options.plan;
        params.impostors &= self.far_field.draws_impostors();
        // Only boards have a cost to weigh a level against; without levels an object's cost
        // would be its full mesh: Süß's fallback, kept as it was.
        if self.far_field.boards().is_none() || !self.far_field.fallback_through_levels() {
            params.triangle_cost_pixels = 0.0;
        }
        let mut plan = plan_with_levels(
            view,
            &self.objects,
            &params,
            |id| self.far_field.board_state(id),
            |id| self.far_field.pending_board(id),
            |id| {
                let level = self.far_level(view, id);
                (level, self.meshes[id as usize].level_triangles(level))
            },
        );
        if !self.far_field.draws_far_objects() {
            plan.drop_far_objects();
        }
        plan
    }

    fn draw(&mut self, view: &View, plan: &Plan) -> Result<FrameTiming, RenderError> {
        let scene = DrawScene {
            meshes: &self.meshes,
            objects: &self.objects,
            view: *view,
            tint: self.options.tint,
        };
        let items = draw_items(&scene, &*self.far_field, plan);
        self.renderer.draw(view, &items)
    }

    /// Records the planned frame into `encoder`, drawing into a window's `color` and `depth`
    /// targets; returns the triangles submitted.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        view: &View,
        plan: &Plan,
    ) -> u64 {
        let scene = DrawScene {
            meshes: &self.meshes,
            objects: &self.objects,
            view: *view,
            tint: self.options.tint,
        };
        let items = draw_items(&scene, &*self.far_field, plan);
        self.renderer.encode(encoder, color, depth, view, &items)
    }

    /// Draws every visible object as geometry: the reference frame.
    pub fn reference_frame(
        &mut self,
        camera: &Camera,
        resolution: [u32; 2],
    ) -> Result<FrameTiming, RenderError> {
        self.renderer.resize(resolution);
        let view = self.view(camera, resolution);
        let items: Vec<DrawItem> = self
            .objects
            .iter()
            .zip(&self.meshes)
            .filter(|(o, _)| view.sees_sphere(o.center, o.radius))
            .map(|(o, mesh)| DrawItem::Geometry {
                mesh,
                level: 0,
                object: o.suitable,
                tint: NO_TINT,
            })
            .collect();
        self.renderer.draw(&view, &items)
    }

    /// Directions from `eye` to every object's centre (for tests and tools).
    pub fn object_centers(&self) -> Vec<DVec3> {
        self.objects.iter().map(|o| o.center).collect()
    }
}

/// The objects of a batch (from object `first` on) that `keep` says, ready to load.
fn loading<'a>(
    prepared: &'a [backend::PreparedObject],
    meshes: &'a mut [Mesh],
    first: usize,
    keep: impl Fn(usize) -> bool,
) -> Vec<Loading<'a>> {
    prepared
        .iter()
        .zip(meshes)
        .enumerate()
        .filter(|(i, _)| keep(*i))
        .map(|(i, (object, mesh))| Loading {
            id: (first + i) as u32,
            object,
            mesh,
        })
        .collect()
}

/// The frame's draws: near-zone objects and unsuitable objects (at their levels) as
/// geometry, each front to back, then what the far field draws for the rest; nearest first,
/// so that depth tests reject hidden pixels before they are shaded. A free function so the
/// renderer can draw (mutably) while the list borrows the meshes and the far field.
fn draw_items<'a>(
    scene: &DrawScene<'a>,
    far_field: &'a dyn FarField,
    plan: &Plan,
) -> Vec<DrawItem<'a>> {
    let near_tint = if scene.tint { NEAR_TINT } else { NO_TINT };
    let mut items: Vec<DrawItem> = plan
        .near_zone
        .iter()
        .map(|&id| scene.tinted_geometry(id, 0, near_tint))
        .chain(
            plan.unsuitable
                .iter()
                .zip(&plan.unsuitable_levels)
                .map(|(&id, &level)| scene.geometry(id, level)),
        )
        .collect();
    far_field.draw(scene, plan, &mut items);
    items
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_still_camera_raises_the_upload_budget_and_a_moving_one_keeps_it() {
        let options = ViewerOptions {
            upload_budget: Duration::from_millis(4),
            still_upload_budget: Duration::from_millis(33),
            ..ViewerOptions::default()
        };
        assert_eq!(options.upload_budget_for(false), Duration::from_millis(4));
        assert_eq!(options.upload_budget_for(true), Duration::from_millis(33));
        // A still budget below the moving one never slows a still camera down.
        let lower = ViewerOptions {
            still_upload_budget: Duration::from_millis(1),
            ..options
        };
        assert_eq!(lower.upload_budget_for(true), Duration::from_millis(4));
    }
}

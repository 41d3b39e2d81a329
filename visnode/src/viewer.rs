//! The frame loop shared by the benchmark and the window: plan, request, swap in arrived
//! boards, draw. Owns the GPU meshes, the current board of every object and the requests.

use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::{Camera, View};
use crate::plan::{BoardState, ObjectInfo, Plan, PlanParams, plan};
use crate::render::{DrawItem, FrameTiming, GpuBoard, GpuOctahedral, Mesh, RenderError, Renderer};
use crate::workers::{Arrival, BoardRequests};

/// The near plane as a share of the far one. Reverse-Z with 32-bit float depth keeps a
/// relative precision of about 1e-7 at every distance, so the near plane can sit close
/// enough to walk up to an object in a 10 km scene (1 cm at 10 km).
const NEAR_OVER_FAR: f64 = 1e-6;

/// Tint of boards and near-zone objects when tinting is on (debug view).
const BOARD_TINT: [f32; 4] = [1.0, 0.2, 0.2, 0.35];
const NEAR_TINT: [f32; 4] = [0.2, 0.4, 1.0, 0.35];
const NO_TINT: [f32; 4] = [0.0; 4];

/// An object's board on the GPU, and the one it replaces while they cross-fade.
struct BoardSlot {
    current: GpuBoard,
    state: BoardState,
    /// The replaced board and the cross-fade's progress in [0, 1).
    outgoing: Option<GpuBoard>,
    fade: f32,
}

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
    /// Triangles of the near zone.
    pub near_zone_triangles: u64,
    /// Requests issued this frame.
    pub requests_issued: usize,
    /// Requests in flight after this frame.
    pub requests_pending: usize,
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
}

/// Options of the frame loop.
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    /// Planning parameters.
    pub plan: PlanParams,
    /// Frames a new board takes to cross-fade in (0: at once).
    pub fade_frames: u32,
    /// Wait for requested boards before drawing (reproducible runs).
    pub sync: bool,
    /// Tint boards red and near-zone objects blue.
    pub tint: bool,
    /// Issue no new requests.
    pub freeze_requests: bool,
    /// Draw far objects as levels of detail instead of boards (`--impostor lod`): the
    /// coarsest level within this many pixels of error; the chains are built at load.
    pub lod_pixels: Option<f64>,
    /// Draw far objects as baked octahedral impostors of this layout instead of boards
    /// (`--impostor octahedral`); the views are baked at load.
    pub octahedral: Option<crate::octahedral::OctahedralParams>,
    /// Where levels of detail are cached between runs (`None`: not cached).
    pub cache_dir: Option<std::path::PathBuf>,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        ViewerOptions {
            plan: PlanParams::default(),
            fade_frames: 4,
            sync: false,
            tint: false,
            freeze_requests: false,
            lod_pixels: None,
            octahedral: None,
            cache_dir: None,
        }
    }
}

/// The visualization node's state.
pub struct Viewer {
    /// The renderer.
    pub renderer: Renderer,
    objects: Vec<ObjectInfo>,
    meshes: Vec<Mesh>,
    /// Per object, the world-space error of each level of detail (empty: full mesh only).
    lod_errors: Vec<Vec<f64>>,
    /// Per object, its baked octahedral impostor (`--impostor octahedral`).
    octahedral: Vec<Option<GpuOctahedral>>,
    boards: Vec<Option<BoardSlot>>,
    requests: Option<BoardRequests>,
    /// Options, changeable between frames.
    pub options: ViewerOptions,
    bounds: scene::Aabb,
    /// The height of the always-geometry objects, for paths that keep above them.
    ground: crate::camera::Ground,
    frame: u64,
    /// Why there are no boards, when there are none (no worker reachable, or none needed).
    pub no_boards_reason: Option<String>,
}

impl Viewer {
    /// Uploads `objects` (each with whether it is suitable) and takes `requests` for boards
    /// (`None`: geometry only, with `reason`).
    pub fn new(
        renderer: Renderer,
        objects: &[scene::Object],
        suitable: &[bool],
        requests: Result<BoardRequests, String>,
        options: ViewerOptions,
        progress: &indicatif::ProgressBar,
    ) -> anyhow::Result<Viewer> {
        progress.set_length(objects.len() as u64);
        progress.set_position(0);
        let lod = options.lod_pixels.is_some();
        progress.set_message(if lod {
            "building levels of detail and uploading meshes"
        } else if options.octahedral.is_some() {
            "baking octahedral impostors and uploading meshes"
        } else {
            "uploading meshes"
        });
        let mut octahedral = Vec::with_capacity(objects.len());
        // Levels of detail from the cache when it has this scene's; built and written if not.
        let lod_cache = options
            .cache_dir
            .as_deref()
            .filter(|_| lod)
            .map(|dir| crate::lod::cache_path(dir, objects, suitable));
        let cached = lod_cache
            .as_deref()
            .and_then(|path| crate::lod::read_cache(path, objects.len()));
        let mut rebuilt = cached.is_none();
        let mut chains = Vec::new();
        let mut meshes = Vec::with_capacity(objects.len());
        let mut infos = Vec::with_capacity(objects.len());
        let mut lod_errors = Vec::with_capacity(objects.len());
        // Normals (and levels of detail) in parallel, uploads in order, a batch at a time to
        // bound memory.
        for (batch_index, batch) in objects.chunks(32).enumerate() {
            let prepared: Vec<_> = batch
                .par_iter()
                .enumerate()
                .map(|(i, object)| {
                    let object = backend::PreparedObject::new(object)?;
                    let suitable = suitable.get(batch_index * 32 + i).copied() == Some(true);
                    let from_cache = cached
                        .as_ref()
                        .map(|c| &c[batch_index * 32 + i])
                        .filter(|chain| chain.fits(object.vertices.len()));
                    let (chain, built) = match from_cache {
                        Some(chain) => (chain.clone(), false),
                        None if lod && suitable => (crate::lod::LodChain::build(&object), true),
                        None => (crate::lod::LodChain::default(), false),
                    };
                    let atlas = match options.octahedral {
                        Some(params) if suitable => {
                            Some(crate::octahedral::Atlas::bake(&object, params)?)
                        }
                        _ => None,
                    };
                    Ok::<_, backend::RenderError>((object, chain, atlas, built))
                })
                .collect::<Result<_, _>>()?;
            for (object, chain, atlas, built) in prepared {
                meshes.push(renderer.upload_mesh(&object, &chain.levels));
                octahedral.push(atlas.as_ref().map(|a| renderer.upload_octahedral(a)));
                rebuilt |= built;
                lod_errors.push(chain.errors.clone());
                if lod_cache.is_some() {
                    chains.push(chain);
                }
                infos.push(ObjectInfo {
                    center: object.world_center(),
                    radius: object.radius,
                    triangles: object.triangles.len() as u64,
                    suitable: suitable.get(infos.len()).copied().unwrap_or(false),
                });
                progress.inc(1);
            }
        }
        if let Some(path) = lod_cache.filter(|_| rebuilt) {
            // A cache that cannot be written costs time next run, nothing else.
            if let Err(error) = crate::lod::write_cache(&path, &chains) {
                eprintln!("levels of detail not cached: {}: {error}", path.display());
            }
        }
        let bounds = objects
            .iter()
            .fold(scene::Aabb::EMPTY, |b, o| b.union(o.bounds()));
        let ground: Vec<bool> = (0..objects.len())
            .map(|i| suitable.get(i) != Some(&true))
            .collect();
        let ground = crate::camera::Ground::new(objects, &ground, &bounds);
        let (requests, no_boards_reason) = match requests {
            Ok(requests) => (Some(requests), None),
            Err(reason) => (None, Some(reason)),
        };
        Ok(Viewer {
            renderer,
            boards: (0..objects.len()).map(|_| None).collect(),
            objects: infos,
            meshes,
            lod_errors,
            octahedral,
            requests,
            options,
            bounds,
            ground,
            frame: 0,
            no_boards_reason,
        })
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

    /// The requests, when boards are in use.
    pub fn requests(&self) -> Option<&BoardRequests> {
        self.requests.as_ref()
    }

    /// Boards currently held (on the GPU), and their bytes.
    pub fn boards_held(&self) -> (usize, usize) {
        self.boards
            .iter()
            .flatten()
            .fold((0, 0), |(n, bytes), slot| {
                (
                    n + 1 + slot.outgoing.is_some() as usize,
                    bytes + slot.current.bytes + slot.outgoing.as_ref().map_or(0, |b| b.bytes),
                )
            })
    }

    /// GPU bytes spent on the far field: boards held, or the coarser levels of detail.
    pub fn far_field_bytes(&self) -> u64 {
        self.boards_held().1 as u64
            + self.meshes.iter().map(Mesh::lod_bytes).sum::<u64>()
            + self
                .octahedral
                .iter()
                .flatten()
                .map(|o| o.bytes)
                .sum::<u64>()
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
        self.advance_fades();
        let mut report = FrameReport {
            frame: self.frame,
            ..FrameReport::default()
        };
        let arrived = self.requests.as_mut().map(|r| r.poll()).unwrap_or_default();
        self.swap_in(arrived, &mut report);
        let mut plan = self.plan(view);
        if let Some(requests) = &mut self.requests
            && !self.options.freeze_requests
        {
            let before = requests.counts.issued;
            report.unassignable = requests.submit(&plan.requests, self.frame).len();
            report.requests_issued = (requests.counts.issued - before) as usize;
            report.requested_objects = plan
                .requests
                .iter()
                .map(|w| w.object)
                .filter(|&object| requests.is_pending(object))
                .collect();
            if self.options.sync && report.requests_issued > 0 {
                let arrived = requests.wait_all(Duration::from_secs(120));
                self.swap_in(arrived, &mut report);
                plan = self.plan(view);
            }
        }
        report.requests_pending = self.requests.as_ref().map_or(0, |r| r.pending());
        report.boards = plan.boards.len();
        report.geometry_objects =
            plan.unsuitable.len() + plan.near_zone.len() + plan.fallback.len();
        report.near_zone_triangles = plan.near_zone_triangles;
        report.angle_errors = plan.boards.iter().map(|(_, a)| *a).collect();
        report.plan_ms = start.elapsed().as_secs_f64() * 1e3;
        (plan, report)
    }

    fn plan(&self, view: &View) -> Plan {
        let requests = self.requests.as_ref();
        let mut params = self.options.plan;
        params.impostors &= requests.is_some()
            || self.options.lod_pixels.is_some()
            || self.options.octahedral.is_some();
        plan(
            view,
            &self.objects,
            &params,
            |id| self.boards[id as usize].as_ref().map(|slot| slot.state),
            |id| requests.is_some_and(|r| r.is_pending(id)),
        )
    }

    fn draw(&mut self, view: &View, plan: &Plan) -> Result<FrameTiming, RenderError> {
        let parts = SceneParts {
            meshes: &self.meshes,
            boards: &self.boards,
            objects: &self.objects,
            lod_errors: &self.lod_errors,
            lod_pixels: self.options.lod_pixels,
            octahedral: &self.octahedral,
            view: *view,
        };
        let items = draw_items(parts, self.options.tint, plan);
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
        let parts = SceneParts {
            meshes: &self.meshes,
            boards: &self.boards,
            objects: &self.objects,
            lod_errors: &self.lod_errors,
            lod_pixels: self.options.lod_pixels,
            octahedral: &self.octahedral,
            view: *view,
        };
        let items = draw_items(parts, self.options.tint, plan);
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

    fn swap_in(&mut self, arrived: Vec<Arrival>, report: &mut FrameReport) {
        for arrival in arrived {
            report.latencies.push(arrival.latency);
            report.arrived_objects.push(arrival.object);
            report.board_bytes += arrival.bytes as u64;
            report.worker_render_seconds += arrival.render_seconds;
            let Ok(data) = arrival.board else {
                continue;
            };
            let board = self.renderer.upload_board(&data);
            let state = BoardState {
                direction: data.direction,
                size: data.size,
            };
            let slot = &mut self.boards[arrival.object as usize];
            let fade = self.options.fade_frames > 0 && !self.options.sync;
            *slot = Some(match slot.take() {
                // The old board fades out; one older still is freed now.
                Some(old) if fade => BoardSlot {
                    current: board,
                    state,
                    outgoing: Some(old.current),
                    fade: 1.0 / self.options.fade_frames as f32,
                },
                _ => BoardSlot {
                    current: board,
                    state,
                    outgoing: None,
                    fade: 1.0,
                },
            });
        }
    }

    fn advance_fades(&mut self) {
        let step = 1.0 / self.options.fade_frames.max(1) as f32;
        for slot in self.boards.iter_mut().flatten() {
            if slot.outgoing.is_some() {
                slot.fade += step;
                if slot.fade >= 1.0 {
                    slot.outgoing = None;
                    slot.fade = 1.0;
                }
            }
        }
    }

    /// Directions from `eye` to every object's centre (for tests and tools).
    pub fn object_centers(&self) -> Vec<DVec3> {
        self.objects.iter().map(|o| o.center).collect()
    }
}

/// The parts of a [`Viewer`] a draw list is made from: borrowed field by field, so the
/// renderer can draw (mutably) while the list borrows meshes and boards.
struct SceneParts<'a> {
    meshes: &'a [Mesh],
    boards: &'a [Option<BoardSlot>],
    objects: &'a [ObjectInfo],
    lod_errors: &'a [Vec<f64>],
    lod_pixels: Option<f64>,
    octahedral: &'a [Option<GpuOctahedral>],
    view: View,
}

impl SceneParts<'_> {
    /// The level of detail drawn for a far object (0 without `--impostor lod`).
    fn level(&self, id: u32) -> usize {
        let Some(pixels) = self.lod_pixels else {
            return 0;
        };
        let object = &self.objects[id as usize];
        crate::lod::choose_level(
            &self.lod_errors[id as usize],
            (object.center - self.view.eye).length(),
            object.radius,
            self.view.pixels_per_radian,
            pixels,
        )
    }
}

fn draw_items<'a>(parts: SceneParts<'a>, tinted: bool, plan: &Plan) -> Vec<DrawItem<'a>> {
    let SceneParts {
        meshes,
        boards,
        objects,
        octahedral,
        ..
    } = parts;
    let tint = |color| if tinted { color } else { NO_TINT };
    let mut items: Vec<DrawItem> = plan
        .fallback
        .iter()
        .filter_map(|&id| octahedral[id as usize].as_ref())
        .map(|impostor| DrawItem::Octahedral { impostor })
        .collect();
    let geometry = plan
        .unsuitable
        .iter()
        .map(|&id| (id, NO_TINT, 0))
        .chain(plan.near_zone.iter().map(|&id| (id, tint(NEAR_TINT), 0)))
        .chain(
            plan.fallback
                .iter()
                .filter(|&&id| octahedral[id as usize].is_none())
                .map(|&id| (id, NO_TINT, parts.level(id))),
        )
        .map(|(id, tint, level)| DrawItem::Geometry {
            mesh: &meshes[id as usize],
            level,
            object: objects[id as usize].suitable,
            tint,
        });
    items.extend(geometry);
    for &(id, _) in &plan.boards {
        let Some(slot) = &boards[id as usize] else {
            continue;
        };
        let fading = slot.outgoing.as_ref().filter(|_| slot.fade < 1.0);
        items.push(DrawItem::Board {
            board: &slot.current,
            fade: if fading.is_some() { slot.fade } else { 1.0 },
            outgoing: false,
            tint: tint(BOARD_TINT),
        });
        if let Some(old) = fading {
            items.push(DrawItem::Board {
                board: old,
                fade: slot.fade,
                outgoing: true,
                tint: tint(BOARD_TINT),
            });
        }
    }
    items
}

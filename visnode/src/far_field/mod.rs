//! How the suitable objects beyond the near zone are drawn: one kind per `--impostor` value,
//! each in its own module behind [`FarField`]. The frame loop ([`crate::Viewer`]) knows only
//! the trait; [`for_kind`] is the one place that maps a kind to its module, so adding a kind
//! is a module, a CLI value and a line there.
//!
//! - [`boards`]: reliefboards and flat billboards, rendered by the workers on request.
//! - [`lod`]: meshoptimizer level-of-detail chains (the viewer's [`lod::Levels`], built at
//!   load; the plan picks each object's level).
//! - [`octahedral`]: baked multi-view impostors, rendered at load.
//! - [`GeometryOnly`]: every object as its full mesh (`--impostor none`, or a scene within
//!   the near zone).
//! - [`Floor`]: far objects not drawn (`--impostor floor`), the cost every kind shares.

pub mod boards;
pub mod lod;
pub mod octahedral;

use crate::camera::View;
use crate::cli::{BoardArgs, Impostor, WorkerArgs};
use crate::plan::{BoardState, ObjectInfo, Plan};
use crate::render::{DrawItem, Mesh, Renderer};
use crate::viewer::{FrameReport, NO_TINT, ViewerOptions};

/// One way of drawing far objects. Every hook but [`FarField::draw`] has a do-nothing
/// default, so a kind implements only what it uses.
pub trait FarField {
    /// Load-time work on a batch of suitable objects whose full meshes are uploaded (baking
    /// views; levels of detail are the viewer's). Called batch after batch, in object order.
    fn load(
        &mut self,
        _renderer: &Renderer,
        _batch: Vec<Loading<'_>>,
    ) -> Result<(), backend::RenderError> {
        Ok(())
    }

    /// After the last batch (caches are written here).
    fn loaded(&mut self) {}

    /// Whether far objects become impostors; false keeps every object whole (the plan then
    /// fills no far field).
    fn draws_impostors(&self) -> bool {
        true
    }

    /// Whether the far objects are drawn at all; false (the floor) leaves them out of the
    /// frame and of its report.
    fn draws_far_objects(&self) -> bool {
        true
    }

    /// Whether suitable objects drawn as geometry beyond the near zone (fallback: no valid
    /// board yet) go through levels of detail; the viewer then builds them at load.
    fn fallback_through_levels(&self) -> bool {
        false
    }

    /// Why no worker boards are used, when none are (shown to the user).
    fn no_boards_reason(&self) -> Option<&str> {
        None
    }

    /// Before planning a frame: take what arrived since the last one (into `report`).
    fn begin_frame(
        &mut self,
        _renderer: &Renderer,
        _options: &ViewerOptions,
        _report: &mut FrameReport,
    ) {
    }

    /// The board `object` holds now, for planning.
    fn board_state(&self, _object: u32) -> Option<BoardState> {
        None
    }

    /// The board of `object` on its way (direction and size asked for), for planning.
    fn pending_board(&self, _object: u32) -> Option<BoardState> {
        None
    }

    /// After planning: issues what `plan` asks for (counted in `report`). True when boards
    /// arrived that the frame must be planned again with (`--sync`).
    fn request(
        &mut self,
        _renderer: &Renderer,
        _plan: &Plan,
        _options: &ViewerOptions,
        _report: &mut FrameReport,
    ) -> bool {
        false
    }

    /// Appends the draws of the far objects `plan` chose: `plan.boards` and `plan.fallback`.
    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>);

    /// GPU bytes held for the far field (boards, coarser levels, atlases).
    fn gpu_bytes(&self) -> u64 {
        0
    }

    /// The worker boards, when this kind uses them (statistics, the GUI's overlay).
    fn boards(&self) -> Option<&boards::Boards> {
        None
    }
}

/// A suitable object being loaded: its prepared geometry and its mesh on the GPU.
pub struct Loading<'a> {
    /// Object id.
    pub id: u32,
    /// Its geometry with normals.
    pub object: &'a backend::PreparedObject,
    /// Its uploaded mesh (the viewer adds its levels of detail to it).
    pub mesh: &'a mut Mesh,
}

/// What a far field draws from: the viewer's meshes and objects, and the frame's view.
pub struct DrawScene<'a> {
    /// Every object's mesh.
    pub meshes: &'a [Mesh],
    /// Every object.
    pub objects: &'a [ObjectInfo],
    /// The frame's view.
    pub view: View,
    /// Tint impostors (debug view).
    pub tint: bool,
}

impl<'a> DrawScene<'a> {
    /// `object` drawn as level `level` of its mesh (0: the full mesh).
    pub fn geometry(&self, object: u32, level: usize) -> DrawItem<'a> {
        self.tinted_geometry(object, level, NO_TINT)
    }

    /// The plan's fallback objects as geometry, each at the level the plan chose.
    pub fn fallback_geometry<'p>(
        &'p self,
        plan: &'p Plan,
    ) -> impl Iterator<Item = DrawItem<'a>> + 'p {
        plan.fallback_with_levels()
            .map(|(id, level)| self.geometry(id, level))
    }

    /// [`DrawScene::geometry`] with a tint (debug view).
    pub fn tinted_geometry(&self, object: u32, level: usize, tint: [f32; 4]) -> DrawItem<'a> {
        DrawItem::Geometry {
            mesh: &self.meshes[object as usize],
            level,
            object: self.objects[object as usize].suitable,
            tint,
        }
    }
}

/// Every object as its full mesh: `--impostor none`, or a scene that fits the near zone.
/// Boards wanted but impossible are [`lod::LodField::instead_of_boards`], which keeps the
/// unsuitable objects' levels as boards would.
pub struct GeometryOnly {
    reason: String,
}

impl GeometryOnly {
    /// Geometry only, for `reason` (shown to the user).
    pub fn new(reason: impl Into<String>) -> GeometryOnly {
        GeometryOnly {
            reason: reason.into(),
        }
    }
}

impl FarField for GeometryOnly {
    fn draws_impostors(&self) -> bool {
        false
    }

    fn no_boards_reason(&self) -> Option<&str> {
        Some(&self.reason)
    }

    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>) {
        items.extend(scene.fallback_geometry(plan));
    }
}

/// Far objects not drawn (`--impostor floor`): the frame is what every kind draws besides
/// them, so its time is the floor under any far field's on the same path.
pub struct Floor;

impl FarField for Floor {
    fn no_boards_reason(&self) -> Option<&str> {
        Some("--impostor floor: far objects are not drawn")
    }

    fn draws_far_objects(&self) -> bool {
        false
    }

    fn draw<'a>(&'a self, _scene: &DrawScene<'a>, _plan: &Plan, _items: &mut Vec<DrawItem<'a>>) {}
}

/// The far field the flags ask for, over the scene's objects (boards only of suitable ones):
/// workers are started (or connected) and the scene stored on them only for the kinds that
/// use them.
pub fn for_kind(
    board_args: &BoardArgs,
    worker_args: &WorkerArgs,
    scene: &crate::setup::LoadedScene,
    record_trace: bool,
    progress: &indicatif::ProgressBar,
) -> Box<dyn FarField> {
    let (objects, suitable) = (&scene.objects, &scene.suitable[..]);
    let shape = match board_args.impostor {
        Impostor::None => return Box::new(GeometryOnly::new("--impostor none: geometry only")),
        Impostor::Lod => return Box::new(lod::LodField::chosen()),
        Impostor::Floor => return Box::new(Floor),
        Impostor::Octahedral => {
            let objects = suitable.iter().filter(|&&s| s).count();
            let params = octahedral_params(board_args, objects);
            eprintln!(
                "octahedral impostors: {v}x{v} views of {s}x{s} texels, a {a}x{a} atlas ({mib:.1} MiB) per object, {total:.0} MiB for {objects} objects",
                v = params.views,
                s = params.view_size,
                a = params.views * params.view_size,
                mib = params.atlas_bytes() as f64 / (1 << 20) as f64,
                total = (params.atlas_bytes() * objects as u64) as f64 / (1 << 20) as f64,
            );
            return Box::new(octahedral::OctahedralField::new(params));
        }
        Impostor::Billboard => crate::board::BoardShape::Billboard,
        Impostor::Relief => crate::board::BoardShape::Relief {
            grid_cells: board_args.board_grid,
            // A cell per that many screen pixels, whatever the maps' texels per pixel.
            cell_pixels: ((board_args.board_cell_pixels as f64 * board_args.texels_per_pixel)
                .round() as u32)
                .max(1),
        },
    };
    if scene.summary.fits_in_near_zone {
        return Box::new(GeometryOnly::new(
            "the whole scene fits in the near zone: no board is needed, so no worker was started",
        ));
    }
    let fallback_levels = !board_args.whole_fallback;
    if !suitable.contains(&true) {
        return Box::new(lod::LodField::instead_of_boards(
            "no object is suitable for a board (each is too large for the near zone's size limit sl_c, or too simple): no worker was started; far objects are drawn through their levels of detail",
            fallback_levels,
        ));
    }
    let requests = crate::setup::connect_workers(worker_args)
        .map_err(|e| format!("{e:#}"))
        .and_then(|workers| {
            crate::setup::requests_on(
                workers,
                objects,
                suitable,
                worker_args.replicas,
                shape,
                record_trace,
                progress,
            )
        })
        .map(|mut requests| {
            requests.use_speeds(worker_args.balancer_speeds.into());
            requests
        });
    boards_or_fallback(requests, fallback_levels)
}

/// Worker boards over `requests`, a suitable object without a valid board drawn through its
/// levels of detail when `fallback_levels`, else whole. Without workers (with the reason)
/// every far object is such a fallback, the unsuitable ones through their levels as always.
pub fn boards_or_fallback(
    requests: Result<crate::workers::BoardRequests, String>,
    fallback_levels: bool,
) -> Box<dyn FarField> {
    match requests {
        Ok(requests) => Box::new(boards::Boards::new(requests, fallback_levels)),
        Err(reason) => {
            let how = if fallback_levels {
                "through their levels"
            } else {
                "whole (--whole-fallback)"
            };
            eprintln!("no worker boards, suitable far objects drawn {how}: {reason}");
            Box::new(lod::LodField::instead_of_boards(reason, fallback_levels))
        }
    }
}

/// The octahedral atlas layout of the flags for `suitable` objects: the view size given, or
/// the largest within the memory budget (reported, since it decides quality).
pub fn octahedral_params(board_args: &BoardArgs, suitable: usize) -> octahedral::OctahedralParams {
    match board_args.octahedral_view_size {
        Some(view_size) => octahedral::OctahedralParams {
            views: board_args.octahedral_views,
            view_size,
        },
        None => octahedral::OctahedralParams::within_budget(
            board_args.octahedral_views,
            suitable,
            board_args.octahedral_budget_mb << 20,
        ),
    }
}

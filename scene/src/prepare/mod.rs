//! Preprocessing (Süß §4.5): from a [`Scene`] as loaded to objects that are each drawn as
//! geometry or as one reliefboard.
//!
//! 1. **Phase II first**: the near-zone diameter `d_nz` and from it the largest cluster side
//!    `sl_c` ([`near_zone_diameter`], [`max_cluster_side`]). It needs only triangle positions,
//!    so it can tell, before any other work, whether the scene needs cutting at all.
//! 2. Every input object is classified. Suitable objects are kept as they are.
//! 3. **Phase I** ([`components`]) runs only on unsuitable objects that cutting could help:
//!    too large with enough triangles to fill suitable pieces, or too simple.
//! 4. **Phase III** ([`cluster_boxes`]) joins the base clusters that fit `sl_c`; it is skipped
//!    when there is nothing to join.
//! 5. Phases I and III are cached on disk, keyed by the geometry they saw and the parameters.

mod cache;
mod clustering;
mod components;
mod near_zone;

use std::path::PathBuf;
use std::time::Instant;

use crate::progress::Progress;
use rayon::prelude::*;
use serde::Serialize;

pub use clustering::{ClusterOutcome, cluster_boxes};
pub use near_zone::{max_cluster_side, near_zone_diameter};

use crate::error::SceneError;
use crate::geometry::Aabb;
use crate::object::{Object, ObjectBuilder, Scene};

/// Parameters of preprocessing.
#[derive(Debug, Clone)]
pub struct PrepareParams {
    /// Near-zone triangle budget `t_nz`: the nearest triangles up to this count are drawn as
    /// geometry.
    pub t_nz: u64,
    /// Largest reliefboard map side `p`, in pixels.
    pub map_size: u32,
    /// Display resolution, width and height in pixels.
    pub resolution: [u32; 2],
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f64,
    /// Objects with fewer triangles are too simple to gain from a reliefboard.
    pub min_triangles: u64,
    /// Where Phases I and III are cached; `None` disables the cache.
    pub cache_dir: Option<PathBuf>,
    /// Progress of the long phases.
    pub progress: Progress,
}

impl PrepareParams {
    /// Default `t_nz`, for a GPU: far below Süß's 3.5 M (for GPUs of 2011), and not measured
    /// here (no GPU was lent). visnode gives a CPU adapter a smaller one.
    pub const DEFAULT_T_NZ: u64 = 1_000_000;
    /// Default map side `p` (Süß's).
    pub const DEFAULT_MAP_SIZE: u32 = 256;
    /// Default display resolution (Süß's).
    pub const DEFAULT_RESOLUTION: [u32; 2] = [1024, 768];
    /// Default vertical field of view, degrees.
    pub const DEFAULT_FOV_Y_DEGREES: f64 = 60.0;
    /// Default `min_triangles`: about a 45x45 board grid; below it a board saves nothing.
    pub const DEFAULT_MIN_TRIANGLES: u64 = 4096;
    /// The largest map side preprocessing may raise `map_size` to, so a dense mesh too
    /// large for the near zone can still be cut into pieces worth a board (the workers'
    /// default `--max-map-size`).
    pub const MAX_RAISED_MAP_SIZE: u32 = 1024;
}

impl Default for PrepareParams {
    fn default() -> Self {
        PrepareParams {
            t_nz: Self::DEFAULT_T_NZ,
            map_size: Self::DEFAULT_MAP_SIZE,
            resolution: Self::DEFAULT_RESOLUTION,
            fov_y_degrees: Self::DEFAULT_FOV_Y_DEGREES,
            min_triangles: Self::DEFAULT_MIN_TRIANGLES,
            cache_dir: None,
            progress: Progress::hidden(),
        }
    }
}

/// How an object is drawn beyond the near zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectClass {
    /// Small enough and complex enough: drawn as a reliefboard beyond the near zone.
    Suitable,
    /// Its longest side exceeds `sl_c`: always drawn as geometry.
    TooLarge,
    /// Fewer than `min_triangles` triangles: always drawn as geometry.
    TooSimple,
}

/// One phase's report for the summary.
#[derive(Debug, Clone, Serialize)]
pub struct PhaseReport {
    /// Which phase.
    pub name: &'static str,
    /// Whether it ran (or was answered from the cache).
    pub ran: bool,
    /// What it did, or why it was skipped.
    pub note: String,
    /// Wall-clock time.
    pub seconds: f64,
}

/// What preprocessing found and did: the figures `visnode inspect` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// The scene's source.
    pub source: String,
    /// Objects as loaded.
    pub input_objects: usize,
    /// Triangles after loading (zero-area ones already dropped).
    pub input_triangles: u64,
    /// Zero-area triangles dropped while loading, or when a cut's piece was recentred (a
    /// tiny part far from its object's centre whose f32 corners had already collapsed).
    pub degenerate_triangles_dropped: u64,
    /// Duplicate faces dropped by Phase I.
    pub duplicate_faces_dropped: u64,
    /// Objects after preprocessing.
    pub objects: usize,
    /// Triangles after preprocessing.
    pub triangles: u64,
    /// Suitable objects.
    pub suitable: usize,
    /// Too-large objects.
    pub too_large: usize,
    /// Too-simple objects.
    pub too_simple: usize,
    /// Triangles in suitable objects.
    pub suitable_triangles: u64,
    /// Near-zone triangle budget.
    pub t_nz: u64,
    /// Near-zone diameter.
    pub d_nz: f64,
    /// Largest suitable cluster side.
    pub sl_c: f64,
    /// The whole scene fits in `t_nz`: no reliefboard is ever needed.
    pub fits_in_near_zone: bool,
    /// How dense meshes too large for `sl_c`, whose pieces of side `sl_c` would be too
    /// small for a board, were cut instead, one entry per map size used.
    pub dense: Vec<DenseCut>,
    /// How sparse objects no map size makes boards of were cut all the same, so that each
    /// piece is drawn at its own distance's level of detail (or as a board, where a piece
    /// is suitable); `None` when none was. Its `sl_c` is the largest side a piece took (a
    /// side doubles from the largest raised one until the pieces are large enough).
    pub sparse: Option<DenseCut>,
    /// The phases in the order they ran.
    pub phases: Vec<PhaseReport>,
    /// "hit", "miss", "disabled" or "not needed".
    pub cache: String,
}

/// A scene cut into objects, each classified.
#[derive(Debug, Clone)]
pub struct PreparedScene {
    /// The objects.
    pub objects: Vec<Object>,
    /// The class of each object.
    pub classes: Vec<ObjectClass>,
    /// Each object's largest board side as a multiple of the map size: 1, or more for the
    /// pieces of a dense mesh cut at a larger side ([`DenseCut`]); it is suitable when its
    /// side is at most `sl_c` times this.
    pub map_scales: Vec<u32>,
    /// The summary.
    pub summary: Summary,
}

/// Runs the preprocessing pipeline described in the module docs.
pub fn prepare(scene: Scene, params: &PrepareParams) -> Result<PreparedScene, SceneError> {
    check_params(params)?;
    let Scene {
        source,
        objects,
        mut degenerate_triangles_dropped,
    } = scene;
    let input_objects = objects.len();
    let input_triangles: u64 = objects.iter().map(|o| o.triangles.len() as u64).sum();
    let mut phases = Vec::new();

    let start = Instant::now();
    let d_nz = near_zone_diameter(&objects, params.t_nz);
    let sl_c = max_cluster_side(
        d_nz,
        params.map_size,
        params.resolution[1],
        params.fov_y_degrees,
    );
    let fits_in_near_zone = input_triangles <= params.t_nz;
    let phase_two = PhaseReport {
        name: "phase II: near zone",
        ran: true,
        note: format!("d_nz = {d_nz:.4}, sl_c = {sl_c:.4}"),
        seconds: start.elapsed().as_secs_f64(),
    };

    // Cutting helps an object that is too simple (it may join neighbours) or too large but
    // dense enough that pieces of side sl_c would hold enough triangles to be suitable.
    let needs_cutting = |object: &Object| match classify(object, sl_c, params.min_triangles) {
        ObjectClass::Suitable => false,
        ObjectClass::TooSimple => true,
        ObjectClass::TooLarge => components::dense_enough_to_cut(
            object.triangles.len() as u64,
            &object.bounds(),
            sl_c,
            params.min_triangles,
        ),
    };
    let (mut to_cut, mut kept, mut too_large) = (Vec::new(), Vec::new(), Vec::new());
    for object in objects {
        if fits_in_near_zone {
            kept.push(object);
        } else if needs_cutting(&object) {
            to_cut.push(object);
        } else if classify(&object, sl_c, params.min_triangles) == ObjectClass::TooLarge {
            too_large.push(object);
        } else {
            kept.push(object);
        }
    }

    let mut cache_state = "not needed".to_string();
    let mut duplicate_faces_dropped = 0;
    if to_cut.is_empty() {
        // Nothing to cut at sl_c: every object is suitable, or too large but too sparse for
        // pieces of side sl_c to hold min_triangles each (a terrain, or a scan under a small
        // near zone, which may still be cut below with larger maps).
        let sparse = too_large.len();
        let suitable = kept.len();
        let why = if fits_in_near_zone {
            "skipped: the whole scene fits in the near-zone budget, every object is drawn as geometry".to_string()
        } else if sparse == 0 {
            "skipped: the input objects are already suitable".to_string()
        } else {
            format!(
                "skipped: of the {} input objects, {suitable} are already suitable and {sparse} \
                 too large but too sparse to cut (pieces of side sl_c would hold fewer than {} \
                 triangles each)",
                suitable + sparse,
                params.min_triangles
            )
        };
        for name in ["phase I: components", "phase III: clustering"] {
            phases.push(PhaseReport {
                name,
                ran: false,
                note: why.clone(),
                seconds: 0.0,
            });
        }
        phases.insert(1, phase_two);
    } else {
        let cut = cut(&to_cut, sl_c, params);
        phases.extend(cut.phases);
        phases.insert(1, phase_two);
        cache_state = cut.cache_state;
        duplicate_faces_dropped += cut.duplicate_faces;
        degenerate_triangles_dropped += cut.zero_area;
        let first_new = kept.len();
        kept.extend(cut.objects);
        for (number, object) in kept[first_new..].iter_mut().enumerate() {
            object.name = format!("cluster {number}");
        }
    }
    // Every object's largest board side, as a multiple of the map size.
    let mut map_scales = vec![1; kept.len()];
    // Too large and too sparse at sl_c: cut with larger maps where that makes boards, else
    // all the same where pieces pay for their draw calls, else kept whole.
    let start = Instant::now();
    let mut dense: Vec<DenseCut> = Vec::new();
    let mut sparse: Option<DenseCut> = None;
    let mut stays_whole = 0;
    // Each object is cut on its own, so they are cut in parallel; the outer bar counts
    // objects, since the inner phases' bars would jump between threads.
    if !too_large.is_empty() {
        params.progress.set_message("dense objects");
        params.progress.set_length(too_large.len() as u64);
        params.progress.set_position(0);
    }
    let quiet = PrepareParams {
        progress: Progress::hidden(),
        ..params.clone()
    };
    let outcomes: Vec<LargeOutcome> = too_large
        .par_iter()
        .map(|object| {
            let outcome = if let Some((scale, cut)) = cut_dense(object, sl_c, &quiet) {
                LargeOutcome::Dense(scale, cut)
            } else if let Some((scale, side, cut)) = cut_sparse(object, sl_c, &quiet) {
                LargeOutcome::Sparse(scale, side, cut)
            } else {
                LargeOutcome::Whole
            };
            params.progress.inc(1);
            outcome
        })
        .collect();
    for (object, outcome) in too_large.into_iter().zip(outcomes) {
        let (scale, cut) = match outcome {
            LargeOutcome::Dense(scale, cut) => {
                let at = match dense
                    .iter()
                    .position(|d| d.map_size == params.map_size * scale)
                {
                    Some(at) => at,
                    None => {
                        dense.push(DenseCut {
                            map_size: params.map_size * scale,
                            sl_c: sl_c * scale as f64,
                            objects: 0,
                            pieces: 0,
                        });
                        dense.len() - 1
                    }
                };
                dense[at].objects += 1;
                dense[at].pieces += cut.objects.len();
                (scale, cut)
            }
            LargeOutcome::Sparse(scale, side, cut) => {
                let sparse = sparse.get_or_insert(DenseCut {
                    map_size: params.map_size * scale,
                    sl_c: side,
                    objects: 0,
                    pieces: 0,
                });
                sparse.sl_c = sparse.sl_c.max(side);
                sparse.objects += 1;
                sparse.pieces += cut.objects.len();
                (scale, cut)
            }
            LargeOutcome::Whole => {
                stays_whole += 1;
                map_scales.push(1);
                kept.push(object);
                continue;
            }
        };
        if cache_state == "not needed" {
            cache_state = cut.cache_state.clone();
        }
        duplicate_faces_dropped += cut.duplicate_faces;
        degenerate_triangles_dropped += cut.zero_area;
        map_scales.extend(std::iter::repeat_n(scale, cut.objects.len()));
        for (number, mut piece) in cut.objects.into_iter().enumerate() {
            piece.name = format!("{} piece {number}", object.name);
            kept.push(piece);
        }
    }
    if !dense.is_empty() || sparse.is_some() || stays_whole > 0 {
        let cuts: Vec<String> = dense
            .iter()
            .map(|d| {
                format!(
                    "{} into {} pieces of side at most {:.4} with maps up to {} pixels",
                    d.objects, d.pieces, d.sl_c, d.map_size
                )
            })
            .collect();
        phases.push(PhaseReport {
            name: "dense objects",
            ran: !dense.is_empty() || sparse.is_some(),
            note: format!(
                "of {} objects too large for sl_c and too sparse to cut at it, cut {}{}{}",
                dense.iter().map(|d| d.objects).sum::<usize>()
                    + sparse.as_ref().map_or(0, |s| s.objects)
                    + stays_whole,
                if cuts.is_empty() {
                    "none".to_string()
                } else {
                    cuts.join(", ")
                },
                match &sparse {
                    Some(s) => format!(
                        "; {} too sparse for any map cut into {} pieces of side at most {:.4} \
                         all the same, each drawn at its own level of detail",
                        s.objects, s.pieces, s.sl_c
                    ),
                    None => String::new(),
                },
                if stays_whole > 0 {
                    format!(
                        "; {stays_whole} stay whole (no map up to {} pixels leaves 3/4 of \
                         their triangles in suitable pieces, and they are too simple to pay \
                         for pieces of their own)",
                        PrepareParams::MAX_RAISED_MAP_SIZE
                    )
                } else {
                    String::new()
                }
            ),
            seconds: start.elapsed().as_secs_f64(),
        });
    }

    // Each object against the side its own maps allow.
    let classes: Vec<ObjectClass> = kept
        .iter()
        .zip(&map_scales)
        .map(|(object, &scale)| classify(object, sl_c * scale as f64, params.min_triangles))
        .collect();
    let count = |class| classes.iter().filter(|c| **c == class).count();
    let summary = Summary {
        source,
        input_objects,
        input_triangles,
        degenerate_triangles_dropped,
        duplicate_faces_dropped,
        objects: kept.len(),
        triangles: kept.iter().map(|o| o.triangles.len() as u64).sum(),
        suitable: count(ObjectClass::Suitable),
        too_large: count(ObjectClass::TooLarge),
        too_simple: count(ObjectClass::TooSimple),
        suitable_triangles: kept
            .iter()
            .zip(&classes)
            .filter(|(_, c)| **c == ObjectClass::Suitable)
            .map(|(o, _)| o.triangles.len() as u64)
            .sum(),
        t_nz: params.t_nz,
        d_nz,
        sl_c,
        fits_in_near_zone,
        dense,
        sparse,
        phases,
        cache: cache_state,
    };
    Ok(PreparedScene {
        objects: kept,
        classes,
        map_scales,
        summary,
    })
}

/// The connected components of one object after welding vertices at identical positions and
/// dropping duplicate faces (Phase I without any cutting): each component's box and triangle
/// count, in order of first triangle.
pub fn connected_components(object: &Object) -> Vec<(Aabb, u64)> {
    let result = components::split_into_components(&[object], f64::INFINITY, u64::MAX);
    result
        .clusters
        .iter()
        .map(|c| (c.bounds, c.triangles))
        .collect()
}

/// How dense meshes too large for `sl_c` are cut when pieces of side `sl_c` would hold
/// fewer than `min_triangles` (a scanned mesh under a small near zone: the dragon at `t_nz`
/// 20,000 holds about 700 triangles per piece of side `sl_c`): into pieces of a larger side
/// whose boards may take larger maps, so that seen from the near zone's edge they are as
/// sharp as any other board. Per object, the map size doubles from the parameter's up to
/// [`PrepareParams::MAX_RAISED_MAP_SIZE`] until the cut leaves at least 3/4 of its
/// triangles in suitable pieces; objects for which none does (a terrain, a floor) stay
/// whole.
#[derive(Debug, Clone, Serialize)]
pub struct DenseCut {
    /// The largest map side their pieces' boards take.
    pub map_size: u32,
    /// The largest side of their pieces: `sl_c` for that map size.
    pub sl_c: f64,
    /// How many input objects were cut so.
    pub objects: usize,
    /// Into how many pieces.
    pub pieces: usize,
}

/// What became of one object too large for `sl_c` and too sparse to cut at it.
enum LargeOutcome {
    /// Cut at a raised map scale ([`cut_dense`]).
    Dense(u32, Cut),
    /// Cut all the same, at a raised scale and a side ([`cut_sparse`]).
    Sparse(u32, f64, Cut),
    /// Kept whole.
    Whole,
}

/// Share of a dense object's triangles that must land in suitable pieces.
const DENSE_SUITABLE_SHARE: f64 = 0.75;

/// The largest multiple of the map size a piece's boards may take
/// ([`PrepareParams::MAX_RAISED_MAP_SIZE`]).
fn largest_map_scale(params: &PrepareParams) -> u32 {
    (PrepareParams::MAX_RAISED_MAP_SIZE / params.map_size).max(1)
}

/// `object` (too large for `sl_c`, too sparse to cut at it) cut at the smallest map scale
/// that makes most of it boards, with that scale; `None` when no scale does.
fn cut_dense(object: &Object, sl_c: f64, params: &PrepareParams) -> Option<(u32, Cut)> {
    let largest_scale = largest_map_scale(params);
    let mut scale = 2;
    while scale <= largest_scale {
        let side = sl_c * scale as f64;
        // Cheap first: the box over-counts the volume, so a miss here is a miss.
        let bounds = object.bounds();
        if components::dense_enough_to_cut(
            object.triangles.len() as u64,
            &bounds,
            side,
            params.min_triangles,
        ) {
            let cut = cut(std::slice::from_ref(object), side, params);
            let suitable: u64 = cut
                .objects
                .iter()
                .filter(|o| classify(o, side, params.min_triangles) == ObjectClass::Suitable)
                .map(|o| o.triangles.len() as u64)
                .sum();
            if suitable as f64 >= DENSE_SUITABLE_SHARE * object.triangles.len() as f64 {
                return Some((scale, cut));
            }
        }
        scale *= 2;
    }
    None
}

/// How many suitable objects' worth of triangles (`min_triangles`) a sparse object must
/// hold for cutting it to pay: pieces are draw calls of their own, which a terrain or a
/// floor of a few thousand triangles, drawn whole in one, does not repay.
const SPARSE_CUT_MIN_SHARE: u64 = 2;

/// A sparse object's pieces hold at least `min_triangles / SPARSE_PIECE_DIVISOR` on
/// average: smaller pieces cost more in draw calls than their own levels of detail save
/// (the plant orbit at `t_nz` 100 k, its pipe runs cut into 4,511 pieces of 660 triangles:
/// 56 → 91 ms a frame on lavapipe).
const SPARSE_PIECE_DIVISOR: u64 = 2;

/// `object` (too large for `sl_c`, too sparse for any raised map size to make boards of most
/// of it: a pipe run across a whole site) cut all the same, when it holds at least
/// `SPARSE_CUT_MIN_SHARE × min_triangles` triangles, at the largest raised side or twice
/// that, four times..., the first whose pieces are large enough; with the largest raised map
/// scale and the side. `None` for an object too simple to pay for pieces (a terrain, a
/// floor: cheap whole). Drawn whole, such an object takes the level of detail of its
/// nearest point everywhere, and its far end costs as much as its near one; cut, each piece
/// takes its own distance's level, and pieces that hold enough triangles within the raised
/// side become boards.
fn cut_sparse(object: &Object, sl_c: f64, params: &PrepareParams) -> Option<(u32, f64, Cut)> {
    let triangles = object.triangles.len() as u64;
    if triangles < SPARSE_CUT_MIN_SHARE * params.min_triangles {
        return None;
    }
    let least = (params.min_triangles / SPARSE_PIECE_DIVISOR).max(1);
    let scale = largest_map_scale(params);
    // Phase I cuts a component only where the cells would hold min_triangles, which a
    // sparse object never does: here any cell is worth cutting.
    let any_cell = PrepareParams {
        min_triangles: 1,
        ..params.clone()
    };
    let objects = std::slice::from_ref(object);
    let mut side = sl_c * scale as f64;
    // A side of 0 (a scene all at one point) would never grow.
    while side > 0.0 && side.is_finite() {
        // Counted before regrouping, which costs more than the clustering: only the side
        // kept is regrouped (every base cluster holds a triangle, so groups are pieces).
        let clustered = cluster(objects, side, &any_cell);
        let pieces = u64::from(clustered.clustering.group_count);
        if pieces < 2 {
            return None;
        }
        if triangles >= least * pieces {
            return Some((scale, side, clustered.regroup(objects)));
        }
        side *= 2.0;
    }
    None
}

/// What cutting a set of objects at one side gave.
struct Cut {
    objects: Vec<Object>,
    phases: Vec<PhaseReport>,
    cache_state: String,
    duplicate_faces: u64,
    /// Triangles the pieces dropped as zero-area ([`ObjectBuilder::finish`]).
    zero_area: u64,
}

/// Phases I and III on `objects` at the largest side `sl_c`, answered from the cache when
/// it holds them, and the pieces they make.
fn cut(objects: &[Object], sl_c: f64, params: &PrepareParams) -> Cut {
    cluster(objects, sl_c, params).regroup(objects)
}

/// Which piece each triangle goes to, before the pieces are built.
struct Clustered {
    clustering: cache::CachedClustering,
    phases: Vec<PhaseReport>,
    cache_state: String,
}

impl Clustered {
    /// The pieces of `objects` (those clustered).
    fn regroup(self, objects: &[Object]) -> Cut {
        let (pieces, zero_area) = regroup(objects, &self.clustering);
        Cut {
            objects: pieces,
            phases: self.phases,
            cache_state: self.cache_state,
            duplicate_faces: self.clustering.duplicate_faces,
            zero_area,
        }
    }
}

/// Phases I and III on `objects` at the largest side `sl_c`, answered from the cache when
/// it holds them.
fn cluster(objects: &[Object], sl_c: f64, params: &PrepareParams) -> Clustered {
    let mut phases = Vec::new();
    let cut_refs: Vec<&Object> = objects.iter().collect();
    let parameters = [sl_c, params.min_triangles as f64];
    let cache_path = params
        .cache_dir
        .as_ref()
        .map(|dir| cache::path(dir, cache::key(&cut_refs, &parameters)));
    let cached = cache_path
        .as_ref()
        .and_then(|path| cache::read(path, &cut_refs));
    let mut cache_state = match (&cache_path, &cached) {
        (None, _) => "disabled".to_string(),
        (Some(_), Some(_)) => "hit".into(),
        (Some(_), None) => "miss".into(),
    };
    let clustering = match cached {
        Some(cached) => {
            for name in ["phase I: components", "phase III: clustering"] {
                phases.push(PhaseReport {
                    name,
                    ran: true,
                    note: "answered from the cache".into(),
                    seconds: 0.0,
                });
            }
            cached
        }
        None => {
            let (computed, phase_one, phase_three) = cut_and_cluster(&cut_refs, sl_c, params);
            phases.push(phase_one);
            phases.push(phase_three);
            if let Some(path) = &cache_path {
                // A cache that cannot be written costs time next run, nothing else.
                if let Err(error) = cache::write(path, &computed) {
                    cache_state = format!("miss (not written: {error})");
                }
            }
            computed
        }
    };
    Clustered {
        clustering,
        phases,
        cache_state,
    }
}

/// The class of one object for a given `sl_c`.
pub fn classify(object: &Object, sl_c: f64, min_triangles: u64) -> ObjectClass {
    if object.bounds().longest_side() > sl_c {
        ObjectClass::TooLarge
    } else if (object.triangles.len() as u64) < min_triangles {
        ObjectClass::TooSimple
    } else {
        ObjectClass::Suitable
    }
}

fn check_params(params: &PrepareParams) -> Result<(), SceneError> {
    let bad = |message: String| Err(SceneError::BadParameter(message));
    if params.t_nz == 0 {
        return bad("t_nz must be at least 1 triangle".into());
    }
    if !(1..=16_384).contains(&params.map_size) {
        return bad(format!(
            "map size must lie in 1..=16384 pixels, got {}",
            params.map_size
        ));
    }
    if params.resolution.iter().any(|r| !(1..=65_536).contains(r)) {
        return bad(format!(
            "resolution must lie in 1..=65536 pixels a side, got {:?}",
            params.resolution
        ));
    }
    if !(params.fov_y_degrees > 0.0 && params.fov_y_degrees < 180.0) {
        return bad(format!(
            "field of view must lie strictly between 0 and 180 degrees, got {}",
            params.fov_y_degrees
        ));
    }
    Ok(())
}

/// Phases I and III on the objects to cut.
fn cut_and_cluster(
    objects: &[&Object],
    sl_c: f64,
    params: &PrepareParams,
) -> (cache::CachedClustering, PhaseReport, PhaseReport) {
    let start = Instant::now();
    params.progress.set_message("phase I: components");
    let phase_one = components::split_into_components(objects, sl_c, params.min_triangles);
    let joinable = phase_one
        .clusters
        .iter()
        .filter(|c| c.bounds.longest_side() <= sl_c)
        .count();
    let phase_one_report = PhaseReport {
        name: "phase I: components",
        ran: true,
        note: format!(
            "{} objects: {} vertices welded, {} duplicate faces dropped, {} connected components, {} cut on a grid, {} base clusters ({} fit sl_c)",
            objects.len(),
            phase_one.welded_vertices,
            phase_one.duplicate_faces,
            phase_one.connected_components,
            phase_one.cut_components,
            phase_one.clusters.len(),
            joinable
        ),
        seconds: start.elapsed().as_secs_f64(),
    };

    let start = Instant::now();
    let boxes: Vec<_> = phase_one.clusters.iter().map(|c| c.bounds).collect();
    let (outcome, phase_three_report) = if joinable >= 2 {
        let outcome = cluster_boxes(&boxes, sl_c, &params.progress);
        let note = format!(
            "{} base clusters joined {} times into {} clusters",
            boxes.len(),
            outcome.joins,
            outcome.group_count
        );
        (
            outcome,
            PhaseReport {
                name: "phase III: clustering",
                ran: true,
                note,
                seconds: start.elapsed().as_secs_f64(),
            },
        )
    } else {
        let outcome = ClusterOutcome {
            group_of: (0..boxes.len() as u32).collect(),
            group_count: boxes.len(),
            joins: 0,
        };
        let note = "skipped: fewer than two base clusters fit sl_c, nothing to join".to_string();
        (
            outcome,
            PhaseReport {
                name: "phase III: clustering",
                ran: false,
                note,
                seconds: 0.0,
            },
        )
    };
    let group_of_triangle = phase_one
        .cluster_of_triangle
        .iter()
        .map(|clusters| {
            clusters
                .iter()
                .map(|&c| {
                    if c == components::DROPPED {
                        c
                    } else {
                        outcome.group_of[c as usize]
                    }
                })
                .collect()
        })
        .collect();
    let cached = cache::CachedClustering {
        group_of_triangle,
        group_count: outcome.group_count as u32,
        duplicate_faces: phase_one.duplicate_faces,
        welded_vertices: phase_one.welded_vertices,
        connected_components: phase_one.connected_components,
        cut_components: phase_one.cut_components,
        base_clusters: phase_one.clusters.len() as u64,
        joins: outcome.joins as u64,
    };
    (cached, phase_one_report, phase_three_report)
}

/// The vertices of `object` on a cut: used by triangles of two groups or more (or on a cut
/// made before).
fn cut_vertices(object: &Object, group_of_triangle: &[u32]) -> Vec<bool> {
    const UNSEEN: u32 = u32::MAX - 1;
    let mut group_of_vertex = vec![UNSEEN; object.positions.len()];
    let mut seams = object.seams.clone();
    for (triangle, &group) in object.triangles.iter().zip(group_of_triangle) {
        if group == components::DROPPED {
            continue;
        }
        for &v in triangle {
            let seen = &mut group_of_vertex[v as usize];
            if *seen == UNSEEN {
                *seen = group;
            } else if *seen != group {
                seams[v as usize] = true;
            }
        }
    }
    seams
}

/// Builds one object per group from the triangles of the cut objects; also returns how many
/// triangles the pieces dropped as zero-area.
fn regroup(objects: &[Object], clustering: &cache::CachedClustering) -> (Vec<Object>, u64) {
    let mut builders: Vec<ObjectBuilder> = (0..clustering.group_count)
        .map(|_| ObjectBuilder::new(""))
        .collect();
    // Per group, the builder's index of each (object, vertex) seen so far.
    let mut local: Vec<rustc_hash::FxHashMap<(u32, u32), u32>> =
        vec![Default::default(); clustering.group_count as usize];
    for (object_index, (object, groups)) in objects
        .iter()
        .zip(&clustering.group_of_triangle)
        .enumerate()
    {
        let seams = cut_vertices(object, groups);
        for (triangle, &group) in object.triangles.iter().zip(groups) {
            if group == components::DROPPED {
                continue;
            }
            let builder = &mut builders[group as usize];
            let map = &mut local[group as usize];
            let [a, b, c] = triangle.map(|v| {
                *map.entry((object_index as u32, v)).or_insert_with(|| {
                    let new = builder.vertex(object.world_position(v), object.colors[v as usize]);
                    if seams[v as usize] {
                        builder.mark_seam(new);
                    }
                    new
                })
            });
            builder.triangle(a, b, c);
        }
    }
    let mut zero_area = 0;
    let pieces = builders
        .into_iter()
        .map(|b| {
            let (piece, dropped) = b.finish();
            zero_area += dropped;
            piece
        })
        .filter(|o| !o.triangles.is_empty())
        .collect();
    (pieces, zero_area)
}

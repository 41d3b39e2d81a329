//! `visnode bench`: error against run time as a user lives it.
//!
//! 1. Record: frames are drawn back to back along a camera path defined in seconds
//!    (`--timing wall`), each with the camera at its start time; the image on screen is
//!    sampled at `--sample-hz` ([`crate::timeline`]). Only the frames shown at some sample
//!    instant are read back, with the clock stopped. `--timing frames` draws one path step
//!    per frame and samples every frame (reproducible, for tests).
//! 2. Reference: after the run, all geometry on the same adapter for the camera of every
//!    sample instant (shared by every run of one invocation: same path, same instants).
//! 3. Score: per sample, whole-frame and object-pixel MSE, FLIP over object pixels, and
//!    popping against the sample before; averaged as MSE before any dB.
//!
//! `--compare relief,lod,billboard,none` runs each kind on the same path and writes one
//! table, side-by-side frames and a Pareto plot; `--sweep` adds a curve over one knob.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use rayon::prelude::*;
use serde::Serialize;

use crate::camera::{Camera, CameraPredictor};
use crate::cli::{BenchArgs, BoardArgs, Impostor, SceneArgs, WorkerArgs};
use crate::image_error::{
    ImageError, PackedShot, Shot, compare, object_flip, psnr_db, temporal_mse,
};
use crate::plan::BudgetController;
use crate::timeline::{RunClock, TimedPath, Timing, instants_in};
use crate::viewer::{FrameReport, Viewer};

/// Frames drawn at the path's first camera before a `--timing frames` run, so the first boards
/// can arrive. A `--timing wall` run draws frames at its first camera until no board is asked
/// for or on its way (at most [`WARMUP_LIMIT_SECONDS`]) before its clock starts.
pub const WARMUP_FRAMES: usize = 8;

/// Longest warm-up of a `--timing wall` run, seconds.
pub const WARMUP_LIMIT_SECONDS: f64 = 60.0;

/// One drawn frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// The frame loop's report.
    #[serde(flatten)]
    pub report: FrameReport,
    /// When the frame started and completed, seconds on the run's clock.
    pub start: f64,
    /// Completion time.
    pub end: f64,
    /// Frame time: planning, command recording and GPU.
    pub frame_ms: f64,
    /// t_nz used for the frame (changes with `--target-frame-ms`).
    pub t_nz: u64,
}

/// One sample instant: what was on screen and how far it was from the reference.
#[derive(Debug, Clone, Serialize)]
pub struct SampleRecord {
    /// The instant, seconds (frames mode: the frame's number).
    pub t: f64,
    /// The frame on screen.
    pub frame: usize,
    /// How old the image on screen was: the instant less its frame's start, ms.
    pub age_ms: f64,
    /// Its error against the reference for the camera at `t`.
    pub error: ImageError,
    /// Its error against the reference for its frame's own camera (`--error-split`, or
    /// one step per frame): the part of `error` not due to the image's age.
    pub own_error: Option<ImageError>,
    /// Popping against the sample before (MSE of the change against the reference's change).
    pub popping_mse: Option<f64>,
}

/// Mean, percentiles and maximum of a sample: one definition for every report.
pub use report::Stats;

/// Image error over the samples of a run, averaged as MSE and then converted.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ErrorSummary {
    /// PSNR over object pixels from the mean object MSE, dB: the headline.
    pub object_psnr_db: f64,
    /// PSNR of the median sample's object MSE.
    pub object_psnr_p50_db: f64,
    /// PSNR of the 90th-percentile object MSE (nine samples in ten are better).
    pub object_psnr_p90_db: f64,
    /// Whole-frame PSNR from the mean MSE (sky and terrain included), dB.
    pub frame_psnr_db: f64,
    /// Object-pixel MSE per sample.
    pub object_mse: Stats,
    /// Whole-frame MSE per sample.
    pub frame_mse: Stats,
    /// Mean FLIP over object pixels per sample (0 identical, 1 most different).
    pub object_flip: Stats,
    /// Popping: root of the mean temporal MSE over object pixels, 0-255 scale.
    pub popping_rms: f64,
    /// Share of pixels off by more than `--diff-threshold`.
    pub differing_share: Stats,
    /// Share of the frame that is object pixels.
    pub object_share: f64,
    /// Age of the image on screen at the sample instants, ms.
    pub image_age_ms: Stats,
    /// Where the object-pixel error comes from.
    pub split: ErrorSplit,
}

/// The mean object-pixel MSE split by cause; the parts add up to the mean object MSE.
/// Silhouette and interior split the frames' own error where it is known (`--error-split`,
/// or one step per frame), else the whole.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ErrorSplit {
    /// Pixels only one of frame and reference shows an object on: outlines, holes,
    /// coverage.
    pub silhouette_mse: f64,
    /// Pixels both show an object on: colour, lighting, sampling, occlusion between
    /// objects.
    pub interior_mse: f64,
    /// What the image's age adds: the sample's error less its frame's own (`None` unless
    /// known).
    pub image_age_mse: Option<f64>,
}

impl ErrorSplit {
    /// The split of `samples`' mean object MSE.
    pub fn of(samples: &[SampleRecord]) -> ErrorSplit {
        let count = samples.len().max(1) as f64;
        let mean = |f: &dyn Fn(&SampleRecord) -> f64| samples.iter().map(f).sum::<f64>() / count;
        let total = mean(&|s| s.error.object_mse);
        let own_known = !samples.is_empty() && samples.iter().all(|s| s.own_error.is_some());
        let (basis, image_age_mse) = if own_known {
            let own = mean(&|s| s.own_error.map_or(0.0, |e| e.object_mse));
            let silhouette = mean(&|s| s.own_error.map_or(0.0, |e| e.silhouette_mse));
            ((own, silhouette), Some(total - own))
        } else {
            ((total, mean(&|s| s.error.silhouette_mse)), None)
        };
        ErrorSplit {
            silhouette_mse: basis.1,
            interior_mse: basis.0 - basis.1,
            image_age_mse,
        }
    }
}

/// What one run reports.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// The swept parameter's value, when sweeping.
    pub sweep_value: Option<String>,
    /// What stands in for far objects.
    pub impostor: Impostor,
    /// Scene source.
    pub scene: String,
    /// Triangles in the scene.
    pub triangles: u64,
    /// Objects.
    pub objects: usize,
    /// Suitable objects (those an impostor may replace: their pixels are object pixels).
    pub suitable: usize,
    /// The adapter.
    pub adapter: String,
    /// Image size.
    pub resolution: [u32; 2],
    /// How time advanced.
    pub timing: Timing,
    /// Path length in seconds (wall timing).
    pub path_seconds: f64,
    /// Sample instants per second (wall timing).
    pub sample_hz: f64,
    /// Sample instants scored.
    pub samples: usize,
    /// Frames drawn.
    pub frames: usize,
    /// Seconds of reading back images left out of the clock, the workers paused too.
    pub excluded_seconds: f64,
    /// Thread seconds the workers still rendered off the clock: boards begun before a pause
    /// and finished in it. `None` when some worker in use could not be paused (unreachable,
    /// or without the `Pause` call) and may have kept working.
    pub worker_seconds_off_clock: Option<f64>,
    /// Workers used (0: none).
    pub workers: usize,
    /// Frames waited for their boards.
    pub sync: bool,
    /// Planning parameters at the start.
    pub plan: crate::plan::PlanParams,
    /// Most cells per side of a board's grid.
    pub board_grid: u32,
    /// Map pixels per grid cell side.
    pub board_cell_pixels: u32,
    /// Where boards take their depth from.
    pub board_depth: crate::render::BoardDepth,
    /// Milliseconds of a frame spent uploading arrived boards at most.
    pub upload_ms: f64,
    /// The same while the camera stands still (the warm-up's first boards).
    pub still_upload_ms: f64,
    /// Unsuitable objects drawn whole (else through levels of detail).
    pub whole_unsuitable: bool,
    /// Objects waiting for a valid board drawn whole (else through levels of detail).
    pub whole_fallback: bool,
    /// Frames drawn for the predicted camera (`--timing wall`).
    pub predict_camera: bool,
    /// Boards' silhouettes blended by their coverage.
    pub soft_edges: bool,
    /// The LOD rule's pixel bound (`--impostor lod`).
    pub lod_pixels: Option<f64>,
    /// The atlas layout (`--impostor octahedral`).
    pub octahedral: Option<crate::far_field::octahedral::OctahedralParams>,
    /// Frame time, ms.
    pub frame_ms: Stats,
    /// Frame time of the reference (all geometry, same adapter), ms.
    pub reference_ms: Stats,
    /// Image error.
    pub error: ErrorSummary,
    /// Triangles drawn per frame.
    pub triangles_per_frame: Stats,
    /// Boards drawn per frame.
    pub boards_per_frame: Stats,
    /// GPU bytes held for the far field at the end: boards or atlases, and the suitable
    /// objects' coarser levels of detail.
    pub far_field_bytes: u64,
    /// GPU bytes of the unsuitable objects' coarser levels (0 with `--whole-unsuitable`).
    pub unsuitable_lod_bytes: u64,
    /// Seconds to load and prepare the scene (clustering, from the cache when there).
    pub load_seconds: f64,
    /// Seconds to build the frame loop: uploads, levels of detail, storing on workers.
    pub build_seconds: f64,
    /// Seconds of frames at the start camera before the clock started, until the first
    /// boards had arrived (`--timing wall`; 0 for kinds without boards after one frame).
    pub warmup_seconds: f64,
    /// Encoded board bytes received per second of the run.
    pub board_bytes_per_second: f64,
    /// Worker CPU seconds per board received, as the workers report.
    pub worker_seconds_per_board: f64,
    /// Request latency, issue to arrival, ms.
    pub latency_ms: Stats,
    /// Angle error of every drawn board, degrees.
    pub angle_error_degrees: Stats,
    /// Angle errors in 2.5-degree bins from 0 (Süß Figure 4.18).
    pub angle_error_histogram: Vec<u64>,
    /// Angle error quantiles 0.1, 0.25, 0.5, 0.75 and 0.9, degrees (a box plot's box).
    pub angle_error_box_degrees: [f64; 5],
    /// With `--path turn --timing wall`: seconds from the end of the turn until the first
    /// frame that draws every board within ε with no request in flight or issued (`None`
    /// on other paths, or when that never happened within the run).
    pub refresh_after_turn_s: Option<f64>,
    /// Request totals.
    pub requests: crate::workers::RequestCounts,
    /// Arrived boards that cross-faded in (the rest swapped in at once, `--fade-pixels`).
    pub boards_faded: u64,
    /// Why requests failed: each distinct message (up to 16) and how many times.
    pub failure_reasons: std::collections::BTreeMap<String, u64>,
    /// Requests still in flight when the run ended:
    /// `issued == received + failed + cancelled + pending`.
    pub requests_pending: u64,
    /// Each worker's address, in the order of the per-worker lists (workers that joined while
    /// running last).
    pub worker_addresses: Vec<String>,
    /// Boards received from each worker (a slower worker should answer fewer).
    pub boards_per_worker: Vec<u64>,
    /// Each worker's speed as the balancer measured it at the end (triangles per second of
    /// its own render time; 1 before any measurement).
    pub worker_speeds: Vec<f64>,
    /// Each worker's health at the end.
    pub worker_health: Vec<crate::workers::WorkerHealth>,
    /// Workers going down and coming back during the run.
    pub health_log: Vec<crate::workers::HealthRecord>,
    /// Boards held on the GPU at the end.
    pub boards_held: usize,
    /// Bytes of the boards held at the end.
    pub board_bytes_held: usize,
    /// Peak resident memory of the process.
    pub peak_memory_bytes: Option<u64>,
    /// Why no boards were used, if none were.
    pub no_boards_reason: Option<String>,
}

/// The path every run of one invocation flies, and the reference for every sample instant:
/// all geometry, drawn once per invocation.
#[derive(Default)]
struct References {
    /// The first run's path. A flythrough keeps above the ground, the objects that run's
    /// scene left unsuitable, and that set changes with `t_nz`: each run's own path would
    /// score a t-nz sweep's later runs against another path's references.
    cameras: Option<Vec<Camera>>,
    /// Whether every reference is kept once scored: when later runs of the invocation are
    /// scored against them (and `compare-NNNN.png` shows them beside every run's shot).
    /// Otherwise only the picked samples' are kept, for their pictures: held to the end,
    /// 360 references took 0.8 GB of peak memory (the forest at 3 M, 2.5 against 1.7 GB).
    keep_all: bool,
    /// Per sample instant, its reference once drawn (compressed, as a run's shots are);
    /// `None` once scored and not kept.
    shots: Vec<Option<PackedShot>>,
    draw_ms: Vec<f64>,
}

impl References {
    /// The reference of sample `k`, which must still be held.
    fn shot(&self, k: usize) -> anyhow::Result<Shot> {
        self.shots
            .get(k)
            .and_then(Option::as_ref)
            .map(PackedShot::unpack)
            .with_context(|| format!("the reference of sample {k} is not held"))
    }
}

/// What a run recorded: its frames, and for each sample instant the shot on screen.
struct Recording {
    /// Seconds of frames at the start camera before the clock started (`--timing wall`).
    warmup_seconds: f64,
    frames: Vec<FrameRecord>,
    /// Per frame: the camera it was drawn for.
    frame_cameras: Vec<Camera>,
    /// Per sample: its instant, its camera, the frame on screen and its shot.
    samples: Vec<(f64, Camera, usize, usize)>,
    /// Compressed: held until the run is over and its references drawn, 360 shots took
    /// about 0.9 GB at 1024x768 raw.
    shots: Vec<PackedShot>,
    excluded_seconds: f64,
    worker_seconds_off_clock: Option<f64>,
    seconds: f64,
}

impl Recording {
    /// The shot on screen at sample instant `k`.
    fn shown(&self, k: usize) -> Shot {
        self.shots[self.samples[k].3].unpack()
    }
}

pub(crate) fn run(args: &BenchArgs) -> anyhow::Result<()> {
    check_args(args)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let kinds = args
        .compare
        .clone()
        .unwrap_or_else(|| vec![args.boards.impostor]);
    let comparing = args.compare.is_some();
    // Every run of the invocation, each kind over the sweep's values.
    let mut runs = Vec::new();
    for kind in &kinds {
        for (value, scene, workers, mut boards) in sweep_runs(args, *kind)? {
            boards.impostor = *kind;
            runs.push((*kind, value, scene, workers, boards));
        }
    }
    let mut references = References {
        keep_all: runs.len() > 1,
        ..References::default()
    };
    let mut scenes = SceneCache::default();
    let mut summaries = Vec::new();
    let mut sample_shots: Vec<(String, Vec<Shot>)> = Vec::new();
    for (kind, value, scene, workers, boards) in runs {
        let name = run_name(comparing.then_some(kind), value.as_deref());
        let out = match &name {
            Some(name) => args.out.join(name),
            None => args.out.clone(),
        };
        std::fs::create_dir_all(&out)?;
        if let Some(name) = &name {
            eprintln!("run: {name}");
        }
        let (mut summary, shots) = run_once(
            args,
            &scene,
            &workers,
            &boards,
            &out,
            &mut scenes,
            &mut references,
        )?;
        summary.sweep_value = value;
        sample_shots.push((name.unwrap_or_default(), shots));
        summaries.push(summary);
    }
    // Written before the check, so a failed run still leaves its figures to look at.
    let accounted = |s: &Summary| {
        s.requests.issued
            == s.requests.received + s.requests.failed + s.requests.cancelled + s.requests_pending
    };
    if summaries.len() > 1 {
        write_table(&args.out, &summaries)?;
        crate::plots::pareto_plots(&args.out, &summaries)?;
        write_compare_frames(&args.out, &references, &sample_shots, args.sample_frames)?;
    }
    let text = if summaries.len() == 1 {
        serde_json::to_string_pretty(&summaries[0])?
    } else {
        serde_json::to_string_pretty(&summaries)?
    };
    std::fs::write(args.out.join("summary.json"), &text)?;
    if args.json {
        println!("{text}");
    } else {
        for s in &summaries {
            println!("{}", format_summary(s));
        }
        println!("wrote {}", args.out.display());
    }
    if let Some(s) = summaries.iter().find(|s| !accounted(s)) {
        anyhow::bail!(
            "requests were lost: {} issued, but {} received + {} failed + {} cancelled + {} pending",
            s.requests.issued,
            s.requests.received,
            s.requests.failed,
            s.requests.cancelled,
            s.requests_pending
        );
    }
    Ok(())
}

fn check_args(args: &BenchArgs) -> anyhow::Result<()> {
    if args.timing == Timing::Wall {
        anyhow::ensure!(
            !args.sync,
            "--sync makes every frame wait for its boards, which a user never sees: use it with --timing frames"
        );
        anyhow::ensure!(
            args.max_seconds.is_none(),
            "--max-seconds repeats the path for soaks: use it with --timing frames"
        );
    }
    if let Some(kinds) = &args.compare {
        anyhow::ensure!(!kinds.is_empty(), "--compare needs at least one kind");
    }
    Ok(())
}

/// A run's folder name: the kind when comparing, and the swept value.
fn run_name(kind: Option<Impostor>, value: Option<&str>) -> Option<String> {
    let kind = kind.map(|k| format!("{k:?}").to_lowercase());
    let value = value.map(|v| format!("run-{}", v.replace(['/', ' '], "_")));
    match (kind, value) {
        (Some(k), Some(v)) => Some(format!("{k}-{v}")),
        (k, v) => k.or(v),
    }
}

type Run = (Option<String>, SceneArgs, WorkerArgs, BoardArgs);

/// The kinds whose boards the workers make.
const BOARD_KINDS: &[Impostor] = &[Impostor::Relief, Impostor::Billboard];
/// The kinds with a near zone, the unsuitable objects' levels and a far field of their own:
/// all but geometry only.
const NEAR_ZONE_KINDS: &[Impostor] = &[
    Impostor::Relief,
    Impostor::Billboard,
    Impostor::Lod,
    Impostor::Octahedral,
    Impostor::Floor,
];
/// Every kind.
const EVERY_KIND: &[Impostor] = &[
    Impostor::Relief,
    Impostor::Billboard,
    Impostor::Lod,
    Impostor::Octahedral,
    Impostor::None,
    Impostor::Floor,
];

/// The knobs `--sweep` takes, and the kinds each applies to.
const SWEEPS: [(&str, &[Impostor]); 20] = [
    ("t-nz", NEAR_ZONE_KINDS),
    ("epsilon", BOARD_KINDS),
    ("refresh-pixels", BOARD_KINDS),
    ("map-size", BOARD_KINDS),
    ("texels-per-pixel", BOARD_KINDS),
    ("workers", BOARD_KINDS),
    ("board-grid", &[Impostor::Relief]),
    ("board-cell-pixels", &[Impostor::Relief]),
    ("board-depth", BOARD_KINDS),
    ("upload-ms", BOARD_KINDS),
    ("still-upload-ms", BOARD_KINDS),
    ("fade-frames", BOARD_KINDS),
    ("fade-pixels", BOARD_KINDS),
    ("whole-unsuitable", NEAR_ZONE_KINDS),
    ("whole-fallback", BOARD_KINDS),
    ("soft-edges", BOARD_KINDS),
    ("predict-camera", EVERY_KIND),
    ("triangle-cost-pixels", BOARD_KINDS),
    ("lod-pixels", &[Impostor::Lod]),
    ("octahedral-views", &[Impostor::Octahedral]),
];

/// The runs the `--sweep`s ask for of `kind`: one per value of every swept knob that applies
/// to it (one run without any, or when none applies).
fn sweep_runs(args: &BenchArgs, kind: Impostor) -> anyhow::Result<Vec<Run>> {
    let base = (
        None,
        args.scene.clone(),
        args.workers.clone(),
        args.boards.clone(),
    );
    let mut runs = Vec::new();
    for sweep in &args.sweep {
        runs.extend(one_sweep(sweep, kind, &base)?);
    }
    if runs.is_empty() {
        runs.push(base);
    }
    Ok(runs)
}

/// The runs of one `--sweep NAME=V1,V2,...` for `kind` (none when the knob does not apply).
fn one_sweep(sweep: &str, kind: Impostor, base: &Run) -> anyhow::Result<Vec<Run>> {
    let names = SWEEPS.map(|(name, _)| name).join(", ");
    let (name, values) = sweep
        .split_once('=')
        .with_context(|| format!("--sweep takes NAME=V1,V2,... ({names})"))?;
    let Some((_, kinds)) = SWEEPS.iter().find(|(n, _)| *n == name) else {
        anyhow::bail!("cannot sweep {name:?}: use {names}");
    };
    if !kinds.contains(&kind) {
        return Ok(Vec::new());
    }
    values
        .split(',')
        .map(|value| {
            let (_, mut scene, mut workers, mut boards) = base.clone();
            if let Some(switch) = match name {
                "whole-unsuitable" => Some(&mut boards.whole_unsuitable),
                "whole-fallback" => Some(&mut boards.whole_fallback),
                "predict-camera" => Some(&mut boards.predict_camera),
                "soft-edges" => Some(&mut boards.soft_edges),
                _ => None,
            } {
                // A switch, not a flag with a value.
                *switch = value.parse().map_err(|_| {
                    anyhow::anyhow!("--sweep {name} takes true or false, not {value:?}")
                })?;
                return Ok((Some(format!("{name}={value}")), scene, workers, boards));
            }
            let flag = if name == "workers" {
                "local-workers"
            } else {
                name
            };
            // Parsed as the flag itself would be, so a swept value is checked the same way.
            let parsed = match <crate::cli::Cli as clap::Parser>::try_parse_from([
                "visnode",
                "bench",
                &format!("--{flag}"),
                value,
            ]) {
                Ok(crate::cli::Cli {
                    command: Some(crate::cli::Command::Bench(parsed)),
                }) => parsed,
                Ok(_) => unreachable!("\"bench\" parses as the bench subcommand"),
                Err(error) => {
                    let message = error.to_string();
                    let first = message.lines().next().unwrap_or_default();
                    anyhow::bail!("--sweep {name}: {}", first.trim_start_matches("error: "))
                }
            };
            match name {
                "t-nz" => scene.t_nz = parsed.scene.t_nz,
                "epsilon" => boards.epsilon = parsed.boards.epsilon,
                "refresh-pixels" => boards.refresh_pixels = parsed.boards.refresh_pixels,
                "board-cell-pixels" => boards.board_cell_pixels = parsed.boards.board_cell_pixels,
                "board-depth" => boards.board_depth = parsed.boards.board_depth,
                "upload-ms" => boards.upload_ms = parsed.boards.upload_ms,
                "still-upload-ms" => boards.still_upload_ms = parsed.boards.still_upload_ms,
                "fade-frames" => boards.fade_frames = parsed.boards.fade_frames,
                "fade-pixels" => boards.fade_pixels = parsed.boards.fade_pixels,
                "map-size" => scene.map_size = parsed.scene.map_size,
                "texels-per-pixel" => boards.texels_per_pixel = parsed.boards.texels_per_pixel,
                "board-grid" => boards.board_grid = parsed.boards.board_grid,
                "lod-pixels" => boards.lod_pixels = parsed.boards.lod_pixels,
                "triangle-cost-pixels" => {
                    boards.triangle_cost_pixels = parsed.boards.triangle_cost_pixels
                }
                "octahedral-views" => boards.octahedral_views = parsed.boards.octahedral_views,
                _ => workers.local_workers = parsed.workers.local_workers,
            }
            Ok((Some(format!("{name}={value}")), scene, workers, boards))
        })
        .collect()
}

/// The loaded scene, kept between runs that load it with the same flags.
#[derive(Default)]
struct SceneCache {
    key: String,
    scene: Option<crate::setup::LoadedScene>,
    load_seconds: f64,
}

impl SceneCache {
    fn get(&mut self, args: &SceneArgs) -> anyhow::Result<(crate::setup::LoadedScene, f64)> {
        let key = format!("{args:?}");
        if self.key != key || self.scene.is_none() {
            let start = Instant::now();
            self.scene = Some(crate::setup::load_scene(args)?);
            self.load_seconds = start.elapsed().as_secs_f64();
            self.key = key;
        }
        let scene = self.scene.clone().expect("loaded above");
        Ok((scene, self.load_seconds))
    }
}

fn run_once(
    args: &BenchArgs,
    scene_args: &SceneArgs,
    worker_args: &WorkerArgs,
    board_args: &BoardArgs,
    out: &Path,
    scenes: &mut SceneCache,
    references: &mut References,
) -> anyhow::Result<(Summary, Vec<Shot>)> {
    crate::setup::check_flags(board_args)?;
    let (scene, load_seconds) = scenes.get(scene_args)?;
    let build_start = Instant::now();
    let renderer = crate::render::Renderer::new(scene_args.resolution)?;
    let crate::setup::Setup {
        mut viewer,
        summary: scene_summary,
    } = crate::setup::build(
        scene,
        renderer,
        scene_args,
        worker_args,
        board_args,
        args.sync,
        args.record_trace.is_some(),
    )?;
    let build_seconds = build_start.elapsed().as_secs_f64();
    let cameras = match &references.cameras {
        Some(cameras) => cameras.clone(),
        None => references
            .cameras
            .insert(viewer.camera_path(&args.path, args.frames, scene_args.fov_y_degrees)?)
            .clone(),
    };
    let recording = match args.timing {
        Timing::Wall => {
            // A path recorded by the window keeps the pace it was flown at.
            let times = match &args.path {
                crate::camera::PathKind::File(file) => crate::camera::read_timed_path(file)?.1,
                _ => None,
            };
            let path = match times {
                Some(times) => TimedPath::recorded(cameras, &times),
                None => TimedPath::new(cameras, args.path_seconds),
            };
            record_wall(&mut viewer, args, board_args, &path)?
        }
        Timing::Frames => record_frames(&mut viewer, args, board_args, &cameras)?,
    };
    let own_references = match args.timing {
        Timing::Wall if args.error_split => Some(draw_own_references(
            &mut viewer,
            scene_args.resolution,
            &recording,
        )?),
        _ => None,
    };
    let picked = picked_samples(recording.samples.len(), args.sample_frames);
    let samples = draw_references_and_score(
        &mut viewer,
        scene_args.resolution,
        &recording,
        references,
        own_references.as_deref(),
        &picked,
        args,
    )?;
    write_frames_csv(&out.join("frames.csv"), &recording.frames)?;
    write_samples_csv(&out.join("samples.csv"), &samples)?;
    let mut shown = Vec::new();
    for &k in &picked {
        let shot = recording.shown(k);
        crate::image_error::write_png(
            &crate::image_error::side_by_side(&references.shot(k)?.image(), &shot.image()),
            &out.join(format!("frame-{k:04}.png")),
        )?;
        shown.push(shot);
    }
    if let (Some(path), Some(trace)) = (
        &args.record_trace,
        viewer.requests().and_then(|r| r.trace()),
    ) {
        std::fs::write(path, trace.to_json_lines())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let summary = summarize(
        &viewer,
        &recording,
        &samples,
        references,
        (args, scene_args, board_args),
        &scene_summary,
        (load_seconds, build_seconds),
    );
    Ok((summary, shown))
}

/// Frames back to back along `path` for its length; the shot on screen at every sample
/// instant is read back (with the clock stopped) once the frame after it completes.
fn record_wall(
    viewer: &mut Viewer,
    args: &BenchArgs,
    board_args: &BoardArgs,
    path: &TimedPath,
) -> anyhow::Result<Recording> {
    let resolution = viewer_resolution(args);
    let hz = args.sample_hz;
    let mut controller = board_args
        .target_frame_ms
        .map(|target| BudgetController::new(target, viewer.options.plan.t_nz));
    let progress = crate::progress::bar();
    progress.set_length((path.seconds * 1000.0) as u64);
    progress.set_message("milliseconds of the path");
    // Frame 0: what is on screen when the clock starts. Like the alternatives' load-time
    // work (levels built, views baked), the first boards for the starting view are part of
    // getting ready: frames at the start camera until nothing is asked for or on its way.
    let warmup = Instant::now();
    let mut first = viewer.frame(&path.at(0.0), resolution)?;
    while (first.requests_issued > 0 || first.requests_pending > 0)
        && warmup.elapsed().as_secs_f64() < WARMUP_LIMIT_SECONDS
    {
        first = viewer.frame(&path.at(0.0), resolution)?;
    }
    let warmup_seconds = warmup.elapsed().as_secs_f64();
    let mut frame_cameras = vec![path.at(0.0)];
    let mut frames = vec![FrameRecord {
        frame_ms: first.plan_ms + first.timing.cpu_ms + first.timing.gpu_ms,
        report: first,
        start: 0.0,
        end: 0.0,
        t_nz: viewer.options.plan.t_nz,
    }];
    let mut samples = Vec::new();
    let mut shots = Vec::new();
    // Without a terminal the bar is hidden; this line tells a log (and deploy/test-compose.sh)
    // that the timed run, with workers answering, has begun.
    eprintln!("flying the path: {:.1} s", path.seconds);
    let mut predictor = CameraPredictor::default();
    let mut clock = RunClock::start();
    let mut worker_seconds = Some(0.0);
    loop {
        let start = clock.now();
        if start >= path.seconds {
            break;
        }
        // The frame on screen stays readable in the spare target while this one draws.
        viewer.renderer.swap_targets();
        let t_nz = viewer.options.plan.t_nz;
        let camera = if board_args.predict_camera {
            predictor.predict(start, path.at(start))
        } else {
            path.at(start)
        };
        let report = viewer.frame(&camera, resolution)?;
        frame_cameras.push(camera);
        let end = clock.now();
        predictor.frame_done(end - start);
        let frame_ms = (end - start) * 1e3;
        if let Some(controller) = &mut controller {
            viewer.options.plan.t_nz = controller.update(frame_ms);
        }
        let previous = frames.len() - 1;
        let shown = instants_in(hz, frames[previous].end, end.min(path.seconds));
        if !shown.is_empty() {
            let shot = off_clock(&mut clock, &mut worker_seconds, viewer, |viewer| {
                viewer.renderer.swap_targets();
                let shot = Shot::read(&viewer.renderer).map(PackedShot::pack);
                viewer.renderer.swap_targets();
                shot
            })?;
            for k in shown {
                let t = k as f64 / hz;
                samples.push((t, path.at(t), previous, shots.len()));
            }
            shots.push(shot);
        }
        frames.push(FrameRecord {
            report,
            start,
            end,
            frame_ms,
            t_nz,
        });
        progress.set_position((end.min(path.seconds) * 1000.0) as u64);
    }
    // The last frame stays on screen until the path ends.
    let last = frames.len() - 1;
    let shown = instants_in(hz, frames[last].end, path.seconds);
    if !shown.is_empty() {
        let shot = PackedShot::pack(Shot::read(&viewer.renderer)?);
        for k in shown {
            let t = k as f64 / hz;
            samples.push((t, path.at(t), last, shots.len()));
        }
        shots.push(shot);
    }
    progress.finish_and_clear();
    Ok(Recording {
        warmup_seconds,
        frames,
        frame_cameras,
        samples,
        shots,
        excluded_seconds: clock.excluded_seconds(),
        worker_seconds_off_clock: worker_seconds,
        seconds: path.seconds,
    })
}

/// One path step per frame after a warm-up, every frame sampled (reproducible runs).
fn record_frames(
    viewer: &mut Viewer,
    args: &BenchArgs,
    board_args: &BoardArgs,
    cameras: &[Camera],
) -> anyhow::Result<Recording> {
    let resolution = viewer_resolution(args);
    let mut controller = board_args
        .target_frame_ms
        .map(|target| BudgetController::new(target, viewer.options.plan.t_nz));
    let progress = crate::progress::bar();
    progress.set_length((WARMUP_FRAMES + cameras.len()) as u64);
    progress.set_message("frames");
    for _ in 0..WARMUP_FRAMES {
        viewer.frame(&cameras[0], resolution)?;
        progress.inc(1);
    }
    // With a time limit the path repeats until the time is up (soaks); without, it runs once.
    let count = if args.max_seconds.is_some() {
        usize::MAX
    } else {
        cameras.len()
    };
    // A soak keeps only the last shot: its images are not scored, it must run for hours.
    let keep_shots = args.max_seconds.is_none();
    let mut clock = RunClock::start();
    let mut worker_seconds = Some(0.0);
    let (mut frames, mut samples, mut shots) = (Vec::new(), Vec::new(), Vec::new());
    let mut frame_cameras = Vec::new();
    for (index, camera) in cameras.iter().cycle().take(count).enumerate() {
        let start = clock.now();
        if args.max_seconds.is_some_and(|limit| start > limit) {
            break;
        }
        let t_nz = viewer.options.plan.t_nz;
        let report = viewer.frame(camera, resolution)?;
        frame_cameras.push(*camera);
        let frame_ms = report.plan_ms + report.timing.cpu_ms + report.timing.gpu_ms;
        if let Some(controller) = &mut controller {
            viewer.options.plan.t_nz = controller.update(frame_ms);
        }
        let end = clock.now();
        if keep_shots {
            samples.push((index as f64, *camera, index, shots.len()));
            shots.push(off_clock(
                &mut clock,
                &mut worker_seconds,
                viewer,
                |viewer| Shot::read(&viewer.renderer).map(PackedShot::pack),
            )?);
        }
        frames.push(FrameRecord {
            report,
            start,
            end,
            frame_ms,
            t_nz,
        });
        progress.inc(1);
    }
    progress.finish_and_clear();
    Ok(Recording {
        warmup_seconds: 0.0,
        seconds: clock.now(),
        frames,
        frame_cameras,
        samples,
        shots,
        excluded_seconds: clock.excluded_seconds(),
        worker_seconds_off_clock: worker_seconds,
    })
}

/// Measures the run with its clock stopped and the workers paused too, so the run neither
/// pays for being measured nor gains worker time from it. Adds to `worker_seconds` what the
/// workers still rendered in the pause (boards begun before it); sets it to `None` when some
/// worker in use could not be paused or did not say.
fn off_clock<T, E>(
    clock: &mut RunClock,
    worker_seconds: &mut Option<f64>,
    viewer: &mut Viewer,
    measure: impl FnOnce(&mut Viewer) -> Result<T, E>,
) -> Result<T, E> {
    clock.pause();
    let workers = viewer.pause_workers();
    let measured = measure(viewer);
    *worker_seconds = match (workers.resume(), *worker_seconds) {
        (Some(rendered), Some(seconds)) => Some(seconds + rendered.as_secs_f64()),
        _ => None,
    };
    clock.resume();
    measured
}

fn viewer_resolution(args: &BenchArgs) -> [u32; 2] {
    args.scene.resolution
}

/// `--error-split`: all geometry for the camera of every shown frame, by shot, so a sample's
/// error splits into the frame's own and what its age adds (the camera moved on).
fn draw_own_references(
    viewer: &mut Viewer,
    resolution: [u32; 2],
    recording: &Recording,
) -> anyhow::Result<Vec<Shot>> {
    let mut frame_of_shot = vec![0; recording.shots.len()];
    for &(_, _, frame, shot) in &recording.samples {
        frame_of_shot[shot] = frame;
    }
    let progress = crate::progress::bar();
    progress.set_length(frame_of_shot.len() as u64);
    progress.set_message("reference frames for each shown frame's own camera");
    let mut shots = Vec::with_capacity(frame_of_shot.len());
    for frame in frame_of_shot {
        viewer.reference_frame(&recording.frame_cameras[frame], resolution)?;
        shots.push(Shot::read(&viewer.renderer)?);
        progress.inc(1);
    }
    progress.finish_and_clear();
    Ok(shots)
}

/// Samples scored at a time: their references are drawn one after another, then scored in
/// parallel (FLIP is slow), never while a reference is drawn, whose time is geometry only's
/// frame time.
const SCORE_BATCH: usize = 32;

/// Draws the reference of every sample instant not drawn yet (they are the same for every
/// run of one invocation: same path, same instants) and scores every sample against its
/// reference and, with `own_references` (by shot), against the reference of its frame's
/// own camera. References no later run needs are dropped once scored, except the `picked`
/// samples' (their pictures).
fn draw_references_and_score(
    viewer: &mut Viewer,
    resolution: [u32; 2],
    recording: &Recording,
    references: &mut References,
    own_references: Option<&[Shot]>,
    picked: &[usize],
    args: &BenchArgs,
) -> anyhow::Result<Vec<SampleRecord>> {
    let count = recording.samples.len();
    let progress = crate::progress::bar();
    progress.set_length(count as u64);
    progress.set_message(if references.shots.len() < count {
        "reference frames (all geometry) and scores (MSE, FLIP, popping)"
    } else {
        "scoring samples (MSE, FLIP, popping)"
    });
    let records = score_in_batches(
        references,
        count,
        picked,
        |k| {
            let timing = viewer.reference_frame(&recording.samples[k].1, resolution)?;
            Ok((timing.cpu_ms + timing.gpu_ms, Shot::read(&viewer.renderer)?))
        },
        |k, reference, previous| {
            let record = score_sample(recording, k, reference, previous, own_references, args);
            progress.inc(1);
            record
        },
    );
    progress.finish_and_clear();
    records
}

/// The order of [`draw_references_and_score`], apart from what a reference is and how a
/// sample is scored: `draw(k)` gives the time and shot of sample `k`'s reference where
/// `references` lacks it, and `score(k, reference, previous reference)` scores it. A batch
/// at a time: drawn one after another, scored in parallel, then dropped unless
/// `references.keep_all` or `picked` (the last of a batch is held until the next batch has
/// compared with it).
fn score_in_batches<R: Send>(
    references: &mut References,
    count: usize,
    picked: &[usize],
    mut draw: impl FnMut(usize) -> anyhow::Result<(f64, Shot)>,
    score: impl Fn(usize, &Shot, Option<&Shot>) -> R + Sync,
) -> anyhow::Result<Vec<R>> {
    let mut records = Vec::with_capacity(count);
    for start in (0..count).step_by(SCORE_BATCH) {
        let end = (start + SCORE_BATCH).min(count);
        // This batch's references and the one before it: those held already, unpacked, then
        // those drawn now, as drawn.
        let first = start.saturating_sub(1);
        let drawn = references.shots.len().clamp(first, end);
        let mut held = (first..drawn)
            .map(|k| references.shot(k))
            .collect::<anyhow::Result<Vec<Shot>>>()?;
        for k in drawn..end {
            let (ms, shot) = draw(k)?;
            references.draw_ms.push(ms);
            references.shots.push(None);
            held.push(shot);
        }
        let reference = |k: usize| &held[k - first];
        let batch: Vec<R> = (start..end)
            .into_par_iter()
            .map(|k| score(k, reference(k), (k > 0).then(|| reference(k - 1))))
            .collect();
        records.extend(batch);
        // Kept packed: every reference for later runs, else the picked samples' for their
        // pictures and the batch's last for the next batch's popping; the rest are dropped
        // (those drawn now never packed).
        for (k, shot) in (first..end).zip(held) {
            let kept = references.keep_all || picked.contains(&k) || k + 1 == end && end < count;
            references.shots[k] = if !kept {
                None
            } else if k >= drawn {
                Some(PackedShot::pack(shot))
            } else {
                references.shots[k].take()
            };
        }
    }
    Ok(records)
}

/// Scores sample `k` against its `reference` (and the one before, for popping).
fn score_sample(
    recording: &Recording,
    k: usize,
    reference: &Shot,
    previous_reference: Option<&Shot>,
    own_references: Option<&[Shot]>,
    args: &BenchArgs,
) -> SampleRecord {
    let shot = recording.shown(k);
    let (t, _, frame, shot_index) = recording.samples[k];
    let mut error = compare(reference, &shot, args.diff_threshold);
    // One step per frame: the frame is its sample's own.
    let own_error = match (args.timing, own_references) {
        (Timing::Frames, _) => Some(error),
        (Timing::Wall, Some(own)) => Some(compare(&own[shot_index], &shot, args.diff_threshold)),
        (Timing::Wall, None) => None,
    };
    if !args.no_flip {
        error.object_flip = object_flip(reference, &shot);
    }
    let popping_mse = previous_reference
        .map(|previous| temporal_mse((previous, &recording.shown(k - 1)), (reference, &shot)));
    let age_ms = match args.timing {
        Timing::Wall => (t - recording.frames[frame].start) * 1e3,
        Timing::Frames => 0.0,
    };
    SampleRecord {
        t,
        frame,
        age_ms,
        error,
        own_error,
        popping_mse,
    }
}

/// Up to `count` sample indices spread evenly over `samples`.
fn picked_samples(samples: usize, count: usize) -> Vec<usize> {
    let count = count.min(samples);
    (0..count)
        .map(|i| i * samples / count + samples / (2 * count))
        .collect()
}

/// Seconds from the end of the turn of a `turn` path of `seconds` until the first frame after
/// it that draws every board within `epsilon` degrees, with no request in flight or issued:
/// every board the still view needs is fresh.
fn refresh_after_turn(frames: &[FrameRecord], seconds: f64, epsilon: f64) -> Option<f64> {
    let turned = crate::camera::TURN_ENDS * seconds;
    frames
        .iter()
        .filter(|f| f.start >= turned)
        .find(|f| {
            f.report.requests_pending == 0
                && f.report.requests_issued == 0
                && f.report.angle_errors.iter().all(|&a| a <= epsilon)
        })
        .map(|f| f.end - turned)
}

fn summarize(
    viewer: &Viewer,
    recording: &Recording,
    samples: &[SampleRecord],
    references: &References,
    (args, scene_args, board_args): (&BenchArgs, &SceneArgs, &BoardArgs),
    scene_summary: &scene::Summary,
    (load_seconds, build_seconds): (f64, f64),
) -> Summary {
    let frames = &recording.frames[(args.timing == Timing::Wall) as usize..];
    let angle_errors: Vec<f64> = frames
        .iter()
        .flat_map(|r| r.report.angle_errors.iter().copied())
        .collect();
    let mut histogram = vec![0u64; 19];
    for &a in &angle_errors {
        histogram[((a / 2.5) as usize).min(18)] += 1;
    }
    let mut sorted_errors: Vec<f64> = angle_errors
        .iter()
        .copied()
        .filter(|a| a.is_finite())
        .collect();
    sorted_errors.sort_by(f64::total_cmp);
    let angle_error_box_degrees =
        [0.1, 0.25, 0.5, 0.75, 0.9].map(|q| report::quantile(&sorted_errors, q));
    let refresh_after_turn_s = (args.path == crate::camera::PathKind::Turn
        && args.timing == Timing::Wall)
        .then(|| refresh_after_turn(frames, recording.seconds, board_args.epsilon))
        .flatten();
    let object_mse = Stats::of(samples.iter().map(|s| s.error.object_mse));
    let frame_mse = Stats::of(samples.iter().map(|s| s.error.mse));
    let pixels = (scene_args.resolution[0] as f64 * scene_args.resolution[1] as f64).max(1.0);
    let popping = Stats::of(samples.iter().filter_map(|s| s.popping_mse));
    let received: u64 = frames.iter().map(|f| f.report.latencies.len() as u64).sum();
    let (boards_held, board_bytes_held) = viewer.boards_held();
    let requests = viewer.requests();
    Summary {
        sweep_value: None,
        impostor: board_args.impostor,
        scene: scene_summary.source.clone(),
        triangles: scene_summary.triangles,
        objects: scene_summary.objects,
        suitable: scene_summary.suitable,
        adapter: viewer.renderer.adapter.clone(),
        resolution: scene_args.resolution,
        timing: args.timing,
        path_seconds: recording.seconds,
        sample_hz: args.sample_hz,
        samples: samples.len(),
        frames: frames.len(),
        excluded_seconds: recording.excluded_seconds,
        worker_seconds_off_clock: recording.worker_seconds_off_clock,
        workers: requests.map_or(0, |r| r.addresses().len()),
        sync: args.sync,
        plan: crate::setup::plan_params(scene_args, board_args),
        board_grid: board_args.board_grid,
        board_cell_pixels: board_args.board_cell_pixels,
        board_depth: board_args.board_depth,
        upload_ms: board_args.upload_ms,
        still_upload_ms: board_args.still_upload_ms,
        whole_unsuitable: board_args.whole_unsuitable,
        whole_fallback: board_args.whole_fallback,
        predict_camera: board_args.predict_camera,
        soft_edges: board_args.soft_edges,
        lod_pixels: (board_args.impostor == Impostor::Lod).then_some(board_args.lod_pixels),
        octahedral: (board_args.impostor == Impostor::Octahedral)
            .then(|| crate::far_field::octahedral_params(board_args, scene_summary.suitable)),
        frame_ms: Stats::of(frames.iter().map(|r| r.frame_ms)),
        reference_ms: Stats::of(references.draw_ms.iter().copied()),
        error: ErrorSummary {
            object_psnr_db: psnr_db(object_mse.mean),
            object_psnr_p50_db: psnr_db(object_mse.p50),
            object_psnr_p90_db: psnr_db(object_mse.p90),
            frame_psnr_db: psnr_db(frame_mse.mean),
            object_mse,
            frame_mse,
            object_flip: Stats::of(samples.iter().filter_map(|s| s.error.object_flip)),
            popping_rms: popping.mean.sqrt(),
            differing_share: Stats::of(samples.iter().map(|s| s.error.differing_share)),
            object_share: samples
                .iter()
                .map(|s| s.error.object_pixels as f64 / pixels)
                .sum::<f64>()
                / samples.len().max(1) as f64,
            image_age_ms: Stats::of(samples.iter().map(|s| s.age_ms)),
            split: ErrorSplit::of(samples),
        },
        triangles_per_frame: Stats::of(frames.iter().map(|r| r.report.triangles as f64)),
        boards_per_frame: Stats::of(frames.iter().map(|r| r.report.boards as f64)),
        far_field_bytes: viewer.far_field_bytes(),
        unsuitable_lod_bytes: viewer.unsuitable_lod_bytes(),
        load_seconds,
        build_seconds,
        warmup_seconds: recording.warmup_seconds,
        board_bytes_per_second: frames.iter().map(|f| f.report.board_bytes).sum::<u64>() as f64
            / recording.seconds.max(1e-9),
        worker_seconds_per_board: frames
            .iter()
            .map(|f| f.report.worker_render_seconds)
            .sum::<f64>()
            / received.max(1) as f64,
        latency_ms: Stats::of(
            frames
                .iter()
                .flat_map(|f| f.report.latencies.iter().map(|s| s * 1e3)),
        ),
        angle_error_degrees: Stats::of(angle_errors),
        angle_error_histogram: histogram,
        angle_error_box_degrees,
        refresh_after_turn_s,
        requests: requests.map(|r| r.counts).unwrap_or_default(),
        boards_faded: frames.iter().map(|f| f.report.boards_faded as u64).sum(),
        failure_reasons: requests
            .map(|r| r.failure_reasons().clone())
            .unwrap_or_default(),
        requests_pending: requests.map_or(0, |r| r.pending() as u64),
        worker_speeds: requests
            .map(|r| r.worker_status().iter().map(|w| w.speed).collect())
            .unwrap_or_default(),
        worker_addresses: requests.map(|r| r.addresses().to_vec()).unwrap_or_default(),
        boards_per_worker: requests
            .map(|r| r.received_by_worker().to_vec())
            .unwrap_or_default(),
        worker_health: requests.map(|r| r.health().to_vec()).unwrap_or_default(),
        health_log: requests
            .map(|r| r.health_log().to_vec())
            .unwrap_or_default(),
        boards_held,
        board_bytes_held,
        peak_memory_bytes: crate::peak_memory_bytes(),
        no_boards_reason: viewer.no_boards_reason().map(str::to_string),
    }
}

fn write_frames_csv(path: &Path, records: &[FrameRecord]) -> anyhow::Result<()> {
    let mut text = String::from(
        "frame,start_s,end_s,frame_ms,cpu_ms,gpu_ms,plan_ms,triangles,boards,geometry_objects,near_zone_triangles,t_nz,requests_issued,requests_pending,arrived,mean_latency_ms,mean_angle_error,upload_ms,uploads_waiting,requests_cancelled,cheaper_as_levels\n",
    );
    for r in records {
        let mean = |v: &[f64], scale: f64| {
            if v.is_empty() {
                String::new()
            } else {
                format!("{:.3}", v.iter().sum::<f64>() / v.len() as f64 * scale)
            }
        };
        text.push_str(&format!(
            "{},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{},{},{:.3},{},{},{}\n",
            r.report.frame,
            r.start,
            r.end,
            r.frame_ms,
            r.report.timing.cpu_ms,
            r.report.timing.gpu_ms,
            r.report.plan_ms,
            r.report.triangles,
            r.report.boards,
            r.report.geometry_objects,
            r.report.near_zone_triangles,
            r.t_nz,
            r.report.requests_issued,
            r.report.requests_pending,
            r.report.latencies.len(),
            mean(&r.report.latencies, 1e3),
            mean(&r.report.angle_errors, 1.0),
            r.report.upload_ms,
            r.report.uploads_waiting,
            r.report.requests_cancelled,
            r.report.cheaper_as_levels,
        ));
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn write_samples_csv(path: &Path, samples: &[SampleRecord]) -> anyhow::Result<()> {
    let mut text = String::from(
        "t,frame_shown,age_ms,object_psnr_db,frame_psnr_db,object_mse,frame_mse,object_flip,popping_mse,object_pixels,differing_share,silhouette_mse,own_object_mse,own_silhouette_mse\n",
    );
    for s in samples {
        let optional = |v: Option<f64>| v.map(|v| format!("{v:.5}")).unwrap_or_default();
        text.push_str(&format!(
            "{:.4},{},{:.2},{:.3},{:.3},{:.4},{:.4},{},{},{},{:.5},{:.4},{},{}\n",
            s.t,
            s.frame,
            s.age_ms,
            psnr_db(s.error.object_mse),
            psnr_db(s.error.mse),
            s.error.object_mse,
            s.error.mse,
            optional(s.error.object_flip),
            optional(s.popping_mse),
            s.error.object_pixels,
            s.error.differing_share,
            s.error.silhouette_mse,
            optional(s.own_error.map(|e| e.object_mse)),
            optional(s.own_error.map(|e| e.silhouette_mse)),
        ));
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// `compare.csv`: one row per run, the figures a user compares kinds by.
fn write_table(out: &Path, summaries: &[Summary]) -> anyhow::Result<()> {
    let mut text = String::from(
        "kind,run,frame_ms_mean,frame_ms_p95,object_psnr_db,object_psnr_p90_db,frame_psnr_db,object_flip_mean,popping_rms,image_age_ms_mean,triangles_per_frame,boards_per_frame,far_field_mib,load_s,build_s,warmup_s,board_kib_per_s,worker_ms_per_board,reference_ms_mean,object_mse,silhouette_mse,interior_mse,image_age_mse,requests_cancelled\n",
    );
    for s in summaries {
        text.push_str(&format!(
            "{},{},{:.2},{:.2},{:.2},{:.2},{:.2},{:.4},{:.2},{:.1},{:.0},{:.1},{:.2},{:.2},{:.2},{:.2},{:.1},{:.2},{:.2},{:.2},{:.2},{:.2},{},{}\n",
            format!("{:?}", s.impostor).to_lowercase(),
            s.sweep_value.as_deref().unwrap_or(""),
            s.frame_ms.mean,
            s.frame_ms.p95,
            s.error.object_psnr_db,
            s.error.object_psnr_p90_db,
            s.error.frame_psnr_db,
            s.error.object_flip.mean,
            s.error.popping_rms,
            s.error.image_age_ms.mean,
            s.triangles_per_frame.mean,
            s.boards_per_frame.mean,
            s.far_field_bytes as f64 / (1 << 20) as f64,
            s.load_seconds,
            s.build_seconds,
            s.warmup_seconds,
            s.board_bytes_per_second / 1024.0,
            s.worker_seconds_per_board * 1e3,
            s.reference_ms.mean,
            s.error.object_mse.mean,
            s.error.split.silhouette_mse,
            s.error.split.interior_mse,
            s.error
                .split
                .image_age_mse
                .map_or(String::new(), |m| format!("{m:.2}")),
            s.requests.cancelled,
        ));
    }
    std::fs::write(out.join("compare.csv"), text)?;
    Ok(())
}

/// `compare-NNNN.png`: the reference and every run's shot of one sample instant, left to
/// right in the order of `compare.csv`.
fn write_compare_frames(
    out: &Path,
    references: &References,
    runs: &[(String, Vec<Shot>)],
    count: usize,
) -> anyhow::Result<()> {
    let picked = picked_samples(references.shots.len(), count);
    for (i, &k) in picked.iter().enumerate() {
        let mut row = vec![references.shot(k)?.image()];
        row.extend(
            runs.iter()
                .filter_map(|(_, shots)| shots.get(i).map(Shot::image)),
        );
        let row: Vec<&crate::render::Image> = row.iter().collect();
        let path: PathBuf = out.join(format!("compare-{k:04}.png"));
        crate::image_error::write_png(&crate::image_error::row_of(&row), &path)?;
    }
    Ok(())
}

fn format_summary(s: &Summary) -> String {
    let e = &s.error;
    format!(
        "{run}{kind}: {scene}, {triangles} triangles, {frames} frames ({timing:?} timing, {samples} samples) at {w}x{h} on {adapter}, t_nz {t_nz}\n  \
         frame time {fm:.1} ms (p95 {fp:.1}); geometry only {rm:.1} ms\n  \
         object pixels ({share:.1}% of the frame): PSNR {opsnr:.2} dB (90% of samples above {op90:.2} dB), FLIP {flip:.3}, popping {pop:.1} RMS\n  \
         whole frame: PSNR {fpsnr:.2} dB; image on screen {age:.0} ms old on average\n  \
         object MSE {omse:.1}: silhouettes {sil:.1}, interiors {int:.1}{agemse}\n  \
         far field {mib:.1} MiB on the GPU; load {load:.1} s, build {build:.1} s, first boards {warm:.1} s\n  \
         requests: {issued} issued, {received} received ({faded} cross-faded in), {failed} failed, {cancelled} cancelled, {pending} pending, latency p50 {lp50:.0} ms p90 {lp90:.0} ms; \
         angle error mean {am:.1} deg; {boards:.0} boards per frame; boards per worker {per_worker:?}",
        run = s
            .sweep_value
            .as_ref()
            .map(|v| format!("[{v}] "))
            .unwrap_or_default(),
        kind = format!("{:?}", s.impostor).to_lowercase(),
        scene = s.scene,
        triangles = s.triangles,
        frames = s.frames,
        timing = s.timing,
        samples = s.samples,
        w = s.resolution[0],
        h = s.resolution[1],
        adapter = s.adapter,
        t_nz = s.plan.t_nz,
        fm = s.frame_ms.mean,
        fp = s.frame_ms.p95,
        rm = s.reference_ms.mean,
        share = e.object_share * 100.0,
        opsnr = e.object_psnr_db,
        op90 = e.object_psnr_p90_db,
        flip = e.object_flip.mean,
        pop = e.popping_rms,
        fpsnr = e.frame_psnr_db,
        age = e.image_age_ms.mean,
        omse = e.object_mse.mean,
        sil = e.split.silhouette_mse,
        int = e.split.interior_mse,
        agemse = e
            .split
            .image_age_mse
            .map(|m| format!(", the image's age {m:.1}"))
            .unwrap_or_default(),
        mib = s.far_field_bytes as f64 / (1 << 20) as f64,
        load = s.load_seconds,
        build = s.build_seconds,
        warm = s.warmup_seconds,
        issued = s.requests.issued,
        received = s.requests.received,
        faded = s.boards_faded,
        failed = s.requests.failed,
        cancelled = s.requests.cancelled,
        pending = s.requests_pending,
        lp50 = s.latency_ms.p50,
        lp90 = s.latency_ms.p90,
        am = s.angle_error_degrees.mean,
        boards = s.boards_per_frame.mean,
        per_worker = s.boards_per_worker,
    ) + &s
        .failure_reasons
        .iter()
        .map(|(why, n)| format!("\n  {n} failed: {why}"))
        .collect::<String>()
        + &s.refresh_after_turn_s
            .map(|r| format!("\n  every board fresh {r:.2} s after the turn ended"))
            .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::{
        EVERY_KIND, FrameRecord, NEAR_ZONE_KINDS, References, SCORE_BATCH, picked_samples,
        refresh_after_turn, score_in_batches,
    };
    use crate::cli::Impostor;
    use crate::image_error::Shot;
    use crate::render::Image;
    use crate::viewer::FrameReport;
    use clap::ValueEnum;

    /// The kind lists are written out (consts); a kind added to `Impostor` must join them.
    #[test]
    fn every_kind_is_every_impostor_and_the_near_zone_kinds_all_but_geometry_only() {
        assert_eq!(EVERY_KIND, Impostor::value_variants());
        let all_but_none: Vec<Impostor> = Impostor::value_variants()
            .iter()
            .copied()
            .filter(|kind| *kind != Impostor::None)
            .collect();
        assert_eq!(NEAR_ZONE_KINDS, all_but_none.as_slice());
    }

    /// Each reference is drawn once, in order, scored against its own sample and the one
    /// before; an invocation of one run keeps only the picked samples' once scored, one of
    /// several keeps all, and a later run draws only the instants it lacks.
    #[test]
    fn references_are_drawn_once_scored_with_their_sample_and_dropped_unless_kept() {
        // A one-pixel shot whose red says which sample it was drawn for.
        let shot = |k: usize| {
            let image = Image {
                width: 1,
                height: 1,
                rgba: vec![k as u8, 0, 0, 255],
            };
            Shot::new(&image, &[true])
        };
        let id = |s: &Shot| s.rgb(0)[0] as usize;
        // Past two batches, so a batch's first sample compares with the last one's.
        let count = 2 * SCORE_BATCH + 5;
        let picked = [3, SCORE_BATCH - 1, SCORE_BATCH, count - 1];
        for keep_all in [false, true] {
            let mut references = References {
                keep_all,
                ..References::default()
            };
            let mut drawn = Vec::new();
            let scored = score_in_batches(
                &mut references,
                count,
                &picked,
                |k| {
                    drawn.push(k);
                    Ok((k as f64, shot(k)))
                },
                |k, reference, previous| (k, id(reference), previous.map(id)),
            )
            .unwrap();
            assert_eq!(drawn, (0..count).collect::<Vec<_>>());
            let expected: Vec<_> = (0..count).map(|k| (k, k, k.checked_sub(1))).collect();
            assert_eq!(scored, expected);
            assert_eq!(
                references.draw_ms,
                (0..count).map(|k| k as f64).collect::<Vec<_>>()
            );
            let held: Vec<usize> = (0..count)
                .filter(|&k| references.shots[k].is_some())
                .collect();
            if !keep_all {
                assert_eq!(held, picked);
                continue;
            }
            assert_eq!(held.len(), count);
            // The next run, three instants longer, draws those three only.
            let mut drawn = Vec::new();
            let scored = score_in_batches(
                &mut references,
                count + 3,
                &[],
                |k| {
                    drawn.push(k);
                    Ok((k as f64, shot(k)))
                },
                |k, reference, previous| (k, id(reference), previous.map(id)),
            )
            .unwrap();
            assert_eq!(drawn, vec![count, count + 1, count + 2]);
            let expected: Vec<_> = (0..count + 3).map(|k| (k, k, k.checked_sub(1))).collect();
            assert_eq!(scored, expected);
        }
    }

    #[test]
    fn picked_samples_spread_over_the_run() {
        assert_eq!(picked_samples(10, 2), vec![2, 7]);
        assert_eq!(picked_samples(3, 5), vec![0, 1, 2]);
        assert!(picked_samples(0, 3).is_empty());
    }

    #[test]
    fn boards_are_fresh_after_a_turn_at_the_first_still_frame_with_nothing_in_flight() {
        // A 10 s path: the turn ends at 4.5 s. Frames of 0.5 s from 4.0 s on.
        let frame = |start: f64, pending: usize, issued: usize, errors: &[f64]| FrameRecord {
            report: FrameReport {
                requests_pending: pending,
                requests_issued: issued,
                angle_errors: errors.to_vec(),
                ..FrameReport::default()
            },
            start,
            end: start + 0.5,
            frame_ms: 500.0,
            t_nz: 0,
        };
        let frames = [
            // Fresh before the turn ended: does not count.
            frame(4.0, 0, 0, &[1.0]),
            frame(4.5, 3, 3, &[40.0]),
            // Nothing in flight, but a board still past ε.
            frame(5.0, 0, 0, &[1.0, 12.0]),
            frame(5.5, 1, 1, &[1.0]),
            frame(6.0, 0, 0, &[1.0, 11.0]),
            frame(6.5, 0, 0, &[]),
        ];
        assert_eq!(refresh_after_turn(&frames, 10.0, 11.5), Some(6.5 - 4.5));
        assert_eq!(refresh_after_turn(&frames[..4], 10.0, 11.5), None);
    }
}

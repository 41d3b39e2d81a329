//! Command-line flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// The reliefboard visualization node.
#[derive(Debug, Parser)]
#[command(name = "visnode", version, about)]
pub struct Cli {
    /// What to do; without one, `view` on the default scene.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Open a window and fly through the scene, watching the boards and the workers.
    View(ViewArgs),
    /// Load a scene, cut it into objects and report which become reliefboards.
    Inspect(InspectArgs),
    /// Render a camera path with reliefboards and with geometry only, and report image error
    /// against frame time.
    Bench(BenchArgs),
    /// Start backend workers as processes on this machine and run `view` or `bench` on them.
    Cluster(ClusterArgs),
}

/// Which scene to load and how to cut it: shared by every subcommand that reads a scene.
#[derive(Debug, Args, Clone)]
#[command(next_help_heading = "Scene")]
pub struct SceneArgs {
    /// A mesh file (.ply, .obj, .gltf, .glb, optionally .gz) or a built-in scene: forest, plant.
    #[arg(long, default_value = "forest")]
    pub scene: String,
    /// Triangle target of a built-in scene.
    #[arg(long, default_value_t = 10_000_000, value_parser = in_range(1u64, 1_000_000_000))]
    pub triangles: u64,
    /// Seed of a built-in scene.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A mesh copied into the built-in forest beside its trees (repeatable).
    #[arg(long = "forest-mesh")]
    pub forest_meshes: Vec<PathBuf>,
    /// Near-zone triangle budget t_nz [default: 100000 when frames are drawn on a CPU
    /// adapter (lavapipe, llvmpipe) or none is found, 1000000 on a GPU].
    #[arg(long = "t-nz", value_parser = in_range(1u64, 10_000_000_000))]
    pub t_nz: Option<u64>,
    /// Largest reliefboard map side p, in pixels.
    #[arg(long = "map-size", default_value_t = scene::PrepareParams::DEFAULT_MAP_SIZE,
        value_parser = in_range(8u32, 4096))]
    pub map_size: u32,
    /// Display resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768", value_parser = parse_resolution)]
    pub resolution: [u32; 2],
    /// Vertical field of view in degrees.
    #[arg(long = "fov", default_value_t = scene::PrepareParams::DEFAULT_FOV_Y_DEGREES,
        value_parser = in_range(1.0, 170.0))]
    pub fov_y_degrees: f64,
    /// Objects with fewer triangles are too simple for a reliefboard.
    #[arg(long = "min-triangles", default_value_t = scene::PrepareParams::DEFAULT_MIN_TRIANGLES,
        value_parser = in_range(0u64, 1_000_000_000))]
    pub min_triangles: u64,
    /// Refuse a mesh file that yields more triangles (glTF instancing multiplies them).
    #[arg(long = "max-triangles", default_value_t = scene::LoadLimits::DEFAULT_MAX_TRIANGLES,
        value_parser = in_range(1u64, 10_000_000_000))]
    pub max_triangles: u64,
    /// Refuse a gzipped mesh file that inflates past this many MiB.
    #[arg(long = "max-inflated-mb", default_value_t = scene::LoadLimits::DEFAULT_MAX_INFLATED_BYTES >> 20,
        value_parser = in_range(1u64, 1 << 20))]
    pub max_inflated_mb: u64,
    /// Where clustering results are cached [default: $XDG_CACHE_HOME/reliefboard or ~/.cache/reliefboard].
    #[arg(long = "cache-dir")]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the clustering cache.
    #[arg(long = "no-cache")]
    pub no_cache: bool,
}

/// Flags of `visnode inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The scene.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write a top-down picture: suitable, too-large and too-simple objects in three colours.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

impl SceneArgs {
    /// `--t-nz`, or when it is not given the default for the adapter this machine draws
    /// frames on ([`crate::plan::default_t_nz`]).
    pub fn t_nz(&self) -> u64 {
        self.t_nz.unwrap_or_else(|| {
            crate::plan::default_t_nz(crate::render::headless_adapter().map(|a| a.device_type))
        })
    }

    /// How to load the scene these flags name, with progress shown on `progress`.
    pub fn load_options(&self, progress: scene::Progress) -> scene::LoadOptions {
        scene::LoadOptions {
            triangles: self.triangles,
            seed: self.seed,
            forest_meshes: self.forest_meshes.clone(),
            progress,
            limits: scene::LoadLimits {
                max_triangles: self.max_triangles,
                max_inflated_bytes: self.max_inflated_mb << 20,
                ..scene::LoadLimits::default()
            },
        }
    }
}

impl SceneArgs {
    /// Where clustering and levels of detail are cached: `--cache-dir`, else
    /// `$XDG_CACHE_HOME/reliefboard`, else `$HOME/.cache/reliefboard`; `None` with
    /// `--no-cache`.
    pub fn cache_directory(&self) -> Option<PathBuf> {
        if self.no_cache {
            return None;
        }
        self.cache_dir.clone().or_else(|| {
            let base = std::env::var_os("XDG_CACHE_HOME")
                .map(PathBuf::from)
                .or_else(|| {
                    std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".cache"))
                })?;
            Some(base.join("reliefboard"))
        })
    }
}

/// A flag's parser that accepts a number from `min` to `max` (both included) and refuses
/// anything else, NaN and infinities included, naming the range.
pub fn in_range<T>(min: T, max: T) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy + Send + Sync + 'static,
{
    move |text: &str| {
        let value: T = text
            .trim()
            .parse()
            .map_err(|_| format!("{text:?} is not a number"))?;
        // Written so that NaN (which compares false to everything) is refused too.
        if value >= min && value <= max {
            Ok(value)
        } else {
            Err(format!("must be a number from {min} to {max}"))
        }
    }
}

fn parse_resolution(text: &str) -> Result<[u32; 2], String> {
    let (width, height) = text
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, for example 1024x768")?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .map_err(|_| format!("{s:?} is not a whole number of pixels"))
    };
    let resolution = [parse(width)?, parse(height)?];
    if resolution.iter().any(|&r| r == 0 || r > 65_536) {
        return Err("each side must lie in 1..=65536 pixels".into());
    }
    Ok(resolution)
}

/// Where boards come from.
#[derive(Debug, Args, Clone)]
#[command(next_help_heading = "Workers")]
pub struct WorkerArgs {
    /// Running workers to use, `host:port,...`; without it, workers start in this process.
    #[arg(long, value_delimiter = ',')]
    pub workers: Vec<String>,
    /// A `host:port` whose name resolves to every worker (a headless Kubernetes Service, a
    /// scaled compose service); added to `--workers`. Resolved again while running: workers
    /// that appear join (their objects are stored on them first), ones that vanish are
    /// forgotten.
    #[arg(long = "workers-dns")]
    pub workers_dns: Option<String>,
    /// Seconds between resolutions of `--workers-dns`.
    #[arg(long = "dns-interval", default_value_t = 2.0, value_parser = in_range(0.05, 3600.0))]
    pub dns_interval: f64,
    /// Shared token sent on every call to the workers (also RELIEFBOARD_TOKEN).
    #[arg(long, env = "RELIEFBOARD_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Connect with TLS, trusting workers' certificates signed by this CA (PEM).
    #[arg(long = "tls-ca")]
    pub tls_ca: Option<PathBuf>,
    /// This node's certificate (PEM), for workers that demand mutual TLS.
    #[arg(long = "tls-cert", requires_all = ["tls_key", "tls_ca"])]
    pub tls_cert: Option<PathBuf>,
    /// This node's private key (PEM).
    #[arg(long = "tls-key", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// The name on the workers' certificates, when it is not the host dialled.
    #[arg(long = "tls-domain")]
    pub tls_domain: Option<String>,
    /// A render call unanswered this long goes to another replica, in milliseconds.
    #[arg(long = "request-timeout-ms", default_value_t = 5000,
        value_parser = in_range(1u64, 3_600_000))]
    pub request_timeout_ms: u64,
    /// In-process workers on loopback when no `--workers` are given.
    #[arg(long = "local-workers", default_value_t = 4, value_parser = in_range(1usize, 256))]
    pub local_workers: usize,
    /// Render threads of each in-process worker.
    #[arg(long = "worker-threads", default_value_t = 1, value_parser = in_range(1usize, 256))]
    pub worker_threads: usize,
    /// Replicas of each object (capped at the number of workers).
    #[arg(long, default_value_t = crate::workers::REPLICAS, value_parser = in_range(1usize, 64))]
    pub replicas: usize,
    /// Where the balancer uses the speeds the workers report (docs/balancer.md measures
    /// each): ignored, picks (a request goes to the worker that would finish it first), or
    /// offers-and-picks (a slow worker also answers less).
    #[arg(long = "balancer-speeds", value_enum, default_value_t = BalancerSpeeds::OffersAndPicks)]
    pub balancer_speeds: BalancerSpeeds,
}

/// `--balancer-speeds`: [`balancer::SpeedUse`] as a flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BalancerSpeeds {
    /// Every worker counts as equally fast.
    Ignored,
    /// Picks compare expected finish times.
    Picks,
    /// Picks and collision offers both count speed.
    OffersAndPicks,
}

impl From<BalancerSpeeds> for balancer::SpeedUse {
    fn from(speeds: BalancerSpeeds) -> Self {
        match speeds {
            BalancerSpeeds::Ignored => balancer::SpeedUse::Ignored,
            BalancerSpeeds::Picks => balancer::SpeedUse::Picks,
            BalancerSpeeds::OffersAndPicks => balancer::SpeedUse::OffersAndPicks,
        }
    }
}

/// How boards are drawn and refreshed.
#[derive(Debug, Args, Clone)]
#[command(next_help_heading = "Reliefboards")]
pub struct BoardArgs {
    /// What stands in for far objects: reliefboards, flat billboards of the same maps, a
    /// meshoptimizer level-of-detail chain or baked octahedral impostors (no workers), or
    /// nothing (geometry only).
    #[arg(long, value_enum, default_value_t = Impostor::Relief)]
    pub impostor: Impostor,
    /// Request a new board past this angle, degrees (ε).
    #[arg(long, default_value_t = 11.5, value_parser = in_range(0.01, 90.0))]
    pub epsilon: f64,
    /// Request a new board when its parallax bound (Lawlor: half its size on screen times
    /// the sine of its angle error) passes this many pixels.
    #[arg(long = "refresh-pixels", default_value_t = crate::plan::DEFAULT_REFRESH_PIXELS,
        value_parser = in_range(0.01, 1e9))]
    pub refresh_pixels: f64,
    /// Map texels per pixel a board's object covers on screen when asked for (at most
    /// `--map-size` a side): above 1 boards cost the workers more and blur less.
    #[arg(long = "texels-per-pixel", default_value_t = crate::plan::DEFAULT_TEXELS_PER_PIXEL,
        value_parser = in_range(0.25, 4.0))]
    pub texels_per_pixel: f64,
    /// Draw geometry instead of a board past this angle, degrees (E).
    #[arg(long = "max-angle", default_value_t = 45.0, value_parser = in_range(0.01, 90.0))]
    pub max_angle: f64,
    /// Most cells per side of a board's displaced grid (its maps keep full resolution).
    #[arg(long = "board-grid", default_value_t = 32, value_parser = in_range(1u32, 1024))]
    pub board_grid: u32,
    /// Pixels per grid cell: a board's grid has its size on screen over this many cells a
    /// side (at most `--board-grid`), so a small board costs few triangles.
    #[arg(long = "board-cell-pixels", default_value_t = crate::board::DEFAULT_CELL_PIXELS,
        value_parser = in_range(1u32, 1024))]
    pub board_cell_pixels: u32,
    /// Where a board's pixels take their depth from: `grid` uses the displaced grid's depth
    /// (hidden pixels are skipped before shading), `pixel` reads the depth map per pixel
    /// (exact where boards meet other surfaces, but the shader runs for hidden pixels too).
    #[arg(long = "board-depth", value_enum, default_value_t = crate::render::BoardDepth::default())]
    pub board_depth: crate::render::BoardDepth,
    /// Blend a board's silhouette over what is behind it by the coverage of its stencil
    /// (down to a quarter), or (`false`) cut it where the coverage crosses one half.
    #[arg(long = "soft-edges", default_value_t = crate::render::DEFAULT_SOFT_EDGES,
        action = clap::ArgAction::Set, value_name = "BOOL")]
    pub soft_edges: bool,
    /// Milliseconds a frame spends uploading arrived boards at most, highest priority
    /// first (the rest wait for the next frame; one board always goes).
    #[arg(long = "upload-ms", default_value_t = crate::viewer::DEFAULT_UPLOAD_MS,
        value_parser = in_range(0.0, 1e9))]
    pub upload_ms: f64,
    /// The same while the camera stands still, if larger: nothing on screen moves then, so
    /// boards come in faster (the first ones at start-up above all) and the next input waits
    /// at most this long.
    #[arg(long = "still-upload-ms", default_value_t = crate::viewer::DEFAULT_STILL_UPLOAD_MS,
        value_parser = in_range(0.0, 1e9))]
    pub still_upload_ms: f64,
    /// Frames a new board takes to cross-fade in.
    #[arg(long = "fade-frames", default_value_t = crate::viewer::DEFAULT_FADE_FRAMES,
        value_parser = in_range(0u32, 1000))]
    pub fade_frames: u32,
    /// Cross-fade a new board in only when it differs from the one it replaces by more than
    /// this many pixels (their parallax bound); a closer one swaps in at once (0: any change
    /// fades). Keep it above `--refresh-pixels`: a board renewed on time jumps about that far,
    /// so at equal values nearly every board fades (the dragon orbit, both 8: 98%).
    #[arg(long = "fade-pixels", default_value_t = crate::viewer::DEFAULT_FADE_PIXELS,
        value_parser = in_range(0.0, 1e9))]
    pub fade_pixels: f64,
    /// Levels of detail (`--impostor lod`; with every kind but `none`, the objects too large
    /// or too simple for a board; with relief and billboard, objects waiting for a valid
    /// board): draw the coarsest level whose error covers at most this many pixels on screen.
    #[arg(long = "lod-pixels", default_value_t = 1.0, value_parser = in_range(0.01, 1000.0))]
    pub lod_pixels: f64,
    /// Draw each frame for where the camera will be while it is on screen, extrapolated from
    /// the last frames' cameras over 1.5 frame times (`CameraPredictor`), or (`false`) where it
    /// was when the frame began (`visnode view`, and `visnode bench --timing wall`). Every kind
    /// alike.
    #[arg(long = "predict-camera", default_value_t = true, action = clap::ArgAction::Set,
        value_name = "BOOL")]
    pub predict_camera: bool,
    /// Draw the objects too large or too simple for a board always whole, as Süß does,
    /// instead of through levels of detail.
    #[arg(long = "whole-unsuitable")]
    pub whole_unsuitable: bool,
    /// With relief and billboard: draw an object beyond the near zone that has no valid board
    /// yet (new in view, or its board past E) as its full mesh, as Süß does, instead of
    /// through levels of detail (built at load then, and cached like `--impostor lod`'s).
    #[arg(long = "whole-fallback")]
    pub whole_fallback: bool,
    /// With relief and billboard: what drawing one triangle costs on this adapter, in board
    /// pixels shaded. An object beyond the near zone whose level of detail (`--lod-pixels`)
    /// costs less than its board (triangles times this, against the board's area on screen)
    /// is drawn through the level and asks for no board. 0: a board for every object.
    #[arg(long = "triangle-cost-pixels", default_value_t = crate::plan::DEFAULT_TRIANGLE_COST_PIXELS,
        value_parser = in_range(0.0, 1e9))]
    pub triangle_cost_pixels: f64,
    /// With `--impostor octahedral`: views per side of the octahedral grid.
    #[arg(long = "octahedral-views", default_value_t = 16, value_parser = in_range(2u32, 64))]
    pub octahedral_views: u32,
    /// With `--impostor octahedral`: texels per view side [default: the largest power of two
    /// up to 64 that keeps all atlases within `--octahedral-budget-mb`].
    #[arg(long = "octahedral-view-size", value_parser = in_range(4u32, 256))]
    pub octahedral_view_size: Option<u32>,
    /// With `--impostor octahedral`: GPU memory for all atlases, MiB.
    #[arg(long = "octahedral-budget-mb", default_value_t = 512, value_parser = in_range(1u64, 1 << 20))]
    pub octahedral_budget_mb: u64,
    /// Tune t_nz every frame toward this frame time in milliseconds (Niski's controller).
    #[arg(long = "target-frame-ms", value_parser = in_range(0.1, 60_000.0))]
    pub target_frame_ms: Option<f64>,
}

/// The impostor drawn beyond the near zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Impostor {
    /// Displaced grid with per-pixel depth (the reliefboard).
    Relief,
    /// The same maps on a flat quad.
    Billboard,
    /// A level-of-detail chain per object, built at load with meshoptimizer; no workers.
    Lod,
    /// Baked octahedral impostors: views over the whole sphere rendered at load; no workers.
    Octahedral,
    /// Geometry only.
    None,
    /// The far objects not drawn at all: what every other kind draws besides them (the
    /// unsuitable objects' levels, the near zone, the ground), so its frame time is the floor
    /// under every far field's on that path. A measurement, not an image to show.
    Floor,
}

/// Flags of `visnode bench`.
#[derive(Debug, Args, Clone)]
pub struct BenchArgs {
    /// The scene.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The workers.
    #[command(flatten)]
    pub workers: WorkerArgs,
    /// The boards.
    #[command(flatten)]
    pub boards: BoardArgs,
    /// Camera path: orbit, flythrough, turn (still, a fast quarter turn, still: the summary
    /// gives the time until every board is fresh again), or a file recorded by `visnode view`.
    #[arg(long, default_value = "orbit")]
    pub path: crate::camera::PathKind,
    /// wall: the path takes `--path-seconds`, frames are drawn as fast as they come and the
    /// screen is sampled at `--sample-hz` (what a user sees); frames: one path step per frame,
    /// every frame sampled (reproducible).
    #[arg(long, value_enum, default_value_t = crate::timeline::Timing::Wall)]
    pub timing: crate::timeline::Timing,
    /// Length of the camera path in seconds (`--timing wall`; a path recorded by `visnode
    /// view` keeps its own times).
    #[arg(long = "path-seconds", default_value_t = 12.0, value_parser = in_range(0.1, 86_400.0))]
    pub path_seconds: f64,
    /// Sample instants per second of the path (`--timing wall`).
    #[arg(long = "sample-hz", default_value_t = 30.0, value_parser = in_range(0.1, 1000.0))]
    pub sample_hz: f64,
    /// Steps of the path: frames drawn with `--timing frames`, the path's resolution with
    /// `--timing wall` (a recorded path keeps its own).
    #[arg(long, default_value_t = 120, value_parser = in_range(1usize, 10_000_000))]
    pub frames: usize,
    /// Run each of these kinds on the same path and compare them:
    /// `relief,lod,octahedral,billboard,none,floor` (writes compare.csv, compare-*.png,
    /// pareto-*.png).
    #[arg(long, value_delimiter = ',')]
    pub compare: Option<Vec<Impostor>>,
    /// Skip FLIP (the slowest metric).
    #[arg(long = "no-flip")]
    pub no_flip: bool,
    /// With `--timing wall`: also draw all geometry for each shown frame's own camera, to
    /// split the error into the frame's own (silhouettes, interiors) and what the image's
    /// age adds (one more reference per shown frame).
    #[arg(long = "error-split")]
    pub error_split: bool,
    /// Repeat the path until this many seconds of frames have passed (soak runs).
    #[arg(long = "max-seconds", value_parser = in_range(1.0, 7.0 * 86_400.0))]
    pub max_seconds: Option<f64>,
    /// Wait for each frame's requested boards before drawing it (reproducible).
    #[arg(long)]
    pub sync: bool,
    /// Write the balancer's request trace (JSON Lines) here.
    #[arg(long = "record-trace")]
    pub record_trace: Option<PathBuf>,
    /// Repeat the run for each value of a parameter: `t-nz=A,B`, `epsilon=A,B`,
    /// `map-size=A,B`, `workers=A,B`, `board-grid=A,B`, `board-cell-pixels=A,B`,
    /// `refresh-pixels=A,B`, `upload-ms=A,B`, `still-upload-ms=A,B`, `fade-frames=A,B`,
    /// `fade-pixels=A,B`,
    /// `board-depth=pixel,grid`, `lod-pixels=A,B`, `octahedral-views=A,B`,
    /// `triangle-cost-pixels=A,B`, `whole-unsuitable=true,false`, `predict-camera=true,false`,
    /// `soft-edges=true,false` or `whole-fallback=true,false`. Repeatable: each kind of `--compare` runs the sweeps that
    /// apply to it, each a curve of error against time.
    #[arg(long)]
    pub sweep: Vec<String>,
    /// Sample instants written as PNG (reference, frame, difference side by side).
    #[arg(long = "sample-frames", default_value_t = 3)]
    pub sample_frames: usize,
    /// A pixel differs when a channel differs by more than this (0-255).
    #[arg(long = "diff-threshold", default_value_t = 24)]
    pub diff_threshold: u8,
    /// Output folder.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

impl ViewArgs {
    /// `visnode view` with every flag at its default: what runs without a subcommand.
    pub fn defaults() -> ViewArgs {
        match <Cli as Parser>::parse_from(["visnode", "view"]).command {
            Some(Command::View(args)) => args,
            _ => unreachable!("\"view\" parses as the view subcommand"),
        }
    }
}

/// Flags of `visnode view`.
#[derive(Debug, Args, Clone)]
pub struct ViewArgs {
    /// The scene; `--resolution` is the window's first size.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The workers.
    #[command(flatten)]
    pub workers: WorkerArgs,
    /// The boards.
    #[command(flatten)]
    pub boards: BoardArgs,
    /// A camera path to replay at start (and again with P): orbit, flythrough, or a file
    /// recorded with R.
    #[arg(long)]
    pub replay: Option<crate::camera::PathKind>,
    /// Frames of a replayed orbit or flythrough.
    #[arg(long = "replay-frames", default_value_t = 360, value_parser = in_range(1usize, 10_000_000))]
    pub replay_frames: usize,
    /// Where R records the camera path (one JSON camera per line, for `bench --path`).
    #[arg(long, default_value = "camera-path.jsonl")]
    pub record: PathBuf,
    /// Folder for screenshots (F12).
    #[arg(long = "screenshot-dir", default_value = ".")]
    pub screenshot_dir: PathBuf,
    /// Close after this many frames (scripted runs and tests).
    #[arg(long = "exit-after")]
    pub exit_after: Option<u64>,
    /// Save the last frame, overlay included, as this PNG (with `--exit-after`).
    #[arg(long = "screenshot-on-exit")]
    pub screenshot_on_exit: Option<PathBuf>,
}

/// Flags of `visnode cluster`.
#[derive(Debug, Args)]
pub struct ClusterArgs {
    /// Worker processes to start.
    #[arg(long = "workers", default_value_t = 4, value_parser = in_range(1usize, 256))]
    pub count: usize,
    /// Render threads of each worker.
    #[arg(long = "worker-threads", default_value_t = 1, value_parser = in_range(1usize, 256))]
    pub threads: usize,
    /// Slowdown of each worker, `A,B,...` (the last repeats): `1,1,1,4` makes the fourth a
    /// four times weaker machine.
    #[arg(long, value_delimiter = ',', value_parser = in_range(1.0, 1000.0))]
    pub slowdown: Vec<f64>,
    /// The backend binary [default: `backend` beside this executable, else on PATH].
    #[arg(long)]
    pub backend: Option<PathBuf>,
    /// What runs on the workers [default: view].
    #[command(subcommand)]
    pub run: Option<ClusterRun>,
}

/// What `visnode cluster` runs.
#[derive(Debug, Clone, Subcommand)]
pub enum ClusterRun {
    /// The window.
    View(ViewArgs),
    /// The benchmark.
    Bench(BenchArgs),
}

//! `backend`: the worker binary. `serve` runs the gRPC worker; `render` writes one board's
//! maps and mesh for a person to look at; `bench` measures boards per second.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use backend::{Board, EncodedBoard, PreparedObject, render_maps};
use clap::{Args, Parser, Subcommand};
use glam::DVec3;
use serde::Serialize;

/// A reliefboard worker: software-renders reliefboards for the visualization node.
#[derive(Debug, Parser)]
#[command(name = "backend", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Render one board and write its maps as PNG, the board as PLY and figures as JSON.
    Render(RenderArgs),
    /// Measure boards and triangles per second on one thread and on all.
    Bench(BenchArgs),
    /// Serve boards over gRPC until interrupted (Ctrl-C).
    Serve(ServeArgs),
    /// Time wgpu alone (what `bench` runs in a child process, with LP_NUM_THREADS set so
    /// lavapipe gets the same cores as the software renderer).
    #[command(hide = true)]
    WgpuTiming(BenchArgs),
}

#[derive(Debug, Args)]
struct SceneChoice {
    /// A mesh file or a built-in scene (forest, plant).
    #[arg(long)]
    scene: String,
    /// Triangle target of a built-in scene.
    #[arg(long, default_value_t = 1_000_000)]
    triangles: u64,
    /// Which object: its index, or `all` for the whole scene as one object (the default for
    /// a single mesh file).
    #[arg(long, default_value = "all")]
    object: String,
    /// Cut the scene as the visualization node does under this near-zone budget (t_nz) first;
    /// `--object` then picks one of the pieces, whose boards grow past their cuts.
    #[arg(long)]
    t_nz: Option<u64>,
}

#[derive(Debug, Args)]
struct RenderArgs {
    #[command(flatten)]
    scene: SceneChoice,
    /// View direction X,Y,Z (from the viewer to the object).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, default_values_t = [0.0, 0.0, -1.0])]
    dir: Vec<f64>,
    /// Map side in pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, Args)]
struct ServeArgs {
    /// Address to listen on (port 0: any free port; the address is printed). Other than
    /// loopback only with `--token` or `--insecure`.
    #[arg(long, default_value = "127.0.0.1:50051")]
    listen: std::net::SocketAddr,
    /// Shared token every call must carry (`authorization: Bearer TOKEN`); also read from
    /// RELIEFBOARD_TOKEN, so it need not show in the process list.
    #[arg(long, env = "RELIEFBOARD_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Serve TLS with this certificate (PEM); needs `--tls-key`.
    #[arg(long = "tls-cert", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM).
    #[arg(long = "tls-key", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Demand client certificates signed by this CA (PEM): mutual TLS.
    #[arg(long = "tls-ca", requires = "tls_cert")]
    tls_ca: Option<PathBuf>,
    /// Render threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Stand in for a machine F times weaker: after each board, sleep F - 1 times its render
    /// time before the next one starts (latency and throughput both F times worse).
    #[arg(long, default_value_t = 1.0)]
    slowdown: f64,
    /// Render requests queued or running at once; more are refused.
    #[arg(long, default_value_t = 64)]
    queue: usize,
    /// Largest map side served.
    #[arg(long, default_value_t = 1024)]
    max_map_size: u32,
    /// Memory for stored objects, MiB; storing past it is refused (RESOURCE_EXHAUSTED).
    #[arg(long = "memory-limit", default_value_t = 8192)]
    memory_limit_mib: u64,
    /// Allow listening on a non-loopback address without a token.
    #[arg(long)]
    insecure: bool,
}

#[derive(Debug, Args)]
struct BenchArgs {
    #[command(flatten)]
    scene: SceneChoice,
    /// Map side in pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Threads for the "all cores" figure (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Boards per measurement (views spread over the sphere).
    #[arg(long, default_value_t = 32)]
    boards: u32,
    /// Map sides of the whole-request table (render and encoding on one thread, the full
    /// mesh against the level a worker renders from, and that level split over the threads).
    #[arg(long, value_delimiter = ',', default_values_t = [32, 64, 128, 256])]
    sizes: Vec<u32>,
    /// Also time a request from each of the worker's levels at each side, with its stencil
    /// IoU against the full mesh's: what a coarser or finer level than the worker's choice
    /// would cost and keep.
    #[arg(long)]
    every_level: bool,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    backend::keep_large_allocations();
    backend::ensure_runtime_dir();
    let result = match Cli::parse().command {
        Command::Render(args) => render(&args),
        Command::Bench(args) => bench(&args),
        Command::Serve(args) => serve(&args),
        Command::WgpuTiming(args) => wgpu_timing(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn serve(args: &ServeArgs) -> anyhow::Result<()> {
    let token = args.token.clone().filter(|t| !t.is_empty());
    if !backend::is_loopback(&args.listen) && token.is_none() && !args.insecure {
        bail!(
            "{} is not a loopback address: give a shared --token (or RELIEFBOARD_TOKEN), or pass --insecure to serve without one",
            args.listen
        );
    }
    if args.max_map_size == 0 || args.max_map_size > backend::MAX_MAP_SIZE {
        bail!("--max-map-size must lie in 1..={}", backend::MAX_MAP_SIZE);
    }
    let read =
        |path: &PathBuf| std::fs::read(path).with_context(|| format!("reading {}", path.display()));
    let security = backend::Security {
        token,
        tls_identity: match (&args.tls_cert, &args.tls_key) {
            (Some(cert), Some(key)) => Some((read(cert)?, read(key)?)),
            _ => None,
        },
        tls_client_ca: args.tls_ca.as_ref().map(read).transpose()?,
    };
    let config = backend::WorkerConfig {
        threads: args.threads.unwrap_or_else(backend::default_threads),
        slowdown: args.slowdown,
        queue_capacity: args.queue,
        max_map_size: args.max_map_size,
        memory_limit_bytes: args.memory_limit_mib.saturating_mul(1 << 20),
        ..backend::WorkerConfig::default()
    };
    let service = backend::WorkerService::new(config)?;
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("listening on {}", args.listen))?;
        // Scripts (and `visnode cluster`) read the port from this line.
        eprintln!("backend worker listening on {}", listener.local_addr()?);
        backend::serve(listener, service, security, async {
            let terminate = async {
                match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                    Ok(mut signal) => {
                        signal.recv().await;
                    }
                    Err(_) => std::future::pending::<()>().await,
                }
            };
            // Ctrl-C by hand, SIGTERM from docker stop or Kubernetes: drain, then exit.
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = terminate => {}
            }
        })
        .await
    })
}

fn load_object(choice: &SceneChoice) -> anyhow::Result<PreparedObject> {
    let options = scene::LoadOptions {
        triangles: choice.triangles,
        ..scene::LoadOptions::default()
    };
    let mut loaded = scene::load_scene(&choice.scene, &options)?;
    if let Some(t_nz) = choice.t_nz {
        if choice.object == "all" {
            bail!("--t-nz cuts the scene into pieces: pick one with --object");
        }
        let params = scene::PrepareParams {
            t_nz,
            ..scene::PrepareParams::default()
        };
        let pieces = scene::prepare(std::mem::take(&mut loaded), &params)?.objects;
        loaded.objects = pieces;
    }
    let object = if choice.object == "all" {
        if loaded.objects.len() == 1 {
            loaded.objects[0].clone()
        } else {
            scene::merge_objects("all", &loaded.objects)
        }
    } else {
        let index: usize = choice.object.parse().with_context(|| {
            format!(
                "--object must be an index or `all`, got {:?}",
                choice.object
            )
        })?;
        match loaded.objects.get(index) {
            Some(object) => object.clone(),
            None => bail!(
                "object {index} does not exist: the scene has {} objects (0..{})",
                loaded.objects.len(),
                loaded.objects.len()
            ),
        }
    };
    Ok(PreparedObject::new(&object)?)
}

fn pool(threads: Option<usize>) -> anyhow::Result<(rayon::ThreadPool, usize)> {
    let threads = threads.unwrap_or_else(backend::default_threads);
    if threads == 0 {
        bail!("--threads must be at least 1");
    }
    Ok((
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?,
        threads,
    ))
}

#[derive(Debug, Serialize)]
struct BoardReport {
    object: String,
    triangles_in: usize,
    /// Triangles of the level the board was rendered from (a worker's choice).
    triangles_rendered: usize,
    /// That level's error, in pixels of this board.
    level_error_pixels: f64,
    size: u32,
    direction: [f64; 3],
    covered_pixels: usize,
    board_vertices: usize,
    board_triangles: usize,
    encoded_bytes: usize,
    raw_bytes: usize,
    milliseconds: f64,
    threads: usize,
}

fn render(args: &RenderArgs) -> anyhow::Result<()> {
    // With the levels a worker builds once it has stored the object.
    let object = load_object(&args.scene)?.with_levels();
    let level = object.mesh_for_size(args.size);
    let [x, y, z] = args.dir[..] else {
        bail!("--dir needs three numbers X,Y,Z, got {}", args.dir.len());
    };
    let direction = DVec3::new(x, y, z);
    let (pool, threads) = pool(args.threads)?;
    let start = Instant::now();
    let maps = pool.install(|| render_maps(&object, direction, args.size, threads))?;
    let board = Board::from_maps(maps);
    let encoded = EncodedBoard::encode(&board.maps);
    let milliseconds = start.elapsed().as_secs_f64() * 1e3;

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    write_maps(&board, &args.out)?;
    let mesh = board.world_mesh();
    let mut ply = std::io::BufWriter::new(std::fs::File::create(args.out.join("reliefboard.ply"))?);
    scene::write_ply(std::slice::from_ref(&mesh), &mut ply)?;
    let report = BoardReport {
        object: object.name.clone(),
        triangles_in: object.triangles.len(),
        triangles_rendered: level.triangles.len(),
        level_error_pixels: level.error * args.size as f64 / (2.0 * object.radius),
        size: args.size,
        direction: direction.to_array(),
        covered_pixels: board.maps.covered(),
        board_vertices: board.grid.vertices.len(),
        board_triangles: board.grid.triangles.len(),
        encoded_bytes: encoded.bytes.len(),
        raw_bytes: EncodedBoard::raw_bytes(args.size),
        milliseconds,
        threads,
    };
    std::fs::write(
        args.out.join("board.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// Writes distance, stencil, colour and normal maps as PNG.
fn write_maps(board: &Board, out: &std::path::Path) -> anyhow::Result<()> {
    let maps = &board.maps;
    let size = maps.size;
    let write = |name: &str, pixel: &dyn Fn(usize) -> [u8; 4]| -> anyhow::Result<()> {
        let mut pixmap = tiny_skia::Pixmap::new(size, size).context("allocating a map picture")?;
        for (at, out) in pixmap.pixels_mut().iter_mut().enumerate() {
            let [r, g, b, a] = pixel(at);
            // tiny-skia stores premultiplied colour; every map here is opaque or black.
            *out = tiny_skia::PremultipliedColorU8::from_rgba(r, g, b, a)
                .unwrap_or(tiny_skia::PremultipliedColorU8::TRANSPARENT);
        }
        pixmap
            .save_png(out.join(name))
            .with_context(|| format!("writing {name}"))
    };
    // Distance, higher = nearer, stretched over the board's own depth range so the relief
    // shows (the raw map spans [0, 1] for the whole bounding sphere).
    let [near, far] = board.depth_range;
    let span = (far - near).max(f32::EPSILON);
    write("distance.png", &|at| {
        if !maps.stencil[at] {
            return [0, 0, 0, 255];
        }
        let v = (40.0 + 215.0 * (far - maps.depth[at]) / span).round() as u8;
        [v, v, v, 255]
    })?;
    write("stencil.png", &|at| {
        if maps.stencil[at] {
            [255, 255, 255, 255]
        } else {
            [0, 0, 0, 255]
        }
    })?;
    write("color.png", &|at| {
        if maps.stencil[at] {
            [maps.color[at][0], maps.color[at][1], maps.color[at][2], 255]
        } else {
            [0, 0, 0, 255]
        }
    })?;
    write("normal.png", &|at| {
        let n = maps.normal[at];
        if maps.stencil[at] {
            n.map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8)
                .into_iter()
                .chain([255])
                .collect::<Vec<_>>()
                .try_into()
                .unwrap_or([0; 4])
        } else {
            [0, 0, 0, 255]
        }
    })?;
    Ok(())
}

#[derive(Debug, Serialize)]
struct BenchReport {
    object: String,
    triangles: usize,
    size: u32,
    boards: u32,
    /// Seconds to build the levels a worker builds once it has stored the object.
    levels_seconds: f64,
    /// Whole requests by board size, on one thread.
    requests: Vec<RequestCost>,
    one_thread: Throughput,
    all_threads: Throughput,
    /// The same boards rendered by wgpu (render and read back), or why not.
    wgpu: Result<GpuThroughput, String>,
}

#[derive(Debug, Serialize)]
struct GpuThroughput {
    adapter: String,
    /// wgpu with lavapipe on one thread (LP_NUM_THREADS=1; a real GPU ignores it).
    milliseconds_per_board_one_thread: f64,
    /// wgpu with lavapipe on the "all threads" count.
    milliseconds_per_board_all_threads: f64,
    /// How many times wgpu's time per board the software renderer's is, on one thread.
    speedup_one_thread: f64,
    /// The same on all threads.
    speedup_all_threads: f64,
}

/// What one request costs a worker on one thread (render and encoding, as it serves them),
/// from the full mesh and from the level it picks, and how close the two boards are.
#[derive(Debug, Serialize)]
struct RequestCost {
    size: u32,
    full_triangles: usize,
    level_triangles: usize,
    level_error_pixels: f64,
    full_milliseconds: f64,
    level_milliseconds: f64,
    /// Where `level_milliseconds` went (all but the calls between the stages).
    level_stages: StageMilliseconds,
    /// The same request from the level split over `split_threads` threads, as an idle
    /// worker serves a board worth it ([`backend::SPLIT_WORK`]).
    level_split_milliseconds: f64,
    split_threads: usize,
    /// Stencil intersection over union against the full mesh's: the worst view and the mean.
    stencil_iou_min: f64,
    stencil_iou_mean: f64,
    /// Mean |depth difference| over pixels both cover, in pixels of the board.
    depth_error_pixels_mean: f64,
    /// With `--every-level`, a request from each level, finest first; else empty.
    every_level: Vec<LevelCost>,
}

/// One request from one of the worker's levels, whether or not the worker would choose it.
#[derive(Debug, Serialize)]
struct LevelCost {
    triangles: usize,
    /// Whether a worker may render this side's boards from it ([`PreparedObject::allows`]).
    allowed: bool,
    /// Whether it does: the coarsest level allowed.
    chosen: bool,
    milliseconds: f64,
    stencil_iou_min: f64,
    stencil_iou_mean: f64,
}

/// Times whole requests of `size` from the full mesh and from `object`'s chosen level over
/// `directions`, on one thread, and from the level split over `split_pool`'s threads; with
/// `every_level`, from each level on one thread as well.
fn request_cost(
    object: &PreparedObject,
    directions: &[DVec3],
    size: u32,
    split_pool: &rayon::ThreadPool,
    every_level: bool,
) -> anyhow::Result<RequestCost> {
    let level = object.mesh_for_size(size);
    // The fastest of three passes over the views (a busy neighbour on a shared machine only
    // ever adds time), each board on this thread as a busy worker renders it, or handed to
    // the pool as an idle one splits it ([`backend::threads_worth`]). Returns milliseconds
    // per request, the render's stages and the encoding (of that pass), and the maps.
    type Timed = (f64, StageMilliseconds, Vec<backend::Maps>);
    let render = |mesh: backend::MeshRef<'_>, direction: DVec3, split: bool| {
        if split {
            let threads = split_pool.current_num_threads();
            split_pool
                .install(|| backend::render_mesh_timed(object, mesh, direction, size, threads))
        } else {
            backend::render_mesh_timed(object, mesh, direction, size, 1)
        }
    };
    let time = |mesh: backend::MeshRef<'_>, split: bool| -> anyhow::Result<Timed> {
        render(mesh, directions[0], split)?;
        let mut all = Vec::with_capacity(directions.len());
        let mut fastest = (f64::INFINITY, backend::Stages::default(), 0.0);
        for pass in 0..3 {
            let (mut seconds, mut stages, mut encoding) = (0.0, backend::Stages::default(), 0.0);
            for direction in directions {
                let start = Instant::now();
                let (maps, its_stages) = render(mesh, *direction, split)?;
                let rendered = Instant::now();
                std::hint::black_box(EncodedBoard::encode(&maps));
                let end = Instant::now();
                seconds += (end - start).as_secs_f64();
                stages += its_stages;
                encoding += (end - rendered).as_secs_f64();
                if pass == 0 {
                    all.push(maps);
                }
            }
            if seconds < fastest.0 {
                fastest = (seconds, stages, encoding);
            }
        }
        let (seconds, stages, encoding) = fastest;
        let per_request = |seconds: f64| seconds * 1e3 / directions.len() as f64;
        let stages = StageMilliseconds {
            projection: per_request(stages.projection.as_secs_f64()),
            triangle_pass: per_request(stages.triangle_pass.as_secs_f64()),
            grow_at_cuts: per_request(stages.grow_at_cuts.as_secs_f64()),
            per_pixel_pass: per_request(stages.per_pixel_pass.as_secs_f64()),
            encoding: per_request(encoding),
        };
        Ok((per_request(seconds), stages, all))
    };
    let (full_milliseconds, _, full) = time(object.full_mesh(), false)?;
    let (level_milliseconds, level_stages, simplified) = time(level, false)?;
    let (level_split_milliseconds, _, _) = time(level, true)?;
    let (mut depth_sum, mut depth_count) = (0.0, 0usize);
    for (a, b) in full.iter().zip(&simplified) {
        for at in 0..a.stencil.len() {
            if a.stencil[at] && b.stencil[at] {
                // Depth spans [-1, 1] over the sphere's diameter, which is `size` pixels.
                depth_sum += ((a.depth[at] - b.depth[at]).abs() * 0.5 * size as f32) as f64;
                depth_count += 1;
            }
        }
    }
    // The worst view's and the mean stencil IoU of `boards` against the full mesh's.
    let iou = |boards: &[backend::Maps]| {
        let ious: Vec<f64> = full
            .iter()
            .zip(boards)
            .map(|(a, b)| backend::simplify::stencil_iou(&a.stencil, &b.stencil))
            .collect();
        (
            ious.iter().copied().fold(1.0, f64::min),
            ious.iter().sum::<f64>() / ious.len().max(1) as f64,
        )
    };
    let (stencil_iou_min, stencil_iou_mean) = iou(&simplified);
    let levels = if every_level { object.levels() } else { &[] };
    let every_level = levels
        .iter()
        .map(|candidate| {
            let (milliseconds, _, boards) = time(candidate.mesh(), false)?;
            let (stencil_iou_min, stencil_iou_mean) = iou(&boards);
            Ok(LevelCost {
                triangles: candidate.triangles.len(),
                allowed: object.allows(candidate, size),
                chosen: std::ptr::eq(candidate.triangles.as_ptr(), level.triangles.as_ptr()),
                milliseconds,
                stencil_iou_min,
                stencil_iou_mean,
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(RequestCost {
        size,
        full_triangles: object.triangles.len(),
        level_triangles: level.triangles.len(),
        level_error_pixels: level.error * size as f64 / (2.0 * object.radius),
        full_milliseconds,
        level_milliseconds,
        level_stages,
        level_split_milliseconds,
        split_threads: split_pool.current_num_threads(),
        stencil_iou_min,
        stencil_iou_mean,
        depth_error_pixels_mean: depth_sum / depth_count.max(1) as f64,
        every_level,
    })
}

/// A request's milliseconds by stage, in the order they run ([`backend::Stages`], then the
/// encoding for the wire).
#[derive(Debug, Serialize)]
struct StageMilliseconds {
    projection: f64,
    triangle_pass: f64,
    grow_at_cuts: f64,
    per_pixel_pass: f64,
    encoding: f64,
}

#[derive(Debug, Serialize, serde::Deserialize)]
struct WgpuTiming {
    adapter: String,
    milliseconds_per_board: f64,
}

#[derive(Debug, Serialize)]
struct Throughput {
    threads: usize,
    milliseconds_per_board: f64,
    median_milliseconds_per_board: f64,
    boards_per_second: f64,
    triangles_per_second: f64,
}

/// Milliseconds per board for wgpu rendering the same views (object uploaded once, as a
/// worker's replica would be; every board rendered and read back).
#[cfg(not(feature = "gpu-reference"))]
fn measure_wgpu(_: &PreparedObject, _: &[DVec3], _: u32) -> Result<(String, f64), String> {
    Err("this backend was built without the gpu-reference feature".into())
}

/// Milliseconds per board for wgpu rendering the same views (see above).
#[cfg(feature = "gpu-reference")]
fn measure_wgpu(
    object: &PreparedObject,
    directions: &[DVec3],
    size: u32,
) -> Result<(String, f64), String> {
    let gpu = backend::GpuReference::new().map_err(|e| e.to_string())?;
    let uploaded = gpu.upload(object);
    gpu.render(&uploaded, directions[0], size)
        .map_err(|e| e.to_string())?;
    let start = Instant::now();
    for direction in directions {
        std::hint::black_box(
            gpu.render(&uploaded, *direction, size)
                .map_err(|e| e.to_string())?,
        );
    }
    Ok((
        gpu.adapter.clone(),
        start.elapsed().as_secs_f64() * 1e3 / directions.len() as f64,
    ))
}

/// Views spread over the sphere (a Fibonacci lattice), so no single lucky view decides.
fn bench_directions(boards: u32) -> Vec<DVec3> {
    (0..boards)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / boards as f64;
            let theta = std::f64::consts::PI * (3.0 - 5f64.sqrt()) * i as f64;
            let r = (1.0 - y * y).sqrt();
            DVec3::new(r * theta.cos(), y, r * theta.sin())
        })
        .collect()
}

/// Runs `backend wgpu-timing` for the same scene with LP_NUM_THREADS=`threads`: lavapipe
/// reads it when its device is created, so each thread count needs a fresh process.
fn wgpu_in_child(args: &BenchArgs, threads: usize) -> Result<WgpuTiming, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let output = std::process::Command::new(exe)
        .env("LP_NUM_THREADS", threads.to_string())
        .args([
            "wgpu-timing",
            "--scene",
            &args.scene.scene,
            "--triangles",
            &args.scene.triangles.to_string(),
        ])
        .args([
            "--object",
            &args.scene.object,
            "--size",
            &args.size.to_string(),
            "--boards",
            &args.boards.to_string(),
        ])
        .args(
            args.scene
                .t_nz
                .map(|t_nz| ["--t-nz".to_string(), t_nz.to_string()])
                .into_iter()
                .flatten(),
        )
        .output()
        .map_err(|e| e.to_string())?;
    if !output.status.success() {
        return Err(String::from_utf8_lossy(&output.stderr).trim().to_string());
    }
    serde_json::from_slice(&output.stdout).map_err(|e| e.to_string())
}

fn wgpu_timing(args: &BenchArgs) -> anyhow::Result<()> {
    let object = load_object(&args.scene)?;
    let directions = bench_directions(args.boards.max(1));
    let (adapter, milliseconds_per_board) =
        measure_wgpu(&object, &directions, args.size).map_err(anyhow::Error::msg)?;
    println!(
        "{}",
        serde_json::to_string(&WgpuTiming {
            adapter,
            milliseconds_per_board
        })?
    );
    Ok(())
}

fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let object = load_object(&args.scene)?;
    if args.boards == 0 {
        bail!("--boards must be at least 1");
    }
    // Views spread over the sphere (a Fibonacci lattice), so no single lucky view decides.
    let directions = bench_directions(args.boards);
    let measure = |threads: usize| -> anyhow::Result<Throughput> {
        let (pool, threads) = pool(Some(threads))?;
        // One warm-up board: page faults and thread start-up are not the renderer's.
        pool.install(|| render_maps(&object, directions[0], args.size, threads))?;
        let start = Instant::now();
        let mut board_ms = Vec::with_capacity(directions.len());
        for direction in &directions {
            let board_start = Instant::now();
            let maps = pool.install(|| render_maps(&object, *direction, args.size, threads))?;
            board_ms.push(board_start.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(maps);
        }
        let seconds = start.elapsed().as_secs_f64();
        let per_board = seconds / directions.len() as f64;
        board_ms.sort_by(f64::total_cmp);
        Ok(Throughput {
            threads,
            milliseconds_per_board: per_board * 1e3,
            // Less moved by a busy neighbour on a shared machine than the mean.
            median_milliseconds_per_board: report::quantile(&board_ms, 0.5),
            boards_per_second: 1.0 / per_board,
            triangles_per_second: object.triangles.len() as f64 / per_board,
        })
    };
    let start = Instant::now();
    let with_levels = object.clone().with_levels();
    let levels_seconds = start.elapsed().as_secs_f64();
    let all = args.threads.unwrap_or_else(backend::default_threads);
    let (split_pool, _) = pool(Some(all))?;
    let requests = args
        .sizes
        .iter()
        .map(|&size| {
            request_cost(
                &with_levels,
                &directions,
                size,
                &split_pool,
                args.every_level,
            )
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (one_thread, all_threads) = (measure(1)?, measure(all)?);
    let wgpu = wgpu_in_child(args, 1).and_then(|one| {
        let all = wgpu_in_child(args, all)?;
        Ok(GpuThroughput {
            adapter: one.adapter,
            milliseconds_per_board_one_thread: one.milliseconds_per_board,
            milliseconds_per_board_all_threads: all.milliseconds_per_board,
            speedup_one_thread: one.milliseconds_per_board / one_thread.milliseconds_per_board,
            speedup_all_threads: all.milliseconds_per_board / all_threads.milliseconds_per_board,
        })
    });
    let report = BenchReport {
        object: object.name.clone(),
        triangles: object.triangles.len(),
        size: args.size,
        boards: args.boards,
        levels_seconds,
        requests,
        one_thread,
        all_threads,
        wgpu,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "whole requests (render + encoding) on one thread, and split as an idle worker splits them (levels built in {:.2} s):",
            report.levels_seconds
        );
        for r in &report.requests {
            println!(
                "  {0}x{0}: full mesh {1:.2} ms ({2} triangles), worker's level {3:.2} ms (encoding {9:.2}; split over {11} threads {10:.2}; {4} triangles, error {5:.2} px); stencil IoU min {6:.4} mean {7:.4}, depth error {8:.3} px",
                r.size,
                r.full_milliseconds,
                r.full_triangles,
                r.level_milliseconds,
                r.level_triangles,
                r.level_error_pixels,
                r.stencil_iou_min,
                r.stencil_iou_mean,
                r.depth_error_pixels_mean,
                r.level_stages.encoding,
                r.level_split_milliseconds,
                r.split_threads
            );
            let s = &r.level_stages;
            println!(
                "    the level's request by stage: projection {:.3}, triangle pass {:.3}, grow at cuts {:.3}, per-pixel pass {:.3}, encoding {:.3} ms",
                s.projection, s.triangle_pass, s.grow_at_cuts, s.per_pixel_pass, s.encoding
            );
            for l in &r.every_level {
                println!(
                    "    {} level of {} triangles: {:.2} ms; stencil IoU min {:.4} mean {:.4}",
                    match (l.chosen, l.allowed) {
                        (true, _) => "the worker's",
                        (false, true) => "an allowed",
                        (false, false) => "a disallowed",
                    },
                    l.triangles,
                    l.milliseconds,
                    l.stencil_iou_min,
                    l.stencil_iou_mean
                );
            }
        }
        match &report.wgpu {
            Ok(g) => println!(
                "wgpu on {}: {:.2} ms per board on one thread, {:.2} ms on all; software is {:.1}x faster on one thread, {:.1}x on all",
                g.adapter,
                g.milliseconds_per_board_one_thread,
                g.milliseconds_per_board_all_threads,
                g.speedup_one_thread,
                g.speedup_all_threads
            ),
            Err(why) => println!("wgpu: not measured ({why})"),
        }
        for t in [&report.one_thread, &report.all_threads] {
            println!(
                "{} thread(s): {:.2} ms per {}x{} board of {} triangles (median {:.2} ms), {:.0} boards/s, {:.1} M triangles/s",
                t.threads,
                t.milliseconds_per_board,
                args.size,
                args.size,
                report.triangles,
                t.median_milliseconds_per_board,
                t.boards_per_second,
                t.triangles_per_second / 1e6
            );
        }
    }
    Ok(())
}

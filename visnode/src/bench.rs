//! `visnode bench`: a camera path drawn twice per frame from the same camera, with
//! reliefboards and with all geometry (the reference), on the same adapter. Reports frame
//! times, image error, request latency and angle error, per frame (`frames.csv`) and summed
//! up (`summary.json`); sample frames as PNG; sweeps of one parameter as an
//! error-versus-time curve (`sweep.csv`, `error-vs-time.png`, `latency-angle.png`).

use std::path::Path;

use anyhow::Context;
use serde::Serialize;

use crate::camera::camera_path;
use crate::cli::{BenchArgs, BoardArgs, SceneArgs, WorkerArgs};
use crate::image_error::{ImageError, compare, side_by_side, write_png};
use crate::plan::BudgetController;
use crate::viewer::FrameReport;

/// Frames drawn at the path's first camera before measuring, so the first boards can arrive
/// (a walk-through starts after the scene is loaded, not at the first request).
pub const WARMUP_FRAMES: usize = 8;

/// One measured frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// The frame loop's report.
    #[serde(flatten)]
    pub report: FrameReport,
    /// Frame time with the impostors: planning, command recording and GPU.
    pub frame_ms: f64,
    /// Frame time of the reference (all geometry), same camera and adapter.
    pub reference_ms: f64,
    /// Image error against the reference.
    pub error: ImageError,
    /// t_nz used for the frame (changes with `--target-frame-ms`).
    pub t_nz: u64,
}

/// Percentiles of a sample.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Stats {
    /// Mean.
    pub mean: f64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
    /// Sample size.
    pub count: usize,
}

impl Stats {
    /// Statistics of `values` (all zero when empty).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Stats {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Stats::default();
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Stats {
            mean: v.iter().sum::<f64>() / v.len() as f64,
            p50: at(0.5),
            p90: at(0.9),
            p99: at(0.99),
            max: v[v.len() - 1],
            count: v.len(),
        }
    }
}

/// What one run reports.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// The swept parameter's value, when sweeping.
    pub sweep_value: Option<String>,
    /// Scene source.
    pub scene: String,
    /// Triangles in the scene.
    pub triangles: u64,
    /// Objects, and how many may become boards.
    pub objects: usize,
    /// Suitable objects.
    pub suitable: usize,
    /// The adapter.
    pub adapter: String,
    /// Image size.
    pub resolution: [u32; 2],
    /// Measured frames (after the warm-up).
    pub frames: usize,
    /// Warm-up frames not measured.
    pub warmup_frames: usize,
    /// relief, billboard or none.
    pub impostor: crate::cli::Impostor,
    /// Workers used (0: none).
    pub workers: usize,
    /// Frames waited for their boards.
    pub sync: bool,
    /// Planning parameters at the start.
    pub plan: crate::plan::PlanParams,
    /// Cells per side of a board's grid.
    pub board_grid: u32,
    /// Frame time with impostors, ms.
    pub frame_ms: Stats,
    /// Frame time of the reference (geometry only), ms.
    pub reference_ms: Stats,
    /// Mean reference time over mean frame time.
    pub speedup: f64,
    /// PSNR against the reference, dB (mean, and `worst` = lowest).
    pub psnr_db: Stats,
    /// Lowest PSNR of any frame.
    pub worst_psnr_db: f64,
    /// RMSE against the reference (0-255 scale).
    pub rmse: Stats,
    /// Share of pixels differing by more than the threshold.
    pub differing_share: Stats,
    /// Request latency, issue to arrival, ms.
    pub latency_ms: Stats,
    /// Angle error of every drawn board, degrees.
    pub angle_error_degrees: Stats,
    /// Angle errors in 2.5-degree bins from 0 (Süß Figure 4.18).
    pub angle_error_histogram: Vec<u64>,
    /// Boards drawn per frame.
    pub boards_per_frame: Stats,
    /// Triangles drawn per frame.
    pub triangles_per_frame: Stats,
    /// Request totals.
    pub requests: crate::workers::RequestCounts,
    /// Requests still in flight when the run ended: `issued == received + failed + pending`.
    pub requests_pending: u64,
    /// Boards received from each worker (a slower worker should answer fewer).
    pub boards_per_worker: Vec<u64>,
    /// Each worker's health at the end.
    pub worker_health: Vec<crate::workers::WorkerHealth>,
    /// Workers going down and coming back during the run.
    pub health_log: Vec<crate::workers::HealthRecord>,
    /// Boards held on the GPU at the end, and their bytes.
    pub boards_held: usize,
    /// Bytes of the boards held at the end.
    pub board_bytes_held: usize,
    /// Peak resident memory of the process.
    pub peak_memory_bytes: Option<u64>,
    /// Why no boards were used, if none were.
    pub no_boards_reason: Option<String>,
}

pub(crate) fn run(args: &BenchArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let runs = sweep_runs(args)?;
    let sweeping = runs.len() > 1;
    let mut summaries = Vec::new();
    for (value, scene, workers, boards) in runs {
        let out = match &value {
            Some(value) => args
                .out
                .join(format!("run-{}", value.replace(['/', ' '], "_"))),
            None => args.out.clone(),
        };
        std::fs::create_dir_all(&out)?;
        if let Some(value) = &value {
            eprintln!("sweep: {value}");
        }
        let mut summary = run_once(args, &scene, &workers, &boards, &out)?;
        summary.sweep_value = value;
        summaries.push(summary);
    }
    // Written before the check, so a failed run still leaves its figures to look at.
    let accounted = |s: &Summary| {
        s.requests.issued == s.requests.received + s.requests.failed + s.requests_pending
    };
    if sweeping {
        write_sweep(&args.out, &summaries)?;
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
            "requests were lost: {} issued, but {} received + {} failed + {} pending",
            s.requests.issued,
            s.requests.received,
            s.requests.failed,
            s.requests_pending
        );
    }
    Ok(())
}

type Run = (Option<String>, SceneArgs, WorkerArgs, BoardArgs);

/// The runs a `--sweep` asks for (one run without it).
fn sweep_runs(args: &BenchArgs) -> anyhow::Result<Vec<Run>> {
    let base = (
        None,
        args.scene.clone(),
        args.workers.clone(),
        args.boards.clone(),
    );
    let Some(sweep) = &args.sweep else {
        return Ok(vec![base]);
    };
    let (name, values) = sweep
        .split_once('=')
        .context("--sweep takes NAME=V1,V2,... (t-nz, epsilon, map-size, workers, board-grid)")?;
    values
        .split(',')
        .map(|value| {
            let (_, mut scene, mut workers, mut boards) = base.clone();
            let flag = match name {
                "t-nz" | "epsilon" | "map-size" | "board-grid" => name,
                "workers" => "local-workers",
                other => anyhow::bail!(
                    "cannot sweep {other:?}: use t-nz, epsilon, map-size, workers or board-grid"
                ),
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
                "map-size" => scene.map_size = parsed.scene.map_size,
                "board-grid" => boards.board_grid = parsed.boards.board_grid,
                _ => workers.local_workers = parsed.workers.local_workers,
            }
            Ok((Some(format!("{name}={value}")), scene, workers, boards))
        })
        .collect()
}

fn run_once(
    args: &BenchArgs,
    scene_args: &SceneArgs,
    worker_args: &WorkerArgs,
    board_args: &BoardArgs,
    out: &Path,
) -> anyhow::Result<Summary> {
    let crate::setup::Setup {
        mut viewer,
        summary: scene_summary,
    } = crate::setup::setup(
        scene_args,
        worker_args,
        board_args,
        args.sync,
        args.record_trace.is_some(),
    )?;
    let resolution = scene_args.resolution;
    let cameras = camera_path(
        &args.path,
        &viewer.bounds(),
        args.frames,
        scene_args.fov_y_degrees,
    )?;
    let mut controller = board_args
        .target_frame_ms
        .map(|target| BudgetController::new(target, scene_args.t_nz));
    let progress = crate::progress::bar();
    progress.set_length((WARMUP_FRAMES + cameras.len()) as u64);
    progress.set_message("frames");
    for _ in 0..WARMUP_FRAMES {
        viewer.frame(&cameras[0], resolution)?;
        progress.inc(1);
    }
    let samples: Vec<usize> = (0..args.sample_frames.min(cameras.len()))
        .map(|i| {
            (i * cameras.len()) / args.sample_frames.max(1)
                + cameras.len() / (2 * args.sample_frames.max(1))
        })
        .collect();
    let mut records = Vec::with_capacity(cameras.len());
    let mut latencies = Vec::new();
    let started = std::time::Instant::now();
    // With a time limit the path repeats until the time is up (soaks); without, it runs once.
    let frame_count = if args.max_seconds.is_some() {
        usize::MAX
    } else {
        cameras.len()
    };
    let frames = cameras.iter().cycle().take(frame_count);
    for (index, camera) in frames.enumerate() {
        if args
            .max_seconds
            .is_some_and(|limit| started.elapsed().as_secs_f64() > limit)
        {
            break;
        }
        let t_nz = viewer.options.plan.t_nz;
        let report = viewer.frame(camera, resolution)?;
        let frame_ms = report.plan_ms + report.timing.cpu_ms + report.timing.gpu_ms;
        if let Some(controller) = &mut controller {
            viewer.options.plan.t_nz = controller.update(frame_ms);
        }
        let image = viewer.renderer.read_frame()?;
        let reference_timing = viewer.reference_frame(camera, resolution)?;
        let reference = viewer.renderer.read_frame()?;
        let error = compare(&reference, &image, args.diff_threshold);
        if samples.contains(&index) {
            write_png(
                &side_by_side(&reference, &image),
                &out.join(format!("frame-{index:04}.png")),
            )?;
        }
        latencies.extend(report.latencies.iter().map(|s| s * 1e3));
        records.push(FrameRecord {
            report,
            frame_ms,
            reference_ms: reference_timing.cpu_ms + reference_timing.gpu_ms,
            error,
            t_nz,
        });
        progress.inc(1);
    }
    progress.finish_and_clear();
    write_frames_csv(&out.join("frames.csv"), &records)?;
    if let (Some(path), Some(trace)) = (
        &args.record_trace,
        viewer.requests().and_then(|r| r.trace()),
    ) {
        std::fs::write(path, trace.to_json_lines())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let angle_errors: Vec<f64> = records
        .iter()
        .flat_map(|r| r.report.angle_errors.iter().copied())
        .collect();
    let mut histogram = vec![0u64; 19];
    for &a in &angle_errors {
        histogram[((a / 2.5) as usize).min(18)] += 1;
    }
    let frame_ms = Stats::of(records.iter().map(|r| r.frame_ms));
    let reference_ms = Stats::of(records.iter().map(|r| r.reference_ms));
    let psnr = Stats::of(records.iter().map(|r| r.error.psnr_db));
    let (boards_held, board_bytes_held) = viewer.boards_held();
    Ok(Summary {
        sweep_value: None,
        scene: scene_summary.source.clone(),
        triangles: scene_summary.triangles,
        objects: scene_summary.objects,
        suitable: scene_summary.suitable,
        adapter: viewer.renderer.adapter.clone(),
        resolution,
        frames: records.len(),
        warmup_frames: WARMUP_FRAMES,
        impostor: board_args.impostor,
        workers: viewer.requests().map_or(0, |r| r.addresses().len()),
        sync: args.sync,
        plan: crate::setup::plan_params(scene_args, board_args),
        board_grid: board_args.board_grid,
        speedup: reference_ms.mean / frame_ms.mean.max(1e-9),
        frame_ms,
        reference_ms,
        worst_psnr_db: records
            .iter()
            .map(|r| r.error.psnr_db)
            .fold(f64::INFINITY, f64::min),
        psnr_db: psnr,
        rmse: Stats::of(records.iter().map(|r| r.error.rmse)),
        differing_share: Stats::of(records.iter().map(|r| r.error.differing_share)),
        latency_ms: Stats::of(latencies),
        angle_error_degrees: Stats::of(angle_errors),
        angle_error_histogram: histogram,
        boards_per_frame: Stats::of(records.iter().map(|r| r.report.boards as f64)),
        triangles_per_frame: Stats::of(records.iter().map(|r| r.report.triangles as f64)),
        requests: viewer.requests().map(|r| r.counts).unwrap_or_default(),
        requests_pending: viewer.requests().map_or(0, |r| r.pending() as u64),
        boards_per_worker: viewer
            .requests()
            .map(|r| r.received_by_worker().to_vec())
            .unwrap_or_default(),
        worker_health: viewer
            .requests()
            .map(|r| r.health().to_vec())
            .unwrap_or_default(),
        health_log: viewer
            .requests()
            .map(|r| r.health_log().to_vec())
            .unwrap_or_default(),
        boards_held,
        board_bytes_held,
        peak_memory_bytes: crate::peak_memory_bytes(),
        no_boards_reason: viewer.no_boards_reason.clone(),
    })
}

fn write_frames_csv(path: &Path, records: &[FrameRecord]) -> anyhow::Result<()> {
    let mut text = String::from(
        "frame,frame_ms,cpu_ms,gpu_ms,plan_ms,reference_ms,triangles,boards,geometry_objects,near_zone_triangles,t_nz,requests_issued,requests_pending,arrived,mean_latency_ms,mean_angle_error,rmse,psnr_db,differing_share\n",
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
            "{},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{},{},{:.4},{:.3},{:.5}\n",
            r.report.frame,
            r.frame_ms,
            r.report.timing.cpu_ms,
            r.report.timing.gpu_ms,
            r.report.plan_ms,
            r.reference_ms,
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
            r.error.rmse,
            r.error.psnr_db,
            r.error.differing_share,
        ));
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn write_sweep(out: &Path, summaries: &[Summary]) -> anyhow::Result<()> {
    let mut text = String::from(
        "run,mean_frame_ms,mean_reference_ms,speedup,mean_psnr_db,worst_psnr_db,mean_differing_share,latency_p50_ms,latency_p90_ms,mean_angle_error,boards_per_frame\n",
    );
    for s in summaries {
        text.push_str(&format!(
            "{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.5},{:.1},{:.1},{:.3},{:.1}\n",
            s.sweep_value.as_deref().unwrap_or(""),
            s.frame_ms.mean,
            s.reference_ms.mean,
            s.speedup,
            s.psnr_db.mean,
            s.worst_psnr_db,
            s.differing_share.mean,
            s.latency_ms.p50,
            s.latency_ms.p90,
            s.angle_error_degrees.mean,
            s.boards_per_frame.mean,
        ));
    }
    std::fs::write(out.join("sweep.csv"), text)?;
    crate::plots::sweep_plots(out, summaries)
}

fn format_summary(s: &Summary) -> String {
    format!(
        "{run}{scene}: {triangles} triangles, {frames} frames at {w}x{h} on {adapter}\n  \
         frame time {fm:.1} ms (p90 {fp:.1}) with {impostor:?}, {rm:.1} ms geometry only: {speedup:.2}x\n  \
         image error: mean PSNR {psnr:.2} dB, worst {worst:.2} dB, {diff:.2}% pixels differ\n  \
         requests: {issued} issued, {received} received, {failed} failed, {pending} pending, latency p50 {lp50:.0} ms p90 {lp90:.0} ms; \
         angle error mean {am:.1} deg, p90 {ap:.1} deg; {boards:.0} boards per frame",
        run = s
            .sweep_value
            .as_ref()
            .map(|v| format!("[{v}] "))
            .unwrap_or_default(),
        scene = s.scene,
        triangles = s.triangles,
        frames = s.frames,
        w = s.resolution[0],
        h = s.resolution[1],
        adapter = s.adapter,
        fm = s.frame_ms.mean,
        fp = s.frame_ms.p90,
        impostor = s.impostor,
        rm = s.reference_ms.mean,
        speedup = s.speedup,
        psnr = s.psnr_db.mean,
        worst = s.worst_psnr_db,
        diff = s.differing_share.mean * 100.0,
        issued = s.requests.issued,
        received = s.requests.received,
        failed = s.requests.failed,
        pending = s.requests_pending,
        lp50 = s.latency_ms.p50,
        lp90 = s.latency_ms.p90,
        am = s.angle_error_degrees.mean,
        ap = s.angle_error_degrees.p90,
        boards = s.boards_per_frame.mean,
    )
}

#[cfg(test)]
mod tests {
    use super::Stats;

    #[test]
    fn stats_take_the_nearest_index_and_skip_non_finite_values() {
        let stats = Stats::of((1..=11).map(f64::from).chain([f64::NAN, f64::INFINITY]));
        assert_eq!(stats.count, 11);
        assert_eq!(stats.mean, 6.0);
        assert_eq!(
            (stats.p50, stats.p90, stats.p99, stats.max),
            (6.0, 10.0, 11.0, 11.0)
        );
        let one = Stats::of([4.0]);
        assert_eq!((one.p50, one.p90, one.max), (4.0, 4.0, 4.0));
        assert_eq!(Stats::of([]).count, 0);
    }
}

//! `visnode inspect`: load a scene, prepare it, and report what will be drawn how.

use std::time::Instant;

use anyhow::Context;
use serde::Serialize;

use crate::cli::{InspectArgs, SceneArgs};

/// What `inspect` reports: preprocessing's summary plus load time and peak memory.
#[derive(Debug, Serialize)]
pub struct InspectReport {
    /// Preprocessing's figures.
    #[serde(flatten)]
    pub summary: scene::Summary,
    /// Time to load or generate the scene.
    pub load_seconds: f64,
    /// Peak resident memory of the process, if known.
    pub peak_memory_bytes: Option<u64>,
    /// Without `--t-nz`: the adapter whose default `t_nz` was taken.
    pub t_nz_default_for: Option<String>,
}

/// Loads and prepares the scene described by `args`.
pub fn inspect(args: &SceneArgs) -> anyhow::Result<(scene::PreparedScene, InspectReport)> {
    let bar = crate::progress::bar();
    let progress = crate::progress::for_scene(&bar);
    let load_options = args.load_options(progress.clone());
    let start = Instant::now();
    let loaded = scene::load_scene(&args.scene, &load_options)?;
    let load_seconds = start.elapsed().as_secs_f64();
    let params = scene::PrepareParams {
        t_nz: args.t_nz(),
        map_size: args.map_size,
        resolution: args.resolution,
        fov_y_degrees: args.fov_y_degrees,
        min_triangles: args.min_triangles,
        cache_dir: args.cache_directory(),
        progress: progress.clone(),
    };
    let prepared = scene::prepare(loaded, &params)?;
    bar.finish_and_clear();
    let report = InspectReport {
        summary: prepared.summary.clone(),
        load_seconds,
        peak_memory_bytes: crate::peak_memory_bytes(),
        t_nz_default_for: args
            .t_nz
            .is_none()
            .then(|| match crate::render::headless_adapter() {
                Some(adapter) => format!(
                    "{} ({:?}, {:?})",
                    adapter.name, adapter.backend, adapter.device_type
                ),
                None => "no adapter found".into(),
            }),
    };
    Ok((prepared, report))
}

pub(crate) fn run(args: &InspectArgs) -> anyhow::Result<()> {
    let (prepared, report) = inspect(&args.scene)?;
    if let Some(path) = &args.png {
        crate::topview::write_png(&prepared, path)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", format_report(&report));
    }
    Ok(())
}

fn format_report(report: &InspectReport) -> String {
    let s = &report.summary;
    let mut out = String::new();
    let mut line = |label: &str, text: String| out.push_str(&format!("{label:<13}{text}\n"));
    line("scene", s.source.clone());
    line(
        "input",
        format!(
            "{} objects, {} triangles ({} zero-area triangles dropped)",
            s.input_objects, s.input_triangles, s.degenerate_triangles_dropped
        ),
    );
    line(
        "objects",
        format!(
            "{} objects, {} triangles ({} duplicate faces dropped)",
            s.objects, s.triangles, s.duplicate_faces_dropped
        ),
    );
    line(
        "  suitable",
        format!(
            "{} objects, {} triangles: drawn as reliefboards beyond the near zone",
            s.suitable, s.suitable_triangles
        ),
    );
    line(
        "  too large",
        format!(
            "{} objects: always geometry (longest side over sl_c, or its own for pieces of dense objects)",
            s.too_large
        ),
    );
    line(
        "  too simple",
        format!(
            "{} objects: always geometry (too few triangles)",
            s.too_simple
        ),
    );
    line(
        "near zone",
        format!(
            "t_nz = {} triangles, d_nz = {:.4}, sl_c = {:.4}",
            s.t_nz, s.d_nz, s.sl_c
        ),
    );
    if let Some(adapter) = &report.t_nz_default_for {
        line(
            "",
            format!("t_nz is the default for the adapter: {adapter}; --t-nz sets it"),
        );
    }
    for dense in &s.dense {
        line(
            "dense",
            format!(
                "{} objects too large for sl_c cut into {} pieces of side at most {:.4}, boards up to {} pixels",
                dense.objects, dense.pieces, dense.sl_c, dense.map_size
            ),
        );
    }
    if let Some(sparse) = &s.sparse {
        line(
            "sparse",
            format!(
                "{} objects too large and too sparse for boards cut into {} pieces of side at most {:.4}, each drawn at its own level of detail (boards up to {} pixels where a piece is suitable)",
                sparse.objects, sparse.pieces, sparse.sl_c, sparse.map_size
            ),
        );
    }
    if s.fits_in_near_zone {
        line(
            "",
            "the whole scene fits in t_nz: no reliefboard is needed".into(),
        );
    }
    line("phases", String::new());
    for phase in &s.phases {
        let state = if phase.ran { "ran" } else { "skipped" };
        line(
            "",
            format!(
                "{:<22} {:<8} {:>8.3} s  {}",
                phase.name, state, phase.seconds, phase.note
            ),
        );
    }
    line("cache", s.cache.clone());
    line("load", format!("{:.3} s", report.load_seconds));
    if let Some(bytes) = report.peak_memory_bytes {
        line(
            "peak memory",
            format!("{:.2} GiB", bytes as f64 / (1u64 << 30) as f64),
        );
    }
    out
}

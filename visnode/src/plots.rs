//! PNG plots of a benchmark sweep (plotters, in the look `report::plot` gives every plot).

use std::path::Path;

use plotters::prelude::*;
use report::plot::{PALETTE, chart, draw_legend, register_font};

use crate::bench::Summary;
use crate::cli::Impostor;

/// A plotted figure: file, axis label, and how to read it off a run.
type Metric = (&'static str, &'static str, fn(&Summary) -> f64);

/// `pareto-object-psnr.png` and `pareto-flip.png`: object-pixel error against mean frame time,
/// one curve per kind over its swept knob (a point without a sweep), the geometry-only
/// reference time and each `floor` run's frame time as vertical lines; and
/// `latency-angle.png` (request latency and angle error per run).
pub fn pareto_plots(out: &Path, all: &[Summary]) -> anyhow::Result<()> {
    register_font();
    // A floor run leaves the far objects out: its error is no kind's, its time bounds all.
    let (floors, summaries): (Vec<&Summary>, Vec<&Summary>) =
        all.iter().partition(|s| s.impostor == Impostor::Floor);
    let label = |s: &Summary| s.sweep_value.clone().unwrap_or_default();
    let metrics: [Metric; 2] = [
        (
            "pareto-object-psnr.png",
            "object-pixel PSNR vs all geometry (dB, higher is better)",
            |s| s.error.object_psnr_db,
        ),
        (
            "pareto-flip.png",
            "object-pixel FLIP (lower is better)",
            |s| s.error.object_flip.mean,
        ),
    ];
    // One curve per kind and swept knob.
    let curve = |s: &Summary| {
        let knob = s
            .sweep_value
            .as_deref()
            .and_then(|v| v.split_once('='))
            .map(|(name, _)| format!(" over {name}"))
            .unwrap_or_default();
        format!("{:?}{knob}", s.impostor).to_lowercase()
    };
    let mut curves: Vec<String> = Vec::new();
    for &s in &summaries {
        if !curves.contains(&curve(s)) {
            curves.push(curve(s));
        }
    }
    for (file, y_desc, metric) in metrics {
        let path = out.join(file);
        let root = BitMapBackend::new(&path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let x_max = all
            .iter()
            .map(|s| s.frame_ms.mean.max(s.reference_ms.mean))
            .fold(1.0, f64::max)
            * 1.1;
        let values: Vec<f64> = summaries.iter().map(|s| metric(s)).collect();
        let low = values.iter().copied().fold(f64::INFINITY, f64::min);
        let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let pad = ((high - low) * 0.15).max(if high > 2.0 { 1.0 } else { 0.01 });
        let (y_min, y_max) = (low - pad, high + pad);
        let mut chart = chart(
            &root,
            "Error against frame time, as a user watches (wall clock)",
            0.0..x_max,
            y_min..y_max,
            ("mean frame time (ms)", y_desc),
        )?;
        let reference =
            all.iter().map(|s| s.reference_ms.mean).sum::<f64>() / all.len().max(1) as f64;
        chart
            .draw_series(LineSeries::new(
                [(reference, y_min), (reference, y_max)],
                RGBColor(127, 127, 127).stroke_width(2),
            ))?
            .label("all geometry (reference draw)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RGBColor(127, 127, 127)));
        for floor in &floors {
            let x = floor.frame_ms.mean;
            let dark = RGBColor(60, 60, 60);
            chart
                .draw_series(DashedLineSeries::new(
                    [(x, y_min), (x, y_max)],
                    6,
                    4,
                    dark.stroke_width(2),
                ))?
                .label(format!("floor: no far objects{}", label(floor)))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], dark));
        }
        for (index, name) in curves.iter().enumerate() {
            let color = PALETTE[index % PALETTE.len()];
            let runs: Vec<&Summary> = summaries
                .iter()
                .copied()
                .filter(|s| curve(s) == *name)
                .collect();
            let mut points: Vec<(f64, f64)> =
                runs.iter().map(|s| (s.frame_ms.mean, metric(s))).collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart.draw_series(LineSeries::new(points, color.stroke_width(2)))?;
            chart
                .draw_series(runs.iter().map(|s| {
                    EmptyElement::at((s.frame_ms.mean, metric(s)))
                        + Circle::new((0, 0), 5, color.filled())
                        + Text::new(label(s), (8, -14), ("sans-serif", 12))
                }))?
                .label(name.clone())
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
        }
        draw_legend(&mut chart, SeriesLabelPosition::MiddleRight)?;
        root.present()?;
    }
    {
        let path = out.join("latency-angle.png");
        let root = BitMapBackend::new(&path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let halves = root.split_evenly((1, 2));
        let runs = all.len() as f64;
        for (area, (title, value, color)) in halves.iter().zip([
            (
                "Request latency p50 (ms)",
                (|s: &Summary| s.latency_ms.p50) as fn(&Summary) -> f64,
                RGBColor(214, 39, 40),
            ),
            (
                "Mean angle error (degrees)",
                |s: &Summary| s.angle_error_degrees.mean,
                RGBColor(44, 160, 44),
            ),
        ]) {
            let y_max = all.iter().map(value).fold(1.0, f64::max) * 1.2;
            let mut chart = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d(-0.5..runs - 0.5, 0.0..y_max)?;
            chart
                .configure_mesh()
                .x_labels(all.len())
                .x_label_formatter(&|x| {
                    all.get(x.round().max(0.0) as usize)
                        .map(label)
                        .unwrap_or_default()
                })
                .label_style(("sans-serif", 12))
                .draw()?;
            chart.draw_series(all.iter().enumerate().map(|(i, s)| {
                Rectangle::new(
                    [(i as f64 - 0.3, 0.0), (i as f64 + 0.3, value(s))],
                    color.filled(),
                )
            }))?;
        }
        root.present()?;
    }
    Ok(())
}

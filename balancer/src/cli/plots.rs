//! PNG plots of a simulation (plotters, in the look `report::plot` gives every plot).

use std::path::Path;

use balancer::{Policy, SimulationConfig, SimulationResult};
use plotters::prelude::*;
use report::plot::{PALETTE, chart, draw_legend, register_font};

/// Writes `load-*.png` (per-worker share per position, like Süß Figures 5.9-5.13),
/// `busiest-*.png` (busiest worker over the lower bound, every policy) and `summary-k*.png`.
pub fn draw(
    out: &Path,
    results: &[(String, SimulationConfig, SimulationResult)],
    summary: Vec<(usize, usize, &str, f64)>,
) -> anyhow::Result<()> {
    register_font();
    let mut pairs: Vec<(usize, usize)> = results
        .iter()
        .map(|(_, c, _)| (c.workers, c.replicas))
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    for &(nodes, replicas) in &pairs {
        let seed0: Vec<&(String, SimulationConfig, SimulationResult)> = results
            .iter()
            .filter(|(_, c, _)| c.workers == nodes && c.replicas == replicas && c.seed == 0)
            .collect();
        if let Some((name, _, result)) = seed0
            .iter()
            .find(|(_, c, _)| matches!(c.policy, Policy::Balancer(_)))
        {
            for (file, sorted) in [("load", false), ("load-sorted", true)] {
                load_plot(
                    &out.join(format!("{file}-n{nodes}-k{replicas}.png")),
                    name,
                    nodes,
                    replicas,
                    result,
                    sorted,
                )?;
            }
        }
        let balancer_runs: Vec<&(String, SimulationConfig, SimulationResult)> = seed0
            .iter()
            .copied()
            .filter(|(_, c, _)| matches!(c.policy, Policy::Balancer(_)))
            .collect();
        if let [first, second] = balancer_runs[..] {
            difference_plot(
                &out.join(format!("difference-n{nodes}-k{replicas}.png")),
                nodes,
                replicas,
                first,
                second,
            )?;
        }
        busiest_plot(
            &out.join(format!("busiest-n{nodes}-k{replicas}.png")),
            nodes,
            replicas,
            &seed0,
        )?;
    }
    let mut replica_counts: Vec<usize> = summary.iter().map(|r| r.1).collect();
    replica_counts.sort_unstable();
    replica_counts.dedup();
    for replicas in replica_counts {
        summary_plot(
            &out.join(format!("summary-k{replicas}.png")),
            replicas,
            &summary,
        )?;
    }
    Ok(())
}

/// The two kinds of position the per-position plots tell apart, as (fewer requests than
/// workers, colour, legend): those with at least n requests under `label`, the others apart
/// (most of their workers must be idle, so their spread says little).
fn position_kinds(label: &'static str) -> [(bool, RGBColor, &'static str); 2] {
    [
        (false, PALETTE[0], label),
        (
            true,
            PALETTE[2],
            "positions with fewer requests than workers",
        ),
    ]
}

/// Per-worker load per position (Süß Figs. 5.9-5.13): the 0.1-0.9 quantile band and the
/// median over workers, in units of an even share. Every position with requests is shown;
/// those with fewer requests than workers (where most workers must be idle) in another
/// colour. `sorted`: positions ordered by their number of requests instead of by time.
fn load_plot(
    path: &Path,
    name: &str,
    nodes: usize,
    replicas: usize,
    result: &SimulationResult,
    sorted: bool,
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1200, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut shown: Vec<(usize, &balancer::PositionStats)> = result
        .positions
        .iter()
        .enumerate()
        .filter(|(_, p)| p.requests > 0)
        .collect();
    if sorted {
        shown.sort_by_key(|(_, p)| p.requests);
    }
    // (x, q10, median, q90, few requests)
    let positions: Vec<(f64, f64, f64, f64, bool)> = shown
        .iter()
        .enumerate()
        .map(|(rank, (index, p))| {
            (
                if sorted { rank } else { *index } as f64,
                p.q10_share * nodes as f64,
                p.median_share * nodes as f64,
                p.q90_share * nodes as f64,
                p.requests < nodes,
            )
        })
        .collect();
    let x_max = if sorted {
        positions.len().max(1) as f64
    } else {
        result.positions.len().max(1) as f64
    };
    let y_max = positions
        .iter()
        .map(|p| p.3)
        .fold(2.0f64, f64::max)
        .min(10.0);
    let mut chart = chart(
        &root,
        format!("{name}: per-worker load per position, {nodes} workers, {replicas} replicas"),
        0.0..x_max,
        0.0..y_max,
        (
            if sorted {
                "positions, sorted by requests per position"
            } else {
                "walk-through position"
            },
            "load / (total / n)",
        ),
    )?;
    for (few, color, label) in position_kinds("0.1 to 0.9 quantile over workers") {
        chart
            .draw_series(
                positions
                    .iter()
                    .filter(|p| p.4 == few)
                    .map(|&(x, low, _, high, _)| {
                        PathElement::new(vec![(x, low), (x, high)], color.mix(0.35))
                    }),
            )?
            .label(label)
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], color.mix(0.35).filled())
            });
    }
    chart
        .draw_series(
            positions
                .iter()
                .map(|&(x, _, median, _, _)| Circle::new((x, median), 1, PALETTE[1].filled())),
        )?
        .label("median")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, PALETTE[1].filled()));
    chart
        .draw_series(LineSeries::new([(0.0, 1.0), (x_max, 1.0)], BLACK.mix(0.6)))?
        .label("even share")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.6)));
    draw_legend(&mut chart, SeriesLabelPosition::MiddleRight)?;
    root.present()?;
    Ok(())
}

/// |a − b| per position of the busiest worker over the lower bound, for two runs of the
/// balancer on the same placement (Süß Fig. 5.14: deterministic against randomized).
fn difference_plot(
    path: &Path,
    nodes: usize,
    replicas: usize,
    a: &(String, SimulationConfig, SimulationResult),
    b: &(String, SimulationConfig, SimulationResult),
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1200, 450)).into_drawing_area();
    root.fill(&WHITE)?;
    let points: Vec<(f64, f64, bool)> =
        a.2.positions
            .iter()
            .zip(&b.2.positions)
            .enumerate()
            .filter(|(_, (p, _))| p.requests > 0)
            .map(|(i, (p, q))| {
                (
                    i as f64,
                    (p.busiest_over_bound - q.busiest_over_bound).abs(),
                    p.requests < nodes,
                )
            })
            .collect();
    let x_max = a.2.positions.len().max(1) as f64;
    let y_max = points.iter().map(|p| p.1).fold(0.5f64, f64::max) * 1.05;
    let mut chart = chart(
        &root,
        format!(
            "|{} - {}| of busiest / bound, {nodes} workers, {replicas} replicas",
            a.0, b.0
        ),
        0.0..x_max,
        0.0..y_max,
        ("walk-through position", "difference of busiest / bound"),
    )?;
    for (few, color, label) in position_kinds("positions with at least n requests") {
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.2 == few)
                    .map(|&(x, y, _)| Circle::new((x, y), 2, color.filled())),
            )?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
    }
    draw_legend(&mut chart, SeriesLabelPosition::MiddleRight)?;
    root.present()?;
    Ok(())
}

fn busiest_plot(
    path: &Path,
    nodes: usize,
    replicas: usize,
    runs: &[&(String, SimulationConfig, SimulationResult)],
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let curves: Vec<(&str, Vec<f64>)> = runs
        .iter()
        .map(|(name, _, result)| {
            let mut ratios: Vec<f64> = result
                .positions
                .iter()
                .filter(|p| p.requests >= 2 * nodes)
                .map(|p| p.busiest_over_bound)
                .collect();
            if ratios.is_empty() {
                ratios = result
                    .positions
                    .iter()
                    .filter(|p| p.requests > 0)
                    .map(|p| p.busiest_over_bound)
                    .collect();
            }
            ratios.sort_by(f64::total_cmp);
            (name.as_str(), ratios)
        })
        .collect();
    let y_max = curves
        .iter()
        .flat_map(|(_, r)| r.last().copied())
        .fold(1.5f64, f64::max)
        * 1.05;
    let mut chart = chart(
        &root,
        format!(
            "busiest worker / lower bound at busy positions, {nodes} workers, {replicas} replicas"
        ),
        0.0..1.0,
        0.0..y_max,
        (
            "fraction of positions (sorted)",
            "busiest / max(total/n, heaviest)",
        ),
    )?;
    for (index, (name, ratios)) in curves.iter().enumerate() {
        let color = PALETTE[index % PALETTE.len()];
        let n = ratios.len().max(1) as f64;
        chart
            .draw_series(LineSeries::new(
                ratios.iter().enumerate().map(|(i, r)| (i as f64 / n, *r)),
                color.stroke_width(2),
            ))?
            .label(*name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    root.present()?;
    Ok(())
}

fn summary_plot(
    path: &Path,
    replicas: usize,
    summary: &[(usize, usize, &str, f64)],
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (900, 550)).into_drawing_area();
    root.fill(&WHITE)?;
    // NaN: no busy position at that worker count; nothing to draw.
    let rows: Vec<&(usize, usize, &str, f64)> = summary
        .iter()
        .filter(|r| r.1 == replicas && !r.3.is_nan())
        .collect();
    let mut policies: Vec<&str> = Vec::new();
    for row in &rows {
        if !policies.contains(&row.2) {
            policies.push(row.2);
        }
    }
    let mut node_counts: Vec<usize> = rows.iter().map(|r| r.0).collect();
    node_counts.sort_unstable();
    node_counts.dedup();
    let x_max = *node_counts.last().unwrap_or(&1) as f64 * 1.1;
    let y_max = rows.iter().map(|r| r.3).fold(1.5f64, f64::max) * 1.1;
    let mut chart = chart(
        &root,
        format!("mean busiest / lower bound at busy positions, {replicas} replicas"),
        0.0..x_max,
        0.0..y_max,
        ("workers", "busiest / lower bound"),
    )?;
    for (index, policy) in policies.iter().enumerate() {
        let color = PALETTE[index % PALETTE.len()];
        let points: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.2 == *policy)
            .map(|r| (r.0 as f64, r.3))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
            .label(*policy)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(points.iter().map(|p| Circle::new(*p, 4, color.filled())))?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::LowerRight)?;
    root.present()?;
    Ok(())
}

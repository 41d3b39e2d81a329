//! `balancer scaling`: Süß chapter 4's figures (4.14 and 4.18) from the table that
//! `scripts/chapter4-scaling.sh` writes, one row per worker count of live runs.

use std::path::Path;

use anyhow::{Context, bail};
use plotters::prelude::*;
use report::plot::{PALETTE, draw_legend, register_font};

/// One worker count's live figures.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalingRow {
    /// Worker processes.
    pub workers: u32,
    /// Request latency (issue to arrival), ms.
    pub latency_p50_ms: f64,
    /// Its 0.9 quantile.
    pub latency_p90_ms: f64,
    /// Its mean (Süß's mean response time).
    pub latency_mean_ms: f64,
    /// Angle error quantiles 0.1, 0.25, 0.5, 0.75, 0.9 of every drawn board, degrees.
    pub angle_box: [f64; 5],
    /// Seconds after a fast turn until every board is fresh (`None`: not within the run).
    pub refresh_s: Option<f64>,
    /// Mean latency of the run with the turn, ms: what Süß compares the refresh time with.
    pub turn_latency_mean_ms: f64,
}

/// The columns read, by name (others are ignored).
const COLUMNS: [&str; 11] = [
    "workers",
    "latency_p50_ms",
    "latency_p90_ms",
    "latency_mean_ms",
    "angle_p10_deg",
    "angle_p25_deg",
    "angle_p50_deg",
    "angle_p75_deg",
    "angle_p90_deg",
    "refresh_after_turn_s",
    "turn_latency_mean_ms",
];

/// Parses the script's CSV; an empty `refresh_after_turn_s` is `None`.
pub fn parse(text: &str) -> anyhow::Result<Vec<ScalingRow>> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines.next().context("empty table")?.split(',').collect();
    let index: Vec<usize> = COLUMNS
        .iter()
        .map(|name| {
            header
                .iter()
                .position(|h| h.trim() == *name)
                .with_context(|| format!("no column {name:?}"))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut rows = Vec::new();
    for (number, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let cell = |column: usize| -> anyhow::Result<Option<f64>> {
            let text = cells
                .get(index[column])
                .with_context(|| format!("row {}: too few cells", number + 1))?;
            if text.is_empty() {
                return Ok(None);
            }
            let value: f64 = text.parse().with_context(|| {
                format!(
                    "row {}: {:?} in {} is not a number",
                    number + 1,
                    text,
                    COLUMNS[column]
                )
            })?;
            if !value.is_finite() || value < 0.0 {
                bail!(
                    "row {}: {} must be a finite number >= 0, got {value}",
                    number + 1,
                    COLUMNS[column]
                );
            }
            Ok(Some(value))
        };
        let need = |column: usize| -> anyhow::Result<f64> {
            cell(column)?
                .with_context(|| format!("row {}: {} is empty", number + 1, COLUMNS[column]))
        };
        let workers = need(0)?;
        if workers < 1.0 || workers.fract() != 0.0 || workers > 1e6 {
            bail!(
                "row {}: workers must be a whole number >= 1, got {workers}",
                number + 1
            );
        }
        rows.push(ScalingRow {
            workers: workers as u32,
            latency_p50_ms: need(1)?,
            latency_p90_ms: need(2)?,
            latency_mean_ms: need(3)?,
            angle_box: [need(4)?, need(5)?, need(6)?, need(7)?, need(8)?],
            refresh_s: cell(9)?,
            turn_latency_mean_ms: need(10)?,
        });
    }
    if rows.is_empty() {
        bail!("the table has no rows");
    }
    rows.sort_by_key(|r| r.workers);
    Ok(rows)
}

/// A plotted line: its legend and how to read it off a row.
type Series = (&'static str, fn(&ScalingRow) -> f64);

/// Writes `scaling-latency.png`, `scaling-angle.png` and `scaling-refresh.png` into `out`.
pub fn draw(out: &Path, rows: &[ScalingRow]) -> anyhow::Result<()> {
    register_font();
    let x = |r: &ScalingRow| (r.workers as f64).log2();
    let x_max = rows.iter().map(x).fold(0.0, f64::max) + 0.5;

    let latency_max = rows.iter().map(|r| r.latency_p90_ms).fold(1.0, f64::max) * 1.15;
    let path = out.join("scaling-latency.png");
    let root = BitMapBackend::new(&path, (900, 550)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = workers_chart(
        &root,
        "Board latency against workers (Süß Fig. 4.14)",
        x_max,
        latency_max,
        "request latency, issue to arrival (ms)",
    )?;
    let series: [Series; 3] = [
        ("p50", |r| r.latency_p50_ms),
        ("p90", |r| r.latency_p90_ms),
        ("mean", |r| r.latency_mean_ms),
    ];
    for (index, (label, value)) in series.into_iter().enumerate() {
        let points = rows.iter().map(|r| (x(r), value(r))).collect();
        draw_line(&mut chart, points, PALETTE[index % PALETTE.len()], label)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    root.present()?;

    let angle_max = rows.iter().map(|r| r.angle_box[4]).fold(1.0, f64::max) * 1.15;
    let path = out.join("scaling-angle.png");
    let root = BitMapBackend::new(&path, (900, 550)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = workers_chart(
        &root,
        "Angle error of drawn boards against workers (Süß Fig. 4.18)",
        x_max,
        angle_max,
        "angle error (degrees): 0.1 / 0.25 / 0.5 / 0.75 / 0.9",
    )?;
    let color = PALETTE[0];
    for r in rows {
        let [p10, p25, p50, p75, p90] = r.angle_box;
        let (left, right) = (x(r) - 0.15, x(r) + 0.15);
        chart.draw_series([
            PathElement::new([(x(r), p10), (x(r), p25)], BLACK),
            PathElement::new([(x(r), p75), (x(r), p90)], BLACK),
            PathElement::new([(left, p50), (right, p50)], BLACK.stroke_width(2)),
        ])?;
        chart.draw_series([Rectangle::new(
            [(left, p25), (right, p75)],
            color.mix(0.5).filled(),
        )])?;
    }
    root.present()?;

    let seconds_max = rows
        .iter()
        .map(|r| {
            r.refresh_s
                .unwrap_or(0.0)
                .max(2.0 * r.turn_latency_mean_ms / 1e3)
        })
        .fold(0.1, f64::max)
        * 1.15;
    let path = out.join("scaling-refresh.png");
    let root = BitMapBackend::new(&path, (900, 550)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = workers_chart(
        &root,
        "Every board fresh again after a fast quarter turn",
        x_max,
        seconds_max,
        "seconds after the turn",
    )?;
    let band: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (x(r), r.turn_latency_mean_ms / 1e3))
        .chain(
            rows.iter()
                .rev()
                .map(|r| (x(r), 2.0 * r.turn_latency_mean_ms / 1e3)),
        )
        .collect();
    chart
        .draw_series([Polygon::new(band, PALETTE[1].mix(0.25).filled())])?
        .label("1-2x the run's mean response time (Süß)")
        .legend(|(x, y)| {
            Rectangle::new([(x, y - 5), (x + 20, y + 5)], PALETTE[1].mix(0.25).filled())
        });
    let points = rows
        .iter()
        .filter_map(|r| Some((x(r), r.refresh_s?)))
        .collect();
    draw_line(
        &mut chart,
        points,
        PALETTE[0],
        "measured (worker counts that never got there are left out)",
    )?;
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    root.present()?;
    Ok(())
}

/// A labelled line through `points`, each point marked.
fn draw_line(
    chart: &mut report::plot::Chart<'_, '_>,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    label: &str,
) -> anyhow::Result<()> {
    chart
        .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
        .label(label)
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2)));
    chart.draw_series(
        points
            .into_iter()
            .map(|p| Circle::new(p, 4, color.filled())),
    )?;
    Ok(())
}

/// A chart over worker counts on a log2 axis, labelled with the counts themselves.
fn workers_chart<'a, 'b>(
    root: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    caption: &str,
    x_max: f64,
    y_max: f64,
    y_desc: &str,
) -> anyhow::Result<report::plot::Chart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..x_max, 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("worker processes")
        .y_desc(y_desc)
        .x_labels(((x_max + 0.5) as usize).max(1) + 1)
        .x_label_formatter(&|v| format!("{}", 2f64.powf(v.round()).round()))
        .label_style(("sans-serif", 14))
        .draw()?;
    Ok(chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_read_by_column_name_and_bad_cells_are_refused() {
        let text = "workers,latency_p50_ms,latency_p90_ms,latency_mean_ms,angle_p10_deg,angle_p25_deg,angle_p50_deg,angle_p75_deg,angle_p90_deg,refresh_after_turn_s,turn_latency_mean_ms,extra\n\
                    4,30,60,35,1,2,3,4,5,0.5,40,x\n\
                    1,300,600,350,2,4,6,8,10,,400,y\n";
        let rows = parse(text).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].workers, 1, "sorted by workers");
        assert_eq!(rows[0].refresh_s, None);
        assert_eq!(rows[1].refresh_s, Some(0.5));
        assert_eq!(rows[1].angle_box, [1.0, 2.0, 3.0, 4.0, 5.0]);
        let header = text.lines().next().unwrap();
        for bad in [
            "0,1,1,1,1,1,1,1,1,1,1,x",
            "2,NaN,1,1,1,1,1,1,1,1,1,x",
            "2,1,1",
            "2.5,1,1,1,1,1,1,1,1,1,1,x",
            "2,1,1,1,1,1,1,1,1,1,,x",
        ] {
            assert!(parse(&format!("{header}\n{bad}\n")).is_err(), "{bad}");
        }
        assert!(parse("workers\n1\n").is_err(), "missing columns");
        assert!(parse(&format!("{header}\n")).is_err(), "no rows");
    }
}

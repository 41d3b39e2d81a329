//! The egui overlay: what the frame loop and the cluster are doing, and the controls that
//! change them live. It reads the viewer and writes its options; the window acts on the
//! [`Action`]s it returns.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use egui::{Color32, Pos2, Rect, Stroke, Vec2};

use super::controls::{CameraControl, Mode};
use crate::bench::Stats;
use crate::viewer::{FrameReport, Viewer};

/// Frames kept for the frame-time graph.
const GRAPH_FRAMES: usize = 300;
/// Board arrivals kept for the latency percentiles.
const LATENCY_WINDOW: Duration = Duration::from_secs(5);
/// Bins of the angle-error histogram, between 0 and E.
const ANGLE_BINS: usize = 9;

const DEAD: Color32 = Color32::from_rgb(220, 60, 60);
const BUSY: Color32 = Color32::from_rgb(90, 150, 230);

/// What the person asked for through the overlay.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Save the next frame as PNG.
    Screenshot,
    /// Start or stop recording the camera path.
    ToggleRecording,
    /// Start or stop replaying the camera path given on the command line.
    ToggleReplay,
}

/// What the overlay remembers between frames.
pub struct Overlay {
    frame_ms: VecDeque<f32>,
    latencies: VecDeque<(Instant, f64)>,
    last: FrameReport,
    /// Draw the overlay at all (F1).
    pub visible: bool,
    /// Status line: where the last screenshot or path went, or what failed.
    pub message: String,
    /// Where the overlay's windows were last drawn, `[left, top, right, bottom]` in physical
    /// pixels.
    pub rects: Vec<[f32; 4]>,
}

/// Camera-path state shown in the overlay.
pub struct PathState {
    /// Cameras recorded so far, when recording.
    pub recording: Option<usize>,
    /// Frame and length of the replay, when replaying.
    pub replaying: Option<(usize, usize)>,
    /// Whether a path to replay was given.
    pub can_replay: bool,
}

impl Overlay {
    /// An empty history.
    pub fn new() -> Overlay {
        Overlay {
            frame_ms: VecDeque::with_capacity(GRAPH_FRAMES),
            latencies: VecDeque::new(),
            last: FrameReport::default(),
            visible: true,
            message: String::new(),
            rects: Vec::new(),
        }
    }

    /// Takes in a drawn frame: its interval since the previous one and its report.
    pub fn record(&mut self, frame_interval: Duration, report: FrameReport) {
        if self.frame_ms.len() == GRAPH_FRAMES {
            self.frame_ms.pop_front();
        }
        self.frame_ms.push_back(frame_interval.as_secs_f32() * 1e3);
        let now = Instant::now();
        self.latencies
            .extend(report.latencies.iter().map(|&l| (now, l)));
        while self
            .latencies
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t) > LATENCY_WINDOW)
        {
            self.latencies.pop_front();
        }
        self.last = report;
    }

    /// Draws the overlay and returns what was asked for.
    pub fn show(
        &mut self,
        ctx: &egui::Context,
        viewer: &mut Viewer,
        control: &mut CameraControl,
        path: &PathState,
    ) -> Vec<Action> {
        let mut actions = Vec::new();
        if !self.visible {
            return actions;
        }
        let ppp = ctx.pixels_per_point();
        let pixels = |rect: Rect| {
            [
                rect.min.x * ppp,
                rect.min.y * ppp,
                rect.max.x * ppp,
                rect.max.y * ppp,
            ]
        };
        self.rects.clear();
        let stats = egui::Window::new("reliefboard")
            .default_pos([8.0, 8.0])
            .default_width(300.0)
            .show(ctx, |ui| {
                self.stats(ui, viewer);
                egui::CollapsingHeader::new("Workers")
                    .default_open(true)
                    .show(ui, |ui| workers(ui, viewer));
            });
        let controls = egui::Window::new("controls")
            .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
            .default_width(260.0)
            .show(ctx, |ui| {
                self::controls(ui, viewer, control);
                ui.separator();
                camera_path(ui, path, &mut actions);
                if !self.message.is_empty() {
                    ui.label(&self.message);
                }
                ui.weak("F1 overlay · F12 screenshot · R record · P replay · Tab fly/orbit · drag to turn");
            });
        self.rects.extend(
            [stats, controls]
                .into_iter()
                .flatten()
                .map(|r| pixels(r.response.rect)),
        );
        actions
    }

    fn stats(&self, ui: &mut egui::Ui, viewer: &Viewer) {
        let report = &self.last;
        let mean_ms = Stats::of(self.frame_ms.iter().rev().take(60).map(|&v| v as f64)).mean;
        ui.label(format!(
            "{:.1} ms/frame ({:.0} fps) · {}",
            mean_ms,
            1e3 / mean_ms.max(1e-3),
            viewer.renderer.adapter
        ));
        frame_graph(ui, &self.frame_ms);
        egui::Grid::new("counts").num_columns(2).show(ui, |ui| {
            ui.label("triangles drawn");
            ui.label(thousands(report.triangles));
            ui.end_row();
            ui.label("boards / geometry");
            ui.label(format!("{} / {}", report.boards, report.geometry_objects));
            ui.end_row();
            ui.label("near zone");
            ui.label(format!("{} tris", thousands(report.near_zone_triangles)));
            ui.end_row();
            ui.label("requests pending");
            ui.label(format!(
                "{} (+{} this frame)",
                report.requests_pending, report.requests_issued
            ));
            ui.end_row();
            // The same percentiles as `visnode bench` reports.
            let latency = Stats::of(self.latencies.iter().map(|(_, l)| l * 1e3));
            ui.label("latency p50 / p90");
            if latency.count == 0 {
                ui.label("no boards in 5 s");
            } else {
                ui.label(format!("{:.0} / {:.0} ms", latency.p50, latency.p90));
            }
            ui.end_row();
            let (held, bytes) = viewer.boards_held();
            ui.label("boards held");
            ui.label(format!(
                "{held} ({:.1} MiB)",
                bytes as f64 / (1 << 20) as f64
            ));
            ui.end_row();
        });
        if let Some(reason) = viewer.no_boards_reason() {
            ui.colored_label(DEAD, format!("no worker boards: {reason}"));
        }
        if report.unassignable > 0 {
            ui.colored_label(
                DEAD,
                format!("{} objects have no live replica", report.unassignable),
            );
        }
        ui.label("angle error of drawn boards");
        angle_histogram(
            ui,
            &report.angle_errors,
            viewer.options.plan.epsilon_degrees,
            viewer.options.plan.e_degrees,
        );
    }
}

impl Default for Overlay {
    fn default() -> Self {
        Overlay::new()
    }
}

/// Frame intervals, newest on the right, with lines at 60 and 30 fps.
fn frame_graph(ui: &mut egui::Ui, frame_ms: &VecDeque<f32>) {
    let (response, painter) = ui.allocate_painter(Vec2::new(280.0, 60.0), egui::Sense::hover());
    let rect = response.rect;
    painter.rect_filled(rect, 2.0, Color32::from_gray(20));
    // Scaled to the 95th percentile: one stall (the first frame, a resize) must not flatten
    // the rest; taller frames are cut at the top.
    let p95 = report::Stats::of(frame_ms.iter().map(|&ms| ms as f64)).p95 as f32;
    let top = (p95 * 1.5).max(40.0);
    let y = |ms: f32| rect.bottom() - (ms / top).min(1.0) * rect.height();
    for guide in [1e3 / 60.0, 1e3 / 30.0] {
        painter.hline(
            rect.x_range(),
            y(guide),
            Stroke::new(1.0, Color32::from_gray(70)),
        );
    }
    let step = rect.width() / GRAPH_FRAMES as f32;
    let start = rect.right() - frame_ms.len() as f32 * step;
    let points: Vec<Pos2> = frame_ms
        .iter()
        .enumerate()
        .map(|(i, &ms)| Pos2::new(start + i as f32 * step, y(ms)))
        .collect();
    if points.len() > 1 {
        painter.line(points, Stroke::new(1.5, Color32::from_rgb(120, 220, 120)));
    }
    painter.text(
        rect.left_top() + Vec2::new(4.0, 2.0),
        egui::Align2::LEFT_TOP,
        format!("{top:.0} ms"),
        egui::FontId::monospace(10.0),
        Color32::GRAY,
    );
}

/// Drawn boards by angle error, from 0 to E; the bins past ε are waiting for a new board.
fn angle_histogram(ui: &mut egui::Ui, errors: &[f64], epsilon: f64, e: f64) {
    let mut bins = [0usize; ANGLE_BINS];
    for &error in errors {
        let bin = ((error / e) * ANGLE_BINS as f64).floor().max(0.0) as usize;
        bins[bin.min(ANGLE_BINS - 1)] += 1;
    }
    let (response, painter) = ui.allocate_painter(Vec2::new(280.0, 50.0), egui::Sense::hover());
    let rect = response.rect;
    painter.rect_filled(rect, 2.0, Color32::from_gray(20));
    let most = bins.iter().copied().max().unwrap_or(0).max(1) as f32;
    let width = rect.width() / ANGLE_BINS as f32;
    for (i, &count) in bins.iter().enumerate() {
        let height = count as f32 / most * (rect.height() - 12.0);
        let left = rect.left() + i as f32 * width;
        let past_epsilon = (i as f64 + 0.5) * e / ANGLE_BINS as f64 > epsilon;
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(left + 1.0, rect.bottom() - 12.0 - height),
                Pos2::new(left + width - 1.0, rect.bottom() - 12.0),
            ),
            0.0,
            if past_epsilon { DEAD } else { BUSY },
        );
    }
    let x = rect.left() + (epsilon / e) as f32 * rect.width();
    painter.vline(x, rect.y_range(), Stroke::new(1.0, Color32::YELLOW));
    painter.text(
        rect.left_bottom(),
        egui::Align2::LEFT_BOTTOM,
        format!(
            "0°   ε {epsilon:.1}°   E {e:.0}°   ({} boards)",
            errors.len()
        ),
        egui::FontId::monospace(10.0),
        Color32::GRAY,
    );
}

/// A bar per worker: its outstanding triangles against the busiest, its jobs, dead or alive.
fn workers(ui: &mut egui::Ui, viewer: &Viewer) {
    let Some(requests) = viewer.requests() else {
        ui.label("no workers");
        return;
    };
    let status = requests.worker_status();
    let health = requests.health();
    let busiest = status.iter().map(|s| s.load).fold(1.0, f64::max);
    let received = requests.received_by_worker();
    for (index, (address, worker)) in requests.addresses().iter().zip(status).enumerate() {
        ui.horizontal(|ui| {
            ui.monospace(address.trim_start_matches("http://"));
            if worker.alive {
                // The triangles and boards go below the bar: inside it they ran past the
                // panel's edge.
                ui.add(
                    egui::ProgressBar::new((worker.load / busiest) as f32)
                        .desired_width(120.0)
                        .fill(BUSY)
                        .text(format!("jobs {}", worker.jobs)),
                );
            } else {
                let why = health
                    .get(index)
                    .and_then(|h| h.reason.clone())
                    .unwrap_or_default();
                ui.colored_label(DEAD, "DEAD").on_hover_text(why);
            }
        });
        ui.label(
            egui::RichText::new(format!(
                "    {} tris queued · {} boards received",
                thousands(worker.load as u64),
                received.get(index).copied().unwrap_or(0)
            ))
            .small()
            .color(Color32::GRAY),
        );
    }
    let counts = &requests.counts;
    ui.label(format!(
        "issued {} · received {} · failed {} · reassigned {}",
        counts.issued, counts.received, counts.failed, counts.reassigned
    ));
}

/// Sliders and toggles that act on the next frame.
fn controls(ui: &mut egui::Ui, viewer: &mut Viewer, control: &mut CameraControl) {
    let plan = &mut viewer.options.plan;
    ui.add(
        egui::Slider::new(&mut plan.t_nz, 10_000..=20_000_000)
            .logarithmic(true)
            .text("t_nz (near-zone triangles)"),
    );
    ui.add(egui::Slider::new(&mut plan.epsilon_degrees, 0.5..=44.0).text("ε request angle °"));
    ui.add(egui::Slider::new(&mut plan.e_degrees, 1.0..=90.0).text("E geometry angle °"));
    // ε below E always: past E the geometry is drawn, so a request must come first.
    plan.epsilon_degrees = plan.epsilon_degrees.min(plan.e_degrees - 0.5).max(0.5);
    ui.add(
        egui::Slider::new(&mut plan.map_size, plan.min_map_size.max(16)..=1024)
            .logarithmic(true)
            .text("map size p"),
    );
    ui.add(
        egui::Slider::new(&mut plan.triangle_cost_pixels, 0.0..=1000.0)
            .logarithmic(true)
            .text("triangle cost in board pixels (0: a board each)"),
    );
    ui.checkbox(&mut viewer.options.tint, "tint boards red, near zone blue");
    ui.checkbox(&mut viewer.options.freeze_requests, "freeze requests");
    ui.add_enabled(
        viewer.renderer.can_draw_wireframe(),
        egui::Checkbox::new(&mut viewer.renderer.wireframe, "board wireframes"),
    );
    ui.horizontal(|ui| {
        let mut mode = control.mode;
        ui.radio_value(&mut mode, Mode::Orbit, "orbit");
        ui.radio_value(&mut mode, Mode::Fly, "fly");
        if mode != control.mode {
            control.set_mode(mode);
        }
    });
    ui.add(
        egui::Slider::new(&mut control.speed, 1e-3..=1e5)
            .logarithmic(true)
            .text("fly speed /s"),
    );
}

fn camera_path(ui: &mut egui::Ui, path: &PathState, actions: &mut Vec<Action>) {
    ui.horizontal(|ui| {
        let record = match path.recording {
            Some(n) => format!("stop recording ({n})"),
            None => "record (R)".to_string(),
        };
        if ui.button(record).clicked() {
            actions.push(Action::ToggleRecording);
        }
        let replay = match path.replaying {
            Some((at, of)) => format!("stop replay ({at}/{of})"),
            None => "replay (P)".to_string(),
        };
        if ui
            .add_enabled(path.can_replay, egui::Button::new(replay))
            .clicked()
        {
            actions.push(Action::ToggleReplay);
        }
        if ui.button("screenshot (F12)").clicked() {
            actions.push(Action::Screenshot);
        }
    });
}

/// 1234567 → "1,234,567".
fn thousands(value: u64) -> String {
    let digits = value.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thousands_groups_digits() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(thousands(10_004_608), "10,004,608");
    }

    #[test]
    fn the_graph_keeps_only_recent_frames() {
        let mut overlay = Overlay::new();
        for i in 0..GRAPH_FRAMES + 10 {
            overlay.record(Duration::from_millis(i as u64), FrameReport::default());
        }
        assert_eq!(overlay.frame_ms.len(), GRAPH_FRAMES);
        assert_eq!(*overlay.frame_ms.front().unwrap(), 10.0);
    }
}

//! `visnode view`: the window. winit delivers events, the [`Viewer`] plans and draws each frame
//! into the window's surface, and an egui [`overlay`] on top shows what the frame loop and the
//! cluster are doing and changes their parameters live.
//!
//! The frame never waits for a worker: the window redraws continuously and boards appear as
//! they arrive. Everything slow (loading, clustering, storing on workers) happens before the
//! first frame, with progress bars on the terminal.

mod controls;
mod overlay;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::WindowId;

use crate::camera::{Camera, CameraPredictor, camera_path};
use crate::cli::ViewArgs;
use crate::render::{Renderer, depth_target, open_device, pick_adapter};
use crate::setup::LoadedScene;
use crate::viewer::Viewer;
pub use controls::{CameraControl, Held, Mode};
use overlay::{Action, Overlay, PathState};

/// Opens the window and runs until it is closed (or `--exit-after` frames).
pub fn run(args: &ViewArgs) -> anyhow::Result<()> {
    crate::setup::check_flags(&args.boards)?;
    // A recorded path is read now, not after the slow loading.
    if let Some(crate::camera::PathKind::File(path)) = &args.replay {
        crate::camera::read_path(path)?;
    }
    // Before the slow loading: a machine without a display should hear so at once.
    let event_loop = EventLoop::new().map_err(|e| {
        anyhow!(
            "cannot open a window ({e}); is a display available (DISPLAY or WAYLAND_DISPLAY)? \
             `visnode bench` runs the same frame loop headless"
        )
    })?;
    let scene = crate::setup::load_scene(&args.scene)?;
    let mut app = App {
        args,
        scene: Some(scene),
        window: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .context("the window's event loop failed")?;
    let recorded = app.window.as_mut().and_then(|w| w.recording.take());
    if let Some(recording) = recorded {
        save_path(&args.record, &recording)?;
    }
    match app.error {
        Some(error) => Err(error),
        None => Ok(()),
    }
}

struct App<'a> {
    args: &'a ViewArgs,
    /// The scene until the window exists and takes it.
    scene: Option<LoadedScene>,
    window: Option<Window>,
    error: Option<anyhow::Error>,
}

/// Everything that lives as long as the window.
struct Window {
    window: Arc<winit::window::Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    depth: wgpu::TextureView,
    viewer: Viewer,
    egui: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    overlay: Overlay,
    control: CameraControl,
    held: Held,
    /// Cursor position while a mouse button turns the camera.
    dragging: Option<(f64, f64)>,
    last_frame: Instant,
    /// When the window opened: the predictor's clock.
    opened: Instant,
    /// Where the camera will be while a frame is on screen, and how fast the eye moves.
    predictor: CameraPredictor,
    frames: u64,
    /// `--target-frame-ms`: tunes t_nz from the time between displayed frames.
    budget: Option<crate::plan::BudgetController>,
    /// Cameras recorded so far, when recording.
    recording: Option<Recording>,
    /// The path `--replay` names, and the next frame of it while replaying.
    replay_path: Vec<Camera>,
    replaying: Option<usize>,
    screenshot: Option<PathBuf>,
    screenshots_taken: u32,
    screenshot_dir: PathBuf,
    record_file: PathBuf,
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        let Some(scene) = self.scene.take() else {
            return;
        };
        match Window::open(event_loop, self.args, scene) {
            Ok(window) => self.window = Some(window),
            Err(error) => self.fail(event_loop, error),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(window) = &mut self.window else {
            return;
        };
        let consumed = window.egui.on_window_event(&window.window, &event).consumed;
        let result = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                window.resize([size.width, size.height]);
                Ok(())
            }
            WindowEvent::RedrawRequested => window.redraw(self.args).map(|done| {
                if done {
                    event_loop.exit();
                }
            }),
            WindowEvent::Focused(false) => {
                // Keys released while unfocused never arrive: stop moving.
                window.held = Held::default();
                window.dragging = None;
                Ok(())
            }
            WindowEvent::KeyboardInput { event, .. } if !consumed => {
                let pressed = event.state == ElementState::Pressed;
                match event.physical_key {
                    PhysicalKey::Code(KeyCode::Escape) if pressed => {
                        event_loop.exit();
                        Ok(())
                    }
                    PhysicalKey::Code(code) => {
                        window.key(code, pressed, event.repeat);
                        Ok(())
                    }
                    _ => Ok(()),
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                let turning = matches!(button, MouseButton::Left | MouseButton::Right);
                if state == ElementState::Released {
                    window.dragging = None;
                } else if turning && !consumed && !window.egui.egui_ctx().is_pointer_over_egui() {
                    window.dragging = Some((f64::NAN, f64::NAN));
                }
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let Some((x, y)) = window.dragging {
                    if x.is_finite() {
                        window.control.turn(position.x - x, position.y - y);
                    }
                    window.dragging = Some((position.x, position.y));
                }
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } if !consumed => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                window.control.scroll(lines);
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(error) = result {
            self.fail(event_loop, error);
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let Some(window) = &self.window else {
            return;
        };
        if window.config.width == 0 || window.config.height == 0 {
            // Minimised: nothing to draw, so do not spin.
            event_loop.set_control_flow(ControlFlow::WaitUntil(
                Instant::now() + Duration::from_millis(100),
            ));
        } else {
            event_loop.set_control_flow(ControlFlow::Poll);
            window.window.request_redraw();
        }
    }
}

impl App<'_> {
    fn fail(&mut self, event_loop: &ActiveEventLoop, error: anyhow::Error) {
        self.error.get_or_insert(error);
        event_loop.exit();
    }
}

impl Window {
    fn open(
        event_loop: &ActiveEventLoop,
        args: &ViewArgs,
        scene: LoadedScene,
    ) -> anyhow::Result<Window> {
        let [width, height] = args.scene.resolution;
        let attributes = winit::window::Window::default_attributes()
            .with_title("reliefboard")
            .with_inner_size(winit::dpi::PhysicalSize::new(width, height));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .context("cannot open a window; `visnode bench` runs headless")?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                Box::new(event_loop.owned_display_handle()),
            ));
        let surface = instance
            .create_surface(window.clone())
            .context("cannot draw into the window")?;
        let adapter = pick_adapter(&instance, Some(&surface))?;
        let (device, queue, name) = open_device(&adapter)?;
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| anyhow!("the adapter cannot present to this window"))?;
        // A linear format, like the offscreen target: the window shows what `bench` measures.
        let formats = surface.get_capabilities(&adapter).formats;
        config.format = formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .unwrap_or(config.format);
        config.present_mode = wgpu::PresentMode::AutoVsync;
        surface.configure(&device, &config);
        let depth = depth_target(&device, [config.width, config.height]);
        let renderer = Renderer::with_device(
            device.clone(),
            queue,
            config.format,
            [config.width, config.height],
            name,
        );
        let crate::setup::Setup { viewer, .. } = crate::setup::build(
            scene,
            renderer,
            &args.scene,
            &args.workers,
            &args.boards,
            false,
            false,
        )?;
        let bounds = viewer.bounds();
        let fov = args.scene.fov_y_degrees;
        let start = camera_path(&crate::camera::PathKind::Orbit, &bounds, 1, fov)?[0];
        let control = CameraControl::new(&start, bounds.diagonal());
        let replay_path = match &args.replay {
            Some(kind) => viewer.camera_path(kind, args.replay_frames, fov)?,
            None => Vec::new(),
        };
        let egui_ctx = egui::Context::default();
        let egui = egui_winit::State::new(
            egui_ctx,
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(device.limits().max_texture_dimension_2d as usize),
        );
        let egui_renderer = egui_wgpu::Renderer::new(
            &device,
            config.format,
            egui_wgpu::RendererOptions::default(),
        );
        eprintln!(
            "window open on {}: drag to turn, WASD/QE to move, Tab for fly or orbit, F1 overlay",
            viewer.renderer.adapter
        );
        Ok(Window {
            window,
            surface,
            config,
            depth,
            viewer,
            egui,
            egui_renderer,
            overlay: Overlay::new(),
            control,
            held: Held::default(),
            dragging: None,
            last_frame: Instant::now(),
            opened: Instant::now(),
            predictor: CameraPredictor::default(),
            frames: 0,
            budget: args
                .boards
                .target_frame_ms
                .map(|target| crate::plan::BudgetController::new(target, args.scene.t_nz())),
            recording: None,
            replaying: (!replay_path.is_empty()).then_some(0),
            replay_path,
            screenshot: None,
            screenshots_taken: 0,
            screenshot_dir: args.screenshot_dir.clone(),
            record_file: args.record.clone(),
        })
    }

    fn resize(&mut self, size: [u32; 2]) {
        self.config.width = size[0];
        self.config.height = size[1];
        if size[0] > 0 && size[1] > 0 {
            let device = self.viewer.renderer.device();
            self.surface.configure(device, &self.config);
            self.depth = depth_target(device, size);
        }
    }

    /// A key went down (`pressed`, possibly a `repeat` while held) or up.
    fn key(&mut self, code: KeyCode, pressed: bool, repeat: bool) {
        if hold_movement_key(&mut self.held, code, pressed) || !pressed || repeat {
            return;
        }
        match code {
            KeyCode::F1 => self.overlay.visible = !self.overlay.visible,
            KeyCode::F12 => self.act(Action::Screenshot),
            KeyCode::KeyR => self.act(Action::ToggleRecording),
            KeyCode::KeyP => self.act(Action::ToggleReplay),
            KeyCode::Tab => self.control.set_mode(match self.control.mode {
                Mode::Fly => Mode::Orbit,
                Mode::Orbit => Mode::Fly,
            }),
            _ => {}
        }
    }

    fn act(&mut self, action: Action) {
        match action {
            Action::Screenshot => self.screenshot = Some(self.next_screenshot_path()),
            Action::ToggleRecording => match self.recording.take() {
                None => {
                    self.recording = Some(Recording::default());
                    self.overlay.message = "recording the camera path".into();
                }
                Some(recording) => match save_path(&self.record_file, &recording) {
                    Ok(message) => self.overlay.message = message,
                    Err(error) => {
                        // Keep recording: R again retries, and the path is saved at exit.
                        self.overlay.message = format!("{error:#}; still recording");
                        self.recording = Some(recording);
                    }
                },
            },
            Action::ToggleReplay => {
                self.replaying = match self.replaying {
                    Some(_) => None,
                    None if !self.replay_path.is_empty() => Some(0),
                    None => None,
                }
            }
        }
    }

    fn next_screenshot_path(&mut self) -> PathBuf {
        self.screenshots_taken += 1;
        let seconds = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        self.screenshot_dir.join(format!(
            "reliefboard-{seconds}-{}.png",
            self.screenshots_taken
        ))
    }

    /// Draws one frame; true when the scripted run (`--exit-after`) is over.
    fn redraw(&mut self, args: &ViewArgs) -> anyhow::Result<bool> {
        let size = [self.config.width, self.config.height];
        if size[0] == 0 || size[1] == 0 {
            return Ok(false);
        }
        let now = Instant::now();
        let interval = now - self.last_frame;
        self.last_frame = now;
        // The first interval includes the window's start: not a frame time.
        if self.frames > 0
            && let Some(budget) = &mut self.budget
        {
            self.viewer.options.plan.t_nz = budget.update(interval.as_secs_f64() * 1e3);
        }
        let last_frame = args.exit_after == Some(self.frames + 1);
        if last_frame && let Some(path) = &args.screenshot_on_exit {
            self.screenshot = Some(path.clone());
        }

        let camera = self.next_camera(interval);
        if let Some(recording) = &mut self.recording {
            let started = *recording.started.get_or_insert_with(Instant::now);
            recording.cameras.push(camera);
            recording.times.push(started.elapsed().as_secs_f64());
        }
        // As in `visnode bench --timing wall`: the frame is drawn for where the camera will
        // be while it is on screen. The time between redraws is the frame time here.
        if self.frames > 0 {
            self.predictor.frame_done(interval.as_secs_f64());
        }
        let camera = if args.boards.predict_camera {
            self.predictor
                .predict(now.duration_since(self.opened).as_secs_f64(), camera)
        } else {
            camera
        };
        let view = self.viewer.view(&camera, size);
        let (plan, mut report) = self.viewer.prepare_frame(&view);

        let path_state = PathState {
            recording: self.recording.as_ref().map(|r| r.cameras.len()),
            replaying: self.replaying.map(|at| (at, self.replay_path.len())),
            can_replay: !self.replay_path.is_empty(),
        };
        let input = self.egui.take_egui_input(&self.window);
        let mut actions = Vec::new();
        let ctx = self.egui.egui_ctx().clone();
        let mut output = ctx.run_pass(input, |ctx| {
            actions = self
                .overlay
                .show(ctx, &mut self.viewer, &mut self.control, &path_state);
        });
        self.egui
            .handle_platform_output(&self.window, output.platform_output);
        let jobs = ctx.tessellate(output.shapes, output.pixels_per_point);
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: size,
            pixels_per_point: output.pixels_per_point,
        };
        let device = self.viewer.renderer.device().clone();
        let queue = self.viewer.renderer.queue().clone();
        // Textures change before painting and are freed after; taken out of the delta here so
        // an early return (a skipped frame) loses none of them.
        for (id, deltas) in output.textures_delta.set.drain() {
            for delta in deltas {
                self.egui_renderer
                    .update_texture(&device, &queue, id, &delta);
            }
        }
        let freed = std::mem::take(&mut output.textures_delta.free);

        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame)
            | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.resize(size);
                return Ok(false);
            }
            other => return Err(anyhow!("the window's surface failed: {other:?}")),
        };
        let target = frame.texture.create_view(&Default::default());
        let mut encoder = device.create_command_encoder(&Default::default());
        let egui_commands =
            self.egui_renderer
                .update_buffers(&device, &queue, &mut encoder, &jobs, &screen);
        report.triangles = self
            .viewer
            .encode(&mut encoder, &target, &self.depth, &view, &plan);
        self.draw_overlay(&mut encoder, &target, &jobs, &screen);
        let screenshot = self.screenshot.take();
        if screenshot.is_some() {
            // The same frame again into the offscreen target, which can be read back.
            self.viewer.renderer.resize(size);
            let offscreen = self.viewer.renderer.offscreen_view().clone();
            self.viewer
                .encode(&mut encoder, &offscreen, &self.depth, &view, &plan);
            self.draw_overlay(&mut encoder, &offscreen, &jobs, &screen);
        }
        queue.submit(egui_commands.into_iter().chain([encoder.finish()]));
        for id in &freed {
            self.egui_renderer.free_texture(id);
        }
        self.window.pre_present_notify();
        queue.present(frame);
        if let Some(path) = screenshot {
            self.overlay.message = match self.save_screenshot(&path, &report) {
                Ok(()) => format!("saved {}", path.display()),
                Err(error) => format!("screenshot failed: {error:#}"),
            };
            eprintln!("{}", self.overlay.message);
        }
        report.timing.cpu_ms = now.elapsed().as_secs_f64() * 1e3;
        self.overlay.record(interval, report);
        for action in actions {
            self.act(action);
        }
        self.frames += 1;
        Ok(last_frame)
    }

    /// The camera of this frame: the replayed path's next one, or the steered one.
    fn next_camera(&mut self, interval: Duration) -> Camera {
        if let Some(at) = self.replaying {
            let camera = self.replay_path[at.min(self.replay_path.len() - 1)];
            if at + 1 >= self.replay_path.len() {
                // The path is over: steer on from where it ended.
                self.replaying = None;
                self.control.set_camera(&camera);
            } else {
                self.replaying = Some(at + 1);
            }
            return camera;
        }
        // Long stalls (a resize, a breakpoint) must not throw the camera across the scene.
        self.control
            .update(&self.held, interval.as_secs_f64().min(0.1));
        self.control.camera()
    }

    fn draw_overlay(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        jobs: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
    ) {
        let mut pass = encoder
            .begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("overlay"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            })
            .forget_lifetime();
        self.egui_renderer.render(&mut pass, jobs, screen);
    }

    /// Writes the offscreen frame as PNG and, beside it, a JSON note of what it shows.
    fn save_screenshot(
        &self,
        path: &Path,
        report: &crate::viewer::FrameReport,
    ) -> anyhow::Result<()> {
        let image = self.viewer.renderer.read_frame()?;
        crate::image_error::write_png(&image, path)?;
        let note = serde_json::json!({
            "width": image.width,
            "height": image.height,
            "frame": self.frames,
            "overlay": self.overlay.rects,
            "boards": report.boards,
            "geometry_objects": report.geometry_objects,
            "triangles": report.triangles,
            "adapter": self.viewer.renderer.adapter,
        });
        std::fs::write(
            path.with_extension("json"),
            serde_json::to_string_pretty(&note)?,
        )?;
        Ok(())
    }
}

/// Sets the movement key `code` held or released; false for any other key. Key repeats
/// arrive as presses, so a held key stays held.
fn hold_movement_key(held: &mut Held, code: KeyCode, pressed: bool) -> bool {
    let key = match code {
        KeyCode::KeyW => &mut held.forward,
        KeyCode::KeyS => &mut held.back,
        KeyCode::KeyA => &mut held.left,
        KeyCode::KeyD => &mut held.right,
        KeyCode::KeyE => &mut held.up,
        KeyCode::KeyQ => &mut held.down,
        KeyCode::ShiftLeft | KeyCode::ShiftRight => &mut held.fast,
        _ => return false,
    };
    *key = pressed;
    true
}

/// A camera path being recorded, with each camera's time: `visnode bench --path` replays it
/// at the speed it was flown.
#[derive(Default)]
struct Recording {
    started: Option<Instant>,
    cameras: Vec<Camera>,
    times: Vec<f64>,
}

fn save_path(path: &Path, recording: &Recording) -> anyhow::Result<String> {
    crate::camera::write_path(path, &recording.cameras, Some(&recording.times))
        .with_context(|| format!("writing the camera path to {}", path.display()))?;
    let message = format!(
        "recorded {} cameras to {}; replay with `visnode bench --path {}`",
        recording.cameras.len(),
        path.display(),
        path.display()
    );
    eprintln!("{message}");
    Ok(message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_movement_key_stays_held_through_key_repeats_until_released() {
        let mut held = Held::default();
        assert!(hold_movement_key(&mut held, KeyCode::KeyW, true));
        // Repeats of a held key come as presses.
        assert!(hold_movement_key(&mut held, KeyCode::KeyW, true));
        assert!(held.forward);
        assert!(hold_movement_key(&mut held, KeyCode::KeyW, false));
        assert!(!held.forward);
        assert!(!hold_movement_key(&mut held, KeyCode::F12, true));
    }
}

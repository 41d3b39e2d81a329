//! The camera, its frustum, and the camera paths the benchmark replays.

use std::path::Path;

use glam::{DMat4, DVec3, DVec4};
use serde::{Deserialize, Serialize};

/// A perspective camera. Positions are f64 world coordinates; the renderer draws relative to
/// `position` so f32 on the GPU loses nothing far from the origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Eye position.
    pub position: DVec3,
    /// Point looked at.
    pub target: DVec3,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
}

/// The view as the renderer and the planner need it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Eye position.
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Camera-relative world to clip space, reverse-Z: depth 1 at the near plane, 0 at the far.
    pub clip_from_relative: DMat4,
    /// Inward frustum planes `(n, d)`: a point `p` (camera-relative) is inside when
    /// `n·p + d >= 0` for all six.
    pub planes: [DVec4; 6],
    /// Pixels per unit of size at distance 1: `height / (2 tan(fov/2))`.
    pub pixels_per_radian: f64,
    /// Image size in pixels.
    pub resolution: [u32; 2],
}

impl Camera {
    /// The view for an image of `resolution` with depth from `near` to `far`.
    pub fn view(&self, resolution: [u32; 2], near: f64, far: f64) -> View {
        let forward = (self.target - self.position)
            .try_normalize()
            .unwrap_or(DVec3::NEG_Z);
        let (_, up) = scene::view_axes(forward);
        // The eye at the origin: geometry is drawn relative to the camera (f64 world, f32 GPU).
        let view = glam::dcamera::rh::view::look_to_mat4(DVec3::ZERO, forward, up);
        let aspect = resolution[0] as f64 / resolution[1].max(1) as f64;
        let fov = self.fov_y_degrees.to_radians();
        let projection = reverse_z_perspective(fov, aspect, near, far);
        let clip_from_relative = projection * view;
        // Gribb-Hartmann: planes from the rows of the clip matrix (depth in [0, 1]; with
        // reverse-Z, `r2` is the far plane and `r3 - r2` the near one).
        let m = clip_from_relative.transpose();
        let (r0, r1, r2, r3) = (m.x_axis, m.y_axis, m.z_axis, m.w_axis);
        let planes = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2].map(|p| {
            let length = p.truncate().length();
            p / length
        });
        View {
            eye: self.position,
            forward,
            clip_from_relative,
            planes,
            pixels_per_radian: resolution[1] as f64 / (2.0 * (fov * 0.5).tan()),
            resolution,
        }
    }
}

/// Where the camera will be while a frame begun now is on screen. A frame is shown from its
/// end until the next frame's end, on average 1.5 frame times after it began, and a moving
/// camera has moved on by then: on lavapipe most of a moving camera's object error is that
/// age (silhouettes a frame or two behind). The predictor extrapolates the last two cameras
/// it was given linearly over that lead, as head-mounted displays predict the head's pose
/// from its recent motion; it sees only cameras of the past, never the path ahead.
#[derive(Debug, Clone, Default)]
pub struct CameraPredictor {
    /// The camera of the last frame begun, and when (seconds).
    last: Option<(f64, Camera)>,
    /// Recent frame time, seconds (an exponential average, so one slow frame does not throw
    /// the lead far ahead).
    frame_seconds: Option<f64>,
}

impl CameraPredictor {
    /// Weight of the newest frame in the average frame time.
    const NEWEST_WEIGHT: f64 = 0.25;

    /// The camera to draw a frame begun at `now` (seconds) with, where the camera is `camera`.
    /// A still camera, a first frame, or a clock that did not move gets `camera` itself.
    pub fn predict(&mut self, now: f64, camera: Camera) -> Camera {
        let predicted = match (self.last, self.frame_seconds) {
            (Some((then, before)), Some(frame)) if now > then => {
                // Velocity over the last frame, carried 1.5 frame times ahead.
                let ahead = 1.5 * frame / (now - then);
                Camera {
                    position: camera.position + (camera.position - before.position) * ahead,
                    target: camera.target + (camera.target - before.target) * ahead,
                    fov_y_degrees: camera.fov_y_degrees,
                }
            }
            _ => camera,
        };
        self.last = Some((now, camera));
        predicted
    }

    /// The frame last begun took `seconds` from its start to its end.
    pub fn frame_done(&mut self, seconds: f64) {
        if !(seconds.is_finite() && seconds >= 0.0) {
            return;
        }
        self.frame_seconds = Some(match self.frame_seconds {
            Some(average) => average + (seconds - average) * Self::NEWEST_WEIGHT,
            None => seconds,
        });
    }
}

/// Right-handed perspective projection to wgpu's clip space with reverse-Z: depth 1 at
/// `near`, 0 at `far` (glam's WebGPU projection with near and far swapped). A 32-bit float
/// depth buffer is most precise near 0, which reverse-Z spends on the far distances where
/// standard Z (near at 0) rounds a board and the terrain it stands on to the same value;
/// measured in `visnode/tests/precision.rs` on a 10 km terrain.
pub fn reverse_z_perspective(fov_y: f64, aspect: f64, near: f64, far: f64) -> DMat4 {
    glam::dcamera::rh::proj::directx::perspective(fov_y, aspect, far, near)
}

impl View {
    /// Whether a sphere (world centre, radius) touches the frustum.
    pub fn sees_sphere(&self, center: DVec3, radius: f64) -> bool {
        let relative = (center - self.eye).extend(1.0);
        self.planes
            .iter()
            .all(|plane| plane.dot(relative) >= -radius)
    }

    /// Projected diameter in pixels of a sphere at `center` with `radius`.
    pub fn projected_pixels(&self, center: DVec3, radius: f64) -> f64 {
        let distance = (center - self.eye).length().max(radius.max(1e-9));
        2.0 * radius / distance * self.pixels_per_radian
    }
}

/// A named path or one read from a file.
#[derive(Debug, Clone, PartialEq)]
pub enum PathKind {
    /// Around the scene, looking at its centre, slightly from above.
    Orbit,
    /// Through the scene at eye height, looking ahead.
    Flythrough,
    /// Where the orbit starts, still; then a quarter of the orbit in a twentieth of the path
    /// (a fast turn, from [`TURN_STARTS`] to [`TURN_ENDS`]); then still again. Süß's test of
    /// how long the workers take to make every board fresh again.
    Turn,
    /// One camera per line (JSON), as `visnode view` records them.
    File(std::path::PathBuf),
}

impl std::str::FromStr for PathKind {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        Ok(match text {
            "orbit" => PathKind::Orbit,
            "flythrough" => PathKind::Flythrough,
            "turn" => PathKind::Turn,
            path => PathKind::File(path.into()),
        })
    }
}

/// When the turn of [`PathKind::Turn`] starts, as a fraction of the path.
pub const TURN_STARTS: f64 = 0.4;
/// When it ends.
pub const TURN_ENDS: f64 = 0.45;

/// `frames` cameras along the path over `bounds`.
pub fn camera_path(
    kind: &PathKind,
    bounds: &scene::Aabb,
    frames: usize,
    fov_y_degrees: f64,
) -> anyhow::Result<Vec<Camera>> {
    let center = bounds.center();
    let size = bounds.size();
    let radius = (size.x.max(size.z) * 0.5).max(1e-3);
    // On the orbit at `angle`, looking at the centre, slightly from above.
    let orbit = |angle: f64| {
        let distance = radius * 1.6;
        Camera {
            position: center
                + DVec3::new(
                    angle.cos() * distance,
                    size.y * 0.5 + radius * 0.35,
                    angle.sin() * distance,
                ),
            target: center,
            fov_y_degrees,
        }
    };
    let cameras = match kind {
        PathKind::Orbit => (0..frames)
            .map(|i| orbit(i as f64 / frames.max(1) as f64 * std::f64::consts::TAU))
            .collect(),
        PathKind::Turn => (0..frames)
            .map(|i| {
                let t = i as f64 / frames.max(2).saturating_sub(1) as f64;
                let s = ((t - TURN_STARTS) / (TURN_ENDS - TURN_STARTS)).clamp(0.0, 1.0);
                // Smooth at both ends, as a hand on a mouse turns.
                orbit(s * s * (3.0 - 2.0 * s) * std::f64::consts::FRAC_PI_2)
            })
            .collect(),
        PathKind::Flythrough => (0..frames)
            .map(|i| {
                // A straight line across the scene, along x, at a fifth of its height.
                let t = i as f64 / frames.max(2).saturating_sub(1) as f64;
                let x = bounds.min.x + (bounds.max.x - bounds.min.x) * (0.05 + 0.9 * t);
                let eye = DVec3::new(x, bounds.min.y + size.y * 0.2, center.z);
                Camera {
                    position: eye,
                    target: eye + DVec3::new(1.0, -0.05, 0.15),
                    fov_y_degrees,
                }
            })
            .collect(),
        PathKind::File(path) => read_path(path)?,
    };
    anyhow::ensure!(!cameras.is_empty(), "the camera path has no positions");
    Ok(cameras)
}

/// A recorded camera and, when the window recorded it, its time in seconds from the start of
/// the recording.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct RecordedCamera {
    #[serde(flatten)]
    camera: Camera,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    t: Option<f64>,
}

/// The height of the ground (the objects that are always geometry: terrain, floors, walls)
/// over a grid on the scene's x-z plane, so a flythrough can keep above it.
#[derive(Debug, Clone)]
pub struct Ground {
    min: [f64; 2],
    cell: [f64; 2],
    /// Highest ground vertex per cell, row-major in z; `NEG_INFINITY` where there is none.
    heights: Vec<f64>,
}

impl Ground {
    /// Cells per side of the grid.
    const CELLS: usize = 64;

    /// The ground of `objects` (those marked in `ground`) over `bounds`.
    pub fn new(objects: &[scene::Object], ground: &[bool], bounds: &scene::Aabb) -> Ground {
        let n = Self::CELLS;
        let size = bounds.size();
        let mut grid = Ground {
            min: [bounds.min.x, bounds.min.z],
            cell: [size.x.max(1e-9) / n as f64, size.z.max(1e-9) / n as f64],
            heights: vec![f64::NEG_INFINITY; n * n],
        };
        // Each triangle raises every cell its x-z bounds touch to its highest corner: exact
        // for fine terrain, on the safe side for a large sloping floor.
        for (object, _) in objects.iter().zip(ground).filter(|(_, g)| **g) {
            for triangle in &object.triangles {
                let corners = triangle.map(|i| {
                    object.origin
                        + object
                            .positions
                            .get(i as usize)
                            .map_or(DVec3::NAN, |p| p.as_dvec3())
                });
                let top = corners
                    .iter()
                    .map(|c| c.y)
                    .fold(f64::NEG_INFINITY, f64::max);
                let lo = corners.iter().fold(DVec3::INFINITY, |a, c| a.min(*c));
                let hi = corners.iter().fold(DVec3::NEG_INFINITY, |a, c| a.max(*c));
                let (Some((i0, j0)), Some((i1, j1))) =
                    (grid.cell_of(lo.x, lo.z), grid.cell_of(hi.x, hi.z))
                else {
                    continue;
                };
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        let at = j * n + i;
                        grid.heights[at] = grid.heights[at].max(top);
                    }
                }
            }
        }
        grid
    }

    /// The cell of `(x, z)`, clamped to the grid; `None` for a non-finite point.
    fn cell_of(&self, x: f64, z: f64) -> Option<(usize, usize)> {
        let (i, j) = (
            (x - self.min[0]) / self.cell[0],
            (z - self.min[1]) / self.cell[1],
        );
        let clamp = |v: f64| (v.max(0.0) as usize).min(Self::CELLS - 1);
        (i.is_finite() && j.is_finite()).then(|| (clamp(i), clamp(j)))
    }

    /// The cell of `(x, z)` when it lies on the grid.
    fn index(&self, x: f64, z: f64) -> Option<usize> {
        let n = Self::CELLS as f64;
        let (i, j) = (
            (x - self.min[0]) / self.cell[0],
            (z - self.min[1]) / self.cell[1],
        );
        (i >= 0.0 && j >= 0.0 && i <= n && j <= n)
            .then(|| self.cell_of(x, z))
            .flatten()
            .map(|(i, j)| j * Self::CELLS + i)
    }

    /// The highest ground in the cell of `(x, z)` and its neighbours, if any.
    pub fn height(&self, x: f64, z: f64) -> Option<f64> {
        let mut highest = f64::NEG_INFINITY;
        for dj in [-1.0, 0.0, 1.0] {
            for di in [-1.0, 0.0, 1.0] {
                if let Some(at) = self.index(x + di * self.cell[0], z + dj * self.cell[1]) {
                    highest = highest.max(self.heights[at]);
                }
            }
        }
        highest.is_finite().then_some(highest)
    }

    /// Raises each camera (and its target with it) to at least `clearance` above the ground,
    /// smoothly: the raise is the largest needed within three cameras either side, averaged
    /// over the same window, so the path does not jerk over every bump.
    pub fn keep_above(&self, cameras: &mut [Camera], clearance: f64) {
        let needed: Vec<f64> = cameras
            .iter()
            .map(|c| {
                self.height(c.position.x, c.position.z)
                    .map_or(0.0, |g| (g + clearance - c.position.y).max(0.0))
            })
            .collect();
        let window = |i: usize| i.saturating_sub(3)..(i + 4).min(needed.len());
        let peaks: Vec<f64> = (0..needed.len())
            .map(|i| needed[window(i)].iter().copied().fold(0.0, f64::max))
            .collect();
        for (i, camera) in cameras.iter_mut().enumerate() {
            let range = window(i);
            let raise = peaks[range.clone()].iter().sum::<f64>() / range.len() as f64;
            camera.position.y += raise.max(needed[i]);
            camera.target.y += raise.max(needed[i]);
        }
    }
}

/// Reads a path: one JSON camera per line.
pub fn read_path(path: &Path) -> anyhow::Result<Vec<Camera>> {
    Ok(read_timed_path(path)?.0)
}

/// Reads a path with its timestamps: `Some` when every line has a time `t` (seconds), the
/// times finite and never decreasing.
pub fn read_timed_path(path: &Path) -> anyhow::Result<(Vec<Camera>, Option<Vec<f64>>)> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading camera path {}: {e}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(number, line)| {
            let RecordedCamera { camera, t } = serde_json::from_str(line).map_err(|e| {
                anyhow::anyhow!("{}:{}: not a camera: {e}", path.display(), number + 1)
            })?;
            anyhow::ensure!(
                camera.position.is_finite()
                    && camera.target.is_finite()
                    && camera.fov_y_degrees > 1.0
                    && camera.fov_y_degrees < 179.0,
                "{}:{}: camera has non-finite coordinates or a field of view outside 1..179 degrees",
                path.display(),
                number + 1
            );
            anyhow::ensure!(
                t.is_none_or(f64::is_finite),
                "{}:{}: the time is not a finite number",
                path.display(),
                number + 1
            );
            Ok((camera, t))
        })
        .collect::<anyhow::Result<Vec<_>>>()
        .map(|lines| {
            let times: Option<Vec<f64>> = lines.iter().map(|(_, t)| *t).collect();
            let ordered = times
                .as_ref()
                .is_some_and(|t| t.windows(2).all(|w| w[0] <= w[1]) && t[t.len() - 1] > t[0]);
            let cameras = lines.into_iter().map(|(camera, _)| camera).collect();
            (cameras, times.filter(|_| ordered))
        })
}

/// Writes a path in the format [`read_path`] reads, each camera with its time when given.
pub fn write_path(path: &Path, cameras: &[Camera], times: Option<&[f64]>) -> anyhow::Result<()> {
    let mut text = String::new();
    for (i, camera) in cameras.iter().enumerate() {
        let line = RecordedCamera {
            camera: *camera,
            t: times.and_then(|t| t.get(i).copied()),
        };
        text.push_str(&serde_json::to_string(&line)?);
        text.push('\n');
    }
    std::fs::write(path, text)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_predictor_leads_a_steady_camera_by_one_and_a_half_frames() {
        // A camera moving at constant velocity, frames of 0.1 s: a frame begun at t is on
        // screen from t + 0.1 to t + 0.2, so it should show the camera of t + 0.15.
        let at = |t: f64| Camera {
            position: DVec3::new(2.0 * t, 1.0, -3.0 * t),
            target: DVec3::new(2.0 * t, 0.0, 5.0 - 3.0 * t),
            fov_y_degrees: 60.0,
        };
        let mut predictor = CameraPredictor::default();
        assert_eq!(
            predictor.predict(0.0, at(0.0)),
            at(0.0),
            "nothing to go by yet"
        );
        predictor.frame_done(0.1);
        for step in 1..5 {
            let t = step as f64 * 0.1;
            let predicted = predictor.predict(t, at(t));
            let expected = at(t + 0.15);
            assert!(
                predicted.position.distance(expected.position) < 1e-9,
                "{predicted:?}"
            );
            assert!(
                predicted.target.distance(expected.target) < 1e-9,
                "{predicted:?}"
            );
            predictor.frame_done(0.1);
        }
    }

    #[test]
    fn the_predictor_leaves_a_still_camera_and_a_stopped_clock_alone() {
        let camera = Camera {
            position: DVec3::new(1.0, 2.0, 3.0),
            target: DVec3::ZERO,
            fov_y_degrees: 45.0,
        };
        let mut predictor = CameraPredictor::default();
        predictor.predict(0.0, camera);
        predictor.frame_done(0.05);
        assert_eq!(predictor.predict(0.05, camera), camera);
        // Two frames begun at the same instant give no velocity to go by.
        let moved = Camera {
            position: DVec3::new(9.0, 2.0, 3.0),
            ..camera
        };
        assert_eq!(predictor.predict(0.05, moved), moved);
        // A frame time that is not a number does not poison the lead.
        predictor.frame_done(f64::NAN);
        let later = predictor.predict(0.1, moved);
        assert!(later.position.is_finite() && later == moved);
    }

    #[test]
    fn a_view_equals_the_same_cameras_view_and_no_other() {
        // The viewer calls a frame's camera still when its view equals the last frame's.
        let camera = Camera {
            position: DVec3::new(10.0, 2.0, 5.0),
            target: DVec3::ZERO,
            fov_y_degrees: 60.0,
        };
        let view = |c: &Camera, resolution| c.view(resolution, 0.1, 100.0);
        assert_eq!(view(&camera, [640, 480]), view(&camera, [640, 480]));
        let nudged = Camera {
            position: camera.position + DVec3::new(1e-9, 0.0, 0.0),
            ..camera
        };
        assert_ne!(view(&camera, [640, 480]), view(&nudged, [640, 480]));
        let turned = Camera {
            target: DVec3::new(0.0, 1e-6, 0.0),
            ..camera
        };
        assert_ne!(view(&camera, [640, 480]), view(&turned, [640, 480]));
        assert_ne!(view(&camera, [640, 480]), view(&camera, [800, 600]));
    }

    #[test]
    fn the_projection_puts_the_near_plane_at_depth_1_and_the_far_plane_at_0() {
        let projection = reverse_z_perspective(1.0, 1.5, 0.1, 1000.0);
        let depth = |distance: f64| {
            let clip = projection * DVec4::new(0.0, 0.0, -distance, 1.0);
            clip.z / clip.w
        };
        assert!((depth(0.1) - 1.0).abs() < 1e-12);
        assert!(depth(1000.0).abs() < 1e-12);
        assert!(depth(1.0) > depth(10.0), "nearer is deeper in reverse-Z");
    }

    #[test]
    fn a_flythrough_keeps_above_the_ground() {
        // A ramp from y = 0 at x = 0 to y = 10 at x = 100, as one ground object.
        let positions: Vec<glam::Vec3> = (0..=100)
            .flat_map(|x| [0.0, 50.0].map(|z| glam::Vec3::new(x as f32, x as f32 / 10.0, z)))
            .collect();
        let triangles: Vec<[u32; 3]> = (0..100u32)
            .flat_map(|x| {
                [
                    [2 * x, 2 * x + 1, 2 * x + 2],
                    [2 * x + 1, 2 * x + 3, 2 * x + 2],
                ]
            })
            .collect();
        let ramp = scene::Object {
            name: "ramp".into(),
            origin: DVec3::ZERO,
            colors: vec![[0; 4]; positions.len()],
            seams: vec![false; positions.len()],
            positions,
            triangles,
        };
        let bounds = scene::Aabb::from_points(ramp.positions.iter().map(|p| p.as_dvec3()));
        let ground = Ground::new(std::slice::from_ref(&ramp), &[true], &bounds);
        // The highest ground in the cells around x = 50: about 5, never below.
        let height = ground.height(50.0, 25.0).unwrap();
        assert!((5.0..5.5).contains(&height), "{height}");
        assert_eq!(
            Ground::new(&[ramp], &[false], &bounds).height(50.0, 25.0),
            None
        );
        let mut cameras: Vec<Camera> = (0..=20)
            .map(|i| Camera {
                position: DVec3::new(i as f64 * 5.0, 2.0, 25.0),
                target: DVec3::new(i as f64 * 5.0 + 1.0, 2.0, 25.0),
                fov_y_degrees: 60.0,
            })
            .collect();
        ground.keep_above(&mut cameras, 1.0);
        for camera in &cameras {
            let floor = camera.position.x / 10.0 + 1.0;
            assert!(camera.position.y >= floor - 1e-9, "{camera:?}");
            // Looking level still: the target rose with the eye.
            assert_eq!(camera.target.y, camera.position.y);
        }
        // No camera rises above what the ground six cameras (30 units) ahead needs (the
        // largest need within three, averaged over three), give or take a grid cell.
        for camera in &cameras {
            let ahead = (camera.position.x + 30.0 + 3.2).min(100.0) / 10.0 + 1.0;
            assert!(camera.position.y <= ahead.max(2.0) + 1e-9, "{camera:?}");
        }
    }

    #[test]
    fn a_recorded_path_keeps_its_times_and_an_untimed_one_has_none() {
        let dir = std::env::temp_dir().join(format!("camera-path-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let camera = |x: f64| Camera {
            position: DVec3::new(x, 1.0, 0.0),
            target: DVec3::ZERO,
            fov_y_degrees: 50.0,
        };
        let cameras = [camera(0.0), camera(1.0), camera(2.0)];
        let timed = dir.join("timed.jsonl");
        write_path(&timed, &cameras, Some(&[0.5, 0.75, 2.0])).unwrap();
        let (read, times) = read_timed_path(&timed).unwrap();
        assert_eq!(read, cameras);
        assert_eq!(times, Some(vec![0.5, 0.75, 2.0]));
        let untimed = dir.join("untimed.jsonl");
        write_path(&untimed, &cameras, None).unwrap();
        assert_eq!(read_timed_path(&untimed).unwrap().1, None);
        // Times that run backwards are not a pace to keep.
        write_path(&timed, &cameras, Some(&[0.5, 0.25, 2.0])).unwrap();
        assert_eq!(read_timed_path(&timed).unwrap().1, None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_turn_path_is_still_then_turns_a_quarter_about_the_centre_then_is_still() {
        let bounds =
            scene::Aabb::from_points([DVec3::new(-10.0, 0.0, -10.0), DVec3::new(10.0, 4.0, 10.0)]);
        let cameras = camera_path(&PathKind::Turn, &bounds, 201, 50.0).unwrap();
        let center = bounds.center();
        // The horizontal direction from the centre to the eye.
        let bearing = |c: &Camera| {
            let d = c.position - center;
            d.z.atan2(d.x).to_degrees()
        };
        for (i, camera) in cameras.iter().enumerate() {
            let t = i as f64 / 200.0;
            assert_eq!(camera.target, center);
            if t <= TURN_STARTS {
                assert!(bearing(camera).abs() < 1e-9, "still before the turn: {t}");
            } else if t >= TURN_ENDS {
                assert!((bearing(camera) - 90.0).abs() < 1e-9, "still after: {t}");
            }
        }
        // Halfway through the turn, halfway round; the distance to the centre never changes.
        let middle = &cameras[85];
        assert!((bearing(middle) - 45.0).abs() < 1e-6, "{}", bearing(middle));
        let distance = (cameras[0].position - center).length();
        assert!(
            cameras
                .iter()
                .all(|c| ((c.position - center).length() - distance).abs() < 1e-9)
        );
        assert_eq!("turn".parse::<PathKind>(), Ok(PathKind::Turn));
    }
}

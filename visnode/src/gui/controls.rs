//! The camera a person steers: fly (WASD moves, QE down and up, the mouse turns) or orbit
//! (the camera circles a target point; WASD turns around it, QE and the wheel zoom). Pure
//! state, so it is tested without a window.

use glam::DVec3;

use crate::camera::Camera;

/// How the keys and the mouse move the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Free flight.
    Fly,
    /// Around a target point.
    Orbit,
}

/// Movement keys held this frame.
#[derive(Debug, Clone, Copy, Default)]
pub struct Held {
    /// W.
    pub forward: bool,
    /// S.
    pub back: bool,
    /// A.
    pub left: bool,
    /// D.
    pub right: bool,
    /// E.
    pub up: bool,
    /// Q.
    pub down: bool,
    /// Shift: four times faster.
    pub fast: bool,
}

/// Radians turned per pixel of mouse motion.
const TURN_PER_PIXEL: f64 = 0.004;
/// Radians per second an orbit turns with the keys.
const ORBIT_TURN_RATE: f64 = 1.2;
/// Pitch stays this far from straight up or down (the view's up vector needs it).
const MAX_PITCH: f64 = 89.0 * std::f64::consts::PI / 180.0;

/// The steered camera.
#[derive(Debug, Clone)]
pub struct CameraControl {
    /// Fly or orbit.
    pub mode: Mode,
    /// Flying speed in world units per second (orbit: zoom speed scales with distance).
    pub speed: f64,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
    position: DVec3,
    /// Heading around +y, radians; 0 looks along +x.
    yaw: f64,
    /// Elevation, radians; positive looks up.
    pitch: f64,
    orbit_target: DVec3,
}

impl CameraControl {
    /// Starts at `camera`, orbiting its target; flying speed crosses `scene_size` in 10 s.
    pub fn new(camera: &Camera, scene_size: f64) -> CameraControl {
        let mut control = CameraControl {
            mode: Mode::Orbit,
            speed: (scene_size / 10.0).max(1e-3),
            fov_y_degrees: camera.fov_y_degrees,
            position: camera.position,
            yaw: 0.0,
            pitch: 0.0,
            orbit_target: camera.target,
        };
        control.set_camera(camera);
        control
    }

    /// The camera to draw from.
    pub fn camera(&self) -> Camera {
        Camera {
            position: self.position,
            target: self.position + self.forward(),
            fov_y_degrees: self.fov_y_degrees,
        }
    }

    /// Jumps to `camera` (the end of a replayed path): same eye, same direction; an orbit
    /// continues around the point looked at.
    pub fn set_camera(&mut self, camera: &Camera) {
        let direction = (camera.target - camera.position)
            .try_normalize()
            .unwrap_or(DVec3::NEG_Z);
        self.position = camera.position;
        self.yaw = direction.z.atan2(direction.x);
        self.pitch = direction
            .y
            .clamp(-1.0, 1.0)
            .asin()
            .clamp(-MAX_PITCH, MAX_PITCH);
        self.fov_y_degrees = camera.fov_y_degrees;
        let distance = (camera.target - camera.position).length();
        if distance > 1e-9 {
            self.orbit_target = camera.target;
        }
    }

    /// Switches mode without moving the camera: an orbit goes around the point `distance`
    /// ahead that the camera looked at last.
    pub fn set_mode(&mut self, mode: Mode) {
        if mode == Mode::Orbit && self.mode == Mode::Fly {
            let distance = self.orbit_distance();
            self.orbit_target = self.position + self.forward() * distance;
        }
        self.mode = mode;
    }

    /// Unit view direction.
    pub fn forward(&self) -> DVec3 {
        DVec3::new(
            self.pitch.cos() * self.yaw.cos(),
            self.pitch.sin(),
            self.pitch.cos() * self.yaw.sin(),
        )
    }

    fn orbit_distance(&self) -> f64 {
        (self.orbit_target - self.position).length().max(1e-6)
    }

    /// Turns by a mouse motion of `dx`, `dy` pixels (right and down positive).
    pub fn turn(&mut self, dx: f64, dy: f64) {
        let distance = self.orbit_distance();
        self.yaw += dx * TURN_PER_PIXEL;
        self.pitch = (self.pitch - dy * TURN_PER_PIXEL).clamp(-MAX_PITCH, MAX_PITCH);
        if self.mode == Mode::Orbit {
            self.position = self.orbit_target - self.forward() * distance;
        }
    }

    /// Mouse wheel: flying changes speed, orbiting zooms.
    pub fn scroll(&mut self, lines: f64) {
        match self.mode {
            Mode::Fly => self.speed *= 1.25f64.powf(lines),
            Mode::Orbit => self.zoom(0.9f64.powf(lines)),
        }
    }

    fn zoom(&mut self, factor: f64) {
        let distance = (self.orbit_distance() * factor).max(1e-3);
        self.position = self.orbit_target - self.forward() * distance;
    }

    /// Moves for `dt` seconds with the keys `held`.
    pub fn update(&mut self, held: &Held, dt: f64) {
        let axis = |plus: bool, minus: bool| plus as i32 as f64 - minus as i32 as f64;
        let forward_back = axis(held.forward, held.back);
        let right_left = axis(held.right, held.left);
        let up_down = axis(held.up, held.down);
        let boost = if held.fast { 4.0 } else { 1.0 };
        match self.mode {
            Mode::Fly => {
                let forward = self.forward();
                let (right, _) = scene::view_axes(forward);
                let step = self.speed * boost * dt;
                self.position +=
                    (forward * forward_back + right * right_left + DVec3::Y * up_down) * step;
            }
            Mode::Orbit => {
                let turn = ORBIT_TURN_RATE * boost * dt / TURN_PER_PIXEL;
                // Keys move the camera around the target: D to the right, W up over it.
                self.turn(-right_left * turn, forward_back * turn);
                if up_down != 0.0 {
                    self.zoom((1.0 + 0.8 * boost * dt).powf(-up_down));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(position: DVec3, target: DVec3) -> Camera {
        Camera {
            position,
            target,
            fov_y_degrees: 60.0,
        }
    }

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-9
    }

    #[test]
    fn starts_exactly_at_the_given_camera() {
        let start = camera(DVec3::new(3.0, 2.0, -1.0), DVec3::new(0.0, 0.5, 4.0));
        let control = CameraControl::new(&start, 10.0);
        let got = control.camera();
        assert!(close(got.position, start.position));
        let expected = (start.target - start.position).normalize();
        assert!(close((got.target - got.position).normalize(), expected));
    }

    #[test]
    fn flying_forward_moves_along_the_view_at_the_set_speed() {
        let mut control =
            CameraControl::new(&camera(DVec3::ZERO, DVec3::new(0.0, 0.0, -5.0)), 10.0);
        control.set_mode(Mode::Fly);
        control.speed = 2.0;
        let held = Held {
            forward: true,
            ..Held::default()
        };
        control.update(&held, 0.5);
        assert!(close(control.camera().position, DVec3::new(0.0, 0.0, -1.0)));
        // Strafing right while looking down -z goes toward +x; E goes up.
        let held = Held {
            right: true,
            up: true,
            ..Held::default()
        };
        control.update(&held, 1.0);
        assert!(close(control.camera().position, DVec3::new(2.0, 2.0, -1.0)));
    }

    #[test]
    fn orbiting_keeps_the_distance_and_looks_at_the_target() {
        let target = DVec3::new(1.0, 0.0, 1.0);
        let mut control = CameraControl::new(&camera(DVec3::new(1.0, 0.0, 6.0), target), 10.0);
        let held = Held {
            right: true,
            forward: true,
            ..Held::default()
        };
        for _ in 0..30 {
            control.update(&held, 1.0 / 30.0);
        }
        let got = control.camera();
        assert!(((got.position - target).length() - 5.0).abs() < 1e-9);
        let looking = (got.target - got.position).normalize();
        assert!(close(looking, (target - got.position).normalize()));
        assert!(!close(got.position, DVec3::new(1.0, 0.0, 6.0)), "it moved");
        assert!(got.position.y > 0.0, "W went over the top");
    }

    #[test]
    fn pitch_stops_short_of_straight_up() {
        let mut control = CameraControl::new(&camera(DVec3::ZERO, DVec3::X), 10.0);
        control.set_mode(Mode::Fly);
        control.turn(0.0, -1e6);
        let forward = control.forward();
        assert!(forward.y < 1.0 && forward.y > 0.99, "{forward}");
        assert!(control.camera().view([64, 64], 0.1, 10.0).planes[0].is_finite());
    }

    /// Regression: the view switched its up vector at 87.4 degrees of pitch while the controls
    /// allow 89, so the image rolled by the heading there.
    #[test]
    fn the_view_turns_smoothly_across_the_whole_pitch_range() {
        let start = camera(DVec3::ZERO, DVec3::new(1.0, 0.0, 0.6));
        let mut control = CameraControl::new(&start, 10.0);
        control.set_mode(Mode::Fly);
        control.turn(0.0, 1e6);
        assert!(
            (control.pitch + MAX_PITCH).abs() < 1e-12,
            "straight down first"
        );
        let clip = |control: &CameraControl| {
            control
                .camera()
                .view([64, 64], 0.1, 10.0)
                .clip_from_relative
        };
        // 0.05 degrees a step moves no matrix element by more than about 0.002.
        let step_pixels = -(0.05f64.to_radians()) / TURN_PER_PIXEL;
        let mut previous = clip(&control);
        let mut steps = 0;
        while control.pitch < MAX_PITCH {
            control.turn(0.0, step_pixels);
            let next = clip(&control);
            let change = (next - previous)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                change < 0.01,
                "at pitch {:.2} degrees the view jumped by {change}",
                control.pitch.to_degrees()
            );
            previous = next;
            steps += 1;
        }
        assert!(steps >= 3560, "{steps} steps from -89 to 89 degrees");
    }

    #[test]
    fn switching_modes_leaves_the_camera_where_it_is() {
        let start = camera(DVec3::new(0.0, 1.0, 8.0), DVec3::new(0.0, 0.0, 0.0));
        let mut control = CameraControl::new(&start, 10.0);
        control.set_mode(Mode::Fly);
        let before = control.camera();
        control.set_mode(Mode::Orbit);
        let after = control.camera();
        assert!(close(before.position, after.position));
        assert!(close(before.target, after.target));
    }

    #[test]
    fn the_wheel_speeds_up_flight_and_zooms_an_orbit() {
        let start = camera(DVec3::new(0.0, 0.0, 10.0), DVec3::ZERO);
        let mut control = CameraControl::new(&start, 10.0);
        control.scroll(1.0);
        assert!((control.camera().position.length() - 9.0).abs() < 1e-9);
        control.set_mode(Mode::Fly);
        let speed = control.speed;
        control.scroll(2.0);
        assert!((control.speed - speed * 1.5625).abs() < 1e-12);
    }
}

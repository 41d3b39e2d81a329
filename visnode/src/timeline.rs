//! Time as a user lives it (Lawlor's image-stream error): frames are drawn back to back
//! along a camera path defined in seconds, and the run is sampled at fixed instants. The
//! image on screen at instant `t` is the last frame completed before `t`; its error is taken
//! against the reference for the camera at `t`, so a slow frame shows a stale image and
//! costs error too.

use std::ops::Range;
use std::time::{Duration, Instant};

use glam::DVec3;

use crate::camera::Camera;

/// How the benchmark advances the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Timing {
    /// The path is defined in seconds; frames are drawn as fast as they come, each with the
    /// camera at its start time, and the run is sampled at `--sample-hz`.
    Wall,
    /// One path step per frame, every frame sampled (reproducible, for tests).
    Frames,
}

/// The sample instants `k / hz` that lie in `[from, to)`, as indices `k`.
pub fn instants_in(hz: f64, from: f64, to: f64) -> Range<usize> {
    let first = (from.max(0.0) * hz - 1e-9).ceil().max(0.0) as usize;
    let end = (to.max(0.0) * hz - 1e-9).ceil().max(0.0) as usize;
    first..end.max(first)
}

/// Which frame is on screen at each sample instant of a run `duration` seconds long,
/// sampled at `hz`: frame 0 (drawn before the clock starts) from 0, frame `i` from
/// `ends[i - 1]`, the time frame `i` completed, where `ends` holds the completion times of
/// frames 1, 2, ... in order.
pub fn displayed_frames(ends: &[f64], hz: f64, duration: f64) -> Vec<usize> {
    let mut shown = Vec::new();
    let mut from = 0.0;
    for (frame, &end) in ends.iter().enumerate() {
        shown.extend(instants_in(hz, from, end.min(duration)).map(|_| frame));
        from = from.max(end.min(duration));
    }
    shown.extend(instants_in(hz, from, duration).map(|_| ends.len()));
    shown
}

/// A clock that can leave spans out: the benchmark's reading back of images is not part of
/// what a user waits for.
#[derive(Debug)]
pub struct RunClock {
    started: Instant,
    excluded: Duration,
    paused_at: Option<Instant>,
}

impl RunClock {
    /// A clock at 0 now.
    pub fn start() -> RunClock {
        RunClock {
            started: Instant::now(),
            excluded: Duration::ZERO,
            paused_at: None,
        }
    }

    /// Seconds since the start, less the excluded spans.
    pub fn now(&self) -> f64 {
        let end = self.paused_at.unwrap_or_else(Instant::now);
        (end - self.started - self.excluded).as_secs_f64()
    }

    /// Stops counting until [`RunClock::resume`].
    pub fn pause(&mut self) {
        self.paused_at.get_or_insert_with(Instant::now);
    }

    /// Counts again.
    pub fn resume(&mut self) {
        if let Some(at) = self.paused_at.take() {
            self.excluded += at.elapsed();
        }
    }

    /// Seconds left out so far.
    pub fn excluded_seconds(&self) -> f64 {
        self.excluded.as_secs_f64()
    }
}

/// A camera path in time, interpolated between its cameras.
#[derive(Debug, Clone)]
pub struct TimedPath {
    cameras: Vec<Camera>,
    /// Each camera's time from the path's start (non-decreasing, from 0).
    times: Vec<f64>,
    /// The path's length in seconds.
    pub seconds: f64,
}

impl TimedPath {
    /// `cameras` (at least one) spread evenly over `seconds`.
    pub fn new(cameras: Vec<Camera>, seconds: f64) -> TimedPath {
        assert!(!cameras.is_empty(), "a path has at least one camera");
        let steps = (cameras.len() - 1).max(1) as f64;
        let times = (0..cameras.len())
            .map(|i| i as f64 / steps * seconds)
            .collect();
        TimedPath {
            cameras,
            times,
            seconds,
        }
    }

    /// `cameras` at the recorded `times` (as many, non-decreasing, spanning some time): the
    /// path runs as fast as it was flown.
    pub fn recorded(cameras: Vec<Camera>, times: &[f64]) -> TimedPath {
        assert!(cameras.len() == times.len() && !cameras.is_empty());
        let times: Vec<f64> = times.iter().map(|t| t - times[0]).collect();
        TimedPath {
            seconds: times[times.len() - 1],
            cameras,
            times,
        }
    }

    /// The camera at `t` seconds (clamped to the path).
    pub fn at(&self, t: f64) -> Camera {
        let last = self.cameras.len() - 1;
        // The last camera at or before t, and the share of the way to the next.
        let i = self
            .times
            .partition_point(|&time| time <= t)
            .saturating_sub(1)
            .min(last);
        let (a, b) = (self.cameras[i], self.cameras[(i + 1).min(last)]);
        let span = self.times[(i + 1).min(last)] - self.times[i];
        let f = if span > 0.0 {
            ((t - self.times[i]) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lerp = |p: DVec3, q: DVec3| p + (q - p) * f;
        Camera {
            position: lerp(a.position, b.position),
            target: lerp(a.target, b.target),
            fov_y_degrees: a.fov_y_degrees + (b.fov_y_degrees - a.fov_y_degrees) * f,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instants_are_half_open() {
        assert_eq!(instants_in(10.0, 0.0, 0.35), 0..4);
        assert_eq!(instants_in(10.0, 0.3, 0.35), 3..4);
        assert_eq!(instants_in(10.0, 0.31, 0.35), 4..4);
        assert_eq!(instants_in(30.0, 1.0, 2.0), 30..60);
    }

    #[test]
    fn each_instant_shows_the_last_frame_completed_before_it() {
        // Frames completing at 0.25 s, 0.26 s, 0.9 s in a 1 s run sampled at 10 Hz:
        // frame 0 (drawn before the clock) shows at 0.0-0.2, frame 1 at 0.3 and onward
        // until frame 2 completes at 0.26 (no instant between), frame 2 from 0.3 to 0.8,
        // frame 3 at 0.9.
        let shown = displayed_frames(&[0.25, 0.26, 0.9], 10.0, 1.0);
        assert_eq!(shown, vec![0, 0, 0, 2, 2, 2, 2, 2, 2, 3]);
        // An exact but slow renderer: one frame a second shows frame 0 for a whole second.
        assert_eq!(
            displayed_frames(&[1.0, 2.0], 4.0, 2.0),
            vec![0, 0, 0, 0, 1, 1, 1, 1]
        );
        // A frame completing after the run ends never shows.
        assert_eq!(displayed_frames(&[5.0], 2.0, 1.0), vec![0, 0]);
    }

    #[test]
    fn a_paused_clock_stands_still() {
        let mut clock = RunClock::start();
        clock.pause();
        let a = clock.now();
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(clock.now(), a);
        clock.resume();
        assert!(clock.excluded_seconds() >= 0.02);
        assert!(clock.now() < a + 0.02);
    }

    #[test]
    fn the_timed_path_interpolates_between_cameras() {
        let camera = |x: f64| Camera {
            position: DVec3::new(x, 0.0, 0.0),
            target: DVec3::ZERO,
            fov_y_degrees: 60.0,
        };
        let path = TimedPath::new(vec![camera(0.0), camera(10.0), camera(20.0)], 4.0);
        assert_eq!(path.at(1.0).position.x, 5.0);
        assert_eq!(path.at(3.0).position.x, 15.0);
        assert_eq!(path.at(9.0).position.x, 20.0);
        assert_eq!(path.at(-1.0).position.x, 0.0);
        // A recorded path keeps its pace: slow first, fast after.
        let recorded = TimedPath::recorded(
            vec![camera(0.0), camera(10.0), camera(20.0)],
            &[5.0, 8.0, 9.0],
        );
        assert_eq!(recorded.seconds, 4.0);
        assert_eq!(recorded.at(1.5).position.x, 5.0);
        assert_eq!(recorded.at(3.5).position.x, 15.0);
    }
}

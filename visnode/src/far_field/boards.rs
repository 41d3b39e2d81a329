//! `--impostor relief` and `billboard`: boards rendered by the workers on request, never
//! waited for (unless `--sync`). Each object holds its latest board; a new one cross-fades in
//! over the old when it jumps more than `--fade-pixels` (`fades_in`), else swaps in at
//! once, and the plan draws an object as geometry until its first board arrives.
//!
//! Arrived boards are uploaded at the start of a frame, highest priority first, a band of
//! rows at a time, until `--upload-ms` have passed (`--still-upload-ms` while the camera
//! stands still); the rest wait for the next frame (still counted as pending, so nothing
//! asks for them again), and a large board's bands go over several frames: neither a burst
//! of arrivals nor one large board stalls a frame.

use std::time::{Duration, Instant};

use super::{DrawScene, FarField};
use crate::plan::{BoardState, Plan, WantedBoard};
use crate::render::{BoardUpload, DrawItem, GpuBoard, Renderer};
use crate::viewer::{FrameReport, ViewerOptions};
use crate::workers::{Arrival, BoardRequests};

/// Tint of boards when tinting is on (debug view).
const BOARD_TINT: [f32; 4] = [1.0, 0.2, 0.2, 0.35];

/// An object's board on the GPU, and the one it replaces while they cross-fade.
struct BoardSlot {
    current: GpuBoard,
    state: BoardState,
    /// The replaced board and the cross-fade's progress in [0, 1).
    outgoing: Option<GpuBoard>,
    fade: f32,
}

/// The boards held and the requests for new ones.
pub struct Boards {
    slots: Vec<Option<BoardSlot>>,
    requests: BoardRequests,
    /// Arrived boards not uploaded yet (over a frame's upload budget).
    waiting: Vec<Arrival>,
    /// The board being uploaded, its bands partly written (drawn once all are).
    uploading: Option<(Arrival, BoardUpload)>,
    /// Boards uploaded at the last frame's start: what the node can take per frame.
    uploaded_last_frame: usize,
    /// Whether objects without a valid board are drawn through levels of detail.
    fallback_levels: bool,
}

/// Boards on their way (in flight and waiting for their upload) are kept within this many
/// frames' uploads: past that, workers would render boards the node cannot take in time, on
/// CPU a shared machine's renderer needs, and they would arrive stale.
const OUTSTANDING_FRAMES_OF_UPLOADS: usize = 3;
/// ... but never fewer than this, so requests flow before any upload was measured.
const MIN_OUTSTANDING: usize = 32;

impl Boards {
    /// Boards made by the workers behind `requests`; objects without a valid board are
    /// drawn through levels of detail when `fallback_levels`, else whole.
    pub fn new(requests: BoardRequests, fallback_levels: bool) -> Boards {
        Boards {
            slots: Vec::new(),
            requests,
            waiting: Vec::new(),
            uploading: None,
            uploaded_last_frame: 0,
            fallback_levels,
        }
    }

    /// The requests (counts, workers' health, the trace).
    pub fn requests(&self) -> &BoardRequests {
        &self.requests
    }

    /// Boards held on the GPU (cross-fading ones counted twice), and their bytes.
    pub fn held(&self) -> (usize, usize) {
        self.slots
            .iter()
            .flatten()
            .fold((0, 0), |(n, bytes), slot| {
                (
                    n + 1 + slot.outgoing.is_some() as usize,
                    bytes + slot.current.bytes + slot.outgoing.as_ref().map_or(0, |b| b.bytes),
                )
            })
    }

    /// Takes what `arrival` brought: its board uploaded whole and cross-faded in, or nothing
    /// (a failure: the object stays geometry).
    fn swap_in(
        &mut self,
        renderer: &Renderer,
        options: &ViewerOptions,
        arrival: Arrival,
        report: &mut FrameReport,
    ) {
        let board = arrival
            .board
            .as_ref()
            .ok()
            .map(|data| renderer.upload_board(data));
        self.install(options, arrival, board, report);
    }

    /// Counts `arrival` in `report` and puts its uploaded `board` (none: a failure) in its
    /// object's slot, cross-fading in over the old one or swapping at once.
    fn install(
        &mut self,
        options: &ViewerOptions,
        arrival: Arrival,
        board: Option<GpuBoard>,
        report: &mut FrameReport,
    ) {
        report.latencies.push(arrival.latency);
        report.arrived_objects.push(arrival.object);
        report.board_bytes += arrival.bytes as u64;
        report.worker_render_seconds += arrival.render_seconds;
        let (Ok(data), Some(board)) = (arrival.board, board) else {
            return;
        };
        let state = BoardState {
            direction: data.direction,
            size: data.size,
        };
        let index = arrival.object as usize;
        if self.slots.len() <= index {
            self.slots.resize_with(index + 1, || None);
        }
        let slot = &mut self.slots[index];
        *slot = Some(match slot.take() {
            // The old board fades out; one older still is freed now.
            Some(old) if fades_in(old.state, state, options) => {
                report.boards_faded += 1;
                BoardSlot {
                    current: board,
                    state,
                    outgoing: Some(old.current),
                    fade: 1.0 / options.fade_frames as f32,
                }
            }
            _ => BoardSlot {
                current: board,
                state,
                outgoing: None,
                fade: 1.0,
            },
        });
    }

    fn advance_fades(&mut self, fade_frames: u32) {
        let step = 1.0 / fade_frames.max(1) as f32;
        for slot in self.slots.iter_mut().flatten() {
            if slot.outgoing.is_some() {
                slot.fade += step;
                if slot.fade >= 1.0 {
                    slot.outgoing = None;
                    slot.fade = 1.0;
                }
            }
        }
    }

    /// Boards asked for and not drawable yet: in flight, waiting for their upload or being
    /// uploaded.
    fn on_its_way(&self) -> usize {
        self.requests.pending() + self.waiting.len() + self.uploading.is_some() as usize
    }

    fn slot(&self, object: u32) -> Option<&BoardSlot> {
        self.slots.get(object as usize)?.as_ref()
    }

    /// `--sync`: asks for every board `plan` wants and waits for them all, so a still shows
    /// each one fresh. The balancer gives a worker at most `MAX_JOBS_PER_WORKER` at once and
    /// defers the rest, so the wanted boards go out in rounds until each has ended (arrived,
    /// failed or found no worker). Returns whether any went out: the frame is planned again.
    fn request_all(
        &mut self,
        renderer: &Renderer,
        plan: &Plan,
        options: &ViewerOptions,
        report: &mut FrameReport,
    ) -> bool {
        let mut ended = std::collections::HashSet::new();
        loop {
            let before = self.requests.counts.issued;
            let wanted: Vec<WantedBoard> = plan
                .requests
                .iter()
                .filter(|w| !ended.contains(&w.object))
                .copied()
                .collect();
            let unassignable = self.requests.submit(&wanted, report.frame);
            report.unassignable += unassignable.len();
            ended.extend(unassignable);
            let issued = (self.requests.counts.issued - before) as usize;
            report.requests_issued += issued;
            if issued == 0 {
                break;
            }
            for arrival in self.requests.wait_all(Duration::from_secs(120)) {
                ended.insert(arrival.object);
                self.swap_in(renderer, options, arrival, report);
            }
        }
        report.requests_issued > 0
    }
}

impl FarField for Boards {
    fn begin_frame(
        &mut self,
        renderer: &Renderer,
        options: &ViewerOptions,
        report: &mut FrameReport,
    ) {
        self.advance_fades(options.fade_frames);
        self.waiting.extend(self.requests.poll());
        let budget = if options.sync {
            Duration::MAX
        } else {
            options.upload_budget
        };
        let start = Instant::now();
        let mut waiting = std::mem::take(&mut self.waiting);
        let mut uploading = self.uploading.take();
        let before = report.arrived_objects.len();
        // The steps share `self` and `report` (one runs at a time).
        let state = std::cell::RefCell::new((&mut *self, &mut *report));
        upload_within(
            &mut waiting,
            &mut uploading,
            budget,
            || start.elapsed(),
            |arrival| match &arrival.board {
                Ok(data) => {
                    let upload = renderer.begin_board_upload(data);
                    Some((arrival, upload))
                }
                Err(_) => {
                    let (boards, report) = &mut *state.borrow_mut();
                    boards.install(options, arrival, None, report);
                    None
                }
            },
            |(arrival, upload)| {
                let data = arrival.board.as_ref().expect("only boards are uploaded");
                renderer.upload_board_band(upload, data)
            },
            |(arrival, upload)| {
                let (boards, report) = &mut *state.borrow_mut();
                boards.install(options, arrival, Some(upload.finish()), report);
            },
        );
        self.waiting = waiting;
        self.uploading = uploading;
        self.uploaded_last_frame = report.arrived_objects.len() - before;
        report.upload_ms = start.elapsed().as_secs_f64() * 1e3;
        report.uploads_waiting = self.waiting.len() + self.uploading.is_some() as usize;
    }

    fn board_state(&self, object: u32) -> Option<BoardState> {
        self.slot(object).map(|slot| slot.state)
    }

    fn pending_board(&self, object: u32) -> Option<BoardState> {
        self.requests.pending_board(object).or_else(|| {
            let arrival = self
                .waiting
                .iter()
                .chain(self.uploading.as_ref().map(|(a, _)| a))
                .find(|a| a.object == object)?;
            let data = arrival.board.as_ref().ok()?;
            Some(BoardState {
                direction: data.direction,
                size: data.size,
            })
        })
    }

    fn request(
        &mut self,
        renderer: &Renderer,
        plan: &Plan,
        options: &ViewerOptions,
        report: &mut FrameReport,
    ) -> bool {
        let mut replan = false;
        // Cancelled even when requests are frozen: they would only be stored. A board that
        // arrived and waits for its upload is dropped the same way.
        report.cancelled_objects = self.requests.cancel(&plan.cancels);
        let cancelled = &mut report.cancelled_objects;
        self.waiting.retain(|a| {
            let keep = !plan.cancels.contains(&a.object);
            if !keep {
                cancelled.push(a.object);
            }
            keep
        });
        if let Some((arrival, _)) = &self.uploading
            && plan.cancels.contains(&arrival.object)
        {
            cancelled.push(arrival.object);
            self.uploading = None;
        }
        report.requests_cancelled = report.cancelled_objects.len();
        if !options.freeze_requests {
            if options.sync {
                replan = self.request_all(renderer, plan, options, report);
            } else {
                let before = self.requests.counts.issued;
                let outstanding = self.on_its_way();
                let room = (OUTSTANDING_FRAMES_OF_UPLOADS * self.uploaded_last_frame)
                    .max(MIN_OUTSTANDING)
                    .saturating_sub(outstanding);
                let wanted = most_urgent(&plan.requests, room);
                report.unassignable = self.requests.submit(&wanted, report.frame).len();
                report.requests_issued = (self.requests.counts.issued - before) as usize;
            }
            report.requested_objects = plan
                .requests
                .iter()
                .map(|w| w.object)
                .filter(|&object| self.requests.is_pending(object))
                .collect();
        }
        report.requests_pending = self.on_its_way();
        replan
    }

    fn fallback_through_levels(&self) -> bool {
        self.fallback_levels
    }

    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>) {
        items.extend(scene.fallback_geometry(plan));
        let tint = if scene.tint {
            BOARD_TINT
        } else {
            crate::viewer::NO_TINT
        };
        for &(id, _) in &plan.boards {
            let Some(slot) = self.slot(id) else {
                continue;
            };
            let fading = slot.outgoing.as_ref().filter(|_| slot.fade < 1.0);
            items.push(DrawItem::Board {
                board: &slot.current,
                fade: if fading.is_some() { slot.fade } else { 1.0 },
                outgoing: false,
                tint,
            });
            if let Some(old) = fading {
                items.push(DrawItem::Board {
                    board: old,
                    fade: slot.fade,
                    outgoing: true,
                    tint,
                });
            }
        }
    }

    fn gpu_bytes(&self) -> u64 {
        self.held().1 as u64
    }

    fn boards(&self) -> Option<&Boards> {
        Some(self)
    }
}

/// Whether a board made as `new` cross-fades in over `old` rather than swapping in at once: a
/// fade hides a jump, and costs both boards' drawing for `fade_frames` frames, so only a
/// jump of more than `fade_pixels` (the parallax bound between their views, on the new one's
/// pixels) gets one. A new resolution alone sharpens the board without moving it: no fade.
/// Never with `--sync` (stills show fresh boards alone).
fn fades_in(old: BoardState, new: BoardState, options: &ViewerOptions) -> bool {
    let angle = crate::plan::angle_degrees(old.direction, new.direction);
    let jump = crate::plan::parallax_pixels(angle, new.size as f64);
    options.fade_frames > 0 && !options.sync && jump > options.fade_pixels
}

/// The `count` wanted boards of highest priority.
fn most_urgent(wanted: &[WantedBoard], count: usize) -> Vec<WantedBoard> {
    let mut wanted = wanted.to_vec();
    wanted.sort_by(|a, b| b.priority.total_cmp(&a.priority));
    wanted.truncate(count);
    wanted
}

/// Uploads arrived boards within `budget` on `clock`: first the bands left of the board in
/// progress (`uploading`), then from `waiting`, highest priority first (failures first: they
/// take no upload, and their objects fall back to geometry; `begin` takes them at once and
/// returns none), each begun and written a band at a time (`write_band`, true after the
/// last) and handed to `finish` when complete. Always at least one band, so every frame
/// makes progress however large a board; what is left waits for the next frame.
fn upload_within<U>(
    waiting: &mut Vec<Arrival>,
    uploading: &mut Option<U>,
    budget: Duration,
    clock: impl Fn() -> Duration,
    mut begin: impl FnMut(Arrival) -> Option<U>,
    mut write_band: impl FnMut(&mut U) -> bool,
    mut finish: impl FnMut(U),
) {
    // Last in the vector is uploaded first.
    waiting.sort_by(|a, b| {
        a.board
            .is_err()
            .cmp(&b.board.is_err())
            .then(a.priority.total_cmp(&b.priority))
    });
    let mut wrote = false;
    loop {
        if let Some(upload) = uploading.as_mut() {
            loop {
                if wrote && clock() >= budget {
                    return;
                }
                wrote = true;
                if write_band(upload) {
                    break;
                }
            }
            finish(uploading.take().expect("a board in progress"));
        }
        let Some(arrival) = waiting.pop() else {
            return;
        };
        if arrival.board.is_ok() && wrote && clock() >= budget {
            waiting.push(arrival);
            return;
        }
        *uploading = begin(arrival);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::BoardData;

    fn arrival(object: u32, priority: f64, side: u32) -> Arrival {
        let pixels = (side * side) as usize;
        let board = BoardData {
            basis: backend::Basis::new(glam::DVec3::NEG_Z, glam::DVec3::ZERO, 1.0).unwrap(),
            direction: glam::DVec3::NEG_Z,
            size: side,
            layers: vec![0; pixels * 12],
            vertices: Vec::new(),
            indices: Vec::new(),
            flat: true,
        };
        Arrival {
            object,
            board: Ok(board),
            latency: 0.0,
            bytes: 0,
            render_seconds: 0.0,
            worker: 0,
            priority,
        }
    }

    #[test]
    fn only_a_board_that_jumps_past_the_fade_tolerance_cross_fades() {
        let state = |degrees: f64, size: u32| BoardState {
            direction: glam::DQuat::from_rotation_y(degrees.to_radians()) * glam::DVec3::NEG_Z,
            size,
        };
        let options = ViewerOptions {
            fade_frames: 4,
            fade_pixels: 4.0,
            ..ViewerOptions::default()
        };
        let old = state(0.0, 200);
        // Half of 200 pixels times sin 1 degree: 1.75 pixels, swapped at once; sin 3 degrees:
        // 5.2 pixels, faded.
        assert!(!fades_in(old, state(1.0, 200), &options));
        assert!(fades_in(old, state(3.0, 200), &options));
        // Twice the resolution from the same view: sharper, not moved.
        assert!(!fades_in(state(0.0, 128), state(0.0, 256), &options));
        // The jump is counted on the new board's pixels: 3 degrees on 100 pixels is 2.6.
        assert!(!fades_in(state(0.0, 200), state(3.0, 100), &options));
        // A tolerance of 0 fades any change, but not an identical board.
        let always = ViewerOptions {
            fade_pixels: 0.0,
            ..options
        };
        assert!(fades_in(old, state(1.0, 200), &always));
        assert!(!fades_in(old, old, &always));
        // No fade frames, or stills waiting for fresh boards: never.
        for never in [
            ViewerOptions {
                fade_frames: 0,
                ..always
            },
            ViewerOptions {
                sync: true,
                ..always
            },
        ] {
            assert!(!fades_in(old, state(30.0, 200), &never));
        }
    }

    /// One frame's uploads on a clock where every band takes 3 ms and a board of side N has
    /// N / 64 bands: the objects taken (failures, finished boards), in order.
    fn upload_frame(
        waiting: &mut Vec<Arrival>,
        uploading: &mut Option<(u32, u32)>,
        budget_ms: u64,
    ) -> Vec<u32> {
        let spent = std::cell::Cell::new(0u64);
        let taken = std::cell::RefCell::new(Vec::new());
        upload_within(
            waiting,
            uploading,
            Duration::from_millis(budget_ms),
            || Duration::from_millis(spent.get()),
            |a| match &a.board {
                Ok(board) => Some((a.object, board.size / 64)),
                Err(_) => {
                    taken.borrow_mut().push(a.object);
                    None
                }
            },
            |(_, bands_left)| {
                spent.set(spent.get() + 3);
                *bands_left -= 1;
                *bands_left == 0
            },
            |(object, _)| taken.borrow_mut().push(object),
        );
        taken.into_inner()
    }

    #[test]
    fn uploads_stop_at_the_frame_budget_highest_priority_first() {
        let mut waiting = vec![
            arrival(0, 1.0, 64),
            arrival(1, 4.0, 64),
            arrival(2, 3.0, 64),
            arrival(3, 2.0, 64),
        ];
        waiting.push(Arrival {
            board: Err("worker failed".into()),
            ..arrival(4, 0.0, 1)
        });
        let mut uploading = None;
        // 7 ms: the failure (free), then boards until 7 ms have passed: three of them.
        assert_eq!(
            upload_frame(&mut waiting, &mut uploading, 7),
            vec![4, 1, 2, 3]
        );
        assert_eq!(waiting.len(), 1);
        // A budget smaller than one board still uploads one, after any failures.
        waiting.extend([arrival(5, 9.0, 64), arrival(6, 0.5, 64)]);
        waiting.push(Arrival {
            board: Err("worker failed".into()),
            ..arrival(7, 0.0, 1)
        });
        assert_eq!(upload_frame(&mut waiting, &mut uploading, 0), vec![7, 5]);
        assert_eq!(upload_frame(&mut waiting, &mut uploading, 100), vec![0, 6]);
        assert!(waiting.is_empty() && uploading.is_none());
    }

    #[test]
    fn a_large_board_is_uploaded_over_several_frames_and_finished_first() {
        // Five bands of 3 ms: 15 ms, over a 7 ms budget.
        let mut waiting = vec![arrival(0, 9.0, 320), arrival(1, 1.0, 64)];
        let mut uploading = None;
        // Bands at 0, 3 and 6 ms; at 9 ms the frame stops with the board unfinished, and
        // the smaller board waits behind it.
        assert_eq!(
            upload_frame(&mut waiting, &mut uploading, 7),
            Vec::<u32>::new()
        );
        assert_eq!(uploading, Some((0, 2)));
        assert_eq!(waiting.len(), 1);
        // A board that arrives meanwhile with a higher priority waits for the one begun.
        waiting.push(arrival(2, 99.0, 64));
        // The last two bands, then the new board of higher priority: 9 ms.
        assert_eq!(upload_frame(&mut waiting, &mut uploading, 7), vec![0, 2]);
        // No budget: still one band a frame, so a board always finishes.
        let mut waiting = vec![arrival(3, 1.0, 192)];
        let mut frames = 0;
        while upload_frame(&mut waiting, &mut uploading, 0) != vec![3] {
            frames += 1;
            assert!(frames < 3, "three bands, one a frame");
        }
        assert_eq!(frames, 2);
    }
}

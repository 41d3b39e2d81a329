//! `--impostor relief` and `billboard`: boards rendered by the workers on request, never
//! waited for (unless `--sync`). Each object holds its latest board; a new one cross-fades in
//! over the old, and the plan draws an object as geometry until its first board arrives.
//!
//! Arrived boards are uploaded at the start of a frame, highest priority first, until
//! `--upload-mb` is spent; the rest wait for the next frame (still counted as pending, so
//! nothing asks for them again), so a burst of arrivals never stalls one frame.

use std::time::Duration;

use super::{DrawScene, FarField};
use crate::plan::{BoardState, Plan};
use crate::render::{DrawItem, GpuBoard, Renderer};
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
}

impl Boards {
    /// Boards made by the workers behind `requests`.
    pub fn new(requests: BoardRequests) -> Boards {
        Boards {
            slots: Vec::new(),
            requests,
            waiting: Vec::new(),
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

    fn swap_in(
        &mut self,
        renderer: &Renderer,
        options: &ViewerOptions,
        arrived: Vec<Arrival>,
        report: &mut FrameReport,
    ) {
        for arrival in arrived {
            report.latencies.push(arrival.latency);
            report.arrived_objects.push(arrival.object);
            report.board_bytes += arrival.bytes as u64;
            report.worker_render_seconds += arrival.render_seconds;
            let Ok(data) = arrival.board else {
                continue;
            };
            let board = renderer.upload_board(&data);
            let state = BoardState {
                direction: data.direction,
                size: data.size,
            };
            let index = arrival.object as usize;
            if self.slots.len() <= index {
                self.slots.resize_with(index + 1, || None);
            }
            let slot = &mut self.slots[index];
            let fade = options.fade_frames > 0 && !options.sync;
            *slot = Some(match slot.take() {
                // The old board fades out; one older still is freed now.
                Some(old) if fade => BoardSlot {
                    current: board,
                    state,
                    outgoing: Some(old.current),
                    fade: 1.0 / options.fade_frames as f32,
                },
                _ => BoardSlot {
                    current: board,
                    state,
                    outgoing: None,
                    fade: 1.0,
                },
            });
        }
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

    fn slot(&self, object: u32) -> Option<&BoardSlot> {
        self.slots.get(object as usize)?.as_ref()
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
            usize::MAX
        } else {
            options.upload_bytes_per_frame
        };
        let uploads = take_uploads(&mut self.waiting, budget);
        report.uploads_waiting = self.waiting.len();
        self.swap_in(renderer, options, uploads, report);
    }

    fn board_state(&self, object: u32) -> Option<BoardState> {
        self.slot(object).map(|slot| slot.state)
    }

    fn pending_board(&self, object: u32) -> Option<BoardState> {
        self.requests.pending_board(object).or_else(|| {
            let arrival = self.waiting.iter().find(|a| a.object == object)?;
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
        report.requests_cancelled = report.cancelled_objects.len();
        if !options.freeze_requests {
            let before = self.requests.counts.issued;
            report.unassignable = self.requests.submit(&plan.requests, report.frame).len();
            report.requests_issued = (self.requests.counts.issued - before) as usize;
            report.requested_objects = plan
                .requests
                .iter()
                .map(|w| w.object)
                .filter(|&object| self.requests.is_pending(object))
                .collect();
            if options.sync && report.requests_issued > 0 {
                let arrived = self.requests.wait_all(Duration::from_secs(120));
                self.swap_in(renderer, options, arrived, report);
                replan = true;
            }
        }
        report.requests_pending = self.requests.pending() + self.waiting.len();
        replan
    }

    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>) {
        items.extend(plan.fallback.iter().map(|&id| scene.geometry(id, 0)));
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

/// Takes from `waiting` the arrivals to upload this frame: highest priority first, until
/// their GPU bytes reach `budget`; always at least one, so a board larger than the budget
/// still goes. Failures take no upload and always go (their objects fall back to geometry).
fn take_uploads(waiting: &mut Vec<Arrival>, budget: usize) -> Vec<Arrival> {
    let (mut uploads, boards): (Vec<Arrival>, Vec<Arrival>) =
        waiting.drain(..).partition(|a| a.board.is_err());
    let mut boards = boards;
    boards.sort_by(|a, b| b.priority.total_cmp(&a.priority));
    let mut spent = 0usize;
    let mut rest = boards.into_iter();
    for arrival in rest.by_ref() {
        let bytes = arrival.board.as_ref().map_or(0, |b| b.gpu_bytes());
        if spent > 0 && spent.saturating_add(bytes) > budget {
            waiting.push(arrival);
            break;
        }
        spent += bytes;
        uploads.push(arrival);
    }
    waiting.extend(rest);
    uploads
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
            depth: vec![0.0; pixels],
            color: vec![[0; 4]; pixels],
            normal: vec![[0; 4]; pixels],
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
    fn uploads_stop_at_the_frame_budget_highest_priority_first() {
        // Four 64² boards of 48 KiB each (12 bytes a texel), and a failure.
        let board_bytes = 64 * 64 * 12;
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
        let objects = |arrivals: &[Arrival]| arrivals.iter().map(|a| a.object).collect::<Vec<_>>();
        // Room for two boards: the two highest priorities, and the failure at no cost.
        let first = take_uploads(&mut waiting, 2 * board_bytes + 100);
        assert_eq!(objects(&first), vec![4, 1, 2]);
        let mut left = objects(&waiting);
        left.sort_unstable();
        assert_eq!(left, vec![0, 3]);
        // A budget smaller than one board still uploads one, the next in priority.
        let second = take_uploads(&mut waiting, 10);
        assert_eq!(objects(&second), vec![3]);
        assert_eq!(objects(&take_uploads(&mut waiting, usize::MAX)), vec![0]);
        assert!(waiting.is_empty());
    }
}

//! `--impostor relief` and `billboard`: boards rendered by the workers on request, never
//! waited for (unless `--sync`). Each object holds its latest board; a new one cross-fades in
//! over the old, and the plan draws an object as geometry until its first board arrives.

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
}

impl Boards {
    /// Boards made by the workers behind `requests`.
    pub fn new(requests: BoardRequests) -> Boards {
        Boards {
            slots: Vec::new(),
            requests,
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
        let arrived = self.requests.poll();
        self.swap_in(renderer, options, arrived, report);
    }

    fn board_state(&self, object: u32) -> Option<BoardState> {
        self.slot(object).map(|slot| slot.state)
    }

    fn is_pending(&self, object: u32) -> bool {
        self.requests.is_pending(object)
    }

    fn request(
        &mut self,
        renderer: &Renderer,
        plan: &Plan,
        options: &ViewerOptions,
        report: &mut FrameReport,
    ) -> bool {
        let mut replan = false;
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
        report.requests_pending = self.requests.pending();
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

//! Worker health: one probe task per worker asks for its status every
//! [`Deadlines::probe_interval`]. A worker believed alive that refuses a probe, leaves
//! [`Deadlines::probe_misses`] in a row unanswered, or where another process answers (its
//! instance number changed), is reported down; one believed down that answers is re-stored
//! if it lost its objects (fewer than it should hold, or another process) and reported up.
//! The frame loop applies the reports ([`super::BoardRequests::poll`]); the probes only
//! observe.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::Instant;

use super::{Client, Deadlines, store_one};

/// A change in a worker's health.
#[derive(Debug, Clone)]
pub enum HealthEvent {
    /// The worker stopped answering.
    Down {
        /// The worker.
        worker: u32,
        /// Why it is considered down.
        reason: String,
    },
    /// The worker answers and holds its objects.
    Up {
        /// The worker.
        worker: u32,
        /// Objects stored on it again before this report (0 if it had kept them).
        restored: usize,
    },
}

/// What the node knows about one worker.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct WorkerHealth {
    /// Requests go to it.
    pub alive: bool,
    /// Times it was marked down.
    pub failures: u32,
    /// Objects stored on it again after it came back.
    pub restored_objects: usize,
    /// Why it was last marked down.
    pub reason: Option<String>,
    /// It left the cluster (no longer listed, [`super::Workers::follow`]): not probed or used.
    pub gone: bool,
    /// When its first board arrived since it last came up (joined, or returned after being
    /// down), in seconds since the Unix epoch: how long a new worker waits for work. None
    /// while it is down (a new process at a dead worker's address starts afresh).
    pub first_board_since_up_unix: Option<f64>,
    /// When its first board arrived since it was last listed (joined, or rejoined after it
    /// left), in seconds since the Unix epoch: whether a new process at that address got
    /// work. Unlike `first_board_since_up_unix`, a brief down and up (a probe timing out on
    /// a loaded machine) keeps it.
    pub first_board_since_listed_unix: Option<f64>,
    /// When it was last marked down.
    #[serde(skip)]
    pub down_since: Option<Instant>,
    /// A worker marked down by a timeout is not used again before this.
    #[serde(skip)]
    pub usable_after: Option<Instant>,
}

/// What a probe task needs.
pub(super) struct Probe {
    pub worker: u32,
    pub client: Client,
    /// The objects this worker should hold.
    pub ids: Vec<u32>,
    /// Every stored object by id (shared by all probes), to store them again.
    pub objects: super::StoredObjects,
    /// Whether the frame loop currently uses the worker (written only by the frame loop).
    pub believed_up: Arc<AtomicBool>,
    /// Set by the frame loop when the worker left the cluster: the probe ends.
    pub gone: Arc<AtomicBool>,
    /// The worker process's instance number when its objects were last known stored there
    /// (0: not yet known); kept across probes of the same worker.
    pub instance: Arc<AtomicU64>,
    pub deadlines: Deadlines,
    /// Where changes go, with when they were seen.
    pub events: mpsc::Sender<(Instant, HealthEvent)>,
}

impl Probe {
    /// Probes until the frame loop stops listening.
    pub async fn run(mut self) {
        let mut interval = tokio::time::interval(self.deadlines.probe_interval);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut reported_down = false;
        // Probes unanswered in a row since the last answer.
        let mut misses: u32 = 0;
        loop {
            interval.tick().await;
            if self.gone.load(Ordering::Acquire) {
                return;
            }
            let probe = tokio::time::timeout(
                self.deadlines.probe_timeout,
                self.client.status(proto::StatusRequest {}),
            )
            .await;
            let believed_up = self.believed_up.load(Ordering::Acquire);
            if believed_up {
                reported_down = false;
            }
            let known = self.instance.load(Ordering::Acquire);
            misses = if probe.is_err() {
                misses.saturating_add(1)
            } else {
                0
            };
            let event = match probe {
                Ok(Ok(reply)) => {
                    let status = reply.into_inner();
                    // Another process at this address (a restart, or an address a scaled
                    // cluster handed to another worker) holds none of our objects.
                    let other_process = known != 0 && status.instance != known;
                    if believed_up && other_process && !reported_down {
                        Some(HealthEvent::Down {
                            worker: self.worker,
                            reason: "another worker process answers at its address".into(),
                        })
                    } else if believed_up {
                        if known == 0 {
                            self.instance.store(status.instance, Ordering::Release);
                        }
                        None
                    } else {
                        let held = if other_process {
                            0
                        } else {
                            status.objects as usize
                        };
                        match self.restore_if_lost(held).await {
                            Ok(restored) => {
                                self.instance.store(status.instance, Ordering::Release);
                                Some(HealthEvent::Up {
                                    worker: self.worker,
                                    restored,
                                })
                            }
                            Err(reason) => {
                                eprintln!(
                                    "worker {} answers but cannot store: {reason}",
                                    self.worker
                                );
                                None
                            }
                        }
                    }
                }
                _ if !believed_up || reported_down => None,
                Ok(Err(status)) => Some(HealthEvent::Down {
                    worker: self.worker,
                    reason: format!("health probe: {}: {}", status.code(), status.message()),
                }),
                Err(_) if misses < self.deadlines.probe_misses => None,
                Err(_) => Some(HealthEvent::Down {
                    worker: self.worker,
                    reason: format!(
                        "no answer to {misses} health probes in a row within {:?} each",
                        self.deadlines.probe_timeout
                    ),
                }),
            };
            if let Some(event) = event {
                reported_down |= matches!(event, HealthEvent::Down { .. });
                if self.events.send((Instant::now(), event)).is_err() {
                    return; // the frame loop is gone
                }
            }
        }
    }

    /// Stores every object again when the worker holds fewer than it should; returns how many.
    async fn restore_if_lost(&mut self, held: usize) -> Result<usize, String> {
        if held >= self.ids.len() {
            return Ok(0);
        }
        for &id in &self.ids {
            if let Some(object) = self.objects.get(id) {
                let chunks = proto::object_to_chunks(id, object);
                store_one(self.client.clone(), chunks, self.deadlines.store).await?;
            }
        }
        Ok(self.ids.len())
    }
}

//! Board requests through the balancer, and what happens when a worker fails them.
//!
//! A request lives until it ends as one [`Arrival`]. When its worker fails (unreachable, no
//! answer within [`super::Deadlines::render`], the object lost), the worker is marked down,
//! and this request and every other one that worker held go to other replicas at the next
//! [`BoardRequests::poll`]; after [`MAX_ATTEMPTS`], or when every replica is down, the
//! request ends as an error and the object is drawn as geometry.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use balancer::{Balancer, Placement, Request};
use proto::RenderRequest;

use super::health::{HealthEvent, Probe, WorkerHealth};
use super::{Client, MAX_JOBS_PER_WORKER, Workers};
use crate::board::{BoardData, BoardShape};
use crate::plan::{BoardState, WantedBoard};

/// Calls per request (the first and its reassignments) before the object falls back to
/// geometry.
pub const MAX_ATTEMPTS: u32 = 4;

/// The answer to one request.
pub struct Arrival {
    /// The object.
    pub object: u32,
    /// The board, or why there is none (the object is drawn as geometry).
    pub board: Result<BoardData, String>,
    /// Seconds from the first call until the answer reached this node, reassignments
    /// included (not counting the wait for the next frame to collect it).
    pub latency: f64,
    /// Encoded bytes received.
    pub bytes: usize,
    /// Seconds the worker spent rendering the board, as it reports (0 without a board).
    pub render_seconds: f64,
    /// The worker that answered last.
    pub worker: u32,
    /// The request's priority (higher first), for uploads held back to a later frame.
    pub priority: f64,
}

/// Statistics of the requests so far. Every issued request ends as received, failed or
/// cancelled, or is still pending: `issued == received + failed + cancelled + pending`.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct RequestCounts {
    /// Requests handed to a worker (reassignments not counted again).
    pub issued: u64,
    /// Boards received.
    pub received: u64,
    /// Requests that ended without a board: the object falls back to geometry.
    pub failed: u64,
    /// Requests the node no longer wanted (the object left the view, or the board on its way
    /// was superseded); the worker drops one it has not started.
    pub cancelled: u64,
    /// Wanted boards no live worker holds (drawn as geometry, not issued).
    pub unassignable: u64,
    /// Wanted boards held back because every replica's queue was full (asked again later).
    pub deferred: u64,
    /// Calls given to another replica after their worker failed.
    pub reassigned: u64,
}

/// Distinct failure messages kept for reports: a worker answering every request with a new
/// message must not grow the node's memory.
pub const FAILURE_REASONS: usize = 16;

/// A change of a worker's health, for reports. Dated when the node saw it (a probe's answer
/// or its absence, a failed call, a new listing), not when the frame loop applied it: a
/// loop held up by a slow frame or a pause would otherwise make detection look slower.
#[derive(Debug, Clone, serde::Serialize)]
pub struct HealthRecord {
    /// Seconds since the requests started.
    pub at: f64,
    /// Seconds since the Unix epoch, to line up with other logs (a `kill`, a restart).
    pub unix_time: f64,
    /// Seconds from seeing the change to the frame loop applying it (until then requests
    /// still went by the old health).
    pub applied_after: f64,
    /// The worker.
    pub worker: u32,
    /// `down: why`, or `up` (with objects stored again).
    pub event: String,
}

impl HealthRecord {
    /// A change seen at `seen`, applied now, on the clock of requests `started` then.
    fn seen(started: Instant, seen: Instant, worker: u32, event: String) -> HealthRecord {
        let applied_after = seen.elapsed().as_secs_f64();
        HealthRecord {
            at: seen.saturating_duration_since(started).as_secs_f64(),
            unix_time: unix_now() - applied_after,
            applied_after,
            worker,
            event,
        }
    }
}

fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Why a call failed, which decides what happens next.
#[derive(Debug)]
enum CallError {
    /// The worker failed: mark it down (for a timeout, with a cool-down) and reassign.
    Worker { message: String, timed_out: bool },
    /// The worker is busy: reassign, it stays up.
    Busy(String),
    /// The request itself was refused: no other worker would do better.
    Fatal(String),
}

impl CallError {
    fn from_status(status: tonic::Status) -> CallError {
        use tonic::Code;
        let message = format!("{}: {}", status.code(), status.message());
        match status.code() {
            Code::ResourceExhausted => CallError::Busy(message),
            Code::InvalidArgument
            | Code::OutOfRange
            | Code::FailedPrecondition
            | Code::PermissionDenied
            | Code::Unimplemented => CallError::Fatal(message),
            _ => CallError::Worker {
                message,
                timed_out: false,
            },
        }
    }
}

struct Reply {
    id: u64,
    result: Result<(BoardData, (usize, f64)), CallError>,
    /// When the reply reached this node and was decoded (not when a frame collected it),
    /// less any wait for a pause to end.
    at: Instant,
}

/// A call in flight: its request and the task that makes it (aborted to cancel it, which
/// resets the call's stream, so the worker drops the board if it has not started it).
struct InFlight {
    pending: Pending,
    task: tokio::task::AbortHandle,
}

/// A request in flight or waiting to be reassigned.
#[derive(Clone, Copy)]
struct Pending {
    want: WantedBoard,
    worker: u32,
    attempts: u32,
    first_issued: Instant,
}

/// Board requests through the balancer.
pub struct BoardRequests {
    workers: Workers,
    balancer: Balancer,
    weights: Vec<f64>,
    shape: BoardShape,
    sender: mpsc::Sender<Reply>,
    replies: mpsc::Receiver<Reply>,
    in_flight: HashMap<u64, InFlight>,
    /// Requests whose worker failed, to be handed to another replica, with the last error.
    reassign: Vec<(Pending, String)>,
    /// The board each pending request asks for, by object.
    pending_objects: HashMap<u32, BoardState>,
    next_id: u64,
    /// Running totals.
    pub counts: RequestCounts,
    /// Why requests failed: each distinct message (at most [`FAILURE_REASONS`]) and how often.
    failure_reasons: BTreeMap<String, u64>,
    health: Vec<WorkerHealth>,
    received_by_worker: Vec<u64>,
    believed_up: Vec<Arc<AtomicBool>>,
    /// Per worker: tells its probe to stop (the worker left).
    gone: Vec<Arc<AtomicBool>>,
    /// Per worker: the process instance its objects are stored on (see [`Probe`]).
    instances: Vec<Arc<AtomicU64>>,
    /// Every stored object by id, to store them on workers that restart or join.
    stored: super::StoredObjects,
    /// Health changes from the probes, each with when its probe saw it.
    health_sender: mpsc::Sender<(Instant, HealthEvent)>,
    health_events: mpsc::Receiver<(Instant, HealthEvent)>,
    health_log: Vec<HealthRecord>,
    trace: Option<Vec<balancer::TraceRecord>>,
    started: Instant,
}

impl BoardRequests {
    /// Requests over `workers`, whose replicas `placement` describes; `weights[object]` is its
    /// triangle count. `stored` holds each stored object, kept to store it again on a
    /// worker that restarts empty.
    pub fn new(
        workers: Workers,
        placement: Placement,
        weights: Vec<f64>,
        shape: BoardShape,
        record_trace: bool,
        stored: super::StoredObjects,
    ) -> anyhow::Result<BoardRequests> {
        let objects_of_workers = placement.objects_of_workers();
        let balancer = Balancer::new(
            placement,
            balancer::Config {
                max_jobs_per_worker: Some(MAX_JOBS_PER_WORKER),
                ..balancer::Config::default()
            },
        )?;
        let (sender, replies) = mpsc::channel();
        let (health_sender, health_events) = mpsc::channel();
        let count = workers.len();
        let mut requests = BoardRequests {
            health: vec![
                WorkerHealth {
                    alive: true,
                    ..WorkerHealth::default()
                };
                count
            ],
            received_by_worker: vec![0; count],
            workers,
            balancer,
            weights,
            shape,
            sender,
            replies,
            in_flight: HashMap::new(),
            reassign: Vec::new(),
            pending_objects: HashMap::new(),
            next_id: 0,
            counts: RequestCounts::default(),
            failure_reasons: BTreeMap::new(),
            believed_up: Vec::new(),
            gone: Vec::new(),
            instances: Vec::new(),
            stored,
            health_sender,
            health_events,
            health_log: Vec::new(),
            trace: record_trace.then(Vec::new),
            started: Instant::now(),
        };
        for (worker, ids) in objects_of_workers.into_iter().enumerate() {
            requests.believed_up.push(Arc::new(AtomicBool::new(true)));
            requests.gone.push(Arc::new(AtomicBool::new(false)));
            requests.instances.push(Arc::new(AtomicU64::new(0)));
            requests.start_probe(worker as u32, ids);
        }
        Ok(requests)
    }

    /// Starts probing `worker`, which should hold `ids` (stored again when it does not).
    fn start_probe(&mut self, worker: u32, ids: Vec<u32>) {
        let w = worker as usize;
        let probe = Probe {
            worker,
            client: self.workers.clients[w].clone(),
            ids: ids
                .into_iter()
                .filter(|&id| self.stored.get(id).is_some())
                .collect(),
            objects: self.stored.clone(),
            believed_up: self.believed_up[w].clone(),
            gone: self.gone[w].clone(),
            instance: self.instances[w].clone(),
            deadlines: self.workers.deadlines,
            events: self.health_sender.clone(),
        };
        self.workers.runtime.spawn(probe.run());
    }

    /// Applies a change in the set of workers ([`Workers::follow`]): a listed address not
    /// known joins (with its share of replicas, stored by its probe before it is used; an
    /// address that left and is back resumes), and a known one no longer listed leaves (its
    /// calls go to other replicas).
    fn follow_membership(&mut self) {
        for (seen, listed) in self.workers.membership_changes() {
            self.apply_membership(seen, listed);
        }
    }

    /// Applies one listing of the workers, made at `seen`.
    fn apply_membership(&mut self, seen: Instant, listed: Vec<String>) {
        let listed: HashSet<String> = listed.into_iter().collect();
        for worker in 0..self.workers.len() as u32 {
            let w = worker as usize;
            let is_listed = listed.contains(&self.workers.addresses[w]);
            if !is_listed && !self.health[w].gone {
                self.mark_down(worker, "no longer listed".to_string(), false, seen);
                self.health[w].gone = true;
                self.gone[w].store(true, Ordering::Release);
                self.record(seen, worker, "left".into());
            } else if is_listed && self.health[w].gone {
                self.health[w].gone = false;
                // Another process may answer at that address now: its work starts afresh.
                self.health[w].first_board_since_listed_unix = None;
                self.gone[w] = Arc::new(AtomicBool::new(false));
                self.record(seen, worker, "rejoined".into());
                let ids = self.balancer.placement().objects_of_workers()[w].clone();
                self.start_probe(worker, ids);
            }
        }
        let mut new: Vec<&String> = listed
            .iter()
            .filter(|a| !self.workers.addresses.contains(a))
            .collect();
        new.sort();
        for address in new {
            let worker = match self.workers.add(address) {
                Ok(worker) => worker,
                Err(error) => {
                    eprintln!("cannot use worker {address}: {error:#}");
                    continue;
                }
            };
            let (index, ids) = self.balancer.add_worker(u64::from(worker) ^ 0x5eed);
            debug_assert_eq!(index, worker, "the balancer and the clients count alike");
            self.health.push(WorkerHealth {
                alive: false,
                reason: Some("joining: storing its objects".into()),
                ..WorkerHealth::default()
            });
            self.received_by_worker.push(0);
            self.believed_up.push(Arc::new(AtomicBool::new(false)));
            self.gone.push(Arc::new(AtomicBool::new(false)));
            self.instances.push(Arc::new(AtomicU64::new(0)));
            self.record(
                seen,
                worker,
                format!("joined ({address}): storing {} objects", ids.len()),
            );
            self.start_probe(worker, ids);
        }
    }

    /// Whether a request for `object` is in flight (or waiting to be reassigned).
    pub fn is_pending(&self, object: u32) -> bool {
        self.pending_objects.contains_key(&object)
    }

    /// The board a pending request for `object` asks for (direction and size).
    pub fn pending_board(&self, object: u32) -> Option<BoardState> {
        self.pending_objects.get(&object).copied()
    }

    /// Ends the pending requests for `objects` as cancelled: calls in flight are aborted (the
    /// worker drops a board it has not started), waiting reassignments forgotten. Returns the
    /// objects whose requests ended (those of `objects` that were pending).
    pub fn cancel(&mut self, objects: &[u32]) -> Vec<u32> {
        let objects: HashSet<u32> = objects
            .iter()
            .copied()
            .filter(|o| self.is_pending(*o))
            .collect();
        if objects.is_empty() {
            return Vec::new();
        }
        let balancer = &mut self.balancer;
        self.in_flight.retain(|&id, call| {
            let keep = !objects.contains(&call.pending.want.object);
            if !keep {
                call.task.abort();
                let _ = balancer.cancel(id);
            }
            keep
        });
        self.reassign
            .retain(|(pending, _)| !objects.contains(&pending.want.object));
        for object in &objects {
            self.pending_objects.remove(object);
        }
        self.counts.cancelled += objects.len() as u64;
        objects.into_iter().collect()
    }

    /// Requests not yet ended.
    pub fn pending(&self) -> usize {
        self.pending_objects.len()
    }

    /// Where the balancer uses the workers' measured speeds (the default: in offers and picks).
    pub fn use_speeds(&mut self, speeds: balancer::SpeedUse) {
        self.balancer.use_speeds(speeds);
    }

    /// The balancer's view of the workers (load, queue, alive).
    pub fn worker_status(&self) -> &[balancer::WorkerStatus] {
        self.balancer.workers()
    }

    /// What this node knows about each worker's health.
    pub fn health(&self) -> &[WorkerHealth] {
        &self.health
    }

    /// Boards received from each worker.
    pub fn received_by_worker(&self) -> &[u64] {
        &self.received_by_worker
    }

    /// Every change of health so far, in the order the frame loop applied them (each dated
    /// when it was seen, so a failed call can follow a change a probe saw later).
    pub fn health_log(&self) -> &[HealthRecord] {
        &self.health_log
    }

    /// Seconds since the requests started (the clock of [`HealthRecord::at`]).
    pub fn elapsed(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Worker addresses.
    pub fn addresses(&self) -> &[String] {
        &self.workers.addresses
    }

    /// Pauses the workers in use, those believed up ([`super::Workers::pause`]).
    pub fn pause_workers(&self) -> super::WorkersPause {
        self.workers
            .pause(|worker| self.health.get(worker).is_some_and(|h| h.alive && !h.gone))
    }

    /// Hands wanted boards to the balancer and sends the assigned ones; returns the objects no
    /// live worker holds. `frame` numbers the trace records.
    pub fn submit(&mut self, wanted: &[WantedBoard], frame: u64) -> Vec<u32> {
        let wanted: Vec<&WantedBoard> = wanted
            .iter()
            .filter(|w| !self.is_pending(w.object))
            .collect();
        if wanted.is_empty() {
            return Vec::new();
        }
        let mut by_id = HashMap::new();
        let requests: Vec<Request> = wanted
            .iter()
            .map(|w| {
                let id = self.next_id;
                self.next_id += 1;
                by_id.insert(id, **w);
                self.request(id, w)
            })
            .collect();
        let assignment = self.balancer.assign(requests);
        self.counts.deferred += assignment.deferred.len() as u64;
        self.counts.unassignable += assignment.unassignable.len() as u64;
        let now = Instant::now();
        let seconds = self.elapsed();
        for (request, worker) in assignment.assigned {
            if let Some(trace) = &mut self.trace {
                trace.push(balancer::TraceRecord {
                    frame,
                    object: request.object,
                    weight: request.weight,
                    time: Some(seconds),
                });
            }
            self.counts.issued += 1;
            let want = by_id[&request.id];
            self.pending_objects.insert(
                request.object,
                BoardState {
                    direction: want.direction,
                    size: want.size,
                },
            );
            let pending = Pending {
                want,
                worker,
                attempts: 1,
                first_issued: now,
            };
            self.send(request.id, pending);
        }
        assignment
            .unassignable
            .iter()
            .map(|(r, _)| r.object)
            .collect()
    }

    fn request(&self, id: u64, want: &WantedBoard) -> Request {
        Request {
            id,
            object: want.object,
            weight: self
                .weights
                .get(want.object as usize)
                .copied()
                .unwrap_or(1.0),
            priority: want.priority,
        }
    }

    fn send(&mut self, id: u64, pending: Pending) {
        let mut client = self.workers.clients[pending.worker as usize].clone();
        let sender = self.sender.clone();
        let shape = self.shape;
        let deadline = self.workers.deadlines.render;
        let decoding = self.workers.decoding.clone();
        let want = pending.want;
        let task = self.workers.runtime.spawn(async move {
            let received = tokio::time::timeout(deadline, receive(&mut client, &want))
                .await
                .unwrap_or_else(|_| {
                    Err(CallError::Worker {
                        message: format!("no answer within {deadline:?}"),
                        timed_out: true,
                    })
                });
            // Decoded only while the node is not paused ([`Workers::pause`]): work done in
            // a pause would be off the run's clock. Outside the deadline, so that a pause
            // never times a call out; left out of its latency too.
            let mut held = Duration::ZERO;
            let result = match received {
                Ok((bytes, render_seconds)) => {
                    let figures = (bytes.len(), render_seconds);
                    let waiting = Instant::now();
                    let _open = decoding.read().await;
                    held = waiting.elapsed();
                    decode(bytes, &want)
                        .map(|maps| (BoardData::new(&maps, want.direction, shape), figures))
                }
                Err(error) => Err(error),
            };
            let now = Instant::now();
            // The receiver is gone only when the node is shutting down.
            let _ = sender.send(Reply {
                id,
                result,
                at: now.checked_sub(held).unwrap_or(now),
            });
        });
        let task = task.abort_handle();
        self.in_flight.insert(id, InFlight { pending, task });
    }

    /// Everything that ended since the last call: boards, and requests that fell back to
    /// geometry. Also applies health reports and hands failed calls to other replicas.
    pub fn poll(&mut self) -> Vec<Arrival> {
        self.follow_membership();
        while let Ok((seen, event)) = self.health_events.try_recv() {
            match event {
                HealthEvent::Down { worker, reason } => self.mark_down(worker, reason, false, seen),
                HealthEvent::Up { worker, restored } => self.mark_up(worker, restored, seen),
            }
        }
        let mut arrived = Vec::new();
        while let Ok(reply) = self.replies.try_recv() {
            arrived.extend(self.handle(reply));
        }
        arrived.extend(self.reassign_failed());
        arrived
    }

    /// Waits until every request has ended or `timeout` passed (`--sync`).
    pub fn wait_all(&mut self, timeout: Duration) -> Vec<Arrival> {
        let deadline = Instant::now() + timeout;
        let mut arrived = self.poll();
        while !self.pending_objects.is_empty() {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            // Wake at least every 50 ms: health reports and reassignments need polls too.
            if let Ok(reply) = self
                .replies
                .recv_timeout(left.min(Duration::from_millis(50)))
            {
                arrived.extend(self.handle(reply));
            }
            arrived.extend(self.poll());
        }
        arrived
    }

    /// One call's reply: a board, a failure to reassign, or an end.
    fn handle(&mut self, reply: Reply) -> Option<Arrival> {
        // Unknown: its worker was marked down and the request went elsewhere already, or it
        // was cancelled.
        let pending = self.in_flight.remove(&reply.id)?.pending;
        match reply.result {
            Ok((board, figures)) => {
                // The worker's own render time: the call's time would count its queue, and one
                // slow early sample would make a worker look slow and starve it.
                let _ = self.balancer.complete(reply.id, Some(figures.1));
                Some(self.end(pending, Ok(board), figures, reply.at))
            }
            Err(error) => {
                let _ = self.balancer.cancel(reply.id);
                match error {
                    CallError::Fatal(message) => {
                        Some(self.end(pending, Err(message), (0, 0.0), reply.at))
                    }
                    CallError::Busy(message) => {
                        self.reassign.push((pending, message));
                        None
                    }
                    CallError::Worker { message, timed_out } => {
                        self.mark_down(pending.worker, message.clone(), timed_out, reply.at);
                        self.reassign.push((pending, message));
                        None
                    }
                }
            }
        }
    }

    /// Ends a request that `arrived` (its last reply, or now for one that went nowhere).
    fn end(
        &mut self,
        pending: Pending,
        board: Result<BoardData, String>,
        (bytes, render_seconds): (usize, f64),
        arrived: Instant,
    ) -> Arrival {
        self.pending_objects.remove(&pending.want.object);
        match &board {
            Ok(_) => {
                self.counts.received += 1;
                self.received_by_worker[pending.worker as usize] += 1;
                let health = &mut self.health[pending.worker as usize];
                // A call still in flight when its worker went down is not work since it came up.
                if health.alive {
                    let now = unix_now();
                    health.first_board_since_up_unix =
                        health.first_board_since_up_unix.or(Some(now));
                    health.first_board_since_listed_unix =
                        health.first_board_since_listed_unix.or(Some(now));
                }
            }
            Err(message) => {
                self.counts.failed += 1;
                let known = self.failure_reasons.len();
                if let Some(count) = self.failure_reasons.get_mut(message) {
                    *count += 1;
                } else if known < FAILURE_REASONS {
                    self.failure_reasons.insert(message.clone(), 1);
                }
            }
        }
        Arrival {
            object: pending.want.object,
            board,
            latency: arrived.duration_since(pending.first_issued).as_secs_f64(),
            bytes,
            render_seconds,
            worker: pending.worker,
            priority: pending.want.priority,
        }
    }

    /// Hands failed calls to other live replicas; ends those that cannot go anywhere.
    fn reassign_failed(&mut self) -> Vec<Arrival> {
        let mut ended = Vec::new();
        let waiting = std::mem::take(&mut self.reassign);
        let mut requests = Vec::new();
        let mut by_id = HashMap::new();
        for (pending, last_error) in waiting {
            if pending.attempts >= MAX_ATTEMPTS {
                let why = format!("gave up after {} attempts: {last_error}", pending.attempts);
                ended.push(self.end(pending, Err(why), (0, 0.0), Instant::now()));
                continue;
            }
            let id = self.next_id;
            self.next_id += 1;
            requests.push(self.request(id, &pending.want));
            by_id.insert(id, (pending, last_error));
        }
        if requests.is_empty() {
            return ended;
        }
        let assignment = self.balancer.assign(requests);
        for (request, worker) in assignment.assigned {
            let (pending, _) = by_id.remove(&request.id).expect("assigned ids are ours");
            self.counts.reassigned += 1;
            let next = Pending {
                worker,
                attempts: pending.attempts + 1,
                ..pending
            };
            self.send(request.id, next);
        }
        for (request, why) in assignment.unassignable {
            let (pending, last_error) = by_id.remove(&request.id).expect("ids are ours");
            let why = format!("{why} (last error: {last_error})");
            ended.push(self.end(pending, Err(why), (0, 0.0), Instant::now()));
        }
        // Live replicas with full queues: try again at the next poll.
        for request in assignment.deferred {
            self.reassign
                .push(by_id.remove(&request.id).expect("deferred ids are ours"));
        }
        ended
    }

    /// Stops using `worker`, seen failing at `seen`; its calls in flight go to other replicas.
    /// After a timeout it is not used again for a cool-down that doubles with each failure.
    fn mark_down(&mut self, worker: u32, reason: String, timed_out: bool, seen: Instant) {
        let Some(health) = self.health.get_mut(worker as usize) else {
            return;
        };
        if !health.alive {
            return;
        }
        health.alive = false;
        health.first_board_since_up_unix = None;
        health.failures += 1;
        health.down_since = Some(seen);
        health.usable_after = timed_out
            .then(|| seen + self.workers.deadlines.cooldown * (1 << (health.failures - 1).min(4)));
        health.reason = Some(reason.clone());
        self.believed_up[worker as usize].store(false, Ordering::Release);
        self.record(seen, worker, format!("down: {reason}"));
        for id in self.balancer.set_alive(worker, false).unwrap_or_default() {
            if let Some(call) = self.in_flight.remove(&id) {
                self.reassign
                    .push((call.pending, format!("worker {worker} is down: {reason}")));
            }
        }
    }

    /// Uses `worker` again (seen answering at `seen`), unless it is cooling down after a
    /// timeout.
    fn mark_up(&mut self, worker: u32, restored: usize, seen: Instant) {
        let Some(health) = self.health.get_mut(worker as usize) else {
            return;
        };
        health.restored_objects += restored;
        if health.alive || health.gone || health.usable_after.is_some_and(|t| Instant::now() < t) {
            return;
        }
        health.alive = true;
        health.reason = None;
        health.first_board_since_up_unix = None;
        self.believed_up[worker as usize].store(true, Ordering::Release);
        let _ = self.balancer.set_alive(worker, true);
        let event = if restored > 0 {
            format!("up: {restored} objects stored again")
        } else {
            "up".to_string()
        };
        self.record(seen, worker, event);
    }

    /// Logs a change of `worker`'s health seen at `seen`.
    fn record(&mut self, seen: Instant, worker: u32, event: String) {
        self.health_log
            .push(HealthRecord::seen(self.started, seen, worker, event));
    }

    /// Marks a worker down from the start (it could not store its objects); health probes
    /// store them again and bring it back when it answers.
    pub fn mark_dead(&mut self, worker: u32, reason: &str) {
        self.mark_down(
            worker,
            format!("storing failed: {reason}"),
            false,
            Instant::now(),
        );
    }

    /// Why requests failed so far: each distinct message and how many times.
    pub fn failure_reasons(&self) -> &BTreeMap<String, u64> {
        &self.failure_reasons
    }

    /// The trace recorded so far (`--record-trace`).
    pub fn trace(&self) -> Option<balancer::Trace> {
        self.trace.clone().map(balancer::Trace::new)
    }
}

/// One render call: the board's chunks reassembled, with the seconds the worker says it
/// rendered.
async fn receive(client: &mut Client, want: &WantedBoard) -> Result<(Vec<u8>, f64), CallError> {
    let (direction, size) = (want.direction, want.size);
    let request = RenderRequest {
        object_id: want.object,
        dir_x: direction.x,
        dir_y: direction.y,
        dir_z: direction.z,
        size,
        priority: want.priority,
    };
    let mut stream = client
        .render(request)
        .await
        .map_err(CallError::from_status)?
        .into_inner();
    let mut bytes = Vec::new();
    let mut render_seconds = 0.0;
    while let Some(chunk) = stream.message().await.map_err(CallError::from_status)? {
        // Checked before growing the buffer: a worker cannot make this node allocate more.
        if chunk.total_bytes > backend::MAX_BOARD_BYTES as u64
            || bytes.len() + chunk.data.len() > backend::MAX_BOARD_BYTES
        {
            return Err(CallError::Fatal(format!(
                "board of {} bytes is over the {} byte limit",
                chunk.total_bytes,
                backend::MAX_BOARD_BYTES
            )));
        }
        if bytes.is_empty() {
            bytes.reserve_exact(chunk.total_bytes as usize);
            // A lying worker's figure only skews a report; kept finite and non-negative.
            render_seconds = (chunk.render_milliseconds / 1e3).clamp(0.0, 3600.0);
        }
        bytes.extend_from_slice(&chunk.data);
    }
    Ok((bytes, render_seconds))
}

/// A received board decoded, if it is the board `want` asked for.
fn decode(bytes: Vec<u8>, want: &WantedBoard) -> Result<backend::Maps, CallError> {
    let (direction, size) = (want.direction, want.size);
    let maps = backend::EncodedBoard { bytes }
        .decode()
        .map_err(|e| CallError::Fatal(format!("undecodable board: {e}")))?;
    // A board that decodes may still answer another question: it must be the view and size
    // asked for, or it would be drawn in the wrong place.
    if maps.size != size {
        return Err(CallError::Fatal(format!(
            "the worker sent a {}-pixel board for a {size}-pixel request",
            maps.size
        )));
    }
    if maps.basis.forward.dot(direction.normalize()) < 1.0 - 1e-6 {
        return Err(CallError::Fatal(format!(
            "the worker sent a board seen along {} for a request along {direction}",
            maps.basis.forward
        )));
    }
    Ok(maps)
}

//! A live worker whose health answers are late now and then, as on a loaded machine: one
//! late probe must not mark it down (with one replica, that would fail every request on
//! it), while a worker that leaves `probe_misses` probes in a row unanswered is marked down,
//! and no sooner.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use backend::WorkerService;
use integration_tests::{
    Misbehaviour, requests_on_one_worker, serve_misbehaving, small_objects, wanted_boards,
};
use proto::{StatusRequest, Worker, WorkerStatus};
use tonic::{Request, Response, Status};
use visnode::workers::{BoardRequests, Deadlines};

const DEADLINES: Deadlines = Deadlines {
    render: Duration::from_secs(20),
    store: Duration::from_secs(20),
    probe_interval: Duration::from_millis(100),
    probe_timeout: Duration::from_millis(300),
    probe_misses: 2,
    cooldown: Duration::from_millis(500),
};
/// How late a late status answer is: well past the probe's timeout.
const LATE: Duration = Duration::from_millis(900);

/// A real worker that answers the next `late` status calls `LATE` late.
struct LateProbes {
    late: Arc<AtomicU32>,
}

#[tonic::async_trait]
impl Misbehaviour for LateProbes {
    async fn status(
        &self,
        worker: &WorkerService,
        request: Request<StatusRequest>,
    ) -> Result<Response<WorkerStatus>, Status> {
        let take = |n: u32| n.checked_sub(1);
        if self
            .late
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, take)
            .is_ok()
        {
            tokio::time::sleep(LATE).await;
        }
        worker.status(request).await
    }
}

/// One worker holding two objects, its status answers late while `late` counts down.
fn one_worker(late: &Arc<AtomicU32>) -> (BoardRequests, tokio::runtime::Runtime) {
    let (address, runtime) = serve_misbehaving(LateProbes { late: late.clone() });
    let requests = requests_on_one_worker(address, small_objects(2, 400), DEADLINES);
    (requests, runtime)
}

/// Polls like a frame loop every 20 ms for `span`, or until `stop` holds.
fn poll_for(requests: &mut BoardRequests, span: Duration, stop: impl Fn(&BoardRequests) -> bool) {
    let end = Instant::now() + span;
    while Instant::now() < end && !stop(requests) {
        requests.poll();
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn one_late_probe_does_not_mark_a_live_worker_down() {
    let late = Arc::new(AtomicU32::new(0));
    let (mut requests, _runtime) = one_worker(&late);
    late.store(1, Ordering::Release);
    requests.submit(&wanted_boards(2), 1);
    // Past the late answer and several prompt probes after it.
    poll_for(&mut requests, LATE + 6 * DEADLINES.probe_interval, |_| {
        false
    });
    assert_eq!(
        late.load(Ordering::Acquire),
        0,
        "no probe was answered late"
    );
    requests.wait_all(Duration::from_secs(30));
    let health = &requests.health()[0];
    assert!(health.alive, "marked down: {:?}", health.reason);
    assert_eq!(health.failures, 0, "{:?}", requests.health_log());
    let counts = requests.counts;
    assert_eq!((counts.received, counts.failed), (2, 0), "{counts:?}");
}

#[test]
fn a_worker_that_leaves_probes_unanswered_in_a_row_is_marked_down_after_the_misses() {
    let late = Arc::new(AtomicU32::new(0));
    let (mut requests, _runtime) = one_worker(&late);
    let since = Instant::now();
    late.store(u32::MAX, Ordering::Release);
    poll_for(&mut requests, Duration::from_secs(20), |r| {
        !r.health()[0].alive
    });
    let waited = since.elapsed();
    let health = &requests.health()[0];
    assert!(!health.alive, "never marked down");
    let why = health.reason.as_deref().unwrap_or_default();
    assert!(
        why.contains("no answer to 2 health probes in a row"),
        "{why}"
    );
    // Each miss is a whole probe timeout, so two cannot come sooner than this.
    assert!(
        waited >= 2 * DEADLINES.probe_timeout,
        "down after {waited:?}"
    );
}

#[test]
fn a_worker_down_is_dated_when_its_probes_saw_it_though_the_frame_loop_stalled() {
    // The frame loop stands still far longer than the misses take (a slow frame, or a pause
    // waiting on this very worker): the log must say when the node saw the worker go, and
    // how late the loop applied it, not date the change when the loop came back.
    const STALL: Duration = Duration::from_secs(5);
    let late = Arc::new(AtomicU32::new(0));
    let (mut requests, _runtime) = one_worker(&late);
    requests.poll();
    let since = requests.elapsed();
    late.store(u32::MAX, Ordering::Release);
    std::thread::sleep(STALL);
    requests.poll();
    let applied = requests.elapsed();
    assert!(!requests.health()[0].alive, "never marked down");
    let log = requests.health_log();
    let down = log
        .iter()
        .find(|r| r.event.starts_with("down"))
        .unwrap_or_else(|| panic!("no down in {log:?}"));
    let seen = down.at - since;
    assert!(
        seen >= 2.0 * DEADLINES.probe_timeout.as_secs_f64(),
        "down seen {seen} s after the probes went unanswered: sooner than two misses"
    );
    assert!(
        seen < STALL.as_secs_f64() / 2.0,
        "down dated {seen} s after the probes went unanswered, the loop stalled {STALL:?}"
    );
    assert!(
        (down.applied_after - (applied - down.at)).abs() < 0.05,
        "applied {} s after being seen, but the loop applied it {} s after",
        down.applied_after,
        applied - down.at
    );
}

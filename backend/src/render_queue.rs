//! The worker's render queue: boards wait in the order of the priority the node gives them
//! (the error in pixels a board removes per pixel it costs), not in the order they came, and
//! a board whose caller went away (the node cancelled it: the object left the view, or the
//! view moved past it) is dropped before it is rendered.
//!
//! The queue has threads of its own, one board each at a time, each taking the first job
//! waiting: the threads are the only limit on concurrency, the order is the queue's.

use std::cmp::Ordering as CmpOrdering;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};

use tokio::sync::oneshot;

/// Jobs waiting for the queue's threads, highest priority first.
pub(crate) struct RenderQueue {
    shared: Arc<Shared>,
    sequence: AtomicU64,
}

/// What the queue's threads and its submitters share.
struct Shared {
    waiting: Mutex<Waiting>,
    ready: Condvar,
    /// Jobs dropped unrun because their caller was gone.
    dropped: AtomicU64,
}

struct Waiting {
    jobs: BinaryHeap<Job>,
    /// Set when the queue is dropped: its threads finish what is queued and end.
    closed: bool,
}

/// A submitted job's result, and its cancellation: dropping the ticket before the job starts
/// drops the job.
pub(crate) struct Ticket<T> {
    result: oneshot::Receiver<T>,
    cancelled: Arc<AtomicBool>,
}

struct Job {
    priority: f64,
    sequence: u64,
    cancelled: Arc<AtomicBool>,
    run: Box<dyn FnOnce() + Send>,
}

impl RenderQueue {
    /// A queue served by `threads` threads of its own, each running `start` first. Plain
    /// threads, not a rayon pool: a rayon thread waiting for its board's other half would
    /// run the next queued board inside the first (rayon takes any task while it waits),
    /// out of priority order, its time counted in the first's, and with a slowdown
    /// deadlocked on the weak machine's lock.
    pub(crate) fn new(
        threads: usize,
        start: impl Fn() + Send + Sync + 'static,
    ) -> std::io::Result<RenderQueue> {
        let shared = Arc::new(Shared {
            waiting: Mutex::new(Waiting {
                jobs: BinaryHeap::new(),
                closed: false,
            }),
            ready: Condvar::new(),
            dropped: AtomicU64::new(0),
        });
        let start = Arc::new(start);
        for i in 0..threads.max(1) {
            let (shared, start) = (shared.clone(), start.clone());
            std::thread::Builder::new()
                .name(format!("board-{i}"))
                .spawn(move || {
                    start();
                    serve(&shared);
                })?;
        }
        Ok(RenderQueue {
            shared,
            sequence: AtomicU64::new(0),
        })
    }

    /// Queues `work` at `priority` (higher first; equal ones in the order submitted; one
    /// that is not a number comes last).
    pub(crate) fn submit<T: Send + 'static>(
        &self,
        priority: f64,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Ticket<T> {
        let (sender, result) = oneshot::channel();
        let cancelled = Arc::new(AtomicBool::new(false));
        let job = Job {
            priority: if priority.is_nan() {
                f64::NEG_INFINITY
            } else {
                priority
            },
            sequence: self.sequence.fetch_add(1, Ordering::Relaxed),
            cancelled: cancelled.clone(),
            run: Box::new(move || {
                // The receiver is gone only if the caller left after the job started.
                let _ = sender.send(work());
            }),
        };
        let mut waiting = self
            .shared
            .waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        waiting.jobs.push(job);
        drop(waiting);
        self.shared.ready.notify_one();
        Ticket { result, cancelled }
    }

    /// Jobs dropped unrun so far because their caller was gone.
    pub(crate) fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }
}

impl Drop for RenderQueue {
    fn drop(&mut self) {
        let mut waiting = self
            .shared
            .waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        waiting.closed = true;
        drop(waiting);
        self.shared.ready.notify_all();
    }
}

/// One queue thread: the first waiting job, each time, until the queue is closed and empty.
fn serve(shared: &Shared) {
    loop {
        let mut waiting = shared.waiting.lock().unwrap_or_else(|e| e.into_inner());
        while waiting.jobs.is_empty() && !waiting.closed {
            waiting = shared
                .ready
                .wait(waiting)
                .unwrap_or_else(|e| e.into_inner());
        }
        let Some(job) = waiting.jobs.pop() else {
            return;
        };
        drop(waiting);
        if job.cancelled.load(Ordering::Acquire) {
            shared.dropped.fetch_add(1, Ordering::Relaxed);
        } else {
            // A panicking job drops its result's sender (its caller sees `None`), not
            // the thread.
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job.run));
        }
    }
}

impl<T> Ticket<T> {
    /// The job's result; `None` only if the job panicked.
    pub(crate) async fn wait(mut self) -> Option<T> {
        (&mut self.result).await.ok()
    }
}

impl<T> Drop for Ticket<T> {
    fn drop(&mut self) {
        // Harmless once the job ran; before that, the job is dropped when its turn comes.
        self.cancelled.store(true, Ordering::Release);
    }
}

impl PartialEq for Job {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == CmpOrdering::Equal
    }
}

impl Eq for Job {}

impl PartialOrd for Job {
    fn partial_cmp(&self, other: &Self) -> Option<CmpOrdering> {
        Some(self.cmp(other))
    }
}

impl Ord for Job {
    /// The heap's greatest is served first: the highest priority, then the earliest.
    fn cmp(&self, other: &Self) -> CmpOrdering {
        self.priority
            .total_cmp(&other.priority)
            .then(other.sequence.cmp(&self.sequence))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    fn one_thread() -> RenderQueue {
        RenderQueue::new(1, || {}).unwrap()
    }

    #[test]
    fn jobs_run_highest_priority_first_and_cancelled_ones_never() {
        let queue = one_thread();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        // The one thread is held, once it has taken the first job, until the others are
        // queued.
        let (release, gate) = mpsc::channel::<()>();
        let (started, has_started) = mpsc::channel::<()>();
        let first = queue.submit(0.0, move || {
            started.send(()).unwrap();
            gate.recv().unwrap()
        });
        has_started.recv().unwrap();
        let (order_sender, order) = mpsc::channel();
        let job = |name: &'static str| {
            let sender = order_sender.clone();
            move || sender.send(name).unwrap()
        };
        let low = queue.submit(1.0, job("low"));
        let high = queue.submit(9.0, job("high"));
        let cancelled = queue.submit(5.0, job("cancelled"));
        let middle = queue.submit(3.0, job("middle"));
        let tie = queue.submit(3.0, job("middle, later"));
        let not_a_number = queue.submit(f64::NAN, job("not a number"));
        drop(cancelled);
        release.send(()).unwrap();
        runtime.block_on(async {
            first.wait().await.unwrap();
            for ticket in [low, high, middle, tie, not_a_number] {
                ticket.wait().await.unwrap();
            }
        });
        let ran: Vec<&str> = order.try_iter().collect();
        assert_eq!(
            ran,
            ["high", "middle", "middle, later", "low", "not a number"]
        );
        assert_eq!(queue.dropped(), 1);
    }
}

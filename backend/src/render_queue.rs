//! The worker's render queue: boards wait in the order of the priority the node gives them
//! (the error in pixels a board removes per pixel it costs), not in the order they came, and
//! a board whose caller went away (the node cancelled it: the object left the view, or the
//! view moved past it) is dropped before it is rendered.
//!
//! The queue has threads of its own, one board each at a time, each taking the first job
//! waiting: the threads are the only limit on concurrency, the order is the queue's.
//!
//! A node pauses the queue while it measures itself off the clock ([`RenderQueue::pause`],
//! through the `Pause` call), so the workers gain no time the node's clock does not count.

use std::cmp::Ordering as CmpOrdering;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

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
    /// Signalled when the last running job finishes.
    idle: Condvar,
    /// Jobs dropped unrun because their caller was gone.
    dropped: AtomicU64,
}

struct Waiting {
    jobs: BinaryHeap<Job>,
    /// Set when the queue is dropped: its threads finish what is queued and end.
    closed: bool,
    /// Jobs being run now.
    running: usize,
    /// Pauses in force; while there is one, no job starts.
    pauses: usize,
    /// When the first of the pauses in force began.
    paused_since: Option<Instant>,
    /// Thread time spent running jobs since then (jobs started before the pause).
    ran_while_paused: Duration,
}

/// A paused render queue: no board starts until it is resumed (or dropped).
pub(crate) struct RenderPause {
    shared: Arc<Shared>,
    resumed: bool,
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
                running: 0,
                pauses: 0,
                paused_since: None,
                ran_while_paused: Duration::ZERO,
            }),
            ready: Condvar::new(),
            idle: Condvar::new(),
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
        let mut waiting = self.shared.lock();
        waiting.jobs.push(job);
        drop(waiting);
        self.shared.ready.notify_one();
        Ticket { result, cancelled }
    }

    /// Jobs being run now.
    pub(crate) fn running(&self) -> usize {
        self.shared.lock().running
    }

    /// Jobs dropped unrun so far because their caller was gone.
    pub(crate) fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Pauses the queue: no job starts from now on (the jobs already running go on; see
    /// [`RenderPause::wait_for_running`]). Jobs still queue meanwhile; they start when the
    /// pause is resumed.
    pub(crate) fn pause(&self) -> RenderPause {
        let mut waiting = self.shared.lock();
        waiting.pauses += 1;
        if waiting.paused_since.is_none() {
            waiting.paused_since = Some(Instant::now());
            waiting.ran_while_paused = Duration::ZERO;
        }
        RenderPause {
            shared: self.shared.clone(),
            resumed: false,
        }
    }
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, Waiting> {
        self.waiting.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl RenderPause {
    /// Returns once the jobs running when the queue was paused have finished (true), or after
    /// `at_most` with some still running (false).
    pub fn wait_for_running(&self, at_most: Duration) -> bool {
        let waiting = self.shared.lock();
        let (waiting, _) = self
            .shared
            .idle
            .wait_timeout_while(waiting, at_most, |w| w.running > 0)
            .unwrap_or_else(|e| e.into_inner());
        waiting.running == 0
    }

    /// Lets jobs start again. Returns the thread time jobs ran while paused: those that had
    /// started before the pause and ran on into it (a job still running counts until now).
    pub fn resume(mut self) -> Duration {
        self.release()
    }

    fn release(&mut self) -> Duration {
        if std::mem::replace(&mut self.resumed, true) {
            return Duration::ZERO;
        }
        let mut waiting = self.shared.lock();
        let since = waiting.paused_since.unwrap_or_else(Instant::now);
        let ran = waiting.ran_while_paused + since.elapsed() * waiting.running as u32;
        waiting.pauses -= 1;
        if waiting.pauses == 0 {
            waiting.paused_since = None;
            drop(waiting);
            self.shared.ready.notify_all();
        }
        ran
    }
}

impl Drop for RenderPause {
    fn drop(&mut self) {
        self.release();
    }
}

impl Drop for RenderQueue {
    fn drop(&mut self) {
        let mut waiting = self.shared.lock();
        waiting.closed = true;
        drop(waiting);
        self.shared.ready.notify_all();
    }
}

/// One queue thread: the first waiting job, each time, until the queue is closed and empty.
fn serve(shared: &Shared) {
    loop {
        let mut waiting = shared.lock();
        while (waiting.jobs.is_empty() || waiting.pauses > 0) && !waiting.closed {
            waiting = shared
                .ready
                .wait(waiting)
                .unwrap_or_else(|e| e.into_inner());
        }
        let Some(job) = waiting.jobs.pop() else {
            return;
        };
        waiting.running += 1;
        drop(waiting);
        if job.cancelled.load(Ordering::Acquire) {
            shared.dropped.fetch_add(1, Ordering::Relaxed);
        } else {
            // A panicking job drops its result's sender (its caller sees `None`), not
            // the thread.
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job.run));
        }
        let mut waiting = shared.lock();
        waiting.running -= 1;
        // Only jobs started before a pause finish during it: their time since it began.
        if let Some(since) = waiting.paused_since {
            waiting.ran_while_paused += since.elapsed();
        }
        if waiting.running == 0 {
            shared.idle.notify_all();
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

    /// Submits a job that holds the queue's one thread, once it has started, until the
    /// returned sender is sent to.
    fn occupy(queue: &RenderQueue) -> (Ticket<()>, mpsc::Sender<()>) {
        let (release, gate) = mpsc::channel::<()>();
        let (started, has_started) = mpsc::channel::<()>();
        let running = queue.submit(0.0, move || {
            started.send(()).unwrap();
            gate.recv().unwrap()
        });
        has_started.recv().unwrap();
        (running, release)
    }

    #[test]
    fn jobs_run_highest_priority_first_and_cancelled_ones_never() {
        let queue = one_thread();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        // The one thread is held, once it has taken the first job, until the others are
        // queued.
        let (first, release) = occupy(&queue);
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

    #[test]
    fn a_pause_waits_for_the_running_job_and_starts_no_other_until_resumed() {
        let queue = one_thread();
        let (_running, release) = occupy(&queue);
        std::thread::scope(|scope| {
            let (paused_sender, paused) = mpsc::channel();
            let pausing = &queue;
            scope.spawn(move || {
                let pause = pausing.pause();
                pause.wait_for_running(Duration::from_secs(60));
                paused_sender.send(pause).unwrap()
            });
            while queue.shared.lock().pauses == 0 {
                std::thread::yield_now();
            }
            // Queued during the pause, at a higher priority than anything: still not run.
            let (ran_sender, ran) = mpsc::channel();
            let _queued = queue.submit(9.0, move || ran_sender.send(()).unwrap());
            let running_into_the_pause = Duration::from_millis(40);
            std::thread::sleep(running_into_the_pause);
            assert!(
                paused.try_recv().is_err(),
                "the pause returned while a job was running"
            );
            release.send(()).unwrap();
            let pause = paused.recv().unwrap();
            assert_eq!(queue.shared.lock().running, 0);
            assert!(
                ran.recv_timeout(Duration::from_millis(100)).is_err(),
                "a job started while the queue was paused"
            );
            let ran_while_paused = pause.resume();
            assert!(
                ran_while_paused >= running_into_the_pause,
                "{ran_while_paused:?}"
            );
            ran.recv_timeout(Duration::from_secs(10))
                .expect("the queued job runs once the queue is resumed");
        });
        // A pause with nothing running returns at once, and counts no time.
        while queue.shared.lock().running > 0 {
            std::thread::yield_now();
        }
        let idle = queue.pause();
        idle.wait_for_running(Duration::from_secs(60));
        assert_eq!(idle.resume(), Duration::ZERO);
    }
}

//! The visualization node's side of the cluster: connecting to workers (or starting them
//! in-process on loopback), storing the objects on them with the balancer's random redundant
//! placement, and asynchronous board requests.
//!
//! Requests run on a background tokio runtime; their answers wait in a channel until the
//! next frame collects them ([`BoardRequests::poll`]), so a frame never waits for a worker.
//! Every request ends as exactly one [`Arrival`]: a board, or an error the frame falls back
//! to geometry for.

use std::collections::HashMap;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;
use balancer::{Balancer, Placement, Request};
use glam::DVec3;
use proto::{RenderRequest, WorkerClient};
use tokio::sync::oneshot;
use tonic::transport::Channel;

use crate::board::{BoardData, BoardShape};
use crate::plan::WantedBoard;

/// Replicas of each object (Süß used 3; 1 → 2 is what helps most).
pub const REPLICAS: usize = 3;
/// A render call that has not answered in this long is abandoned (and the object falls back
/// to geometry until a new request succeeds).
pub const RENDER_DEADLINE: Duration = Duration::from_secs(30);
/// Unfinished requests per worker: more wait on the visualization node, where their
/// direction is still refreshed each frame, instead of in a worker's queue.
pub const MAX_JOBS_PER_WORKER: u32 = 16;

/// Connected workers, and the in-process ones this node started.
pub struct Workers {
    runtime: tokio::runtime::Runtime,
    clients: Vec<WorkerClient<Channel>>,
    /// Their addresses.
    pub addresses: Vec<String>,
    local: Vec<oneshot::Sender<()>>,
}

impl Workers {
    /// Starts `count` workers in this process, each on its own loopback port, each rendering
    /// with `threads` threads.
    pub fn start_local(count: usize, threads: usize) -> anyhow::Result<Workers> {
        anyhow::ensure!(count > 0, "--local-workers must be at least 1");
        let runtime = runtime()?;
        let mut addresses = Vec::new();
        let mut local = Vec::new();
        for _ in 0..count {
            let listener = runtime
                .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
                .context("binding a loopback port for a local worker")?;
            addresses.push(format!("http://{}", listener.local_addr()?));
            let service = backend::WorkerService::new(backend::WorkerConfig {
                threads: threads.max(1),
                ..backend::WorkerConfig::default()
            })?;
            let (stop, stopped) = oneshot::channel::<()>();
            runtime.spawn(async move {
                let shutdown = async {
                    let _ = stopped.await;
                };
                if let Err(error) = backend::serve(listener, service, shutdown).await {
                    eprintln!("local worker stopped: {error:#}");
                }
            });
            local.push(stop);
        }
        let clients = runtime.block_on(async { connect_all(&addresses) })?;
        Ok(Workers {
            runtime,
            clients,
            addresses,
            local,
        })
    }

    /// Connects to running workers (`host:port` or `http://host:port`).
    pub fn connect(addresses: &[String]) -> anyhow::Result<Workers> {
        anyhow::ensure!(!addresses.is_empty(), "no worker addresses given");
        let runtime = runtime()?;
        let addresses: Vec<String> = addresses
            .iter()
            .map(|a| {
                if a.contains("://") {
                    a.clone()
                } else {
                    format!("http://{a}")
                }
            })
            .collect();
        let clients = runtime.block_on(async { connect_all(&addresses) })?;
        Ok(Workers {
            runtime,
            clients,
            addresses,
            local: Vec::new(),
        })
    }

    /// Number of workers.
    pub fn len(&self) -> usize {
        self.clients.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.clients.is_empty()
    }

    /// Stores each `(id, object)` on the workers `placement` names, several uploads at once.
    /// Returns the workers that could not store (unreachable, or refusing), with why.
    pub fn store(
        &self,
        objects: &[(u32, &scene::Object)],
        placement: &Placement,
        progress: &indicatif::ProgressBar,
    ) -> Vec<(u32, String)> {
        let total: usize = objects
            .iter()
            .map(|(id, _)| placement.replicas(*id).map_or(0, |r| r.len()))
            .sum();
        progress.set_length(total as u64);
        progress.set_position(0);
        progress.set_message("storing objects on workers");
        let mut failed: HashMap<u32, String> = HashMap::new();
        self.runtime.block_on(async {
            let mut uploads = tokio::task::JoinSet::new();
            let mut record = |done: Result<(u32, Result<(), String>), tokio::task::JoinError>| {
                if let Ok((worker, Err(error))) = done {
                    failed.entry(worker).or_insert(error);
                }
                progress.inc(1);
            };
            for &(id, object) in objects {
                let chunks = proto::object_to_chunks(id, object);
                for &worker in placement.replicas(id).unwrap_or(&[]) {
                    let mut client = self.clients[worker as usize].clone();
                    let chunks = chunks.clone();
                    uploads.spawn(async move {
                        let stored = tokio::time::timeout(
                            Duration::from_secs(120),
                            client.store_object(tokio_stream::iter(chunks)),
                        )
                        .await;
                        let outcome = match stored {
                            Ok(Ok(_)) => Ok(()),
                            Ok(Err(status)) => {
                                Err(format!("{}: {}", status.code(), status.message()))
                            }
                            Err(_) => Err("storing timed out".to_string()),
                        };
                        (worker, outcome)
                    });
                }
                // Bounded: at most a few objects' chunks in memory at once.
                while uploads.len() >= 8 {
                    if let Some(done) = uploads.join_next().await {
                        record(done);
                    }
                }
            }
            while let Some(done) = uploads.join_next().await {
                record(done);
            }
        });
        let mut failed: Vec<(u32, String)> = failed.into_iter().collect();
        failed.sort_unstable_by_key(|(w, _)| *w);
        failed
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        for stop in self.local.drain(..) {
            let _ = stop.send(());
        }
    }
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("requests")
        .enable_all()
        .build()?)
}

/// Channels that connect on first use (and reconnect after a failure), so one unreachable
/// worker does not stop the others.
fn connect_all(addresses: &[String]) -> anyhow::Result<Vec<WorkerClient<Channel>>> {
    addresses
        .iter()
        .map(|address| {
            let endpoint = Channel::from_shared(address.clone())
                .with_context(|| format!("{address:?} is not a worker address"))?
                .connect_timeout(Duration::from_secs(5));
            Ok(WorkerClient::new(endpoint.connect_lazy())
                .max_decoding_message_size(backend::MAX_MESSAGE_BYTES)
                .max_encoding_message_size(backend::MAX_MESSAGE_BYTES))
        })
        .collect()
}

/// The answer to one request.
pub struct Arrival {
    /// The object.
    pub object: u32,
    /// The board, or why there is none.
    pub board: Result<BoardData, String>,
    /// Seconds from issue to arrival.
    pub latency: f64,
    /// Encoded bytes received.
    pub bytes: usize,
    /// The worker that answered.
    pub worker: u32,
}

struct InFlight {
    object: u32,
}

/// Statistics of the requests so far.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct RequestCounts {
    /// Requests sent to a worker.
    pub issued: u64,
    /// Boards received.
    pub received: u64,
    /// Requests that ended in an error.
    pub failed: u64,
    /// Wanted boards no live worker holds (drawn as geometry).
    pub unassignable: u64,
    /// Wanted boards held back because every replica's queue was full (asked again later).
    pub deferred: u64,
}

/// Board requests through the balancer.
pub struct BoardRequests {
    workers: Workers,
    balancer: Balancer,
    weights: Vec<f64>,
    shape: BoardShape,
    sender: mpsc::Sender<(u64, Arrival)>,
    replies: mpsc::Receiver<(u64, Arrival)>,
    in_flight: HashMap<u64, InFlight>,
    pending_objects: HashMap<u32, u64>,
    next_id: u64,
    /// Running totals.
    pub counts: RequestCounts,
    trace: Option<Vec<balancer::TraceRecord>>,
    started: Instant,
}

impl BoardRequests {
    /// Requests over `workers`, whose replicas `placement` describes; `weights[object]` is its
    /// triangle count.
    pub fn new(
        workers: Workers,
        placement: Placement,
        weights: Vec<f64>,
        shape: BoardShape,
        record_trace: bool,
    ) -> anyhow::Result<BoardRequests> {
        let balancer = Balancer::new(
            placement,
            balancer::Config {
                max_jobs_per_worker: Some(MAX_JOBS_PER_WORKER),
                ..balancer::Config::default()
            },
        )?;
        let (sender, replies) = mpsc::channel();
        Ok(BoardRequests {
            workers,
            balancer,
            weights,
            shape,
            sender,
            replies,
            in_flight: HashMap::new(),
            pending_objects: HashMap::new(),
            next_id: 0,
            counts: RequestCounts::default(),
            trace: record_trace.then(Vec::new),
            started: Instant::now(),
        })
    }

    /// Whether a request for `object` is in flight.
    pub fn is_pending(&self, object: u32) -> bool {
        self.pending_objects.contains_key(&object)
    }

    /// Requests in flight.
    pub fn pending(&self) -> usize {
        self.in_flight.len()
    }

    /// The balancer's view of the workers (load, queue, alive).
    pub fn worker_status(&self) -> &[balancer::WorkerStatus] {
        self.balancer.workers()
    }

    /// Worker addresses.
    pub fn addresses(&self) -> &[String] {
        &self.workers.addresses
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
                Request {
                    id,
                    object: w.object,
                    weight: self.weights.get(w.object as usize).copied().unwrap_or(1.0),
                    priority: w.priority,
                }
            })
            .collect();
        let assignment = self.balancer.assign(requests);
        self.counts.deferred += assignment.deferred.len() as u64;
        self.counts.unassignable += assignment.unassignable.len() as u64;
        let now = self.started.elapsed().as_secs_f64();
        for (request, worker) in assignment.assigned {
            let want = by_id[&request.id];
            if let Some(trace) = &mut self.trace {
                trace.push(balancer::TraceRecord {
                    frame,
                    object: request.object,
                    weight: request.weight,
                    time: Some(now),
                });
            }
            self.send(request.id, want, worker);
        }
        assignment.unassignable.iter().map(|r| r.object).collect()
    }

    fn send(&mut self, id: u64, want: WantedBoard, worker: u32) {
        self.counts.issued += 1;
        self.in_flight.insert(
            id,
            InFlight {
                object: want.object,
            },
        );
        self.pending_objects.insert(want.object, id);
        let mut client = self.workers.clients[worker as usize].clone();
        let sender = self.sender.clone();
        let shape = self.shape;
        let issued = Instant::now();
        self.workers.runtime.spawn(async move {
            let fetched = tokio::time::timeout(
                RENDER_DEADLINE,
                fetch(&mut client, want.object, want.direction, want.size),
            )
            .await
            .unwrap_or_else(|_| Err(format!("no answer within {RENDER_DEADLINE:?}")));
            let (board, bytes) = match fetched {
                Ok((maps, bytes)) => (Ok(BoardData::new(&maps, want.direction, shape)), bytes),
                Err(error) => (Err(error), 0),
            };
            let arrival = Arrival {
                object: want.object,
                board,
                latency: issued.elapsed().as_secs_f64(),
                bytes,
                worker,
            };
            // The receiver is gone only when the node is shutting down.
            let _ = sender.send((id, arrival));
        });
    }

    /// The answers that arrived since the last call.
    pub fn poll(&mut self) -> Vec<Arrival> {
        let mut arrived = Vec::new();
        while let Ok((id, arrival)) = self.replies.try_recv() {
            self.finish(id, &arrival);
            arrived.push(arrival);
        }
        arrived
    }

    /// Waits until every request in flight has answered or `timeout` passed (`--sync`).
    pub fn wait_all(&mut self, timeout: Duration) -> Vec<Arrival> {
        let deadline = Instant::now() + timeout;
        let mut arrived = Vec::new();
        while !self.in_flight.is_empty() {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.replies.recv_timeout(left) {
                Ok((id, arrival)) => {
                    self.finish(id, &arrival);
                    arrived.push(arrival);
                }
                Err(_) => break,
            }
        }
        arrived
    }

    fn finish(&mut self, id: u64, arrival: &Arrival) {
        if let Some(done) = self.in_flight.remove(&id) {
            self.pending_objects.remove(&done.object);
        }
        match &arrival.board {
            Ok(_) => {
                self.counts.received += 1;
                let _ = self.balancer.complete(id, Some(arrival.latency));
            }
            Err(_) => {
                self.counts.failed += 1;
                let _ = self.balancer.cancel(id);
            }
        }
    }

    /// Marks a worker dead (it could not store its objects): nothing is sent to it.
    pub fn mark_dead(&mut self, worker: u32) {
        let _ = self.balancer.set_alive(worker, false);
    }

    /// The trace recorded so far (`--record-trace`).
    pub fn trace(&self) -> Option<balancer::Trace> {
        self.trace.clone().map(balancer::Trace::new)
    }
}

/// One render call: the board's chunks reassembled and decoded.
async fn fetch(
    client: &mut WorkerClient<Channel>,
    object: u32,
    direction: DVec3,
    size: u32,
) -> Result<(backend::Maps, usize), String> {
    let request = RenderRequest {
        object_id: object,
        dir_x: direction.x,
        dir_y: direction.y,
        dir_z: direction.z,
        size,
    };
    let mut stream = client
        .render(request)
        .await
        .map_err(|s| format!("{}: {}", s.code(), s.message()))?
        .into_inner();
    let mut bytes = Vec::new();
    while let Some(chunk) = stream
        .message()
        .await
        .map_err(|s| format!("{}: {}", s.code(), s.message()))?
    {
        if bytes.is_empty() && chunk.total_bytes > 64 << 20 {
            return Err(format!("board of {} bytes is too large", chunk.total_bytes));
        }
        bytes.extend_from_slice(&chunk.data);
    }
    let size = bytes.len();
    let maps = backend::EncodedBoard { bytes }
        .decode()
        .map_err(|e| e.to_string())?;
    Ok((maps, size))
}

//! The gRPC worker service: a thin layer over the renderer, in the manner of the tonic
//! examples. Domain errors become `tonic::Status` here and nowhere else.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock, Weak, mpsc};
use std::time::{Duration, Instant};

use glam::DVec3;
use proto::{
    BoardChunk, ObjectChunk, PauseControl, PauseEvent, RenderRequest, StatusRequest, StoreReply,
    WorkerStatus,
};
use tokio::sync::Semaphore;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

use crate::render_queue::RenderQueue;
use crate::{EncodedBoard, PreparedObject, RenderError, render_mesh, threads_worth};

/// How a worker runs.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// Render threads.
    pub threads: usize,
    /// Stand in for a machine this many times weaker: each board renders at full speed, then
    /// the worker sleeps `slowdown - 1` times the render time before the next board starts,
    /// so both its latency and its throughput are `slowdown` times worse.
    pub slowdown: f64,
    /// Render requests queued or running at once; more are refused (RESOURCE_EXHAUSTED).
    pub queue_capacity: usize,
    /// Largest map side served.
    pub max_map_size: u32,
    /// Largest object accepted, in vertices and in triangles.
    pub max_object_elements: u64,
    /// Memory for stored objects; storing past it is refused.
    pub memory_limit_bytes: u64,
    /// Objects being received and prepared at once; more wait for a slot.
    pub concurrent_stores: usize,
    /// How long a store waits for one of the `concurrent_stores` slots before it is refused
    /// with RESOURCE_EXHAUSTED.
    pub store_wait: Duration,
    /// Render at the lowest CPU priority (nice 19, Linux): for workers that share a machine
    /// with the node's renderer while standing in for other machines, so they use the CPU
    /// the renderer leaves and do not slow its frames.
    pub background: bool,
}

/// Render threads when none are given: one per core this process may use.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

impl Default for WorkerConfig {
    fn default() -> Self {
        WorkerConfig {
            threads: default_threads(),
            slowdown: 1.0,
            queue_capacity: 64,
            max_map_size: 1024,
            max_object_elements: 50_000_000,
            memory_limit_bytes: 8 << 30,
            concurrent_stores: 4,
            store_wait: Duration::from_secs(30),
            background: false,
        }
    }
}

/// The worker: object replicas, a bounded render queue and the measured speed.
#[derive(Clone)]
pub struct WorkerService {
    state: Arc<State>,
}

struct State {
    config: WorkerConfig,
    objects: RwLock<HashMap<u32, Arc<PreparedObject>>>,
    memory: Mutex<MemoryBook>,
    stores: Arc<Semaphore>,
    queue: Arc<Semaphore>,
    /// With a slowdown, one board at a time renders and sleeps: a weak machine is busy while
    /// it works, so boards waiting behind it do not sleep alongside it.
    weak_machine: Mutex<()>,
    queued: AtomicU32,
    outstanding_triangles: AtomicU64,
    boards: AtomicU64,
    /// Triangles per second, exponential moving average over boards.
    speed: Mutex<f64>,
    /// Boards waiting for the render threads, highest priority first.
    renders: RenderQueue,
    /// The threads a board's render splits over.
    render_pool: rayon::ThreadPool,
    /// Stored objects whose levels are to be built ([`spawn_level_builder`]).
    levels: mpsc::Sender<Weak<PreparedObject>>,
    shutting_down: AtomicBool,
    /// Reported in every status ([`proto::WorkerStatus::instance`]).
    instance: u64,
}

impl WorkerService {
    /// A worker with no objects.
    pub fn new(config: WorkerConfig) -> anyhow::Result<WorkerService> {
        if config.threads == 0
            || !(config.slowdown >= 1.0 && config.slowdown.is_finite())
            || config.queue_capacity == 0
            || config.concurrent_stores == 0
        {
            anyhow::bail!(
                "threads, queue capacity and concurrent stores must be at least 1 and the slowdown a finite number of at least 1, got {config:?}"
            );
        }
        let background = config.background;
        let lower_priority = move || {
            if background {
                lowest_cpu_priority();
            }
        };
        // A large board on an otherwise idle worker splits its triangles over this pool
        // ([`threads_worth`]); the queue's own threads take the boards (render_queue.rs says why they are not this pool's).
        let render_pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .thread_name(|i| format!("render-{i}"))
            .start_handler(move |_| lower_priority())
            .build()?;
        let renders = RenderQueue::new(config.threads, lower_priority)?;
        let levels = spawn_level_builder(lower_priority)?;
        Ok(WorkerService {
            state: Arc::new(State {
                queue: Arc::new(Semaphore::new(config.queue_capacity)),
                stores: Arc::new(Semaphore::new(config.concurrent_stores)),
                weak_machine: Mutex::new(()),
                config,
                objects: RwLock::new(HashMap::new()),
                memory: Mutex::new(MemoryBook::default()),
                queued: AtomicU32::new(0),
                outstanding_triangles: AtomicU64::new(0),
                boards: AtomicU64::new(0),
                speed: Mutex::new(0.0),
                renders,
                render_pool,
                levels,
                shutting_down: AtomicBool::new(false),
                instance: random_instance(),
            }),
        })
    }

    /// From now on new requests are refused with UNAVAILABLE; queued ones still finish.
    pub fn begin_shutdown(&self) {
        self.state.shutting_down.store(true, Ordering::SeqCst);
    }

    fn object(&self, id: u32) -> Option<Arc<PreparedObject>> {
        self.state.objects.read().ok()?.get(&id).cloned()
    }

    fn book(&self) -> Result<std::sync::MutexGuard<'_, MemoryBook>, Status> {
        self.state
            .memory
            .lock()
            .map_err(|_| Status::internal("memory book poisoned"))
    }

    /// Reserves `bytes` for a store of object `id`, or refuses when stored objects and
    /// other stores in progress leave too little (an object it replaces is not counted).
    fn reserve(&self, id: u32, bytes: u64) -> Result<Reservation, Status> {
        let replaced = self.object(id).map_or(0, |o| o.memory_bytes() as u64);
        let mut book = self.book()?;
        let used = book.in_use(replaced, 0);
        if used.saturating_add(bytes) > self.state.config.memory_limit_bytes {
            return Err(Status::resource_exhausted(format!(
                "object {id} declares a size needing about {bytes} bytes; {used} of {} are in use or reserved",
                self.state.config.memory_limit_bytes
            )));
        }
        book.reserved += bytes;
        Ok(Reservation {
            state: self.state.clone(),
            bytes,
        })
    }

    /// Bytes held by stored objects, and reserved by stores in progress.
    pub fn memory_in_use(&self) -> (u64, u64) {
        self.state
            .memory
            .lock()
            .map_or((0, 0), |book| (book.stored, book.reserved))
    }
}

/// The worker's memory for objects: what stored objects hold and what stores in progress
/// have reserved from their declared sizes.
#[derive(Debug, Default)]
struct MemoryBook {
    stored: u64,
    reserved: u64,
}

impl MemoryBook {
    /// Bytes held or reserved, leaving out an object about to be `replaced` and a store's
    /// `own` reservation: what a new object's bytes must fit beside.
    fn in_use(&self, replaced: u64, own: u64) -> u64 {
        self.stored.saturating_sub(replaced) + self.reserved.saturating_sub(own)
    }
}

/// A store's share of [`MemoryBook::reserved`], given back when the store ends either way.
struct Reservation {
    state: Arc<State>,
    bytes: u64,
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if let Ok(mut book) = self.state.memory.lock() {
            book.reserved -= self.bytes;
        }
    }
}

type BoardStream = Pin<Box<dyn Stream<Item = Result<BoardChunk, Status>> + Send>>;
type PauseStream = Pin<Box<dyn Stream<Item = Result<PauseEvent, Status>> + Send>>;

/// The longest a node may pause a worker: far past a frame's read-back (milliseconds), short
/// enough that a node stuck while holding a pause does not idle the worker for long.
const MAX_PAUSE: Duration = Duration::from_secs(60);

#[tonic::async_trait]
impl proto::Worker for WorkerService {
    async fn store_object(
        &self,
        request: Request<Streaming<ObjectChunk>>,
    ) -> Result<Response<StoreReply>, Status> {
        if self.state.shutting_down.load(Ordering::SeqCst) {
            return Err(Status::unavailable("worker is shutting down"));
        }
        let wait = self.state.config.store_wait;
        let _slot = tokio::time::timeout(wait, self.state.stores.clone().acquire_owned())
            .await
            .map_err(|_| {
                Status::resource_exhausted(format!(
                    "{} stores in progress for over {wait:?}",
                    self.state.config.concurrent_stores
                ))
            })?
            .map_err(|_| Status::unavailable("worker is shutting down"))?;
        let mut chunks = request.into_inner();
        let mut assembler = proto::ObjectAssembler::new(self.state.config.max_object_elements);
        // Memory is admitted from the sizes the first chunk declares, before the assembler
        // reserves anything; the reservation ends when this call does.
        let mut reservation: Option<Reservation> = None;
        let mut digest = crate::shared::Digest::default();
        while let Some(chunk) = chunks.next().await {
            let chunk = chunk?;
            if reservation.is_none() {
                let bytes =
                    PreparedObject::admission_bytes(chunk.total_vertices, chunk.total_triangles);
                reservation = Some(self.reserve(chunk.object_id, bytes)?);
            }
            // A chunk is a megabyte of numbers to check and copy (10-30 ms of a probe's wait
            // when done here): off the async threads too.
            let (returned, returned_digest, pushed) = tokio::task::spawn_blocking(move || {
                digest.update(&chunk);
                let pushed = assembler.push(chunk);
                (assembler, digest, pushed)
            })
            .await
            .map_err(|_| Status::internal("receiving the object failed"))?;
            assembler = returned;
            digest = returned_digest;
            pushed.map_err(|e| match e {
                proto::AssembleError::TooLarge { .. } => Status::resource_exhausted(e.to_string()),
                _ => Status::invalid_argument(e.to_string()),
            })?;
        }
        // Checking and preparing a large object takes seconds: off the async threads, so the
        // worker keeps answering health probes and render calls meanwhile.
        let (id, prepared) = tokio::task::spawn_blocking(move || {
            let (id, object) = assembler
                .finish()
                .map_err(|e| Status::invalid_argument(e.to_string()))?;
            // Another worker of this process may hold the same object: share its copy. Its
            // levels are built after the store answers.
            let prepared = crate::shared::prepared(id, digest.finish(), || {
                PreparedObject::new(&object).map_err(|e| Status::invalid_argument(e.to_string()))
            })?;
            Ok::<_, Status>((id, prepared))
        })
        .await
        .map_err(|_| Status::internal("preparing the object failed"))??;
        let bytes = prepared.memory_bytes() as u64;
        let triangles = prepared.triangles.len() as u64;
        let mut objects = self
            .state
            .objects
            .write()
            .map_err(|_| Status::internal("object table poisoned"))?;
        let replaced = objects.get(&id).map_or(0, |o| o.memory_bytes() as u64);
        {
            let mut book = self.book()?;
            // This store's own reservation still counts in `reserved`: leave it out.
            let own = reservation.as_ref().map_or(0, |r| r.bytes);
            let used = book.in_use(replaced, own);
            if used.saturating_add(bytes) > self.state.config.memory_limit_bytes {
                return Err(Status::resource_exhausted(format!(
                    "object {id} needs {bytes} bytes; {used} of {} are in use or reserved",
                    self.state.config.memory_limit_bytes
                )));
            }
            book.stored = book.stored.saturating_sub(replaced) + bytes;
        }
        if !prepared.has_levels() {
            // The builder ends only with this service, which holds the sender.
            let _ = self.state.levels.send(Arc::downgrade(&prepared));
        }
        objects.insert(id, prepared);
        Ok(Response::new(StoreReply {
            object_id: id,
            triangles,
        }))
    }

    type RenderStream = BoardStream;

    async fn render(
        &self,
        request: Request<RenderRequest>,
    ) -> Result<Response<Self::RenderStream>, Status> {
        let state = &self.state;
        if state.shutting_down.load(Ordering::SeqCst) {
            return Err(Status::unavailable("worker is shutting down"));
        }
        let request = request.into_inner();
        let direction = DVec3::new(request.dir_x, request.dir_y, request.dir_z);
        if !direction.is_finite() || direction.length_squared() < 1e-24 {
            return Err(Status::invalid_argument(
                RenderError::BadDirection(direction.to_array()).to_string(),
            ));
        }
        if request.size == 0 || request.size > state.config.max_map_size {
            return Err(Status::invalid_argument(format!(
                "resolution {} must lie in 1..={} pixels",
                request.size, state.config.max_map_size
            )));
        }
        let object = self.object(request.object_id).ok_or_else(|| {
            Status::not_found(format!("object {} is not stored here", request.object_id))
        })?;
        // The permit is the queue slot: taken before any work, held until the board is sent
        // on its way, so a full queue refuses at once instead of piling up.
        let permit = state.queue.clone().try_acquire_owned().map_err(|_| {
            Status::resource_exhausted(format!(
                "render queue full ({} requests)",
                state.config.queue_capacity
            ))
        })?;
        let triangles = object.triangles.len() as u64;
        // Counted while queued or rendering, also when the node cancels the call (this
        // future is then dropped, and the queue drops the board if it has not started).
        let _queued = QueuedBoard::new(state.clone(), triangles);
        let worker = self.clone();
        let size = request.size;
        let slowdown = state.config.slowdown;
        let rendered = state.renders.submit(request.priority, move || {
            // A weak machine renders or sleeps one board at a time.
            let _machine = (slowdown > 1.0).then(|| {
                worker
                    .state
                    .weak_machine
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
            });
            // Timed on the render thread: the time a board waited behind others is not its
            // cost (the balancer reads this as speed).
            let start = Instant::now();
            let state = &worker.state;
            let others = (state.queued.load(Ordering::SeqCst) as usize).saturating_sub(1);
            // Picked once: the levels may arrive while the board renders.
            let mesh = object.mesh_for_size(size);
            let threads = threads_worth(mesh, size, state.config.threads, others);
            let maps = if threads > 1 {
                state
                    .render_pool
                    .install(|| render_mesh(&object, mesh, direction, size, threads))
            } else {
                render_mesh(&object, mesh, direction, size, 1)
            };
            let result = maps.map(|maps| EncodedBoard::encode(&maps));
            let elapsed = start.elapsed();
            // A slower machine: take `slowdown` times as long, holding the machine.
            if slowdown > 1.0 {
                std::thread::sleep(elapsed.mul_f64(slowdown - 1.0));
            }
            (result, elapsed)
        });
        let (result, elapsed) = rendered.wait().await.unwrap_or_else(|| {
            (
                Err(RenderError::EmptyObject("render task failed".into())),
                Duration::ZERO,
            )
        });
        let total = elapsed.mul_f64(slowdown).as_secs_f64();
        drop(permit);
        let encoded = result.map_err(|e| Status::invalid_argument(e.to_string()))?;
        state.boards.fetch_add(1, Ordering::SeqCst);
        if total > 0.0
            && let Ok(mut speed) = state.speed.lock()
        {
            let rate = triangles as f64 / total;
            *speed = if *speed == 0.0 {
                rate
            } else {
                0.8 * *speed + 0.2 * rate
            };
        }
        let total_bytes = encoded.bytes.len() as u64;
        let chunks: Vec<Result<BoardChunk, Status>> = encoded
            .bytes
            .chunks(proto::CHUNK_BYTES)
            .enumerate()
            .map(|(index, data)| {
                let first = index == 0;
                Ok(BoardChunk {
                    data: data.to_vec(),
                    total_bytes: if first { total_bytes } else { 0 },
                    render_milliseconds: if first { total * 1e3 } else { 0.0 },
                })
            })
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }

    type PauseStream = PauseStream;

    async fn pause(
        &self,
        request: Request<Streaming<PauseControl>>,
    ) -> Result<Response<Self::PauseStream>, Status> {
        let mut controls = request.into_inner();
        let first = controls
            .next()
            .await
            .ok_or_else(|| Status::invalid_argument("a pause begins with its limit"))??;
        let limit = Duration::from_millis(first.max_milliseconds.into()).min(MAX_PAUSE);
        let pause = self.state.renders.pause();
        let (events, receiver) = tokio::sync::mpsc::channel(2);
        tokio::spawn(async move {
            // Waits for the boards rendering now: a blocking wait on the queue's condition
            // variable, off the async threads, in steps, so a node that gives up meanwhile is
            // noticed (its call reset drops `receiver`) and the worker goes on.
            const STEP: Duration = Duration::from_millis(50);
            let began = Instant::now();
            let mut pause = pause;
            let paused = loop {
                let Ok((returned, idle)) = tokio::task::spawn_blocking(move || {
                    let idle = pause.wait_for_running(STEP);
                    (pause, idle)
                })
                .await
                else {
                    return; // the pause was dropped with the task: resumed
                };
                pause = returned;
                if idle || began.elapsed() >= limit {
                    break idle;
                }
                if events.is_closed() {
                    return; // the node is gone: dropping the pause resumes
                }
            };
            let first = PauseEvent {
                paused,
                ..PauseEvent::default()
            };
            if events.send(Ok(first)).await.is_err() {
                return; // the node is gone: dropping the pause resumes
            }
            // Until the node ends its side (or any message, error or reset), or the limit.
            let _ = tokio::time::timeout(limit, controls.next()).await;
            let rendered = pause.resume();
            let _ = events
                .send(Ok(PauseEvent {
                    resumed: true,
                    seconds_rendered: rendered.as_secs_f64(),
                    ..PauseEvent::default()
                }))
                .await;
        });
        Ok(Response::new(Box::pin(
            tokio_stream::wrappers::ReceiverStream::new(receiver),
        )))
    }

    async fn status(&self, _: Request<StatusRequest>) -> Result<Response<WorkerStatus>, Status> {
        let state = &self.state;
        Ok(Response::new(WorkerStatus {
            queue_length: state.queued.load(Ordering::SeqCst),
            queue_capacity: state.config.queue_capacity as u32,
            outstanding_triangles: state.outstanding_triangles.load(Ordering::SeqCst),
            triangles_per_second: state.speed.lock().map(|s| *s).unwrap_or(0.0),
            objects: state.objects.read().map(|o| o.len() as u32).unwrap_or(0),
            objects_simplifying: state
                .objects
                .read()
                .map(|o| o.values().filter(|o| !o.has_levels()).count() as u32)
                .unwrap_or(0),
            memory_bytes: self.memory_in_use().0,
            boards_rendered: state.boards.load(Ordering::SeqCst),
            boards_cancelled: state.renders.dropped(),
            boards_rendering: state.renders.running() as u32,
            instance: state.instance,
        }))
    }
}

/// Starts the thread that builds the levels of stored objects, one at a time, in the order
/// they were stored. A store answers once its object is checked, so a worker that joins a
/// running cluster takes boards within seconds (rendered from the full mesh until their
/// object's levels are built) instead of after all its objects are simplified: foliage,
/// whose levels are checked by rendering, takes a third of a second per tree. Ends when the
/// service is dropped (the sender with it); an object replaced or dropped meanwhile is
/// skipped.
fn spawn_level_builder(
    start: impl FnOnce() + Send + 'static,
) -> std::io::Result<mpsc::Sender<Weak<PreparedObject>>> {
    let (sender, receiver) = mpsc::channel::<Weak<PreparedObject>>();
    std::thread::Builder::new()
        .name("levels".into())
        .spawn(move || {
            start();
            for object in receiver {
                let Some(object) = object.upgrade() else {
                    continue;
                };
                // A bug in simplification leaves this object on its full mesh; the other
                // objects still get their levels.
                let built = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    object.build_levels()
                }));
                if built.is_err() {
                    eprintln!(
                        "worker: building the levels of {} failed; its boards render from the full mesh",
                        object.name
                    );
                }
            }
        })?;
    Ok(sender)
}

/// Puts the calling thread at the lowest CPU priority: for work that must not take a
/// renderer's CPU on a shared machine. On Linux the nice value is per thread (`setpriority`
/// with `who` 0 names the caller); elsewhere this does nothing.
pub fn lowest_cpu_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: setpriority only changes the scheduling priority of the calling thread; a
    // failure (returned, not a fault) leaves it as it was, which is only slower.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 19);
    }
}

/// A board queued or rendering, counted in the worker's status until it is done or its call
/// is dropped.
struct QueuedBoard {
    state: Arc<State>,
    triangles: u64,
}

impl QueuedBoard {
    fn new(state: Arc<State>, triangles: u64) -> QueuedBoard {
        state.queued.fetch_add(1, Ordering::SeqCst);
        state
            .outstanding_triangles
            .fetch_add(triangles, Ordering::SeqCst);
        QueuedBoard { state, triangles }
    }
}

impl Drop for QueuedBoard {
    fn drop(&mut self) {
        self.state.queued.fetch_sub(1, Ordering::SeqCst);
        self.state
            .outstanding_triangles
            .fetch_sub(self.triangles, Ordering::SeqCst);
    }
}

/// A number no other worker process is likely to pick: std's randomly keyed hasher (seeded
/// from the operating system) over the clock; never 0, which means "unknown" to the node.
fn random_instance() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    hasher.write_u128(nanos);
    hasher.write_u32(std::process::id());
    hasher.finish() | 1
}

/// Largest message either side accepts: object chunks and board chunks are at most
/// `proto::CHUNK_BYTES`, so this leaves room for framing and nothing more.
pub const MAX_MESSAGE_BYTES: usize = 2 * proto::CHUNK_BYTES + 64 * 1024;

/// How a worker checks who calls it.
#[derive(Debug, Clone, Default)]
pub struct Security {
    /// Every call must carry `authorization: Bearer TOKEN` (compared in constant time).
    pub token: Option<String>,
    /// Serve TLS with this certificate and key (PEM).
    pub tls_identity: Option<(Vec<u8>, Vec<u8>)>,
    /// Demand client certificates signed by this CA (PEM): mutual TLS.
    pub tls_client_ca: Option<Vec<u8>>,
}

/// Serves `service` (and the standard gRPC health service) on `listener` until `shutdown`
/// completes; requests already accepted finish first. With a token in `security`, every
/// call (health checks included) without it is refused as UNAUTHENTICATED.
pub async fn serve(
    listener: tokio::net::TcpListener,
    service: WorkerService,
    security: Security,
    shutdown: impl std::future::Future<Output = ()> + Send,
) -> anyhow::Result<()> {
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter
        .set_serving::<proto::WorkerServer<WorkerService>>()
        .await;
    let worker = proto::WorkerServer::new(service.clone())
        .max_decoding_message_size(MAX_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_MESSAGE_BYTES);
    let stopping = service.clone();
    let mut builder = tonic::transport::Server::builder();
    if let Some((cert, key)) = &security.tls_identity {
        let mut tls = tonic::transport::ServerTlsConfig::new()
            .identity(tonic::transport::Identity::from_pem(cert, key));
        if let Some(ca) = &security.tls_client_ca {
            tls = tls.client_ca_root(tonic::transport::Certificate::from_pem(ca));
        }
        builder = builder.tls_config(tls)?;
    }
    builder
        .layer(tonic::service::InterceptorLayer::new(TokenCheck::new(
            security.token.as_deref(),
        )))
        .add_service(health)
        .add_service(worker)
        .serve_with_incoming_shutdown(
            // Without TCP_NODELAY a small write waits for the peer to acknowledge the one
            // before it, and the peer delays acknowledgements by up to 40 ms: a call's
            // trailers after its board, or a pause's answer after its headers, came 40 ms
            // late. (`Server::tcp_nodelay` applies only to listeners tonic opens itself.)
            tokio_stream::wrappers::TcpListenerStream::new(listener).map(|accepted| {
                accepted.inspect(|stream| {
                    let _ = stream.set_nodelay(true);
                })
            }),
            async move {
                shutdown.await;
                stopping.begin_shutdown();
            },
        )
        .await?;
    Ok(())
}

/// Refuses calls that do not carry the shared token.
#[derive(Clone)]
struct TokenCheck {
    expected: Option<Arc<[u8]>>,
}

impl TokenCheck {
    fn new(token: Option<&str>) -> TokenCheck {
        TokenCheck {
            expected: token.map(|t| format!("Bearer {t}").into_bytes().into()),
        }
    }
}

impl tonic::service::Interceptor for TokenCheck {
    fn call(&mut self, request: Request<()>) -> Result<Request<()>, Status> {
        let Some(expected) = &self.expected else {
            return Ok(request);
        };
        let given = request
            .metadata()
            .get("authorization")
            .map(|v| v.as_bytes())
            .unwrap_or_default();
        // Constant time: how much of a guess matches must not show in the time to refuse it.
        if subtle::ConstantTimeEq::ct_eq(given, &expected[..]).into() {
            Ok(request)
        } else {
            Err(Status::unauthenticated(
                "missing or wrong token (authorization: Bearer TOKEN)",
            ))
        }
    }
}

/// Whether an address is on this machine only.
pub fn is_loopback(address: &SocketAddr) -> bool {
    address.ip().is_loopback()
}

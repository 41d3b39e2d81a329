//! The visualization node's side of the cluster: connecting to workers (or starting them
//! in-process on loopback), storing the objects on them with the balancer's random redundant
//! placement, asynchronous board requests, and noticing workers that die, hang or come back.
//!
//! Requests run on a background tokio runtime; their answers wait in a channel until the
//! next frame collects them ([`BoardRequests::poll`]), so a frame never waits for a worker.
//! Every request ends as exactly one [`Arrival`]: a board, or an error the frame falls back
//! to geometry for. A request whose worker fails is first handed to another replica.

mod health;
mod requests;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use anyhow::Context;
use balancer::Placement;
use proto::WorkerClient;
use tokio::sync::oneshot;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

pub use health::{HealthEvent, WorkerHealth};
pub use requests::{Arrival, BoardRequests, HealthRecord, MAX_ATTEMPTS, RequestCounts};

/// The objects stored on the workers, kept to store them again on a worker that restarts
/// empty or joins: the scene's own objects, shared, never copied.
#[derive(Clone)]
pub struct StoredObjects {
    objects: Arc<Vec<scene::Object>>,
    stored: Arc<Vec<bool>>,
}

impl StoredObjects {
    /// `objects[id]` is stored on workers where `stored[id]`.
    pub fn new(objects: Arc<Vec<scene::Object>>, stored: Vec<bool>) -> StoredObjects {
        StoredObjects {
            objects,
            stored: Arc::new(stored),
        }
    }

    /// Object `id`, if it is one stored on workers.
    pub fn get(&self, id: u32) -> Option<&scene::Object> {
        let id = id as usize;
        self.stored
            .get(id)
            .copied()
            .unwrap_or(false)
            .then(|| self.objects.get(id))
            .flatten()
    }
}

/// Replicas of each object (Süß used 3; 1 → 2 is what helps most).
pub const REPLICAS: usize = 3;
/// Objects uploaded to one worker at once while storing (a worker admits 4 by default).
const UPLOADS_PER_WORKER: usize = 2;
/// Unfinished requests per worker: more wait on the visualization node, where their
/// direction is still refreshed each frame, instead of in a worker's queue.
pub const MAX_JOBS_PER_WORKER: u32 = 64;

/// How long calls to workers may take before the worker is suspected and the work goes
/// elsewhere.
#[derive(Debug, Clone, Copy)]
pub struct Deadlines {
    /// A render call unanswered this long is given to another replica, and its worker is
    /// marked unhealthy until it answers health probes again.
    pub render: Duration,
    /// Storing one object.
    pub store: Duration,
    /// Time between health probes of each worker.
    pub probe_interval: Duration,
    /// A probe unanswered this long counts as a miss.
    pub probe_timeout: Duration,
    /// Misses in a row before a worker believed up is reported down. On a loaded machine one
    /// probe can wait past its timeout: in a CI compose run, single misses marked workers
    /// down beside the killed and the cut-off ones, and 8 requests found every replica down.
    /// A probe answered with an error (refused) counts at once.
    pub probe_misses: u32,
    /// A worker marked unhealthy by a timed-out render waits at least this long before it is
    /// used again (doubling each time, up to 16 times), so a slow worker does not flap.
    pub cooldown: Duration,
}

impl Default for Deadlines {
    fn default() -> Self {
        Deadlines {
            render: Duration::from_secs(5),
            store: Duration::from_secs(60),
            probe_interval: Duration::from_millis(250),
            probe_timeout: Duration::from_secs(1),
            probe_misses: 2,
            cooldown: Duration::from_secs(2),
        }
    }
}

/// How this node proves itself to workers: a shared token, TLS, or neither (loopback).
#[derive(Debug, Clone, Default)]
pub struct Credentials {
    /// Sent as `authorization: Bearer TOKEN` on every call.
    pub token: Option<String>,
    /// PEM of the CA that signed the workers' certificates: connect with TLS.
    pub tls_ca: Option<PathBuf>,
    /// PEM certificate and key of this node, for workers that demand mutual TLS.
    pub tls_identity: Option<(PathBuf, PathBuf)>,
    /// The name the workers' certificates carry, when it is not the host name dialled.
    pub tls_domain: Option<String>,
}

/// A client to one worker, with the token attached to every call.
pub type Client = WorkerClient<InterceptedService<Channel, Authorization>>;

/// Adds the shared token to every call.
#[derive(Clone)]
pub struct Authorization(Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>);

impl tonic::service::Interceptor for Authorization {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(value) = &self.0 {
            request
                .metadata_mut()
                .insert("authorization", value.clone());
        }
        Ok(request)
    }
}

/// Connected workers, and the in-process ones this node started.
pub struct Workers {
    runtime: Arc<tokio::runtime::Runtime>,
    clients: Vec<Client>,
    /// Their addresses.
    pub addresses: Vec<String>,
    /// Call deadlines.
    pub deadlines: Deadlines,
    /// Stops each worker this node started in its own process.
    stop_local: Vec<oneshot::Sender<()>>,
    /// How to reach a worker that joins later.
    dialer: Dialer,
    /// The current set of worker addresses, each time it changes ([`Workers::follow`]),
    /// with when it was listed.
    membership: Option<mpsc::Receiver<(Instant, Vec<String>)>>,
    /// Tells the thread behind `membership` to end when these workers are dropped.
    stop_following: Arc<std::sync::atomic::AtomicBool>,
    /// Read by each call before it decodes a board; held for writing through a pause
    /// ([`Workers::pause`]), so that the node decodes nothing off its clock either.
    decoding: Arc<tokio::sync::RwLock<()>>,
}

/// The workers paused while the node measures itself off the clock ([`Workers::pause`]).
pub struct WorkersPause {
    /// Where the pauses' calls run; `None` with nothing to pause.
    runtime: Option<Arc<tokio::runtime::Runtime>>,
    held: Vec<HeldPause>,
    /// Some worker asked could not be paused or did not finish its boards in time.
    incomplete: bool,
    /// Boards that arrive during the pause wait for this to be dropped to be decoded.
    decoding: Option<tokio::sync::OwnedRwLockWriteGuard<()>>,
}

/// One worker's pause: the open `Pause` call, which ends when `end` is dropped.
struct HeldPause {
    end: tokio::sync::mpsc::Sender<proto::PauseControl>,
    events: tonic::Streaming<proto::PauseEvent>,
}

/// How long a worker may take to pause (finish the boards it is rendering, each a few
/// milliseconds), from the call's start.
const PAUSE_WAIT: Duration = Duration::from_secs(2);
/// How long a worker may take to answer a `Pause` call (its reply's headers, sent before it
/// waits for its boards) or to say what it rendered once resumed: one round trip each.
/// Shorter than [`PAUSE_WAIT`], because a worker cut off but not yet found down holds the
/// run up this long at each pause.
const ANSWER_WAIT: Duration = Duration::from_millis(500);
/// The longest a worker stays paused should this node stop answering.
const PAUSE_LIMIT: Duration = Duration::from_secs(30);

impl WorkersPause {
    /// Nothing to pause: a node without workers.
    pub fn none() -> WorkersPause {
        WorkersPause {
            runtime: None,
            held: Vec::new(),
            incomplete: false,
            decoding: None,
        }
    }

    /// Lets the workers render again. Returns the thread time they rendered while paused
    /// (boards begun before the pause and finished during it), or `None` when some worker
    /// was not paused or did not say (unreachable, too slow, a worker without the call, or
    /// an answer that is not a time).
    pub fn resume(self) -> Option<Duration> {
        drop(self.decoding);
        let Some(runtime) = self.runtime else {
            return Some(Duration::ZERO);
        };
        let ended: Vec<_> = self
            .held
            .into_iter()
            .map(|HeldPause { end, mut events }| {
                runtime.spawn(async move {
                    drop(end); // the end of this node's side resumes the worker
                    let last = tokio::time::timeout(ANSWER_WAIT, events.message()).await;
                    match last {
                        Ok(Ok(Some(event))) if event.resumed => {
                            Duration::try_from_secs_f64(event.seconds_rendered).ok()
                        }
                        _ => None,
                    }
                })
            })
            .collect();
        let rendered: Vec<Option<Duration>> = runtime.block_on(async {
            let mut rendered = Vec::new();
            for call in ended {
                rendered.push(call.await.ok().flatten());
            }
            rendered
        });
        let total = rendered.into_iter().sum::<Option<Duration>>()?;
        (!self.incomplete).then_some(total)
    }
}

/// Opens a `Pause` call to one worker and waits until it says it is paused (`Some` with
/// `false` when its boards still ran at its limit).
async fn pause_one(mut client: Client) -> Option<(HeldPause, bool)> {
    let (end, controls) = tokio::sync::mpsc::channel(1);
    let limit = proto::PauseControl {
        max_milliseconds: PAUSE_LIMIT.as_millis() as u32,
    };
    end.send(limit).await.ok()?;
    let began = tokio::time::Instant::now();
    let call = client.pause(tokio_stream::wrappers::ReceiverStream::new(controls));
    let mut events = tokio::time::timeout(ANSWER_WAIT, call)
        .await
        .ok()?
        .ok()?
        .into_inner();
    let first = tokio::time::timeout_at(began + PAUSE_WAIT, events.message());
    let paused = first.await.ok()?.ok()??.paused;
    Some((HeldPause { end, events }, paused))
}

/// What connecting to one more worker needs: the scheme, the token and TLS settings.
#[derive(Clone)]
struct Dialer {
    scheme: &'static str,
    token: Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>,
    tls: Option<tonic::transport::ClientTlsConfig>,
}

impl Workers {
    /// Starts `count` workers in this process, each on its own loopback port, each rendering
    /// with `threads` threads.
    pub fn start_local(count: usize, threads: usize) -> anyhow::Result<Workers> {
        anyhow::ensure!(count > 0, "--local-workers must be at least 1");
        let runtime = runtime()?;
        let mut addresses = Vec::new();
        let mut stop_local = Vec::new();
        for _ in 0..count {
            let listener = runtime
                .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
                .context("binding a loopback port for a local worker")?;
            addresses.push(format!("http://{}", listener.local_addr()?));
            // They stand in for other machines: the renderer's CPU comes first.
            let service = backend::WorkerService::new(backend::WorkerConfig {
                threads: threads.max(1),
                background: true,
                ..backend::WorkerConfig::default()
            })?;
            let (stop, stopped) = oneshot::channel::<()>();
            stop_local.push(stop);
            runtime.spawn(async move {
                let shutdown = async {
                    let _ = stopped.await;
                };
                if let Err(error) =
                    backend::serve(listener, service, backend::Security::default(), shutdown).await
                {
                    eprintln!("local worker stopped: {error:#}");
                }
            });
        }
        let dialer = Dialer::new(&Credentials::default())?;
        let clients = runtime.block_on(async { dialer.connect_all(&addresses) })?;
        Ok(Workers {
            runtime,
            clients,
            addresses,
            deadlines: Deadlines::default(),
            stop_local,
            dialer,
            membership: None,
            stop_following: Arc::default(),
            decoding: Arc::default(),
        })
    }

    /// Pauses the workers `in_use` names while the node measures itself off the clock, in
    /// this process or not, through their `Pause` calls: all at once, then returns once they
    /// have finished the boards they were rendering (each must answer within [`ANSWER_WAIT`]
    /// and is waited for at most [`PAUSE_WAIT`]; one that was not paused in time makes the
    /// pause incomplete). This node's calls decode no board until the pause ends (those
    /// decoding finish first).
    pub fn pause(&self, in_use: impl Fn(usize) -> bool) -> WorkersPause {
        let decoding = self.runtime.block_on(self.decoding.clone().write_owned());
        let calls: Vec<_> = self
            .clients
            .iter()
            .enumerate()
            .filter(|(worker, _)| in_use(*worker))
            .map(|(_, client)| self.runtime.spawn(pause_one(client.clone())))
            .collect();
        let mut pause = WorkersPause {
            runtime: Some(self.runtime.clone()),
            held: Vec::new(),
            incomplete: false,
            decoding: Some(decoding),
        };
        self.runtime.block_on(async {
            for call in calls {
                match call.await.ok().flatten() {
                    Some((held, paused)) => {
                        pause.held.push(held);
                        pause.incomplete |= !paused;
                    }
                    None => pause.incomplete = true,
                }
            }
        });
        pause
    }

    /// Connects to running workers (`host:port`, `http://host:port` or `https://host:port`).
    pub fn connect(addresses: &[String], credentials: &Credentials) -> anyhow::Result<Workers> {
        anyhow::ensure!(!addresses.is_empty(), "no worker addresses given");
        let runtime = runtime()?;
        let dialer = Dialer::new(credentials)?;
        let addresses: Vec<String> = addresses.iter().map(|a| dialer.url(a)).collect();
        let clients = runtime.block_on(async { dialer.connect_all(&addresses) })?;
        Ok(Workers {
            runtime,
            clients,
            addresses,
            deadlines: Deadlines::default(),
            stop_local: Vec::new(),
            dialer,
            membership: None,
            stop_following: Arc::default(),
            decoding: Arc::default(),
        })
    }

    /// Follows a changing set of workers: every `every`, `members` lists the addresses that
    /// should be used now (a DNS name re-resolved, [`resolve_all`]); each change is applied by
    /// the frame loop ([`BoardRequests::poll`]): new addresses join (their objects are stored
    /// first), missing ones are forgotten. A failed listing changes nothing (a DNS hiccup must
    /// not drop the whole cluster).
    pub fn follow(
        &mut self,
        mut members: impl FnMut() -> anyhow::Result<Vec<String>> + Send + 'static,
        every: Duration,
    ) {
        let (sender, receiver) = mpsc::channel();
        let dialer = self.dialer.clone();
        let stop = self.stop_following.clone();
        let mut last: Vec<String> = self.addresses.clone();
        last.sort();
        std::thread::Builder::new()
            .name("membership".into())
            .spawn(move || {
                let mut complained = false;
                loop {
                    std::thread::sleep(every);
                    if stop.load(std::sync::atomic::Ordering::Acquire) {
                        return;
                    }
                    match members() {
                        Ok(listed) => {
                            complained = false;
                            let mut now: Vec<String> =
                                listed.iter().map(|a| dialer.url(a)).collect();
                            now.sort();
                            now.dedup();
                            if now != last {
                                last = now.clone();
                                if sender.send((Instant::now(), now)).is_err() {
                                    return; // the requests are gone
                                }
                            }
                        }
                        Err(error) if !complained => {
                            complained = true;
                            eprintln!(
                                "listing workers failed, keeping the current ones: {error:#}"
                            );
                        }
                        Err(_) => {}
                    }
                }
            })
            .expect("spawning the membership thread");
        self.membership = Some(receiver);
    }

    /// The sets of addresses [`Workers::follow`] listed since last asked, oldest first, each
    /// with when it was listed.
    fn membership_changes(&self) -> Vec<(Instant, Vec<String>)> {
        self.membership
            .as_ref()
            .map_or_else(Vec::new, |changes| changes.try_iter().collect())
    }

    /// Connects to one more worker (lazily, like the others); returns its index.
    fn add(&mut self, address: &str) -> anyhow::Result<u32> {
        let address = self.dialer.url(address);
        // The channel's background task needs the runtime.
        let _runtime = self.runtime.enter();
        let client = self.dialer.connect(&address)?;
        self.clients.push(client);
        self.addresses.push(address);
        Ok(self.clients.len() as u32 - 1)
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
        let deadline = self.deadlines.store;
        // Uploads in flight to each worker. More than a worker admits at once would wait
        // there with their first chunks unread, and on one HTTP/2 connection their unread
        // data can use up the connection's flow-control window and stall the uploads being
        // served: one worker alone then timed out storing a 2 M-triangle forest.
        let mut per_worker = vec![0usize; self.clients.len()];
        self.runtime.block_on(async {
            let mut uploads = tokio::task::JoinSet::new();
            let record =
                |failed: &mut HashMap<u32, String>,
                 per_worker: &mut Vec<usize>,
                 done: Result<(u32, Result<(), String>), tokio::task::JoinError>| {
                    if let Ok((worker, result)) = done {
                        per_worker[worker as usize] -= 1;
                        if let Err(error) = result {
                            failed.entry(worker).or_insert(error);
                        }
                    }
                    progress.inc(1);
                };
            for &(id, object) in objects {
                let chunks = proto::object_to_chunks(id, object);
                for &worker in placement.replicas(id).unwrap_or(&[]) {
                    // A worker that already failed gets nothing more: one dead worker must not
                    // cost a deadline per object.
                    if failed.contains_key(&worker) {
                        progress.inc(1);
                        continue;
                    }
                    while per_worker[worker as usize] >= UPLOADS_PER_WORKER {
                        // None only if an upload task panicked and lost its count.
                        let Some(done) = uploads.join_next().await else {
                            break;
                        };
                        record(&mut failed, &mut per_worker, done);
                    }
                    per_worker[worker as usize] += 1;
                    let client = self.clients[worker as usize].clone();
                    let chunks = chunks.clone();
                    uploads
                        .spawn(async move { (worker, store_one(client, chunks, deadline).await) });
                }
                // Bounded: at most a few objects' chunks in memory at once.
                while uploads.len() >= 8 {
                    if let Some(done) = uploads.join_next().await {
                        record(&mut failed, &mut per_worker, done);
                    }
                }
            }
            while let Some(done) = uploads.join_next().await {
                record(&mut failed, &mut per_worker, done);
            }
        });
        let mut failed: Vec<(u32, String)> = failed.into_iter().collect();
        failed.sort_unstable_by_key(|(w, _)| *w);
        failed
    }

    /// Waits until the workers have built the simplified levels of what they store (they do
    /// it after each store has answered; boards render from the full mesh meanwhile), so the
    /// first frames are drawn with boards as fast as the later ones. Workers that do not
    /// answer are not waited for; nor is any after `deadlines.store` without progress.
    pub fn until_simplified(&self, progress: &indicatif::ProgressBar) {
        let left = |workers: &Workers| -> u64 {
            workers.runtime.block_on(async {
                let mut left = 0;
                for client in &workers.clients {
                    let mut client = client.clone();
                    let status = tokio::time::timeout(
                        workers.deadlines.probe_timeout,
                        client.status(proto::StatusRequest {}),
                    )
                    .await;
                    if let Ok(Ok(status)) = status {
                        left += u64::from(status.into_inner().objects_simplifying);
                    }
                }
                left
            })
        };
        let mut remaining = left(self);
        progress.set_length(remaining);
        progress.set_position(0);
        progress.set_message("workers simplifying objects");
        let mut progressed = Instant::now();
        while remaining > 0 && progressed.elapsed() < self.deadlines.store {
            std::thread::sleep(Duration::from_millis(100));
            let now = left(self);
            if now < remaining {
                progress.inc(remaining - now);
                progressed = Instant::now();
            }
            remaining = now;
        }
    }
}

/// Stores one object's chunks on one worker within `deadline`.
async fn store_one(
    mut client: Client,
    chunks: Vec<proto::ObjectChunk>,
    deadline: Duration,
) -> Result<(), String> {
    match tokio::time::timeout(deadline, client.store_object(tokio_stream::iter(chunks))).await {
        Ok(Ok(_)) => Ok(()),
        Ok(Err(status)) => Err(format!("{}: {}", status.code(), status.message())),
        Err(_) => Err(format!("storing took over {deadline:?}")),
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        self.stop_following
            .store(true, std::sync::atomic::Ordering::Release);
        for stop in self.stop_local.drain(..) {
            let _ = stop.send(());
        }
    }
}

fn runtime() -> anyhow::Result<Arc<tokio::runtime::Runtime>> {
    Ok(Arc::new(
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("requests")
            // Calls, decoding boards and building their grids: the frame comes first, so
            // on a machine whose CPU also draws (lavapipe) boards are made ready in the time
            // the renderer leaves.
            .on_thread_start(backend::lowest_cpu_priority)
            .enable_all()
            .build()?,
    ))
}

/// Resolves `host:port` to every address the name has (a headless Kubernetes Service or a
/// scaled compose service resolves to one address per worker).
pub fn resolve_all(name: &str) -> anyhow::Result<Vec<String>> {
    use std::net::ToSocketAddrs;
    let mut addresses: Vec<String> = name
        .to_socket_addrs()
        .with_context(|| format!("resolving workers at {name:?} (expected host:port)"))?
        .map(|a| a.to_string())
        .collect();
    addresses.sort();
    addresses.dedup();
    anyhow::ensure!(!addresses.is_empty(), "{name:?} resolves to no address");
    Ok(addresses)
}

impl Dialer {
    fn new(credentials: &Credentials) -> anyhow::Result<Dialer> {
        let token = credentials
            .token
            .as_ref()
            .map(|t| {
                format!("Bearer {t}")
                    .parse()
                    .context("the token must be printable ASCII")
            })
            .transpose()?;
        let tls = tls_config(credentials)?;
        Ok(Dialer {
            scheme: if tls.is_some() { "https" } else { "http" },
            token,
            tls,
        })
    }

    /// `host:port` with this node's scheme; an address with a scheme stays as it is.
    fn url(&self, address: &str) -> String {
        if address.contains("://") {
            address.to_string()
        } else {
            format!("{}://{address}", self.scheme)
        }
    }

    /// Channels that connect on first use (and reconnect after a failure), so one
    /// unreachable worker does not stop the others.
    fn connect_all(&self, addresses: &[String]) -> anyhow::Result<Vec<Client>> {
        addresses.iter().map(|a| self.connect(a)).collect()
    }

    fn connect(&self, address: &str) -> anyhow::Result<Client> {
        let mut endpoint = Channel::from_shared(address.to_string())
            .with_context(|| format!("{address:?} is not a worker address"))?
            .connect_timeout(Duration::from_secs(2))
            .tcp_nodelay(true);
        if let Some(tls) = &self.tls {
            endpoint = endpoint
                .tls_config(tls.clone())
                .with_context(|| format!("TLS for {address}"))?;
        }
        Ok(WorkerClient::with_interceptor(
            endpoint.connect_lazy(),
            Authorization(self.token.clone()),
        )
        .max_decoding_message_size(backend::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(backend::MAX_MESSAGE_BYTES))
    }
}

fn tls_config(
    credentials: &Credentials,
) -> anyhow::Result<Option<tonic::transport::ClientTlsConfig>> {
    let Some(ca) = &credentials.tls_ca else {
        anyhow::ensure!(
            credentials.tls_identity.is_none(),
            "a client certificate needs --tls-ca too"
        );
        return Ok(None);
    };
    let read =
        |path: &PathBuf| std::fs::read(path).with_context(|| format!("reading {}", path.display()));
    let mut tls = tonic::transport::ClientTlsConfig::new()
        .ca_certificate(tonic::transport::Certificate::from_pem(read(ca)?));
    if let Some((cert, key)) = &credentials.tls_identity {
        tls = tls.identity(tonic::transport::Identity::from_pem(
            read(cert)?,
            read(key)?,
        ));
    }
    if let Some(domain) = &credentials.tls_domain {
        tls = tls.domain_name(domain.clone());
    }
    Ok(Some(tls))
}

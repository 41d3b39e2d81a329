//! Cross-crate integration tests live in `tests/tests/`; this library holds what several of
//! them share: the workspace's binaries, small scenes, a worker served in this process and
//! requests to it.

use std::path::PathBuf;

use backend::{WorkerConfig, WorkerService};
use proto::{
    ObjectChunk, PauseControl, RenderRequest, StatusRequest, StoreReply, Worker, WorkerStatus,
};
use tonic::{Request, Response, Status, Streaming};

/// A binary of this workspace (`backend`, `visnode`), built beside the test executables:
/// `cargo test --workspace` builds them, since their crates have integration tests.
pub fn workspace_binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    // target/<profile>/deps/<test> → target/<profile>/<name>
    let path = exe
        .parent()
        .and_then(|deps| deps.parent())
        .map(|profile| profile.join(name))
        .expect("a target directory");
    assert!(
        path.exists(),
        "{} is not built: run `cargo build -p {name}` (or `cargo test --workspace`, which builds it)",
        path.display()
    );
    path
}

/// `count` small objects (a few hundred triangles each) in a row along x.
pub fn small_objects(count: usize, triangles_each: usize) -> Vec<scene::Object> {
    let rings = (triangles_each / 16).clamp(2, 64);
    (0..count)
        .map(|i| {
            let mut builder = scene::ObjectBuilder::new(format!("blob-{i}"));
            // A bumpy sphere: rings × 8 segments.
            let segments = 8;
            let center = glam::DVec3::new(i as f64 * 3.0, 0.0, 0.0);
            let mut index = Vec::new();
            for ring in 0..=rings {
                let theta = std::f64::consts::PI * ring as f64 / rings as f64;
                for segment in 0..segments {
                    let phi = std::f64::consts::TAU * segment as f64 / segments as f64;
                    let radius = 1.0 + 0.15 * ((ring + segment + i) % 3) as f64;
                    let p = center
                        + radius
                            * glam::DVec3::new(
                                theta.sin() * phi.cos(),
                                theta.cos(),
                                theta.sin() * phi.sin(),
                            );
                    let shade = (60 + (ring * 20) % 190) as u8;
                    index.push(builder.vertex(p, [shade, 180, 90, 255]));
                }
            }
            for ring in 0..rings {
                for segment in 0..segments {
                    let a = index[ring * segments + segment];
                    let b = index[ring * segments + (segment + 1) % segments];
                    let c = index[(ring + 1) * segments + segment];
                    let d = index[(ring + 1) * segments + (segment + 1) % segments];
                    builder.triangle(a, c, b);
                    builder.triangle(b, c, d);
                }
            }
            builder.finish().0
        })
        .collect()
}

/// `testdata/NAME`: the small real meshes kept in the repository.
pub fn test_mesh(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../testdata")
        .join(name)
}

/// A board's chunks as a worker streams them: boxed, so a misbehaving worker may answer with
/// a stream of its own.
pub type BoardStream = <WorkerService as Worker>::RenderStream;
/// A pause's events as a worker streams them, likewise boxed.
pub type PauseStream = <WorkerService as Worker>::PauseStream;

/// How a test's worker departs from a real one (`worker`): each call it does not override
/// reaches the real worker as it came, so a test writes only the call it is about.
#[tonic::async_trait]
pub trait Misbehaviour: Send + Sync + 'static {
    async fn store_object(
        &self,
        worker: &WorkerService,
        request: Request<Streaming<ObjectChunk>>,
    ) -> Result<Response<StoreReply>, Status> {
        worker.store_object(request).await
    }

    async fn render(
        &self,
        worker: &WorkerService,
        request: Request<RenderRequest>,
    ) -> Result<Response<BoardStream>, Status> {
        worker.render(request).await
    }

    async fn pause(
        &self,
        worker: &WorkerService,
        request: Request<Streaming<PauseControl>>,
    ) -> Result<Response<PauseStream>, Status> {
        worker.pause(request).await
    }

    async fn status(
        &self,
        worker: &WorkerService,
        request: Request<StatusRequest>,
    ) -> Result<Response<WorkerStatus>, Status> {
        worker.status(request).await
    }
}

/// A real worker on one thread that misbehaves as `misbehaviour` says.
struct Misbehaving<M> {
    worker: WorkerService,
    misbehaviour: M,
}

#[tonic::async_trait]
impl<M: Misbehaviour> Worker for Misbehaving<M> {
    async fn store_object(
        &self,
        request: Request<Streaming<ObjectChunk>>,
    ) -> Result<Response<StoreReply>, Status> {
        self.misbehaviour.store_object(&self.worker, request).await
    }

    type RenderStream = BoardStream;

    async fn render(
        &self,
        request: Request<RenderRequest>,
    ) -> Result<Response<BoardStream>, Status> {
        self.misbehaviour.render(&self.worker, request).await
    }

    type PauseStream = PauseStream;

    async fn pause(
        &self,
        request: Request<Streaming<PauseControl>>,
    ) -> Result<Response<PauseStream>, Status> {
        self.misbehaviour.pause(&self.worker, request).await
    }

    async fn status(
        &self,
        request: Request<StatusRequest>,
    ) -> Result<Response<WorkerStatus>, Status> {
        self.misbehaviour.status(&self.worker, request).await
    }
}

/// Serves a real worker of one thread that misbehaves as `misbehaviour` says on a loopback
/// port, on a runtime of its own; returns its address and the runtime, which stops it when
/// dropped.
pub fn serve_misbehaving(misbehaviour: impl Misbehaviour) -> (String, tokio::runtime::Runtime) {
    let worker = WorkerService::new(WorkerConfig {
        threads: 1,
        ..WorkerConfig::default()
    })
    .expect("a worker of one thread");
    let service = Misbehaving {
        worker,
        misbehaviour,
    };
    let runtime = tokio::runtime::Runtime::new().expect("a tokio runtime");
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .expect("a loopback port");
    let address = format!("http://{}", listener.local_addr().expect("its address"));
    runtime.spawn(
        tonic::transport::Server::builder()
            .add_service(
                proto::WorkerServer::new(service)
                    .max_decoding_message_size(backend::MAX_MESSAGE_BYTES)
                    .max_encoding_message_size(backend::MAX_MESSAGE_BYTES),
            )
            .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)),
    );
    (address, runtime)
}

/// Board requests over the one worker at `address`, which stores every object: small relief
/// boards (8 cells), under `deadlines`.
pub fn requests_on_one_worker(
    address: String,
    objects: Vec<scene::Object>,
    deadlines: visnode::workers::Deadlines,
) -> visnode::workers::BoardRequests {
    let credentials = visnode::workers::Credentials::default();
    let mut workers =
        visnode::workers::Workers::connect(&[address], &credentials).expect("a worker address");
    workers.deadlines = deadlines;
    let suitable = vec![true; objects.len()];
    visnode::setup::requests_on(
        workers,
        &std::sync::Arc::new(objects),
        &suitable,
        1,
        visnode::board::BoardShape::Relief {
            grid_cells: 8,
            cell_pixels: 1,
        },
        false,
        &indicatif::ProgressBar::hidden(),
    )
    .expect("the worker stores the objects")
}

/// A 64-pixel board of each of the first `count` objects, all seen along one direction.
pub fn wanted_boards(count: u32) -> Vec<visnode::plan::WantedBoard> {
    (0..count)
        .map(|object| visnode::plan::WantedBoard {
            object,
            direction: glam::DVec3::new(0.3, -0.2, 1.0).normalize(),
            size: 64,
            priority: 1.0,
        })
        .collect()
}

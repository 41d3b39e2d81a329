//! A real worker on loopback: store objects, render concurrently, and the error statuses.

mod common;

use std::time::Duration;

use backend::{EncodedBoard, WorkerConfig, WorkerService};
use common::client;
use glam::DVec3;
use proto::{PauseControl, PauseEvent, RenderRequest, StatusRequest, WorkerClient, WorkerStatus};
use tokio::sync::oneshot;
use tonic::Code;

/// Starts a worker on a free loopback port; dropping the sender shuts it down.
async fn start(config: WorkerConfig) -> (String, oneshot::Sender<()>, tokio::task::JoinHandle<()>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = format!("http://{}", listener.local_addr().unwrap());
    let (stop, stopped) = oneshot::channel::<()>();
    let service = WorkerService::new(config).unwrap();
    let handle = tokio::spawn(async move {
        backend::serve(listener, service, backend::Security::default(), async {
            let _ = stopped.await;
        })
        .await
        .unwrap();
    });
    (address, stop, handle)
}

/// A sphere whose colours vary from vertex to vertex (a hash), so a large board barely
/// compresses.
fn sphere(n: u32) -> scene::Object {
    common::coloured_sphere(n, |ring, s| {
        let hash = (ring * 7919 + s * 104_729).wrapping_mul(2_654_435_761);
        [
            (hash >> 24) as u8,
            (hash >> 16) as u8,
            (hash >> 8) as u8,
            255,
        ]
    })
}

async fn store(
    client: &mut WorkerClient<tonic::transport::Channel>,
    id: u32,
    object: &scene::Object,
) -> Result<u64, tonic::Status> {
    let chunks = proto::object_to_chunks(id, object);
    Ok(client
        .store_object(tokio_stream::iter(chunks))
        .await?
        .into_inner()
        .triangles)
}

/// Waits until the worker has built the levels of every object it holds: its boards come from
/// them from then on.
async fn until_simplified(client: &mut WorkerClient<tonic::transport::Channel>) {
    for _ in 0..1200 {
        let status = client.status(StatusRequest {}).await.unwrap().into_inner();
        if status.objects_simplifying == 0 {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the worker did not build its levels within a minute");
}

/// Asks `client` for its status, a few milliseconds apart, until `done` says so.
async fn wait_for_status(
    client: &WorkerClient<tonic::transport::Channel>,
    done: impl Fn(&WorkerStatus) -> bool,
) {
    let mut client = client.clone();
    while !done(&client.status(StatusRequest {}).await.unwrap().into_inner()) {
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

/// Renders and reassembles a board.
async fn render(
    client: &mut WorkerClient<tonic::transport::Channel>,
    object: u32,
    dir: [f64; 3],
    size: u32,
) -> Result<backend::Maps, tonic::Status> {
    Ok(render_bytes(client, object, dir, size).await?.0)
}

/// Renders a board; also returns its encoded size.
async fn render_bytes(
    client: &mut WorkerClient<tonic::transport::Channel>,
    object: u32,
    dir: [f64; 3],
    size: u32,
) -> Result<(backend::Maps, usize), tonic::Status> {
    let request = RenderRequest {
        object_id: object,
        dir_x: dir[0],
        dir_y: dir[1],
        dir_z: dir[2],
        size,
        priority: 0.0,
    };
    let mut stream = client.render(request).await?.into_inner();
    let mut bytes = Vec::new();
    let mut declared = None;
    while let Some(chunk) = stream.message().await? {
        if declared.is_none() {
            declared = Some(chunk.total_bytes);
        }
        bytes.extend_from_slice(&chunk.data);
    }
    assert_eq!(Some(bytes.len() as u64), declared, "every chunk arrived");
    let length = bytes.len();
    Ok((
        EncodedBoard { bytes }
            .decode()
            .expect("a worker's board decodes"),
        length,
    ))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stores_objects_and_renders_boards_for_several_clients_at_once() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 2,
        max_map_size: 2048,
        ..WorkerConfig::default()
    })
    .await;
    let mut first = client(&address).await;
    let bunny = scene::load_file(
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../testdata/bunny.ply"
        )),
        &Default::default(),
    )
    .unwrap();
    assert_eq!(store(&mut first, 7, &bunny.objects[0]).await.unwrap(), 3674);
    // A sphere of 2 million triangles: its chunks add up to far more than 4 MiB.
    let big = sphere(1024);
    assert_eq!(
        store(&mut first, 8, &big).await.unwrap(),
        big.triangles.len() as u64
    );
    until_simplified(&mut first).await;

    // The same board locally, from the levels a worker builds, to compare with what comes
    // over the wire.
    let local = backend::render_maps(
        &backend::PreparedObject::new(&bunny.objects[0])
            .unwrap()
            .with_levels(),
        DVec3::new(0.0, 0.0, -1.0),
        128,
        1,
    )
    .unwrap();
    let mut tasks = Vec::new();
    for k in 0..6u32 {
        let address = address.clone();
        tasks.push(tokio::spawn(async move {
            let mut c = client(&address).await;
            let maps = render(&mut c, 7, [0.0, 0.0, -1.0], 128).await.unwrap();
            let other = render(&mut c, 8, [1.0, k as f64, 0.5], 64).await.unwrap();
            (maps, other.covered())
        }));
    }
    for task in tasks {
        let (maps, covered) = task.await.unwrap();
        assert_eq!(
            maps.stencil, local.stencil,
            "the wire board shows what the local renderer shows"
        );
        assert!(covered > 1000);
    }
    // A 2048² board of a colourful sphere encodes to more than tonic's 4 MiB default: it
    // still arrives, in chunks.
    let (large, bytes) = render_bytes(&mut first, 8, [0.2, 0.1, -1.0], 2048)
        .await
        .unwrap();
    assert!(large.covered() > 1_000_000);
    assert!(bytes > 4 << 20, "{bytes} bytes");
    let status = first.status(StatusRequest {}).await.unwrap().into_inner();
    assert_eq!(status.objects, 2);
    assert_eq!(status.boards_rendered, 13);
    assert_eq!(status.queue_length, 0);
    assert!(status.triangles_per_second > 0.0);
    // One process, one instance number; another worker process has another.
    let again = first.status(StatusRequest {}).await.unwrap().into_inner();
    assert_ne!(status.instance, 0);
    assert_eq!(again.instance, status.instance);
    let (other_address, other_stop, other_handle) = start(WorkerConfig::default()).await;
    let other = client(&other_address)
        .await
        .status(StatusRequest {})
        .await
        .unwrap()
        .into_inner();
    assert_ne!(other.instance, status.instance);
    let _ = other_stop.send(());
    other_handle.await.unwrap();

    // Standard health checking answers SERVING.
    let channel = tonic::transport::Channel::from_shared(address.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
    let reply = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: "reliefboard.v1.Worker".into(),
        })
        .await
        .unwrap();
    assert_eq!(
        reply.into_inner().status,
        tonic_health::pb::health_check_response::ServingStatus::Serving as i32
    );
    drop(stop);
    handle.await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_answers_before_the_levels_are_built_and_boards_use_them_once_they_are() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    // Two million triangles: two seconds of simplification after the store has answered.
    // Stored twice: object 2's levels are built first, so object 1 waits for them too.
    let big = sphere(1024);
    store(&mut c, 2, &big).await.unwrap();
    store(&mut c, 1, &big).await.unwrap();
    let status = c.status(StatusRequest {}).await.unwrap().into_inner();
    assert_eq!(status.objects, 2);
    assert!(status.objects_simplifying >= 1);
    // Meanwhile a board renders from the full mesh.
    let direction = DVec3::new(0.3, -0.2, -1.0);
    let full = backend::PreparedObject::new(&big).unwrap();
    let early = render(&mut c, 1, direction.to_array(), 64).await.unwrap();
    // What the worker sends: depth quantised to 16 bits.
    let as_sent = |maps: &backend::Maps| EncodedBoard::encode(maps).decode().unwrap();
    // Uncovered pixels have NaN depth: compared by their bits.
    let same_depth = |a: &backend::Maps, b: &backend::Maps| {
        a.depth
            .iter()
            .map(|d| d.to_bits())
            .eq(b.depth.iter().map(|d| d.to_bits()))
    };
    let local_full = as_sent(&backend::render_maps(&full, direction, 64, 1).unwrap());
    assert_eq!(early.stencil, local_full.stencil);
    assert!(
        same_depth(&early, &local_full),
        "the early board is the full mesh's"
    );
    // Then the levels are built, and the same request renders from the coarsest level
    // within half a pixel at 64 pixels: another board, fewer than a tenth of the triangles.
    until_simplified(&mut c).await;
    let simplified = full.with_levels();
    assert!(simplified.mesh_for_size(64).triangles.len() * 10 < big.triangles.len());
    let late = render(&mut c, 1, direction.to_array(), 64).await.unwrap();
    let local_level = as_sent(&backend::render_maps(&simplified, direction, 64, 1).unwrap());
    assert!(
        same_depth(&late, &local_level),
        "the late board is the level's"
    );
    assert!(!same_depth(&late, &early));
    drop(stop);
    handle.await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_get_the_right_status() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        max_map_size: 512,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(32)).await.unwrap();
    let code = |r: Result<backend::Maps, tonic::Status>| r.err().map(|s| s.code());
    assert_eq!(
        code(render(&mut c, 99, [0.0, 0.0, 1.0], 64).await),
        Some(Code::NotFound)
    );
    assert_eq!(
        code(render(&mut c, 1, [0.0, 0.0, 0.0], 64).await),
        Some(Code::InvalidArgument)
    );
    assert_eq!(
        code(render(&mut c, 1, [f64::NAN, 0.0, 1.0], 64).await),
        Some(Code::InvalidArgument)
    );
    assert_eq!(
        code(render(&mut c, 1, [0.0, 0.0, 1.0], 0).await),
        Some(Code::InvalidArgument)
    );
    assert_eq!(
        code(render(&mut c, 1, [0.0, 0.0, 1.0], 513).await),
        Some(Code::InvalidArgument)
    );
    // Malformed objects: an index out of range, and chunks that stop short of the header.
    let mut broken = sphere(8);
    broken.triangles[0][1] = 10_000;
    assert_eq!(
        store(&mut c, 2, &broken).await.unwrap_err().code(),
        Code::InvalidArgument
    );
    let mut chunks = proto::object_to_chunks(3, &sphere(8));
    chunks.pop();
    assert_eq!(
        c.store_object(tokio_stream::iter(chunks))
            .await
            .unwrap_err()
            .code(),
        Code::InvalidArgument
    );
    // The worker still serves after all that.
    assert!(render(&mut c, 1, [0.0, 0.0, 1.0], 64).await.is_ok());
    drop(stop);
    handle.await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_queue_refuses_and_never_drops_what_it_accepted() {
    // One queue slot and a slow worker: of several simultaneous requests, some are refused
    // at once with RESOURCE_EXHAUSTED; every accepted one completes.
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        queue_capacity: 1,
        slowdown: 40.0,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(256)).await.unwrap();
    let mut tasks = Vec::new();
    for _ in 0..5 {
        let address = address.clone();
        tasks.push(tokio::spawn(async move {
            render(&mut client(&address).await, 1, [0.0, 1.0, 1.0], 256).await
        }));
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let (mut done, mut refused) = (0, 0);
    for task in tasks {
        match task.await.unwrap() {
            Ok(maps) => {
                assert!(maps.covered() > 0);
                done += 1;
            }
            Err(status) => {
                assert_eq!(status.code(), Code::ResourceExhausted, "{status}");
                refused += 1;
            }
        }
    }
    assert!(done >= 1 && refused >= 1, "{done} done, {refused} refused");
    drop(stop);
    handle.await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn limits_and_shutdown_answer_with_their_statuses() {
    // Objects above the element limit or the memory limit are refused before being stored.
    let config = WorkerConfig {
        threads: 1,
        max_object_elements: 1_000,
        // A sphere(16) with its levels fits, a sphere(20) does not.
        memory_limit_bytes: 16_000,
        ..WorkerConfig::default()
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = format!("http://{}", listener.local_addr().unwrap());
    let service = WorkerService::new(config).unwrap();
    let handle_on_service = service.clone();
    let (stop, stopped) = oneshot::channel::<()>();
    let server = tokio::spawn(backend::serve(
        listener,
        service,
        backend::Security::default(),
        async {
            let _ = stopped.await;
        },
    ));
    let mut c = client(&address).await;
    assert_eq!(
        store(&mut c, 1, &sphere(64)).await.unwrap_err().code(),
        Code::ResourceExhausted,
        "over the element limit"
    );
    store(&mut c, 2, &sphere(16)).await.unwrap();
    assert_eq!(
        store(&mut c, 3, &sphere(20)).await.unwrap_err().code(),
        Code::ResourceExhausted,
        "over the memory limit"
    );
    let status = c.status(StatusRequest {}).await.unwrap().into_inner();
    assert_eq!(status.objects, 1);
    assert!(status.memory_bytes > 0 && status.memory_bytes <= 16_000);
    // Once shutdown begins, new work is refused with UNAVAILABLE.
    handle_on_service.begin_shutdown();
    assert_eq!(
        render(&mut c, 2, [0.0, 0.0, 1.0], 32)
            .await
            .unwrap_err()
            .code(),
        Code::Unavailable
    );
    assert_eq!(
        store(&mut c, 4, &sphere(8)).await.unwrap_err().code(),
        Code::Unavailable
    );
    drop(stop);
    server.await.unwrap().unwrap();
}

/// Renders `count` boards of object 1 at once, each from its own client; returns the render
/// time each reply reported (ms) and the wall time of the whole batch (ms).
async fn simultaneous_renders(address: &str, count: usize) -> (Vec<f64>, f64) {
    let started = std::time::Instant::now();
    let tasks: Vec<_> = (0..count)
        .map(|i| {
            let address = address.to_string();
            tokio::spawn(async move {
                let request = RenderRequest {
                    object_id: 1,
                    dir_x: 0.1 * i as f64,
                    dir_y: 1.0,
                    dir_z: 1.0,
                    size: 256,
                    priority: 0.0,
                };
                let mut stream = client(&address)
                    .await
                    .render(request)
                    .await
                    .unwrap()
                    .into_inner();
                let mut reported = 0.0;
                while let Some(chunk) = stream.message().await.unwrap() {
                    reported += chunk.render_milliseconds;
                }
                reported
            })
        })
        .collect();
    let mut reported = Vec::new();
    for task in tasks {
        reported.push(task.await.unwrap());
    }
    (reported, started.elapsed().as_secs_f64() * 1e3)
}

/// The render time a worker reports is the board's own cost, not the time it waited for the
/// render thread behind others (the balancer reads it as the worker's speed: counting the
/// queue made a busy worker look slow). On one thread renders cannot overlap, so the
/// reported times of simultaneous requests add up to at most the batch's wall time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reported_render_times_leave_out_the_queue() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        queue_capacity: 8,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(256)).await.unwrap();
    let (reported, wall_ms) = simultaneous_renders(&address, 6).await;
    let sum: f64 = reported.iter().sum();
    assert!(reported.iter().all(|&ms| ms > 0.0), "{reported:?}");
    assert!(
        sum <= wall_ms,
        "reported {sum:.1} ms in all ({reported:?}) within {wall_ms:.1} ms of wall time"
    );
    drop(stop);
    handle.await.unwrap();
}

/// `--slowdown F` stands in for a machine F times weaker: its throughput drops with its
/// latency. While one board sleeps off its slowdown the next does not start, so simultaneous
/// requests are served one after another (their reported times, slowdown included, add up
/// to at most the wall time), even with two render threads. When the sleeps overlapped, a
/// "weak" worker served four boards in about the time of one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slowed_worker_serves_one_board_at_a_time() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 2,
        queue_capacity: 8,
        slowdown: 10.0,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(256)).await.unwrap();
    let (reported, wall_ms) = simultaneous_renders(&address, 4).await;
    let sum: f64 = reported.iter().sum();
    assert!(
        sum <= wall_ms,
        "reported {sum:.1} ms in all ({reported:?}) within {wall_ms:.1} ms of wall time"
    );
    drop(stop);
    handle.await.unwrap();
}

/// A worker serves its queue in the order of the node's priorities, not of arrival, and a
/// call the node cancels (its stream reset: the object left the view, or the view moved past
/// the board) is dropped before it renders. One render thread is held by a slow board while
/// the others queue.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_queue_serves_priority_first_and_drops_cancelled_calls() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        queue_capacity: 8,
        slowdown: 40.0,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(256)).await.unwrap();
    // Each call gets its own connection (a call's cancellation resets its stream), made
    // before the slow board starts: connecting on a loaded machine took long enough that the
    // slow board had ended, and the thread had taken the call meant to be cancelled, before
    // the test could cancel it.
    let mut connections = Vec::new();
    for _ in 0..5 {
        connections.push(client(&address).await);
    }
    let mut call = |size: u32, priority: f64| {
        let mut connection = connections.pop().unwrap();
        async move {
            let request = RenderRequest {
                object_id: 1,
                dir_x: 0.3,
                dir_y: 1.0,
                dir_z: 1.0,
                size,
                priority,
            };
            let mut stream = connection.render(request).await.unwrap().into_inner();
            while stream.message().await.unwrap().is_some() {}
        }
    };
    // The slow board takes the one thread (40 times its render time). The queued boards are
    // large enough that each takes a while too: the order is read from when their answers
    // arrive, so they must end far apart (64-pixel boards, drawn from a coarse level, ended
    // within milliseconds of each other and arrived out of order on a loaded CI machine).
    let holding = tokio::spawn(call(1024, 0.0));
    wait_for_status(&c, |s| s.queue_length == 1).await;
    // Taken by the thread, not only queued: the boards below must queue behind it.
    wait_for_status(&c, |s| s.boards_rendering > 0).await;
    let finished = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let mut waiting = Vec::new();
    for priority in [1.0, 5.0, 3.0] {
        let finished = finished.clone();
        let board = call(256, priority);
        waiting.push(tokio::spawn(async move {
            board.await;
            finished.lock().unwrap().push(priority);
        }));
    }
    let cancelled = tokio::spawn(call(256, 10.0));
    wait_for_status(&c, |s| s.queue_length == 5).await;
    cancelled.abort();
    // The worker saw the call go (its future dropped) while the slow board still renders.
    wait_for_status(&c, |s| s.queue_length == 4).await;
    assert!(
        !holding.is_finished(),
        "the slow board ended too early for this test"
    );
    holding.await.unwrap();
    for task in waiting {
        task.await.unwrap();
    }
    assert_eq!(*finished.lock().unwrap(), vec![5.0, 3.0, 1.0]);
    let status = c.status(StatusRequest {}).await.unwrap().into_inner();
    assert_eq!((status.boards_rendered, status.boards_cancelled), (4, 1));
    assert_eq!((status.queue_length, status.outstanding_triangles), (0, 0));
    drop(stop);
    handle.await.unwrap();
}

/// Opens a `Pause` call with `limit_ms`; returns the sender whose drop ends the pause, and
/// the worker's events.
async fn open_pause(
    client: &mut WorkerClient<tonic::transport::Channel>,
    limit_ms: u32,
) -> (
    tokio::sync::mpsc::Sender<PauseControl>,
    tonic::Streaming<PauseEvent>,
) {
    let (end, controls) = tokio::sync::mpsc::channel(1);
    end.send(PauseControl {
        max_milliseconds: limit_ms,
    })
    .await
    .unwrap();
    let events = client
        .pause(tokio_stream::wrappers::ReceiverStream::new(controls))
        .await
        .unwrap()
        .into_inner();
    (end, events)
}

/// A node pauses a worker while it measures itself off the clock: the worker says it is
/// paused only once the board it was rendering is done, starts no board until the node ends
/// the pause, and then says how long that board rendered into the pause. A node that goes
/// away, or outlives the limit it gave, never leaves the worker paused.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_worker_starts_no_board_until_the_node_ends_the_pause_or_goes() {
    let (address, stop, handle) = start(WorkerConfig {
        threads: 1,
        slowdown: 40.0,
        ..WorkerConfig::default()
    })
    .await;
    let mut c = client(&address).await;
    store(&mut c, 1, &sphere(256)).await.unwrap();
    let board = |size: u32| {
        let address = address.clone();
        tokio::spawn(async move {
            let mut c = client(&address).await;
            render(&mut c, 1, [0.3, 1.0, 1.0], size).await.unwrap();
        })
    };
    let running = |c: &WorkerClient<tonic::transport::Channel>| {
        let mut c = c.clone();
        async move { c.status(StatusRequest {}).await.unwrap().into_inner() }
    };
    // The slow board holds the one thread (40 times its render time) when the pause begins:
    // rendering, not only queued (on a loaded machine the thread may not have taken it yet,
    // and a queued board waits out the pause).
    let slow = board(512);
    wait_for_status(&c, |s| s.boards_rendering > 0).await;
    let began = std::time::Instant::now();
    let (end, mut events) = open_pause(&mut c, 60_000).await;
    let paused = events.message().await.unwrap().unwrap();
    let paused_at = std::time::Instant::now();
    assert!(paused.paused && !paused.resumed, "{paused:?}");
    slow.await.unwrap();
    // Asked for during the pause: queued, not started.
    let small = board(32);
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!small.is_finished(), "a board rendered during the pause");
    let status = running(&c).await;
    assert_eq!((status.queue_length, status.boards_rendering), (1, 0));
    drop(end);
    let resumed = events.message().await.unwrap().unwrap();
    assert!(resumed.resumed, "{resumed:?}");
    // The slow board ran from before the pause until the worker said it was paused (had it
    // said so at once, the board would have rendered on for a few hundred milliseconds).
    let into_the_pause = resumed.seconds_rendered;
    assert!(
        into_the_pause > 0.0 && into_the_pause <= (paused_at - began).as_secs_f64() + 0.05,
        "{into_the_pause} s rendered in a pause of {:?} until paused",
        paused_at - began
    );
    assert!(events.message().await.unwrap().is_none(), "the call ends");
    tokio::time::timeout(Duration::from_secs(30), small)
        .await
        .expect("the board asked for in the pause renders after it")
        .unwrap();

    // A node that goes away while it holds a pause: the worker goes on.
    let (end, mut events) = open_pause(&mut c, 60_000).await;
    assert!(events.message().await.unwrap().unwrap().paused);
    drop((end, events));
    tokio::time::timeout(Duration::from_secs(30), board(32))
        .await
        .expect("a pause ends with the node's call")
        .unwrap();

    // A node that holds a pause past its own limit: the worker goes on, and says so.
    let (_end, mut events) = open_pause(&mut c, 200).await;
    assert!(events.message().await.unwrap().unwrap().paused);
    tokio::time::timeout(Duration::from_secs(30), board(32))
        .await
        .expect("a pause ends at its limit")
        .unwrap();
    let resumed = tokio::time::timeout(Duration::from_secs(30), events.message())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    // Nothing was rendering but, at most, the end of the board before (its answer can
    // reach the node before its thread counts it done).
    assert!(
        resumed.resumed && resumed.seconds_rendered < 0.05,
        "{resumed:?}"
    );
    drop(stop);
    handle.await.unwrap();
}

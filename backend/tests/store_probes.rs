//! Preparing a large object leaves the worker answering probes. Its own test binary with a
//! single test: the probe latencies must not share the machine with other tests.

use std::time::{Duration, Instant};

use backend::{WorkerConfig, WorkerService};
use glam::DVec3;
use proto::{StatusRequest, WorkerClient};

/// A worker on its own single-threaded runtime in its own thread: anything that blocks that
/// thread blocks every call to the worker, which is what the probe test must see.
fn start(config: WorkerConfig) -> (String, WorkerService) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let address = format!("http://{}", listener.local_addr().unwrap());
    let service = WorkerService::new(config).unwrap();
    let serving = service.clone();
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async move {
            let listener = tokio::net::TcpListener::from_std(listener).unwrap();
            backend::serve(listener, serving, backend::Security::default(), std::future::pending())
                .await
                .unwrap();
        });
    });
    (address, service)
}

async fn client(address: &str) -> WorkerClient<tonic::transport::Channel> {
    WorkerClient::connect(address.to_string())
        .await
        .unwrap()
        .max_decoding_message_size(backend::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(backend::MAX_MESSAGE_BYTES)
}

/// A UV sphere of `2 n (n / 2)` triangles.
fn sphere(n: u32) -> scene::Object {
    let mut builder = scene::ObjectBuilder::new("sphere");
    let rings = n / 2;
    for ring in 0..=rings {
        let phi = std::f64::consts::PI * ring as f64 / rings as f64;
        for s in 0..n {
            let theta = std::f64::consts::TAU * s as f64 / n as f64;
            let p = DVec3::new(phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin());
            builder.vertex(p, [200, 200, 200, 255]);
        }
    }
    for ring in 0..rings {
        for s in 0..n {
            let at = |r: u32, s: u32| r * n + s % n;
            builder.triangle(at(ring, s), at(ring, s + 1), at(ring + 1, s + 1));
            builder.triangle(at(ring, s), at(ring + 1, s + 1), at(ring + 1, s));
        }
    }
    builder.finish().0
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_storing_two_million_triangles_answers_probes_within_100_ms() {
    let (address, _service) = start(WorkerConfig {
        threads: 1,
        ..WorkerConfig::default()
    });
    let big = sphere(1416);
    assert!(big.triangles.len() >= 2_000_000, "{}", big.triangles.len());
    let chunks = proto::object_to_chunks(1, &big);
    let mut storer = client(&address).await;
    // One call first: a channel's first call pays for setting the connection up (about 45 ms
    // here), which is not what is measured.
    let mut prober = client(&address).await;
    prober.status(StatusRequest {}).await.unwrap();
    let store = tokio::spawn(async move {
        let started = Instant::now();
        let reply = storer.store_object(tokio_stream::iter(chunks)).await;
        (reply.map(|r| r.into_inner().triangles), started.elapsed())
    });
    let mut latencies = Vec::new();
    while !store.is_finished() {
        let sent = Instant::now();
        prober.status(StatusRequest {}).await.unwrap();
        latencies.push(sent.elapsed());
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let (stored, took) = store.await.unwrap();
    assert_eq!(stored.unwrap(), big.triangles.len() as u64);
    let worst = latencies.iter().max().copied().unwrap_or_default();
    eprintln!(
        "store took {took:?}; {} probes meanwhile, the slowest {worst:?}",
        latencies.len()
    );
    // The store must have lasted long enough for the probes to mean something.
    assert!(latencies.len() >= 5, "only {} probes", latencies.len());
    assert!(worst < Duration::from_millis(100), "a probe took {worst:?}");
}

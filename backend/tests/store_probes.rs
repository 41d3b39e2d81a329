//! Preparing a large object leaves the worker answering probes. Its own test binary with a
//! single test: the probe latencies must not share the machine with other tests.

mod common;

use std::time::{Duration, Instant};

use backend::WorkerConfig;
use common::{client, sphere, start_on_own_thread};
use proto::StatusRequest;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_storing_two_million_triangles_answers_probes_within_100_ms() {
    let (address, _service) = start_on_own_thread(WorkerConfig {
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

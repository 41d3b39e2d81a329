//! A worker under a large or lying store: memory is admitted from the declared sizes before
//! anything is reserved, and stores past the concurrent limit wait, then are refused.

mod common;

use std::time::Duration;

use backend::WorkerConfig;
use common::{client, sphere, start_on_own_thread};
use tonic::Code;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn declared_sizes_are_admitted_before_anything_is_reserved() {
    let (address, service) = start_on_own_thread(WorkerConfig {
        threads: 1,
        memory_limit_bytes: 64 << 20,
        ..WorkerConfig::default()
    });
    let mut worker = client(&address).await;
    // One chunk that declares 40 M vertices and triangles (under the element limit of 50 M,
    // about 1.6 GB once prepared) and carries nothing: refused at once, nothing reserved.
    let lie = proto::ObjectChunk {
        object_id: 9,
        name: "liar".into(),
        total_vertices: 40_000_000,
        total_triangles: 40_000_000,
        ..Default::default()
    };
    let status = worker
        .store_object(tokio_stream::iter(vec![lie]))
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::ResourceExhausted);
    assert!(
        status.message().contains("declares a size"),
        "{}",
        status.message()
    );
    assert_eq!(service.memory_in_use(), (0, 0));
    // A real object that fits is stored, and only its prepared size stays booked.
    let small = sphere(32);
    let reply = worker
        .store_object(tokio_stream::iter(proto::object_to_chunks(1, &small)))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(reply.triangles, small.triangles.len() as u64);
    let (stored, reserved) = service.memory_in_use();
    assert!(
        stored > 0 && reserved == 0,
        "{stored} stored, {reserved} reserved"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stores_beyond_the_concurrent_limit_wait_then_are_refused() {
    let (address, service) = start_on_own_thread(WorkerConfig {
        threads: 1,
        concurrent_stores: 1,
        store_wait: Duration::from_millis(300),
        ..WorkerConfig::default()
    });
    let object = sphere(16);
    let chunks = proto::object_to_chunks(1, &object);
    // A peer that sends its first chunk, then stalls: it holds the only slot.
    let half = chunks[0].clone();
    let (stalled, rest) = tokio::sync::mpsc::channel(1);
    stalled.send(half).await.unwrap();
    let mut holder = client(&address).await;
    let held = tokio::spawn(async move {
        holder
            .store_object(tokio_stream::wrappers::ReceiverStream::new(rest))
            .await
    });
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut other = client(&address).await;
    let refused = other
        .store_object(tokio_stream::iter(chunks.clone()))
        .await
        .unwrap_err();
    assert_eq!(refused.code(), Code::ResourceExhausted);
    assert!(
        refused.message().contains("1 stores in progress"),
        "{}",
        refused.message()
    );
    // The stalled peer gives up: its store fails, its reservation and slot are returned.
    drop(stalled);
    assert_eq!(
        held.await.unwrap().unwrap_err().code(),
        Code::InvalidArgument
    );
    assert_eq!(service.memory_in_use().1, 0, "nothing stays reserved");
    let stored = other
        .store_object(tokio_stream::iter(chunks))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(stored.triangles, object.triangles.len() as u64);
}

//! Helpers shared by the worker's test binaries.
#![allow(dead_code)]

use backend::{WorkerConfig, WorkerService};
use glam::DVec3;
use proto::WorkerClient;

/// A worker on its own single-threaded runtime in its own thread: anything that blocks that
/// thread blocks every call to the worker, which is what the probe test must see.
pub fn start_on_own_thread(config: WorkerConfig) -> (String, WorkerService) {
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
            backend::serve(
                listener,
                serving,
                backend::Security::default(),
                std::future::pending(),
            )
            .await
            .unwrap();
        });
    });
    (address, service)
}

pub async fn client(address: &str) -> WorkerClient<tonic::transport::Channel> {
    WorkerClient::connect(address.to_string())
        .await
        .unwrap()
        .max_decoding_message_size(backend::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(backend::MAX_MESSAGE_BYTES)
}

/// A grey UV sphere of `2 n (n / 2)` triangles.
pub fn sphere(n: u32) -> scene::Object {
    coloured_sphere(n, |_, _| [200, 200, 200, 255])
}

/// A UV sphere of `2 n (n / 2)` triangles, the vertex on `ring` at segment `s` coloured
/// `colour(ring, s)`.
pub fn coloured_sphere(n: u32, colour: impl Fn(u32, u32) -> [u8; 4]) -> scene::Object {
    let mut builder = scene::ObjectBuilder::new("sphere");
    let rings = n / 2;
    for ring in 0..=rings {
        let phi = std::f64::consts::PI * ring as f64 / rings as f64;
        for s in 0..n {
            let theta = std::f64::consts::TAU * s as f64 / n as f64;
            let p = DVec3::new(phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin());
            builder.vertex(p, colour(ring, s));
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

//! While the node measures itself off its clock it pauses its workers, and it must not do
//! the work of a board either: a board whose bytes arrive during the pause is decoded only
//! once the pause ends, and the time it was held does not count as latency.

use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

use backend::WorkerService;
use integration_tests::{
    BoardStream, Misbehaviour, requests_on_one_worker, serve_misbehaving, small_objects,
    wanted_boards,
};
use proto::{RenderRequest, Worker};
use tokio::sync::Semaphore;
use tonic::{Request, Response, Status};
use visnode::workers::Deadlines;

/// How long the pause lasts after the held board is let go.
const PAUSED: Duration = Duration::from_millis(1500);

/// A real worker that renders each board, says so on `rendered`, and answers only when the
/// test releases it (a permit of `release`): the board's bytes arrive when the test wants.
struct Held {
    rendered: Mutex<mpsc::Sender<()>>,
    release: Arc<Semaphore>,
}

#[tonic::async_trait]
impl Misbehaviour for Held {
    async fn render(
        &self,
        worker: &WorkerService,
        request: Request<RenderRequest>,
    ) -> Result<Response<BoardStream>, Status> {
        let answer = worker.render(request).await;
        let _ = self.rendered.lock().unwrap().send(());
        self.release
            .acquire()
            .await
            .expect("the semaphore stays open")
            .forget();
        answer
    }
}

#[test]
fn a_board_that_arrives_during_a_pause_is_decoded_after_it_and_its_wait_is_not_latency() {
    let (rendered, was_rendered) = mpsc::channel();
    let release = Arc::new(Semaphore::new(0));
    let (address, _runtime) = serve_misbehaving(Held {
        rendered: Mutex::new(rendered),
        release: release.clone(),
    });
    let mut requests = requests_on_one_worker(address, small_objects(1, 400), Deadlines::default());
    requests.submit(&wanted_boards(1), 1);
    was_rendered
        .recv_timeout(Duration::from_secs(30))
        .expect("the worker renders the board");

    let pause = requests.pause_workers();
    release.add_permits(1);
    // The bytes arrive now; decoding a 64-pixel board takes milliseconds.
    std::thread::sleep(PAUSED);
    let during = requests.poll();
    assert!(
        during.is_empty(),
        "a board was decoded and handed on during the pause"
    );
    assert_eq!(pause.resume(), Some(Duration::ZERO));

    let arrived = requests.wait_all(Duration::from_secs(30));
    assert_eq!(arrived.len(), 1);
    let arrival = &arrived[0];
    assert!(arrival.board.is_ok(), "{:?}", arrival.board.as_ref().err());
    // From the call to the release, not to the end of the pause.
    assert!(
        arrival.latency < PAUSED.as_secs_f64() * 2.0 / 3.0,
        "latency {:.3} s counts the pause",
        arrival.latency
    );
}

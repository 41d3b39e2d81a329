//! A worker that answers with boards that decode but lie: a NaN radius, axes that are not a
//! basis, another view's board, another size. The node ends each such request as a failure
//! (the object stays geometry) and never hands the board on to be drawn. And one whose
//! pauses lie about what it rendered in them, or never say: the node reports that time as
//! unknown. One that never answers a pause (as a worker cut off but not yet found down) holds
//! the node up only briefly.

use std::time::{Duration, Instant};

use backend::WorkerService;
use glam::DVec3;
use integration_tests::{
    BoardStream, Misbehaviour, PauseStream, requests_on_one_worker, serve_misbehaving,
    small_objects, wanted_boards,
};
use proto::{PauseControl, PauseEvent, RenderRequest, Worker};
use tokio_stream::StreamExt;
use tonic::{Request, Response, Status, Streaming};
use visnode::workers::Deadlines;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Lie {
    NanRadius,
    SkewedAxes,
    OtherView,
    OtherSize,
    /// Says it rendered NaN seconds during a pause.
    PauseTime,
    /// Ends a pause without saying what it rendered.
    PauseSilent,
    /// Never answers a pause, as a worker cut off from the node.
    PauseUnanswered,
    /// Pauses, then never says it resumed, as a worker cut off during the pause.
    PauseCutOff,
    /// Not a lie: answers a pause at once but says it is paused only after `PAUSE_LATE`, as a
    /// worker finishing a long board.
    PauseLate,
}

/// How late a `PauseLate` worker says it is paused: past the node's wait for an answer
/// (0.5 s), within its wait for the boards to finish (2 s).
const PAUSE_LATE: Duration = Duration::from_secs(1);

/// A real worker whose render and pause answers are corrupted as `lie` says.
struct Liar {
    lie: Lie,
}

#[tonic::async_trait]
impl Misbehaviour for Liar {
    async fn render(
        &self,
        worker: &WorkerService,
        request: Request<RenderRequest>,
    ) -> Result<Response<BoardStream>, Status> {
        let mut asked = request.into_inner();
        match self.lie {
            Lie::OtherView => (asked.dir_x, asked.dir_z) = (asked.dir_z, -asked.dir_x),
            Lie::OtherSize => asked.size /= 2,
            _ => {}
        }
        let mut stream = worker.render(Request::new(asked)).await?.into_inner();
        let mut chunks = Vec::new();
        while let Some(chunk) = stream.next().await {
            chunks.push(chunk?);
        }
        // The header: magic, size, then f64 centre (3), radius, right (3), up (3), forward (3).
        let header = &mut chunks[0].data;
        let mut put = |index: usize, value: f64| {
            header[8 + index * 8..16 + index * 8].copy_from_slice(&value.to_le_bytes())
        };
        match self.lie {
            Lie::NanRadius => put(3, f64::NAN),
            // right = (1, 0.5, 0) normalised: unit, but not orthogonal to up and forward.
            Lie::SkewedAxes => {
                let skewed = DVec3::new(1.0, 0.5, 0.0).normalize();
                put(4, skewed.x);
                put(5, skewed.y);
                put(6, skewed.z);
            }
            _ => {}
        }
        Ok(Response::new(Box::pin(tokio_stream::iter(
            chunks.into_iter().map(Ok),
        ))))
    }

    async fn pause(
        &self,
        worker: &WorkerService,
        request: Request<Streaming<PauseControl>>,
    ) -> Result<Response<PauseStream>, Status> {
        let lie = self.lie;
        if lie == Lie::PauseUnanswered {
            return std::future::pending().await;
        }
        let mut events = worker.pause(request).await?.into_inner();
        events = match lie {
            Lie::PauseCutOff => {
                let paused = events.next().await.expect("a pause says it paused");
                Box::pin(tokio_stream::once(paused).chain(tokio_stream::pending()))
            }
            // The first event (paused) comes late; the end's (resumed) at once.
            Lie::PauseLate => Box::pin(events.then(|event| async move {
                if matches!(&event, Ok(event) if !event.resumed) {
                    tokio::time::sleep(PAUSE_LATE).await;
                }
                event
            })),
            _ => events,
        };
        Ok(Response::new(Box::pin(events.filter_map(
            move |event| match (lie, event) {
                (Lie::PauseTime, Ok(event)) if event.resumed => Some(Ok(PauseEvent {
                    seconds_rendered: f64::NAN,
                    ..event
                })),
                (Lie::PauseSilent, Ok(event)) if event.resumed => None,
                (_, event) => Some(event),
            },
        ))))
    }
}

/// Starts a lying worker on a runtime of its own and returns its address.
fn start_liar(lie: Lie) -> (String, tokio::runtime::Runtime) {
    serve_misbehaving(Liar { lie })
}

/// What the node says about each lie.
fn expected_reason(lie: Lie) -> &'static str {
    match lie {
        Lie::NanRadius => "radius NaN is not a finite positive number",
        Lie::SkewedAxes => "not an orthonormal right-handed basis",
        Lie::OtherView => "a board seen along",
        Lie::OtherSize => "a 32-pixel board for a 64-pixel request",
        Lie::PauseTime
        | Lie::PauseSilent
        | Lie::PauseUnanswered
        | Lie::PauseCutOff
        | Lie::PauseLate => unreachable!("{lie:?} is not a board's lie"),
    }
}

#[test]
fn boards_that_lie_end_their_requests_as_failures() {
    let objects = small_objects(2, 400);
    for lie in [
        Lie::NanRadius,
        Lie::SkewedAxes,
        Lie::OtherView,
        Lie::OtherSize,
    ] {
        let (address, _runtime) = start_liar(lie);
        let mut requests = requests_on_one_worker(address, objects.clone(), Deadlines::default());
        requests.submit(&wanted_boards(2), 1);
        let arrived = requests.wait_all(Duration::from_secs(30));
        assert_eq!(arrived.len(), 2, "{lie:?}");
        for arrival in arrived {
            let why = arrival
                .board
                .err()
                .unwrap_or_else(|| panic!("{lie:?}: a lying board was accepted"));
            assert!(why.contains(expected_reason(lie)), "{lie:?}: {why}");
        }
        let counts = requests.counts;
        assert_eq!(
            (counts.issued, counts.failed, counts.received),
            (2, 2, 0),
            "{lie:?}"
        );
        // The reasons are kept for the report, counted by message.
        let reasons = requests.failure_reasons();
        assert_eq!(reasons.values().sum::<u64>(), 2, "{lie:?}: {reasons:?}");
        assert!(reasons.keys().all(|why| why.contains(expected_reason(lie))));
    }
}

#[test]
fn a_pause_that_lies_or_never_says_what_it_rendered_leaves_that_time_unknown() {
    let objects = small_objects(2, 400);
    for (lie, honest) in [
        (Lie::OtherSize, true),
        (Lie::PauseTime, false),
        (Lie::PauseSilent, false),
    ] {
        let (address, _runtime) = start_liar(lie);
        let requests = requests_on_one_worker(address, objects.clone(), Deadlines::default());
        let rendered = requests.pause_workers().resume();
        if honest {
            // Nothing was rendering: an honest worker says so.
            assert_eq!(rendered, Some(Duration::ZERO), "{lie:?}");
        } else {
            assert_eq!(rendered, None, "{lie:?}");
        }
    }
}

#[test]
fn a_pause_gives_up_soon_on_a_worker_that_stops_answering_and_waits_for_one_finishing_its_boards() {
    let objects = small_objects(1, 100);
    for lie in [Lie::PauseUnanswered, Lie::PauseCutOff, Lie::PauseLate] {
        let (address, _runtime) = start_liar(lie);
        let requests = requests_on_one_worker(address, objects.clone(), Deadlines::default());
        let began = Instant::now();
        let pause = requests.pause_workers();
        let paused_after = began.elapsed();
        let rendered = pause.resume();
        let took = began.elapsed();
        if lie == Lie::PauseLate {
            assert!(paused_after >= PAUSE_LATE, "{paused_after:?}");
            assert_eq!(rendered, Some(Duration::ZERO), "paused in time: complete");
        } else {
            // A worker that answered may take up to two seconds to finish its boards; one
            // that stops answering is given up on well before that, pausing or resuming.
            assert!(
                took < Duration::from_millis(1500),
                "{lie:?}: waited {took:?}"
            );
            assert_eq!(rendered, None, "{lie:?}: the pause is incomplete");
        }
    }
}

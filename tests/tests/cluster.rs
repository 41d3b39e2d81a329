//! A real cluster on loopback: `backend serve` processes, the visualization node's request
//! path (balancer, deadlines, health probes) in this process. Workers are killed, frozen and
//! restarted mid-walk; every request must end as a board or an explicit fallback, and the
//! walk must never wait on a worker.
//!
//! Run with `--nocapture` to see the figures (detection and reassignment times, latency
//! percentiles before and after a fault, peak memory).

use std::time::{Duration, Instant};

use glam::DVec3;
use integration_tests::{small_objects, workspace_binary};
use visnode::board::BoardShape;
use visnode::cluster::{WorkerProcesses, WorkerSpec};
use visnode::plan::WantedBoard;
use visnode::workers::{BoardRequests, Credentials, Deadlines, HealthRecord, Workers};

/// Deadlines short enough for a test, long enough for a debug build under load.
fn test_deadlines() -> Deadlines {
    Deadlines {
        render: Duration::from_millis(1500),
        store: Duration::from_secs(20),
        probe_interval: Duration::from_millis(100),
        probe_timeout: Duration::from_millis(500),
        probe_misses: 2,
        cooldown: Duration::from_millis(500),
    }
}

fn start_cluster(specs: &[WorkerSpec]) -> WorkerProcesses {
    WorkerProcesses::start(&workspace_binary("backend"), specs).unwrap()
}

/// Stores `objects` on the workers (`replicas` each) and returns the requests over them.
fn requests(
    cluster: &WorkerProcesses,
    objects: &[scene::Object],
    replicas: usize,
    credentials: &Credentials,
) -> BoardRequests {
    requests_with_deadlines(cluster, objects, replicas, credentials, test_deadlines())
}

fn requests_with_deadlines(
    cluster: &WorkerProcesses,
    objects: &[scene::Object],
    replicas: usize,
    credentials: &Credentials,
    deadlines: Deadlines,
) -> BoardRequests {
    let mut workers = Workers::connect(cluster.addresses(), credentials).unwrap();
    workers.deadlines = deadlines;
    visnode::setup::requests_on(
        workers,
        &std::sync::Arc::new(objects.to_vec()),
        &vec![true; objects.len()],
        replicas,
        BoardShape::Relief {
            grid_cells: 8,
            cell_pixels: 1,
        },
        false,
        &indicatif::ProgressBar::hidden(),
    )
    .unwrap()
}

/// One ended request, as the walk saw it.
struct Ended {
    object: u32,
    at: f64,
    latency: f64,
    worker: u32,
    error: Option<String>,
}

/// A walk that wants a fresh board of every object every frame, as a fast-turning camera
/// would, and records how each request ends.
struct Walk {
    requests: BoardRequests,
    objects: u32,
    map_size: u32,
    frame: u64,
    ended: Vec<Ended>,
    /// The longest a frame's submit and poll took.
    longest_frame: Duration,
    /// Want each object only until it has a board (a burst), instead of every frame.
    once: bool,
    served: std::collections::HashSet<u32>,
}

impl Walk {
    fn new(requests: BoardRequests, objects: usize, map_size: u32) -> Walk {
        Walk {
            requests,
            objects: objects as u32,
            map_size,
            frame: 0,
            ended: Vec::new(),
            longest_frame: Duration::ZERO,
            once: false,
            served: std::collections::HashSet::new(),
        }
    }

    fn step(&mut self) {
        let start = Instant::now();
        self.frame += 1;
        let angle = self.frame as f64 * 0.05;
        let direction = DVec3::new(angle.cos(), -0.3, angle.sin()).normalize();
        let wanted: Vec<WantedBoard> = (0..self.objects)
            .filter(|object| !(self.once && self.served.contains(object)))
            .map(|object| WantedBoard {
                object,
                direction,
                size: self.map_size,
                priority: 1.0,
            })
            .collect();
        self.requests.submit(&wanted, self.frame);
        let arrived = self.requests.poll();
        self.record(arrived);
        self.longest_frame = self.longest_frame.max(start.elapsed());
    }

    fn record(&mut self, arrived: Vec<visnode::workers::Arrival>) {
        let at = self.requests.elapsed();
        for arrival in &arrived {
            if arrival.board.is_ok() {
                self.served.insert(arrival.object);
            }
        }
        self.ended.extend(arrived.into_iter().map(|a| Ended {
            object: a.object,
            at,
            latency: a.latency,
            worker: a.worker,
            error: a.board.err(),
        }));
    }

    fn run_for(&mut self, duration: Duration) {
        let end = Instant::now() + duration;
        while Instant::now() < end {
            self.step();
            std::thread::sleep(Duration::from_millis(15));
        }
    }

    /// Stops asking and waits for everything in flight.
    fn finish(&mut self) {
        let arrived = self.requests.wait_all(Duration::from_secs(60));
        self.record(arrived);
        assert_eq!(self.requests.pending(), 0, "requests left unanswered");
    }

    /// Every issued request ended exactly once, as a board or an explicit fallback.
    fn assert_all_accounted(&self) {
        let counts = self.requests.counts;
        assert_eq!(counts.issued, counts.received + counts.failed, "{counts:?}");
        assert_eq!(self.ended.len() as u64, counts.issued, "{counts:?}");
        let failed = self.ended.iter().filter(|e| e.error.is_some()).count() as u64;
        assert_eq!(failed, counts.failed);
    }

    /// Latency percentiles (ms) of the boards that arrived within `[from, to)` seconds.
    fn latency_ms(&self, from: f64, to: f64) -> [f64; 3] {
        let stats = visnode::bench::Stats::of(
            self.ended
                .iter()
                .filter(|e| e.error.is_none() && e.at >= from && e.at < to)
                .map(|e| e.latency * 1e3),
        );
        if stats.count == 0 {
            return [f64::NAN; 3];
        }
        [stats.p50, stats.p90, stats.p99]
    }

    /// When the health log first says `worker` went `down` or `up` after `after` seconds.
    fn health_change(&self, worker: u32, up: bool, after: f64) -> Option<(f64, String)> {
        self.requests
            .health_log()
            .iter()
            .find(|r| {
                r.worker == worker
                    && r.at >= after
                    && r.event.starts_with(if up { "up" } else { "down" })
            })
            .map(|r| (r.at, r.event.clone()))
    }
}

#[test]
fn a_killed_worker_is_replaced_then_restored_and_used_again() {
    let mut cluster = start_cluster(&vec![WorkerSpec::default(); 4]);
    let objects = small_objects(24, 400);
    let requests = requests(&cluster, &objects, 2, &Credentials::default());
    let mut walk = Walk::new(requests, objects.len(), 96);

    walk.run_for(Duration::from_millis(1500));
    let killed_at = walk.requests.elapsed();
    cluster.kill(1).unwrap();
    walk.run_for(Duration::from_millis(2000));
    let (down_at, why) = walk
        .health_change(1, false, killed_at)
        .expect("the killed worker was marked down");
    assert!(!walk.requests.health()[1].alive);
    // Every object has a second replica, so nothing falls back while one worker is dead.
    assert_eq!(walk.requests.counts.failed, 0, "{:?}", walk.requests.counts);

    let restarted_at = walk.requests.elapsed();
    cluster.restart(1).unwrap();
    walk.run_for(Duration::from_millis(2500));
    let (up_at, event) = walk
        .health_change(1, true, restarted_at)
        .expect("the restarted worker came back");
    assert!(
        event.contains("stored again"),
        "{event}: re-stored, it restarted empty"
    );
    assert!(walk.requests.health()[1].restored_objects > 0);
    let used_again = walk
        .ended
        .iter()
        .filter(|e| e.worker == 1 && e.at > up_at && e.error.is_none())
        .count();
    assert!(
        used_again > 0,
        "worker 1 answered nothing after it came back"
    );

    walk.finish();
    walk.assert_all_accounted();
    assert_eq!(walk.requests.counts.failed, 0);
    assert!(
        walk.longest_frame < Duration::from_secs(1),
        "a frame waited {:?} on the workers",
        walk.longest_frame
    );
    let before = walk.latency_ms(0.5, killed_at);
    let during = walk.latency_ms(killed_at, restarted_at);
    let after = walk.latency_ms(up_at, f64::INFINITY);
    eprintln!(
        "kill: detected after {:.0} ms ({why}); reassigned {} calls; restored {:.0} ms after restart ({event})",
        (down_at - killed_at) * 1e3,
        walk.requests.counts.reassigned,
        (up_at - restarted_at) * 1e3
    );
    eprintln!(
        "latency p50/p90/p99 ms: before {before:.0?}, after the kill {during:.0?}, after the restart {after:.0?}; {:?}; longest frame {:?}",
        walk.requests.counts, walk.longest_frame
    );
}

#[test]
fn a_hung_worker_times_out_its_calls_is_marked_unhealthy_and_returns_when_it_answers() {
    let mut cluster = start_cluster(&vec![WorkerSpec::default(); 3]);
    let objects = small_objects(12, 400);
    let requests = requests(&cluster, &objects, 2, &Credentials::default());
    let mut walk = Walk::new(requests, objects.len(), 96);

    walk.run_for(Duration::from_millis(1000));
    let frozen_at = walk.requests.elapsed();
    // SIGSTOP: the port still accepts connections, nothing ever answers.
    cluster.freeze(0, true).unwrap();
    // Pausing the workers off the clock (a benchmark's read-back) while one hangs unnoticed
    // yet: the pause gives up on it within its wait, and says the pause was incomplete.
    let pausing = Instant::now();
    let pause = walk.requests.pause_workers();
    assert_eq!(pause.resume(), None);
    assert!(
        pausing.elapsed() < Duration::from_secs(10),
        "{:?}",
        pausing.elapsed()
    );
    walk.run_for(Duration::from_millis(3000));
    let (down_at, why) = walk
        .health_change(0, false, frozen_at)
        .expect("the hung worker was marked unhealthy");
    assert!(why.contains("no answer"), "{why}");
    assert!(!walk.requests.health()[0].alive);
    // Known down, it is not asked: the workers in use pause, and say what they rendered.
    let pause = walk.requests.pause_workers();
    assert!(pause.resume().is_some());

    let thawed_at = walk.requests.elapsed();
    cluster.freeze(0, false).unwrap();
    walk.run_for(Duration::from_millis(2500));
    let (up_at, _) = walk
        .health_change(0, true, thawed_at)
        .expect("the worker answers again and is used");
    walk.finish();
    walk.assert_all_accounted();
    assert_eq!(walk.requests.counts.failed, 0, "{:?}", walk.requests.counts);
    assert!(
        walk.longest_frame < Duration::from_secs(1),
        "{:?}",
        walk.longest_frame
    );
    eprintln!(
        "hang: marked unhealthy after {:.0} ms ({why}); back {:.0} ms after it thawed; latency p50/p90/p99 ms before {:.0?}, while hung {:.0?}; {:?}",
        (down_at - frozen_at) * 1e3,
        (up_at - thawed_at) * 1e3,
        walk.latency_ms(0.5, frozen_at),
        walk.latency_ms(frozen_at, thawed_at),
        walk.requests.counts
    );
}

#[test]
fn when_every_replica_is_dead_the_request_ends_as_an_explicit_fallback() {
    let mut cluster = start_cluster(&vec![WorkerSpec::default(); 2]);
    let objects = small_objects(6, 200);
    let requests = requests(&cluster, &objects, 1, &Credentials::default());
    let mut walk = Walk::new(requests, objects.len(), 64);
    walk.run_for(Duration::from_millis(500));
    cluster.kill(0).unwrap();
    cluster.kill(1).unwrap();
    walk.run_for(Duration::from_millis(1500));
    walk.finish();
    walk.assert_all_accounted();
    let fallbacks: Vec<&String> = walk.ended.iter().filter_map(|e| e.error.as_ref()).collect();
    assert!(
        fallbacks
            .iter()
            .all(|e| e.contains("down") || e.contains("gave up")),
        "{fallbacks:?}"
    );
    assert!(walk.requests.health().iter().all(|h| !h.alive));
    // With no live replica, new wants are not even issued: they are drawn as geometry.
    let issued = walk.requests.counts.issued;
    walk.run_for(Duration::from_millis(200));
    assert_eq!(walk.requests.counts.issued, issued);
    assert!(walk.requests.counts.unassignable > 0);
}

#[test]
fn a_burst_of_ten_thousand_requests_is_all_served_with_bounded_memory() {
    let cluster = start_cluster(&vec![
        WorkerSpec {
            queue: 64,
            ..WorkerSpec::default()
        };
        4
    ]);
    let objects = small_objects(10_000, 32);
    // This test is about losing nothing and bounded memory, not deadlines (the tests above
    // are): a call may wait behind a full worker queue while the other tests' workers share
    // CI's two cores (1.5 s let 156 of 10,000 calls time out there).
    let deadlines = Deadlines {
        render: Duration::from_secs(20),
        ..test_deadlines()
    };
    let requests =
        requests_with_deadlines(&cluster, &objects, 2, &Credentials::default(), deadlines);
    let memory_before = visnode::peak_memory_bytes().unwrap_or(0);
    let mut walk = Walk::new(requests, objects.len(), 16);
    walk.once = true;
    // One frame wants all 10,000; the balancer sends at most 16 per worker, the rest wait
    // on this node and are asked again each frame until served.
    let start = Instant::now();
    while walk.served.len() < objects.len() {
        assert!(
            start.elapsed() < Duration::from_secs(240),
            "{:?}",
            walk.requests.counts
        );
        walk.step();
        let in_flight_bound = cluster.len() * visnode::workers::MAX_JOBS_PER_WORKER as usize;
        assert!(
            walk.requests.pending() <= in_flight_bound,
            "in flight: {}",
            walk.requests.pending()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    walk.finish();
    walk.assert_all_accounted();
    assert_eq!(
        walk.requests.counts.failed,
        0,
        "{:?}",
        walk.requests.failure_reasons()
    );
    // Each object was served, and exactly once: nothing answered twice.
    assert_eq!(walk.requests.counts.received, objects.len() as u64);
    let mut objects_served: Vec<u32> = walk.ended.iter().map(|e| e.object).collect();
    objects_served.sort_unstable();
    objects_served.dedup();
    assert_eq!(objects_served.len(), objects.len());
    let workers_peak: Vec<u64> = (0..cluster.len())
        .map(|i| cluster.peak_memory_bytes(i).unwrap_or(0))
        .collect();
    let node_peak = visnode::peak_memory_bytes().unwrap_or(0);
    for &peak in &workers_peak {
        assert!(peak < 512 << 20, "a worker peaked at {} MiB", peak >> 20);
    }
    eprintln!(
        "burst: {} boards in {:.1} s; {:?}; peak memory node {} MiB (before the burst {} MiB), workers {:?} MiB",
        walk.requests.counts.received,
        start.elapsed().as_secs_f64(),
        walk.requests.counts,
        node_peak >> 20,
        memory_before >> 20,
        workers_peak.iter().map(|p| p >> 20).collect::<Vec<_>>()
    );
}

#[test]
fn a_slower_worker_is_sent_less_work() {
    let mut specs = vec![WorkerSpec::default(); 4];
    specs[3].slowdown = 6.0;
    let cluster = start_cluster(&specs);
    let objects = small_objects(40, 1200);
    // Every object on every worker: only speed decides who renders it.
    let requests = requests(&cluster, &objects, 4, &Credentials::default());
    let mut walk = Walk::new(requests, objects.len(), 128);
    walk.run_for(Duration::from_millis(4000));
    walk.finish();
    walk.assert_all_accounted();
    let per_worker = walk.requests.received_by_worker().to_vec();
    let fast_mean = per_worker[..3].iter().sum::<u64>() as f64 / 3.0;
    eprintln!("boards per worker (the last is 6x slower): {per_worker:?}");
    assert!(
        (per_worker[3] as f64) < 0.6 * fast_mean,
        "the slow worker got {per_worker:?}"
    );
}

#[test]
fn workers_with_a_token_refuse_calls_without_it() {
    let cluster = start_cluster(&[WorkerSpec {
        token: Some("correct horse battery staple".into()),
        ..WorkerSpec::default()
    }]);
    let objects = small_objects(2, 100);
    let store = |token: Option<&str>| {
        let workers = Workers::connect(
            cluster.addresses(),
            &Credentials {
                token: token.map(str::to_string),
                ..Credentials::default()
            },
        )
        .unwrap();
        let placement = balancer::Placement::random(objects.len(), 1, 1, 1).unwrap();
        let stored: Vec<(u32, &scene::Object)> = objects
            .iter()
            .enumerate()
            .map(|(i, o)| (i as u32, o))
            .collect();
        workers.store(&stored, &placement, &indicatif::ProgressBar::hidden())
    };
    let refused = store(None);
    assert_eq!(refused.len(), 1);
    assert!(
        refused[0].1.contains("Unauthenticated") || refused[0].1.contains("token"),
        "{refused:?}"
    );
    let wrong = store(Some("correct horse battery stapler"));
    assert_eq!(wrong.len(), 1, "{wrong:?}");
    assert!(store(Some("correct horse battery staple")).is_empty());
}

#[test]
fn a_worker_will_not_listen_beyond_loopback_without_a_token() {
    let output = std::process::Command::new(workspace_binary("backend"))
        .args(["serve", "--listen", "0.0.0.0:0"])
        .env_remove("RELIEFBOARD_TOKEN")
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("--token") && stderr.contains("--insecure"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn tls_and_mutual_tls_admit_only_the_right_certificates() {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, ExtendedKeyUsagePurpose, IsCa,
        KeyPair,
    };
    let dir = std::env::temp_dir().join(format!("reliefboard-tls-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: String| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    let ca = CertifiedIssuer::self_signed(ca_params, KeyPair::generate().unwrap()).unwrap();
    let ca_pem = write("ca.pem", ca.pem());
    let leaf = |name: &str, purpose: ExtendedKeyUsagePurpose| {
        let key = KeyPair::generate().unwrap();
        let mut params = CertificateParams::new(vec![name.to_string()]).unwrap();
        params.extended_key_usages = vec![purpose];
        let cert = params.signed_by(&key, &ca).unwrap();
        (
            write(&format!("{name}.pem"), cert.pem()),
            write(&format!("{name}.key"), key.serialize_pem()),
        )
    };
    let (server_cert, server_key) = leaf("localhost", ExtendedKeyUsagePurpose::ServerAuth);
    let client = leaf("visnode", ExtendedKeyUsagePurpose::ClientAuth);
    let path = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let cluster = start_cluster(&[WorkerSpec {
        extra_args: vec![
            "--tls-cert".into(),
            path(&server_cert),
            "--tls-key".into(),
            path(&server_key),
            "--tls-ca".into(),
            path(&ca_pem),
        ],
        ..WorkerSpec::default()
    }]);
    let objects = small_objects(2, 100);
    let store = |credentials: Credentials| {
        let workers = Workers::connect(cluster.addresses(), &credentials).unwrap();
        let placement = balancer::Placement::random(objects.len(), 1, 1, 1).unwrap();
        let stored: Vec<(u32, &scene::Object)> = objects
            .iter()
            .enumerate()
            .map(|(i, o)| (i as u32, o))
            .collect();
        workers.store(&stored, &placement, &indicatif::ProgressBar::hidden())
    };
    let tls = Credentials {
        tls_ca: Some(ca_pem.clone()),
        tls_domain: Some("localhost".into()),
        ..Credentials::default()
    };
    assert!(
        store(Credentials {
            tls_identity: Some(client.clone()),
            ..tls.clone()
        })
        .is_empty(),
        "mutual TLS with the client certificate"
    );
    assert_eq!(store(tls).len(), 1, "no client certificate");
    assert_eq!(store(Credentials::default()).len(), 1, "plain text");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn visnode_cluster_runs_the_benchmark_on_worker_processes() {
    let out = std::env::temp_dir().join(format!("reliefboard-cluster-{}", std::process::id()));
    let output = std::process::Command::new(workspace_binary("visnode"))
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .args([
            "cluster",
            "--workers",
            "2",
            "--slowdown",
            "1,3",
            "--backend",
        ])
        .arg(workspace_binary("backend"))
        .args([
            "bench",
            "--scene",
            "forest",
            "--triangles",
            "300000",
            "--t-nz",
            "100000",
            "--no-cache",
            "--timing",
            "frames",
            "--frames",
            "4",
            "--resolution",
            "160x120",
            "--sync",
            "--sample-frames",
            "0",
            "--json",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("started 2 worker processes"), "{stderr}");
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(summary["workers"], 2, "{summary}");
    assert!(summary["no_boards_reason"].is_null(), "{summary}");
    let requests = &summary["requests"];
    assert!(requests["received"].as_u64().unwrap() > 0, "{summary}");
    assert_eq!(requests["issued"], requests["received"], "{summary}");
    assert_eq!(summary["boards_per_worker"].as_array().unwrap().len(), 2);
    // Worker processes are paused too while shots are read back (through their `Pause`
    // calls); the summary says what they still rendered meanwhile.
    assert!(
        summary["worker_seconds_off_clock"].as_f64().is_some(),
        "{summary}"
    );
    let _ = std::fs::remove_dir_all(&out);

    // Worker flags belong to `cluster`, not to what it runs.
    let output = std::process::Command::new(workspace_binary("visnode"))
        .args(["cluster", "--workers", "1", "--backend"])
        .arg(workspace_binary("backend"))
        .args(["bench", "--workers", "127.0.0.1:1"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(
        String::from_utf8_lossy(&output.stderr).contains("starts its own workers"),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Workers that appear while running join (their share of objects stored first, then work),
/// and workers that vanish from the listing are forgotten, with nothing lost: what
/// `--workers-dns` does when a compose service or a StatefulSet scales.
#[test]
fn workers_that_join_get_work_and_workers_that_leave_are_forgotten() {
    let cluster = start_cluster(&vec![WorkerSpec::default(); 3]);
    let objects = small_objects(24, 400);
    let all: Vec<String> = cluster.addresses().to_vec();
    let listed = std::sync::Arc::new(std::sync::Mutex::new(all[..2].to_vec()));
    let mut workers = Workers::connect(&all[..2], &Credentials::default()).unwrap();
    workers.deadlines = test_deadlines();
    let source = listed.clone();
    workers.follow(
        move || Ok(source.lock().unwrap().clone()),
        Duration::from_millis(50),
    );
    let requests = visnode::setup::requests_on(
        workers,
        &std::sync::Arc::new(objects.clone()),
        &vec![true; objects.len()],
        2,
        BoardShape::Relief {
            grid_cells: 8,
            cell_pixels: 1,
        },
        false,
        &indicatif::ProgressBar::hidden(),
    )
    .unwrap();
    let mut walk = Walk::new(requests, objects.len(), 96);
    walk.run_for(Duration::from_millis(1000));

    let joined_at = walk.requests.elapsed();
    listed.lock().unwrap().push(all[2].clone());
    walk.run_for(Duration::from_millis(2500));
    assert_eq!(
        walk.requests.addresses().len(),
        3,
        "the new worker was added"
    );
    let log = walk.requests.health_log().to_vec();
    assert!(
        log.iter()
            .any(|r| r.worker == 2 && r.event.starts_with("joined")),
        "{log:?}"
    );
    let (up_at, event) = walk
        .health_change(2, true, joined_at)
        .expect("the new worker stored its objects and came up");
    assert!(event.contains("stored"), "{event}");
    let new_boards = walk
        .ended
        .iter()
        .filter(|e| e.worker == 2 && e.error.is_none())
        .count();
    assert!(new_boards > 0, "the new worker got no work");
    assert!(
        walk.requests.health()[2]
            .first_board_since_up_unix
            .is_some()
    );
    assert!(
        walk.requests.health()[2]
            .first_board_since_listed_unix
            .is_some()
    );

    let left_at = walk.requests.elapsed();
    listed.lock().unwrap().remove(0);
    // The frame loop stalls a second (a slow frame) while the listing changes: the leave is
    // still dated when it was listed, not when the loop came back.
    std::thread::sleep(Duration::from_millis(1000));
    walk.run_for(Duration::from_millis(1500));
    assert!(walk.requests.health()[0].gone);
    assert!(!walk.requests.health()[0].alive);
    let left_record = log_record(&walk, 0, "left").expect("worker 0 was forgotten");
    let (left, applied_after) = (left_record.at, left_record.applied_after);
    assert!(
        left - left_at < 0.5,
        "the leave was dated {:.2} s after the listing changed",
        left - left_at
    );
    assert!(
        applied_after > 0.5,
        "the stalled loop applied the leave {applied_after:.2} s after it was listed"
    );
    // Calls worker 0 had in flight when it left may still arrive within a poll or two.
    let after_leaving = walk
        .ended
        .iter()
        .filter(|e| e.worker == 0 && e.at > left + 0.5)
        .count();
    assert_eq!(after_leaving, 0, "worker 0 got work after it left");

    walk.finish();
    walk.assert_all_accounted();
    assert_eq!(walk.requests.counts.failed, 0, "{:?}", walk.requests.counts);
    eprintln!(
        "join: up {:.0} ms after being listed; left {:.0} ms after being unlisted; boards per worker {:?}",
        (up_at - joined_at) * 1e3,
        (left - left_at) * 1e3,
        walk.requests.received_by_worker()
    );
}

/// The health log's first record of `event` for `worker`.
fn log_record(walk: &Walk, worker: u32, event: &str) -> Option<HealthRecord> {
    walk.requests
        .health_log()
        .iter()
        .find(|r| r.worker == worker && r.event.starts_with(event))
        .cloned()
}

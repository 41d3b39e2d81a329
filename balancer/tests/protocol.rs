//! The balancer's protocol against its specification.

use std::collections::HashSet;

use balancer::{
    Balancer, BalancerError, Collision, Config, Placement, Policy, Request, SimulationConfig,
    Strategy, Trace, TraceRecord, pick_candidate, randomized_probabilities, simulate,
    synthetic_trace,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn request(id: u64, object: u32, weight: f64) -> Request {
    Request {
        id,
        object,
        weight,
        priority: 0.0,
    }
}

#[test]
fn every_request_ends_assigned_once_to_a_live_holder_or_reported() {
    for seed in 0..30u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let workers = rng.random_range(1..40usize);
        let replicas = rng.random_range(1..=workers.min(4));
        let objects = rng.random_range(1..300usize);
        let placement = Placement::random(objects, workers, replicas, seed).unwrap();
        let strategy = if seed % 2 == 0 {
            Strategy::Deterministic
        } else {
            Strategy::Randomized
        };
        let collision = if seed % 3 == 0 {
            Collision::Count
        } else {
            Collision::Load
        };
        let mut balancer = Balancer::new(
            placement.clone(),
            Config {
                strategy,
                collision,
                seed,
                ..Config::default()
            },
        )
        .unwrap();
        let dead: HashSet<u32> = (0..workers as u32)
            .filter(|_| rng.random_bool(0.2))
            .collect();
        for &worker in &dead {
            balancer.set_alive(worker, false).unwrap();
        }
        let count = rng.random_range(0..2000u64);
        let requests: Vec<Request> = (0..count)
            .map(|id| Request {
                id,
                object: rng.random_range(0..objects as u32 + 2),
                weight: rng.random_range(1.0..1e5),
                priority: rng.random_range(0.0..1.0),
            })
            .collect();
        let outcome = balancer.assign(requests.clone());
        let mut seen = HashSet::new();
        for (request, worker) in &outcome.assigned {
            assert!(
                seen.insert(request.id),
                "request {} assigned twice",
                request.id
            );
            let holders = placement
                .replicas(request.object)
                .expect("assigned requests name known objects");
            assert!(
                holders.contains(worker),
                "worker {worker} does not hold object {}",
                request.object
            );
            assert!(!dead.contains(worker), "dead worker {worker} got a request");
        }
        for request in &outcome.unassignable {
            assert!(seen.insert(request.id));
            let all_dead = placement
                .replicas(request.object)
                .is_none_or(|h| h.iter().all(|w| dead.contains(w)));
            assert!(
                all_dead,
                "request {} reported unassignable with a live replica",
                request.id
            );
        }
        assert!(
            outcome.deferred.is_empty(),
            "no queue bound, nothing deferred"
        );
        assert_eq!(
            seen.len() as u64,
            count,
            "seed {seed}: every request accounted for"
        );
        assert_eq!(balancer.in_flight(), outcome.assigned.len());
    }
}

#[test]
fn c_grows_past_a_first_round_where_every_worker_is_over_c() {
    // Every object on all four workers: a group of four requests offers four to each worker,
    // over c = 1. The round answers nothing; c must grow until the workers answer.
    let placement = Placement::from_replicas(4, vec![vec![0, 1, 2, 3]; 10]).unwrap();
    for collision in [Collision::Count, Collision::Load] {
        let config = Config {
            collision,
            c_start: 1.0,
            c_step: 1.0,
            ..Config::default()
        };
        let mut balancer = Balancer::new(placement.clone(), config).unwrap();
        let requests: Vec<Request> = (0..40)
            .map(|id| request(id, (id % 10) as u32, 1000.0))
            .collect();
        let outcome = balancer.assign(requests);
        assert_eq!(outcome.assigned.len(), 40, "{collision:?}");
        assert!(
            outcome.max_c >= 4.0,
            "{collision:?}: c reached {}",
            outcome.max_c
        );
        assert!(
            outcome.rounds > 10,
            "{collision:?}: rounds without progress were played ({})",
            outcome.rounds
        );
        // Deterministic picking by load spreads the 40 equal requests evenly.
        let mut per_worker = [0; 4];
        for (_, worker) in &outcome.assigned {
            per_worker[*worker as usize] += 1;
        }
        assert_eq!(per_worker, [10; 4], "{collision:?}");
    }
}

#[test]
fn randomized_choice_frequencies_match_the_formula() {
    let loads = [1.0, 2.0, 3.0, 4.0];
    let expected = randomized_probabilities(&loads);
    let exact = [9.0 / 30.0, 8.0 / 30.0, 7.0 / 30.0, 6.0 / 30.0]; // (T - s_i) / ((|P| - 1) T), T = 10
    for (p, q) in expected.iter().zip(exact) {
        assert!((p - q).abs() < 1e-12);
    }
    let draws = 60_000;
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut counts = [0u32; 4];
    for _ in 0..draws {
        counts[pick_candidate(&loads, Strategy::Randomized, &mut rng)] += 1;
    }
    for (count, p) in counts.iter().zip(exact) {
        // A binomial count has standard deviation sqrt(N p (1 - p)); five of them is a
        // tolerance a correct sampler exceeds about once in two million runs.
        let sigma = (draws as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (*count as f64 - draws as f64 * p).abs() < 5.0 * sigma,
            "counts {counts:?}"
        );
    }
}

#[test]
fn randomized_choice_handles_one_candidate_and_all_idle() {
    assert_eq!(randomized_probabilities(&[5.0]), vec![1.0]);
    assert_eq!(
        randomized_probabilities(&[0.0, 0.0, 0.0]),
        vec![1.0 / 3.0; 3]
    );
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    assert!((0..100).all(|_| pick_candidate(&[7.0], Strategy::Randomized, &mut rng) == 0));
    let draws = 30_000;
    let mut counts = [0u32; 3];
    for _ in 0..draws {
        counts[pick_candidate(&[0.0, 0.0, 0.0], Strategy::Randomized, &mut rng)] += 1;
    }
    let sigma = (draws as f64 * (1.0 / 3.0) * (2.0 / 3.0)).sqrt();
    assert!(
        counts
            .iter()
            .all(|c| (*c as f64 - draws as f64 / 3.0).abs() < 5.0 * sigma),
        "{counts:?}"
    );
    // Deterministic: the lightest, ties to the first.
    assert_eq!(
        pick_candidate(&[3.0, 1.0, 1.0], Strategy::Deterministic, &mut rng),
        1
    );
}

#[test]
fn a_four_times_slower_worker_gets_less_work_in_heterogeneous_mode() {
    let trace = synthetic_trace("orbit", 1500, 400, 3).unwrap();
    let run = |heterogeneous: bool| {
        let config = SimulationConfig {
            workers: 8,
            replicas: 3,
            seed: 5,
            speeds: vec![1.0, 1.0, 1.0, 0.25, 1.0, 1.0, 1.0, 0.25],
            base_speed: 2e8,
            policy: Policy::Balancer(Config {
                heterogeneous,
                ..Config::default()
            }),
        };
        let shares = simulate(&trace, &config).unwrap().worker_shares;
        let slow = (shares[3] + shares[7]) / 2.0;
        let fast = shares
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 3 && *i != 7)
            .map(|(_, s)| s)
            .sum::<f64>()
            / 6.0;
        slow / fast
    };
    let aware = run(true);
    let blind = run(false);
    eprintln!("slow/fast share: aware {aware:.3}, blind {blind:.3}");
    assert!(
        aware < 0.5,
        "a 4x slower worker should get well under half a fast one's work, got {aware:.3}"
    );
    assert!(
        aware < blind,
        "speed awareness must shift work away: {aware:.3} vs {blind:.3} without it"
    );
}

#[test]
fn higher_priority_goes_first_when_queues_are_full() {
    let placement = Placement::from_replicas(2, vec![vec![0, 1]; 5]).unwrap();
    let config = Config {
        max_jobs_per_worker: Some(1),
        ..Config::default()
    };
    let mut balancer = Balancer::new(placement, config).unwrap();
    let requests: Vec<Request> = (0..5)
        .map(|id| Request {
            id,
            object: id as u32,
            weight: 10.0,
            priority: id as f64,
        })
        .collect();
    let outcome = balancer.assign(requests);
    let mut assigned: Vec<u64> = outcome.assigned.iter().map(|(r, _)| r.id).collect();
    assigned.sort();
    assert_eq!(
        assigned,
        [3, 4],
        "the two most important requests fill the two queues"
    );
    let mut deferred: Vec<u64> = outcome.deferred.iter().map(|r| r.id).collect();
    deferred.sort();
    assert_eq!(deferred, [0, 1, 2]);
    // A completed board frees its worker's queue for the next most important request.
    balancer.complete(4, Some(0.1)).unwrap();
    let again = balancer.assign(outcome.deferred);
    assert_eq!(again.assigned.len(), 1);
    assert_eq!(again.assigned[0].0.id, 2);
}

#[test]
fn dead_workers_hand_back_their_requests_and_are_skipped() {
    let placement = Placement::from_replicas(3, vec![vec![0], vec![0, 1], vec![1, 2]]).unwrap();
    let mut balancer = Balancer::new(placement, Config::default()).unwrap();
    let first = balancer.assign(vec![
        request(1, 0, 5.0),
        request(2, 1, 5.0),
        request(3, 2, 5.0),
    ]);
    assert_eq!(first.assigned.len(), 3);
    let on_zero: Vec<u64> = first
        .assigned
        .iter()
        .filter(|(_, w)| *w == 0)
        .map(|(r, _)| r.id)
        .collect();
    let lost = balancer.set_alive(0, false).unwrap();
    assert_eq!(lost, on_zero, "the dead worker's requests come back");
    let second = balancer.assign(vec![request(4, 0, 5.0), request(5, 1, 5.0)]);
    assert_eq!(
        second.unassignable.iter().map(|r| r.id).collect::<Vec<_>>(),
        [4],
        "object 0 lives only on the dead worker"
    );
    assert_eq!(second.assigned, vec![(request(5, 1, 5.0), 1)]);
    balancer.set_alive(0, true).unwrap();
    assert_eq!(
        balancer.assign(vec![request(6, 0, 5.0)]).assigned,
        vec![(request(6, 0, 5.0), 0)],
        "back alive, used again"
    );
}

#[test]
fn api_misuse_is_an_error() {
    assert_eq!(
        Placement::random(10, 3, 4, 1),
        Err(BalancerError::BadReplicaCount {
            replicas: 4,
            workers: 3
        })
    );
    assert_eq!(
        Placement::random(10, 0, 1, 1),
        Err(BalancerError::NoWorkers)
    );
    assert_eq!(
        Placement::from_replicas(2, vec![vec![5]]),
        Err(BalancerError::BadPlacement { object: 0 })
    );
    let placement = Placement::random(10, 3, 2, 1).unwrap();
    let bad = Config {
        c_start: 0.0,
        ..Config::default()
    };
    assert!(matches!(
        Balancer::new(placement.clone(), bad),
        Err(BalancerError::BadConfig(_))
    ));
    let mut balancer = Balancer::new(placement, Config::default()).unwrap();
    assert_eq!(
        balancer.complete(99, None),
        Err(BalancerError::UnknownRequest(99))
    );
    assert_eq!(
        balancer.set_alive(7, false),
        Err(BalancerError::UnknownWorker(7))
    );
}

#[test]
fn placement_is_random_redundant_and_deterministic() {
    let a = Placement::random(1000, 20, 3, 9).unwrap();
    assert_eq!(a, Placement::random(1000, 20, 3, 9).unwrap());
    assert_ne!(a, Placement::random(1000, 20, 3, 10).unwrap());
    for object in 0..1000 {
        let holders = a.replicas(object).unwrap();
        assert_eq!(holders.len(), 3);
        assert!(holders.windows(2).all(|w| w[0] < w[1]), "distinct workers");
    }
    // Uniform: each worker holds about 1000 * 3 / 20 = 150 objects.
    for held in a.objects_of_workers() {
        assert!((100..200).contains(&held.len()), "{}", held.len());
    }
}

#[test]
fn traces_round_trip_through_json_lines_and_report_bad_lines() {
    let trace = Trace::new(vec![
        TraceRecord {
            frame: 2,
            object: 1,
            weight: 10.0,
            time: Some(0.5),
        },
        TraceRecord {
            frame: 1,
            object: 3,
            weight: 20.0,
            time: None,
        },
    ]);
    assert_eq!(trace.records[0].frame, 1, "sorted by frame");
    assert_eq!(
        Trace::from_json_lines(&trace.to_json_lines()).unwrap(),
        trace
    );
    assert_eq!(trace.object_count(), 4);
    let error = Trace::from_json_lines("{\"frame\":1,\"object\":2,\"weight\":3}\n\nnot json\n")
        .unwrap_err();
    assert!(error.starts_with("line 3:"), "{error}");
    let error = Trace::from_json_lines("{\"frame\":1,\"object\":2,\"weight\":-3}\n").unwrap_err();
    assert!(error.contains("weight"), "{error}");
}

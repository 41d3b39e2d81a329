//! Replaying a trace on simulated workers, for the balancer and for the baselines.
//!
//! Time model: each position of the trace happens at its time; between two positions every
//! worker works off `speed · base_speed · Δt` weight of its queue, first come first served,
//! and finished jobs are reported to the policy. So loads carry over between positions, as
//! they do in the real, asynchronous system.

use std::collections::VecDeque;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::placement::Placement;
use crate::protocol::{Balancer, BalancerError, Config, Request};
use crate::trace::Trace;

/// The simple assignment rules the balancer is measured against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// A replica chosen uniformly at random.
    RandomReplica,
    /// The object's replicas in turn.
    RoundRobin,
    /// The less loaded of two distinct random replicas ("power of two choices"), load in
    /// expected seconds (queued weight over speed).
    TwoChoices,
    /// Request by request, the replica that would finish it first (queued weight plus the
    /// request's, over speed): least loaded when speeds are equal.
    GreedyLeastLoaded,
}

impl Baseline {
    /// Every baseline.
    pub const ALL: [Baseline; 4] = [
        Baseline::RandomReplica,
        Baseline::RoundRobin,
        Baseline::TwoChoices,
        Baseline::GreedyLeastLoaded,
    ];

    /// A short name for files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::RandomReplica => "random-replica",
            Baseline::RoundRobin => "round-robin",
            Baseline::TwoChoices => "two-choices",
            Baseline::GreedyLeastLoaded => "greedy-least-loaded",
        }
    }
}

/// Who assigns the requests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Policy {
    /// The c-collision balancer.
    Balancer(Config),
    /// A baseline.
    Baseline(Baseline),
}

/// One simulation run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationConfig {
    /// Number of workers.
    pub workers: usize,
    /// Replicas per object.
    pub replicas: usize,
    /// Seed of the placement (and of the randomized choices).
    pub seed: u64,
    /// Relative speed of each worker (1 = `base_speed`); empty for all 1.
    pub speeds: Vec<f64>,
    /// Weight a speed-1 worker works off per second.
    pub base_speed: f64,
    /// Who assigns.
    pub policy: Policy,
}

/// The figures of one position of the walk-through.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PositionStats {
    /// The frame.
    pub frame: u64,
    /// Requests at this position.
    pub requests: usize,
    /// Their summed weight.
    pub total_weight: f64,
    /// Median over workers of the share of this position's weight each one got.
    pub median_share: f64,
    /// 0.1 quantile of the shares.
    pub q10_share: f64,
    /// 0.9 quantile of the shares.
    pub q90_share: f64,
    /// The busiest worker's weight over the lower bound `max(total / n, heaviest request)`.
    pub busiest_over_bound: f64,
    /// When the last of this position's requests is done (each worker works off its queue
    /// in order, with what it held before), over the least time they could take on idle
    /// workers: `max(total / Σ speeds, heaviest / fastest speed)`. Unlike
    /// `busiest_over_bound` it counts time, so it judges how speeds are used: giving a slow
    /// worker a fair share of the weight makes it the last to finish.
    pub finish_over_bound: f64,
    /// The largest `c` the balancer needed (0 for baselines).
    pub max_c: f64,
}

/// The result of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationResult {
    /// Per position.
    pub positions: Vec<PositionStats>,
    /// The largest `c` over the run.
    pub max_c: f64,
    /// Mean of `busiest_over_bound` over positions with at least `2n` requests (`NaN` when
    /// there are none).
    pub mean_busiest_over_bound_busy: f64,
    /// Mean of `busiest_over_bound` over all positions with requests.
    pub mean_busiest_over_bound: f64,
    /// Mean of `finish_over_bound` over positions with at least `2n` requests (`NaN` when
    /// there are none).
    pub mean_finish_over_bound_busy: f64,
    /// Mean of `finish_over_bound` over all positions with requests.
    pub mean_finish_over_bound: f64,
    /// Share of the total weight each worker got over the whole run.
    pub worker_shares: Vec<f64>,
}

/// Replays `trace` under `config`.
pub fn simulate(
    trace: &Trace,
    config: &SimulationConfig,
) -> Result<SimulationResult, BalancerError> {
    let workers = config.workers;
    let placement = Placement::random(
        trace.object_count().max(1),
        workers,
        config.replicas,
        config.seed,
    )?;
    let speeds: Vec<f64> = if config.speeds.is_empty() {
        vec![1.0; workers]
    } else {
        config.speeds.clone()
    };
    if speeds.len() != workers || speeds.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
        return Err(BalancerError::BadConfig(format!(
            "need {workers} positive worker speeds, got {:?}",
            speeds.len()
        )));
    }
    let mut balancer = match &config.policy {
        Policy::Balancer(protocol) => {
            let mut balancer = Balancer::new(
                placement.clone(),
                Config {
                    seed: config.seed,
                    ..protocol.clone()
                },
            )?;
            for (worker, speed) in speeds.iter().enumerate() {
                balancer.set_speed(worker as u32, speed * config.base_speed)?;
            }
            Some(balancer)
        }
        Policy::Baseline(_) => None,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut round_robin = vec![0usize; placement.object_count()];
    // Per worker: (request id, weight left, weight).
    let mut queues: Vec<VecDeque<(u64, f64, f64)>> = vec![VecDeque::new(); workers];
    let mut loads = vec![0.0f64; workers];
    let mut totals = vec![0.0f64; workers];
    let mut next_id = 0u64;
    let mut last_time: Option<f64> = None;
    let mut positions = Vec::new();
    let mut run_max_c: f64 = 0.0;
    let mut assigned_now = vec![0.0f64; workers];

    // Weight per second of all workers together, and of the fastest.
    let total_speed = speeds.iter().sum::<f64>() * config.base_speed;
    let fastest = speeds.iter().copied().fold(0.0f64, f64::max) * config.base_speed;
    for (frame, time, records) in trace.positions() {
        // Work off the queues since the last position.
        let elapsed = last_time.map_or(0.0, |t| (time - t).max(0.0));
        last_time = Some(time);
        for worker in 0..workers {
            let mut budget = speeds[worker] * config.base_speed * elapsed;
            while let Some(front) = queues[worker].front_mut() {
                if front.1 > budget {
                    front.1 -= budget;
                    loads[worker] -= budget;
                    break;
                }
                budget -= front.1;
                loads[worker] -= front.1;
                let (id, _, weight) = queues[worker].pop_front().unwrap_or_default();
                if let Some(balancer) = balancer.as_mut() {
                    // The worker's own render time, as a live worker reports it.
                    let seconds = weight / (speeds[worker] * config.base_speed);
                    let _ = balancer.complete(id, Some(seconds));
                }
            }
            if queues[worker].is_empty() {
                loads[worker] = 0.0;
            }
        }

        let requests: Vec<Request> = records
            .iter()
            .map(|r| {
                next_id += 1;
                Request {
                    id: next_id,
                    object: r.object,
                    weight: r.weight,
                    priority: 0.0,
                }
            })
            .collect();
        assigned_now.iter_mut().for_each(|a| *a = 0.0);
        let mut max_c: f64 = 0.0;
        let assignments: Vec<(Request, u32)> = match (&config.policy, balancer.as_mut()) {
            (Policy::Balancer(_), Some(balancer)) => {
                let outcome = balancer.assign(requests);
                max_c = outcome.max_c;
                outcome.assigned
            }
            (Policy::Baseline(baseline), _) => requests
                .into_iter()
                .filter_map(|request| {
                    let holders = placement.replicas(request.object)?;
                    let worker = match baseline {
                        Baseline::RandomReplica => holders[rng.random_range(0..holders.len())],
                        Baseline::RoundRobin => {
                            let turn = &mut round_robin[request.object as usize];
                            *turn += 1;
                            holders[(*turn - 1) % holders.len()]
                        }
                        Baseline::TwoChoices => {
                            // Two distinct replicas (one when there is only one).
                            let first = rng.random_range(0..holders.len());
                            let second =
                                (first + rng.random_range(1..holders.len().max(2))) % holders.len();
                            let (a, b) = (holders[first], holders[second]);
                            let seconds = |w: u32| loads[w as usize] / speeds[w as usize];
                            if seconds(b) < seconds(a) { b } else { a }
                        }
                        Baseline::GreedyLeastLoaded => {
                            let finish =
                                |w: u32| (loads[w as usize] + request.weight) / speeds[w as usize];
                            *holders
                                .iter()
                                .min_by(|a, b| finish(**a).total_cmp(&finish(**b)))
                                .unwrap_or(&holders[0])
                        }
                    };
                    loads[worker as usize] += request.weight;
                    Some((request, worker))
                })
                .collect(),
            _ => Vec::new(),
        };
        for (request, worker) in &assignments {
            if balancer.is_some() {
                loads[*worker as usize] += request.weight;
            }
            queues[*worker as usize].push_back((request.id, request.weight, request.weight));
            assigned_now[*worker as usize] += request.weight;
            totals[*worker as usize] += request.weight;
        }
        run_max_c = run_max_c.max(max_c);
        // FIFO queues: a worker that got a request here finishes it when its queue is empty.
        let last_finish = (0..workers)
            .filter(|&w| assigned_now[w] > 0.0)
            .map(|w| loads[w] / (speeds[w] * config.base_speed))
            .fold(0.0f64, f64::max);
        positions.push(position_stats(
            frame,
            records.iter().map(|r| r.weight),
            &assigned_now,
            max_c,
            (last_finish, total_speed, fastest),
        ));
    }

    // The mean of a figure over positions with at least `fewest` requests.
    let mean = |fewest: usize, figure: fn(&PositionStats) -> f64| {
        let values: Vec<f64> = positions
            .iter()
            .filter(|p| p.requests >= fewest.max(1))
            .map(figure)
            .collect();
        if values.is_empty() {
            f64::NAN
        } else {
            values.iter().sum::<f64>() / values.len() as f64
        }
    };
    let grand_total: f64 = totals.iter().sum();
    Ok(SimulationResult {
        mean_busiest_over_bound_busy: mean(2 * workers, |p| p.busiest_over_bound),
        mean_busiest_over_bound: mean(1, |p| p.busiest_over_bound),
        mean_finish_over_bound_busy: mean(2 * workers, |p| p.finish_over_bound),
        mean_finish_over_bound: mean(1, |p| p.finish_over_bound),
        max_c: run_max_c,
        worker_shares: totals
            .iter()
            .map(|t| {
                if grand_total > 0.0 {
                    t / grand_total
                } else {
                    0.0
                }
            })
            .collect(),
        positions,
    })
}

fn position_stats(
    frame: u64,
    weights: impl Iterator<Item = f64>,
    assigned: &[f64],
    max_c: f64,
    (last_finish, total_speed, fastest): (f64, f64, f64),
) -> PositionStats {
    let (mut requests, mut total, mut heaviest) = (0usize, 0.0f64, 0.0f64);
    for w in weights {
        requests += 1;
        total += w;
        heaviest = heaviest.max(w);
    }
    let mut shares: Vec<f64> = assigned
        .iter()
        .map(|a| if total > 0.0 { a / total } else { 0.0 })
        .collect();
    shares.sort_by(f64::total_cmp);
    let bound = (total / assigned.len() as f64).max(heaviest);
    let busiest = assigned.iter().copied().fold(0.0, f64::max);
    PositionStats {
        frame,
        requests,
        total_weight: total,
        median_share: report::quantile(&shares, 0.5),
        q10_share: report::quantile(&shares, 0.1),
        q90_share: report::quantile(&shares, 0.9),
        busiest_over_bound: if bound > 0.0 { busiest / bound } else { 0.0 },
        finish_over_bound: {
            let ideal = (total / total_speed).max(heaviest / fastest);
            if ideal > 0.0 {
                last_finish / ideal
            } else {
                0.0
            }
        },
        max_c,
    }
}

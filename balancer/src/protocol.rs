//! The c-collision protocol in its weighted c-load-collision form.

use std::collections::HashMap;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::pick::pick_candidate;
use crate::placement::Placement;

/// A request for one object's reliefboard.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Request {
    /// Unique while the request is in flight.
    pub id: u64,
    /// The object.
    pub object: u32,
    /// Its cost to render: the object's triangles.
    pub weight: f64,
    /// Higher goes first when more is pending than the workers can take (for example the
    /// screen-space error the board removes times its screen area).
    pub priority: f64,
}

/// How a worker decides whether to answer a round.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Collision {
    /// c-collision: answer when offered at most `c` requests.
    Count,
    /// c-load-collision: answer when the offered weight is at most `c`, weights measured in
    /// units of the heaviest request of the group.
    Load,
}

/// How the balancer picks among several workers that answered for the same request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// The lightest by the sum of its active jobs.
    Deterministic,
    /// Randomly, lighter workers more likely: see [`crate::randomized_probabilities`].
    Randomized,
}

/// What the balancer does with the workers' measured speeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpeedUse {
    /// Every worker counts as equally fast: loads are weights.
    Ignored,
    /// Picks compare expected time (a request goes to the answering worker that would
    /// finish it first); offers are weights, so a slow worker answers as often as a fast one.
    Picks,
    /// As `Picks`, and a slow worker also sees every offer as heavier, so it answers less.
    OffersAndPicks,
}

/// Parameters of the protocol.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Count or weight.
    pub collision: Collision,
    /// Picking among answering workers.
    pub strategy: Strategy,
    /// `c` at the start and after every round that made progress: 1 in Süß's chapter 4,
    /// 2 in chapter 5; 8 here, tuned on the synthetic orbit (docs/balancer.md): with 2 the
    /// busiest worker was 2-14% above greedy earliest-finish, with 8 within 3%.
    pub c_start: f64,
    /// Added to `c` after a round that answered nothing.
    pub c_step: f64,
    /// Whether measured worker speeds turn loads into expected seconds, and where.
    pub speeds: SpeedUse,
    /// A worker with this many unfinished jobs takes no more (its queue is full); `None` for
    /// no bound.
    pub max_jobs_per_worker: Option<u32>,
    /// A live, idle worker that got none of the last `refresh_after × live workers` requests
    /// takes the next one it holds, whatever its estimate, so a speed misjudged once is
    /// measured again and no live worker starves; an estimate's weight against the next
    /// measurement halves with every such span it went unmeasured. 0: neither.
    pub refresh_after: u32,
    /// Süß's Figure 5.5 rule: a worker assigned requests in a round of a group answers no
    /// later round of that group (requests only it could take are deferred). Off by default:
    /// here it can only matter for a starving worker, which is assigned without answering
    /// (docs/balancer.md measures it).
    pub answer_once_per_group: bool,
    /// Seed of the randomized strategy.
    pub seed: u64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            collision: Collision::Load,
            strategy: Strategy::Deterministic,
            c_start: 8.0,
            c_step: 1.0,
            speeds: SpeedUse::OffersAndPicks,
            max_jobs_per_worker: None,
            refresh_after: 8,
            answer_once_per_group: false,
            seed: 1,
        }
    }
}

/// What the balancer knows of one worker.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WorkerStatus {
    /// Dead workers are offered nothing.
    pub alive: bool,
    /// Summed weight of unfinished jobs.
    pub load: f64,
    /// Number of unfinished jobs.
    pub jobs: u32,
    /// Speed in weight per second: set, or measured (exponential moving average); 1 until
    /// either happens. Only ratios between workers matter.
    pub speed: f64,
    /// How many completions have been measured into `speed`.
    pub speed_samples: u32,
    /// The balancer's count of assigned requests when this worker last got one.
    pub last_job: u64,
    /// That count when `speed` was last measured.
    pub last_sample: u64,
}

/// Errors of the balancer's API (never of the protocol itself, which always terminates).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BalancerError {
    /// A placement over zero workers.
    #[error("there are no workers")]
    NoWorkers,
    /// `k` outside `1..=workers`.
    #[error("cannot place {replicas} replicas on {workers} workers (need 1..=workers)")]
    BadReplicaCount {
        /// Requested replicas.
        replicas: usize,
        /// Workers.
        workers: usize,
    },
    /// An explicit placement with an empty or out-of-range replica list.
    #[error("object {object} has no valid replica")]
    BadPlacement {
        /// The object.
        object: u32,
    },
    /// A request id the balancer does not have in flight.
    #[error("request {0} is not in flight")]
    UnknownRequest(u64),
    /// A worker index out of range.
    #[error("worker {0} does not exist")]
    UnknownWorker(u32),
    /// A configuration value out of range.
    #[error("invalid configuration: {0}")]
    BadConfig(String),
}

/// Why a request cannot be assigned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[serde(rename_all = "kebab-case")]
pub enum Unassignable {
    /// Every worker holding the object is dead: the front end draws its geometry.
    #[error("every replica is down")]
    NoLiveReplica,
    /// The placement does not know the object.
    #[error("no worker holds the object")]
    UnknownObject,
    /// The weight is NaN, infinite, zero or negative: no worker's load could account for it.
    #[error("the weight is not a positive finite number")]
    BadWeight,
}

/// The outcome of one [`Balancer::assign`] call.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Assignment {
    /// Each assigned request with its worker.
    pub assigned: Vec<(Request, u32)>,
    /// Requests that cannot be assigned, each with why (every replica dead, an unknown
    /// object, a weight that is not a positive finite number): the front end draws their
    /// geometry.
    pub unassignable: Vec<(Request, Unassignable)>,
    /// Requests whose live replicas all have full queues: hand them in again later.
    pub deferred: Vec<Request>,
    /// Rounds played.
    pub rounds: u32,
    /// The largest `c` any round needed.
    pub max_c: f64,
}

/// Assigns requests to workers and tracks them until their boards arrive.
#[derive(Debug, Clone)]
pub struct Balancer {
    config: Config,
    placement: Placement,
    workers: Vec<WorkerStatus>,
    in_flight: HashMap<u64, (u32, f64)>,
    /// Requests assigned so far: the clock of staleness.
    assigned_total: u64,
    rng: ChaCha8Rng,
}

impl Balancer {
    /// A balancer for the workers of `placement`, all alive and idle.
    pub fn new(placement: Placement, config: Config) -> Result<Balancer, BalancerError> {
        if !(config.c_start > 0.0)
            || !(config.c_step > 0.0)
            || !config.c_start.is_finite()
            || !config.c_step.is_finite()
        {
            return Err(BalancerError::BadConfig(format!(
                "c_start and c_step must be positive, got {} and {}",
                config.c_start, config.c_step
            )));
        }
        let idle = WorkerStatus {
            alive: true,
            load: 0.0,
            jobs: 0,
            speed: 1.0,
            speed_samples: 0,
            last_job: 0,
            last_sample: 0,
        };
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        Ok(Balancer {
            workers: vec![idle; placement.worker_count()],
            placement,
            config,
            in_flight: HashMap::new(),
            assigned_total: 0,
            rng,
        })
    }

    /// The workers' state.
    pub fn workers(&self) -> &[WorkerStatus] {
        &self.workers
    }

    /// The placement.
    pub fn placement(&self) -> &Placement {
        &self.placement
    }

    /// Requests assigned and not yet completed.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Assigns `requests` (see the crate docs). Higher priorities are served first: requests
    /// are played in groups of at most n (the live workers) in order of priority, so when the
    /// queues fill, what is left over is the least important.
    ///
    /// Within a group, each round offers every open request to every live worker holding it
    /// with room in its queue. A worker whose offers (count, or weight in units of the group's
    /// heaviest request) are at most `c` answers all of them; each answered request goes to
    /// one answering worker, picked by load. A round that answers nothing raises `c` by
    /// `c_step`; the next round after progress starts again from `c_start`. Some worker always
    /// holds an offer while requests are open, so `c` eventually reaches its offers: no
    /// deadlock. The rounds that would answer nothing are counted but not played: `c` jumps
    /// to the first step that reaches the smallest offer, so every played round assigns, and
    /// a call plays at most two rounds per request whatever `c_step` is.
    pub fn assign(&mut self, mut requests: Vec<Request>) -> Assignment {
        let mut outcome = Assignment {
            max_c: self.config.c_start,
            ..Assignment::default()
        };
        // Stable: equal priorities keep their order.
        requests.sort_by(|a, b| b.priority.total_cmp(&a.priority));
        let live = self.workers.iter().filter(|w| w.alive).count().max(1);
        let mut offered = vec![0.0f64; self.workers.len()];
        let mut candidates: Vec<u32> = Vec::new();
        let mut candidate_loads: Vec<f64> = Vec::new();
        let speeds = self.relative_speeds();
        let mut done_in_group: Vec<bool> = Vec::new();
        for group in requests.chunks(live) {
            let heaviest = group
                .iter()
                .map(|r| r.weight)
                .filter(|w| w.is_finite())
                .fold(0.0f64, f64::max);
            let mut open: Vec<Request> = Vec::with_capacity(group.len());
            for request in group {
                match self.placement.replicas(request.object) {
                    _ if !(request.weight > 0.0 && request.weight.is_finite()) => outcome
                        .unassignable
                        .push((*request, Unassignable::BadWeight)),
                    None => outcome
                        .unassignable
                        .push((*request, Unassignable::UnknownObject)),
                    Some(holders) if holders.iter().any(|&w| self.workers[w as usize].alive) => {
                        open.push(*request)
                    }
                    Some(_) => outcome
                        .unassignable
                        .push((*request, Unassignable::NoLiveReplica)),
                }
            }
            let mut c = self.config.c_start;
            // Workers kept out of the group's later rounds (Figure 5.5's rule).
            done_in_group.clear();
            done_in_group.resize(self.workers.len(), false);
            while !open.is_empty() {
                outcome.rounds = outcome.rounds.saturating_add(1);
                outcome.max_c = outcome.max_c.max(c);
                let round_start = outcome.assigned.len();
                let open_to = |balancer: &Balancer, worker: u32| {
                    balancer.has_room(worker) && !done_in_group[worker as usize]
                };
                // Offers.
                offered.iter_mut().for_each(|o| *o = 0.0);
                open.retain(|request| {
                    let mut any = false;
                    for &worker in self.placement.replicas(request.object).unwrap_or(&[]) {
                        if open_to(self, worker) {
                            let slowness = if self.config.speeds == SpeedUse::OffersAndPicks {
                                1.0 / speeds[worker as usize]
                            } else {
                                1.0
                            };
                            offered[worker as usize] +=
                                self.offer_size(request.weight, heaviest, slowness);
                            any = true;
                        }
                    }
                    if !any {
                        outcome.deferred.push(*request);
                    }
                    any
                });
                // Answers and picks, in priority order.
                let mut progress = false;
                let mut still_open = Vec::new();
                for request in std::mem::take(&mut open) {
                    candidates.clear();
                    candidate_loads.clear();
                    // A starving worker answers whatever its offers: it gets the request,
                    // and its speed is measured again.
                    let starving = self
                        .placement
                        .replicas(request.object)
                        .unwrap_or(&[])
                        .iter()
                        .copied()
                        .find(|&w| open_to(self, w) && self.starving(w, live));
                    candidates.extend(
                        self.placement
                            .replicas(request.object)
                            .unwrap_or(&[])
                            .iter()
                            .copied()
                            .filter(|&w| open_to(self, w) && offered[w as usize] <= c),
                    );
                    // Equal loads (idle workers, most often) go to the one that waited
                    // longest: the pick takes the first of equals, and replica lists are
                    // in worker order, which favoured low-numbered workers.
                    candidates.sort_by_key(|&w| self.workers[w as usize].last_job);
                    candidate_loads.extend(
                        candidates
                            .iter()
                            .map(|&w| self.pick_load(w, request.weight, speeds[w as usize])),
                    );
                    let worker = match starving {
                        Some(worker) => worker,
                        None if candidates.is_empty() => {
                            still_open.push(request);
                            continue;
                        }
                        None => {
                            candidates[pick_candidate(
                                &candidate_loads,
                                self.config.strategy,
                                &mut self.rng,
                            )]
                        }
                    };
                    self.start_job(request, worker);
                    outcome.assigned.push((request, worker));
                    progress = true;
                }
                open = still_open;
                if self.config.answer_once_per_group {
                    for (_, worker) in &outcome.assigned[round_start..] {
                        done_in_group[*worker as usize] = true;
                    }
                }
                c = if progress {
                    self.config.c_start
                } else {
                    // The rounds until c reaches the smallest offer would answer nothing:
                    // count them, play the one that answers.
                    let smallest = offered
                        .iter()
                        .copied()
                        .filter(|&o| o > c)
                        .fold(f64::INFINITY, f64::min);
                    let steps = ((smallest - c) / self.config.c_step).ceil().max(1.0);
                    if !steps.is_finite() {
                        // No offer is finite: cannot happen with finite weights and speeds,
                        // but nothing may loop forever.
                        outcome.deferred.append(&mut open);
                        break;
                    }
                    outcome.rounds = outcome.rounds.saturating_add(steps as u32 - 1);
                    // A step short of the smallest offer by rounding still reaches it.
                    (c + steps * self.config.c_step).max(smallest)
                };
            }
        }
        outcome
    }

    /// The board of request `id` arrived: its worker's load drops. `seconds`, when given, is
    /// the time the worker spent rendering it (its own measure, without the time queued or on
    /// the wire, so a job that waited behind others does not make its worker look slow); it
    /// updates the worker's measured speed. A zero, negative or non-finite time is ignored.
    pub fn complete(&mut self, id: u64, seconds: Option<f64>) -> Result<u32, BalancerError> {
        let (worker, weight) = self
            .in_flight
            .remove(&id)
            .ok_or(BalancerError::UnknownRequest(id))?;
        let status = &mut self.workers[worker as usize];
        status.load = (status.load - weight).max(0.0);
        status.jobs = status.jobs.saturating_sub(1);
        if let Some(rate) = seconds
            .map(|s| weight / s)
            .filter(|r| *r > 0.0 && r.is_finite())
        {
            // An estimate weighs less the longer it went unmeasured, so a worker misjudged
            // once (and since passed over) recovers with its next board.
            let kept = 0.8 * self.kept(worker);
            let status = &mut self.workers[worker as usize];
            status.speed = if status.speed_samples == 0 {
                rate
            } else {
                kept * status.speed + (1.0 - kept) * rate
            };
            status.speed_samples += 1;
            status.last_sample = self.assigned_total;
        }
        Ok(worker)
    }

    /// Gives up on request `id` (its worker failed or timed out) without completing it.
    pub fn cancel(&mut self, id: u64) -> Result<u32, BalancerError> {
        self.complete(id, None)
    }

    /// Marks a worker dead or alive. A dead worker's in-flight requests are cancelled and
    /// returned as ids, for the caller to request again (they go to other replicas).
    pub fn set_alive(&mut self, worker: u32, alive: bool) -> Result<Vec<u64>, BalancerError> {
        let status = self
            .workers
            .get_mut(worker as usize)
            .ok_or(BalancerError::UnknownWorker(worker))?;
        status.alive = alive;
        if alive {
            return Ok(Vec::new());
        }
        let mut lost: Vec<u64> = self
            .in_flight
            .iter()
            .filter(|(_, (w, _))| *w == worker)
            .map(|(id, _)| *id)
            .collect();
        lost.sort_unstable();
        for id in &lost {
            self.cancel(*id)?;
        }
        Ok(lost)
    }

    /// Adds a worker that joined while running (a cluster scaled out) with replicas of about its
    /// share of the objects ([`Placement::add_worker`]); returns its index and the objects it
    /// must hold. It starts dead: mark it alive once it has stored them. Its speed starts at the
    /// live workers' mean, so it is neither favoured nor starved before it is measured.
    pub fn add_worker(&mut self, seed: u64) -> (u32, Vec<u32>) {
        let measured: Vec<f64> = self
            .workers
            .iter()
            .filter(|w| w.alive && w.speed_samples > 0 && usable_speed(w.speed))
            .map(|w| w.speed)
            .collect();
        let speed = if measured.is_empty() {
            1.0
        } else {
            measured.iter().sum::<f64>() / measured.len() as f64
        };
        let (worker, held) = self.placement.add_worker(seed);
        self.workers.push(WorkerStatus {
            alive: false,
            load: 0.0,
            jobs: 0,
            speed,
            speed_samples: 0,
            last_job: self.assigned_total,
            last_sample: self.assigned_total,
        });
        (worker, held)
    }

    /// Changes where measured speeds are used ([`Config::speeds`]), keeping what was measured.
    pub fn use_speeds(&mut self, speeds: SpeedUse) {
        self.config.speeds = speeds;
    }

    /// Sets a worker's speed (weight per second), for example from its own status report.
    pub fn set_speed(&mut self, worker: u32, speed: f64) -> Result<(), BalancerError> {
        let status = self
            .workers
            .get_mut(worker as usize)
            .ok_or(BalancerError::UnknownWorker(worker))?;
        if speed > 0.0 && speed.is_finite() {
            status.speed = speed;
            status.speed_samples = status.speed_samples.max(1);
        }
        Ok(())
    }

    fn has_room(&self, worker: u32) -> bool {
        let status = &self.workers[worker as usize];
        status.alive
            && self
                .config
                .max_jobs_per_worker
                .is_none_or(|max| status.jobs < max)
    }

    /// What one request adds to a worker's offers in a round.
    fn offer_size(&self, weight: f64, heaviest: f64, slowness: f64) -> f64 {
        match self.config.collision {
            Collision::Count => 1.0,
            Collision::Load => {
                let normalised = if heaviest > 0.0 {
                    weight / heaviest
                } else {
                    1.0
                };
                normalised * slowness
            }
        }
    }

    /// The load the pick compares: the weight of active jobs; with speeds the time to finish
    /// them, and for the deterministic pick the time until this request would be
    /// done (so an idle slow worker loses to an idle fast one). With equal speeds both orders
    /// are the homogeneous ones, so the randomized formula keeps its meaning.
    fn pick_load(&self, worker: u32, weight: f64, speed: f64) -> f64 {
        let status = &self.workers[worker as usize];
        match (self.config.speeds, self.config.strategy) {
            (SpeedUse::Ignored, _) => status.load,
            (_, Strategy::Randomized) => status.load / speed,
            (_, Strategy::Deterministic) => (status.load + weight) / speed,
        }
    }

    /// Requests assigned since `worker` last got one.
    fn age(&self, worker: u32) -> u64 {
        self.assigned_total - self.workers[worker as usize].last_job
    }

    /// Whether `worker` is live and idle and has had no request for so long that the next
    /// one it answers for is its (see [`Config::refresh_after`]).
    fn starving(&self, worker: u32, live: usize) -> bool {
        let status = &self.workers[worker as usize];
        self.config.refresh_after > 0
            && status.alive
            && status.jobs == 0
            && self.age(worker) >= self.config.refresh_after as u64 * live as u64
    }

    /// The weight left to `worker`'s speed estimate: halved every
    /// `refresh_after × live workers` requests assigned since it was measured (1 when
    /// `refresh_after` is 0).
    fn kept(&self, worker: u32) -> f64 {
        if self.config.refresh_after == 0 {
            return 1.0;
        }
        let live = self.workers.iter().filter(|w| w.alive).count().max(1);
        let half_life = self.config.refresh_after as f64 * live as f64;
        let age = self.assigned_total - self.workers[worker as usize].last_sample;
        0.5f64.powf(age as f64 / half_life)
    }

    /// Each worker's measured speed in units of the mean live worker's, in steps of √2 (see
    /// [`in_steps`]; all 1 when speeds are not used; a worker with no usable speed counts as
    /// the mean).
    fn relative_speeds(&self) -> Vec<f64> {
        if self.config.speeds == SpeedUse::Ignored {
            return vec![1.0; self.workers.len()];
        }
        // A worker not measured yet counts as the mean: its placeholder speed of 1 is no
        // estimate (against measured speeds in the millions it made every measured worker
        // look infinitely faster, and the first one measured took every request).
        let usable = |w: &WorkerStatus| w.alive && w.speed_samples > 0 && usable_speed(w.speed);
        let (sum, count) = self
            .workers
            .iter()
            .filter(|w| usable(w))
            .fold((0.0, 0), |(s, n), w| (s + w.speed, n + 1));
        let mean = if count > 0 { sum / count as f64 } else { 1.0 };
        self.workers
            .iter()
            .map(|w| {
                if usable(w) {
                    in_steps(w.speed / mean)
                } else {
                    1.0
                }
            })
            .collect()
    }

    fn start_job(&mut self, request: Request, worker: u32) {
        let status = &mut self.workers[worker as usize];
        status.load += request.weight;
        status.jobs += 1;
        self.assigned_total += 1;
        // Counted with this request, so a worker that just got one is younger than every
        // worker that never did (their `last_job` is 0).
        status.last_job = self.assigned_total;
        self.in_flight.insert(request.id, (worker, request.weight));
    }
}

/// Whether a speed can be used: positive and finite.
fn usable_speed(speed: f64) -> bool {
    speed > 0.0 && speed.is_finite()
}

/// `relative_speed` rounded to a power of √2: workers within about ±19% of each other count
/// as equal. Measurement noise between identical workers (on a shared machine, render times
/// vary with what else runs) must not make one of them decline every round the others
/// answer (with a continuous factor, 0.02% slower meant no work at all) nor win every tie.
fn in_steps(relative_speed: f64) -> f64 {
    let halves = (relative_speed.log2() * 2.0).round();
    if halves.is_finite() {
        2f64.powf(halves / 2.0)
    } else {
        1.0
    }
}

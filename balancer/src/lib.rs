//! Assigns reliefboard requests to backend workers, and replays request traces to study how
//! well it does.
//!
//! Objects are placed on workers randomly and redundantly ([`Placement`]). The visualization
//! node hands each frame's pending requests to a [`Balancer`], which assigns every request to
//! one live worker holding its object with the c-collision protocol in its weighted
//! c-load-collision form (Süß 2011, §4.3 and §5.4; Berenbrink et al. 1997): see
//! [`Balancer::assign`]. Assignments stay until the board arrives ([`Balancer::complete`]),
//! so a worker's load counts its unfinished jobs and rounds overlap across frames.
//!
//! [`simulate()`] replays a [`Trace`] on any number of simulated workers, for the balancer and
//! for the baselines it is measured against ([`Policy`]).
//!
//! **Architecture invariant:** this crate does no I/O in its library and knows nothing of
//! gRPC, workers or rendering: requests are object ids with weights. Reading and writing
//! traces and reports is the binary's job.
#![warn(missing_docs)]

mod pick;
mod placement;
mod protocol;
mod simulate;
mod trace;

pub use pick::{pick_candidate, randomized_probabilities};
pub use placement::Placement;
pub use protocol::{
    Assignment, Balancer, BalancerError, Collision, Config, Request, SpeedUse, Strategy,
    Unassignable, WorkerStatus,
};
pub use simulate::{Baseline, Policy, PositionStats, SimulationConfig, SimulationResult, simulate};
pub use trace::{SYNTHETIC_TRACES, Trace, TraceRecord, synthetic_trace};

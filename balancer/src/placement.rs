//! Random redundant placement of objects on workers.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::protocol::BalancerError;

/// Which workers hold a replica of each object.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    workers: usize,
    replicas: Vec<Vec<u32>>,
}

impl Placement {
    /// Places each of `objects` on `k` distinct workers out of `workers`, uniformly at random
    /// from `seed`.
    pub fn random(
        objects: usize,
        workers: usize,
        k: usize,
        seed: u64,
    ) -> Result<Placement, BalancerError> {
        if workers == 0 {
            return Err(BalancerError::NoWorkers);
        }
        if k == 0 || k > workers {
            return Err(BalancerError::BadReplicaCount {
                replicas: k,
                workers,
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let replicas = (0..objects)
            .map(|_| {
                let mut chosen: Vec<u32> = rand::seq::index::sample(&mut rng, workers, k)
                    .into_iter()
                    .map(|w| w as u32)
                    .collect();
                chosen.sort_unstable();
                chosen
            })
            .collect();
        Ok(Placement { workers, replicas })
    }

    /// A placement given explicitly: `replicas[object]` lists the workers holding it.
    pub fn from_replicas(
        workers: usize,
        replicas: Vec<Vec<u32>>,
    ) -> Result<Placement, BalancerError> {
        if workers == 0 {
            return Err(BalancerError::NoWorkers);
        }
        for (object, holders) in replicas.iter().enumerate() {
            if holders.is_empty() || holders.iter().any(|&w| w as usize >= workers) {
                return Err(BalancerError::BadPlacement {
                    object: object as u32,
                });
            }
        }
        Ok(Placement { workers, replicas })
    }

    /// Adds a worker that joined later and gives it a replica of each object with probability
    /// `k / workers` (k the mean replicas per object, workers counting the new one), so it
    /// holds about as many objects as the others; replicas already placed stay where they are.
    /// Returns the new worker's index and the objects it holds.
    pub fn add_worker(&mut self, seed: u64) -> (u32, Vec<u32>) {
        let worker = self.workers as u32;
        self.workers += 1;
        let placed: usize = self.replicas.iter().map(Vec::len).sum();
        let share = if self.replicas.is_empty() {
            0.0
        } else {
            placed as f64 / self.replicas.len() as f64 / self.workers as f64
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut held = Vec::new();
        for (object, holders) in self.replicas.iter_mut().enumerate() {
            if rng.random_bool(share.clamp(0.0, 1.0)) {
                holders.push(worker);
                held.push(object as u32);
            }
        }
        (worker, held)
    }

    /// The workers holding `object`, or `None` for an unknown object.
    pub fn replicas(&self, object: u32) -> Option<&[u32]> {
        self.replicas.get(object as usize).map(Vec::as_slice)
    }

    /// Number of workers.
    pub fn worker_count(&self) -> usize {
        self.workers
    }

    /// Number of objects.
    pub fn object_count(&self) -> usize {
        self.replicas.len()
    }

    /// The objects each worker holds.
    pub fn objects_of_workers(&self) -> Vec<Vec<u32>> {
        let mut held = vec![Vec::new(); self.workers];
        for (object, holders) in self.replicas.iter().enumerate() {
            for &worker in holders {
                held[worker as usize].push(object as u32);
            }
        }
        held
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_worker_added_later_holds_about_its_share() {
        let mut placement = Placement::random(3000, 4, 2, 1).unwrap();
        let before = placement.objects_of_workers();
        let (worker, held) = placement.add_worker(9);
        assert_eq!(worker, 4);
        assert_eq!(placement.worker_count(), 5);
        // Expected 3000 * 2 / 5 = 1200; the old workers keep what they held.
        assert!((1100..1300).contains(&held.len()), "{}", held.len());
        let of_workers = placement.objects_of_workers();
        assert_eq!(of_workers[4], held);
        assert_eq!(of_workers[..4], before[..]);
        for &object in &held {
            assert!(placement.replicas(object).unwrap().contains(&4));
        }
    }
}

//! Random redundant placement of objects on workers.

use rand::SeedableRng;
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

//! Choosing one worker among several that could take a request (Süß §5.4).

use rand::RngExt;

use crate::protocol::Strategy;

/// The randomized strategy's probability for each candidate with loads `loads`:
/// `(T - s_i) / ((|P| - 1) · T)`, `T` the sum of the loads. The formula is undefined for one
/// candidate (it gets probability 1) and when every candidate is idle (`T = 0`: uniform).
pub fn randomized_probabilities(loads: &[f64]) -> Vec<f64> {
    let count = loads.len();
    let total: f64 = loads.iter().sum();
    if count == 1 {
        return vec![1.0];
    }
    if !(total > 0.0) {
        return vec![1.0 / count as f64; count];
    }
    loads
        .iter()
        .map(|&s| (total - s) / ((count - 1) as f64 * total))
        .collect()
}

/// Picks the index of one candidate given their loads: the lightest (ties to the first) for
/// [`Strategy::Deterministic`], or by [`randomized_probabilities`].
pub fn pick_candidate(loads: &[f64], strategy: Strategy, rng: &mut impl rand::Rng) -> usize {
    debug_assert!(!loads.is_empty());
    match strategy {
        Strategy::Deterministic => {
            let mut best = 0;
            for (index, &load) in loads.iter().enumerate() {
                if load < loads[best] {
                    best = index;
                }
            }
            best
        }
        Strategy::Randomized => {
            let probabilities = randomized_probabilities(loads);
            let mut draw: f64 = rng.random();
            for (index, p) in probabilities.iter().enumerate() {
                if draw < *p {
                    return index;
                }
                draw -= p;
            }
            loads.len() - 1 // rounding left a sliver: the last candidate
        }
    }
}

//! Times Phase III on synthetic base clusters: `cargo run --release -p scene --example cluster_timing -- N`.
use glam::DVec3;
use rand::{RngExt, SeedableRng};

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(100_000);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    // Tiny triangles, uniformly spread: the density stays the same for every n.
    let side = (n as f64).cbrt();
    let boxes: Vec<scene::Aabb> = (0..n)
        .map(|_| {
            let p = DVec3::new(rng.random_range(0.0..side), rng.random_range(0.0..side), rng.random_range(0.0..side));
            let s = DVec3::new(rng.random_range(0.1..0.5), rng.random_range(0.1..0.5), rng.random_range(0.1..0.5));
            scene::Aabb { min: p, max: p + s }
        })
        .collect();
    let start = std::time::Instant::now();
    let outcome = scene::cluster_boxes(&boxes, std::env::args().nth(2).and_then(|a| a.parse().ok()).unwrap_or(4.0), &scene::ProgressBar::hidden());
    println!("{n} boxes -> {} groups, {} joins, {:.3} s", outcome.group_count, outcome.joins, start.elapsed().as_secs_f64());
}

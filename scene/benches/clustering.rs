//! Phase III timing against the number of base clusters: `cargo bench -p scene --bench clustering`.
//!
//! The input is a triangle soup's base clusters: boxes of side 0.1-0.5 spread uniformly at one
//! per unit volume, so density stays the same as n grows, clustered with the `sl_c` that
//! Phase II derives for a near zone of a tenth of the scene (a ball holding 10 % of a cube of
//! side L has diameter 0.58 L; sl_c = 0.222 d_nz at 1024x768, 60 degrees, p = 256).
//! O(n log n) means 10x the clusters costs a little over 10x the time.

use criterion::{BenchmarkId, Criterion, SamplingMode, criterion_group, criterion_main};
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use scene::Aabb;

fn soup(count: usize) -> (Vec<Aabb>, f64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let side = (count as f64).cbrt();
    let boxes = (0..count)
        .map(|_| {
            let p = DVec3::new(
                rng.random_range(0.0..side),
                rng.random_range(0.0..side),
                rng.random_range(0.0..side),
            );
            let s = DVec3::new(
                rng.random_range(0.1..0.5),
                rng.random_range(0.1..0.5),
                rng.random_range(0.1..0.5),
            );
            Aabb { min: p, max: p + s }
        })
        .collect();
    let d_nz = 2.0 * (0.1 * 3.0 / (4.0 * std::f64::consts::PI)).cbrt() * side;
    (boxes, scene::max_cluster_side(d_nz, 256, 768, 60.0))
}

fn clustering(c: &mut Criterion) {
    let mut group = c.benchmark_group("phase III clustering");
    group.sampling_mode(SamplingMode::Flat).sample_size(10);
    for count in [10_000usize, 100_000, 1_000_000] {
        let (boxes, sl_c) = soup(count);
        group.bench_with_input(BenchmarkId::from_parameter(count), &boxes, |b, boxes| {
            b.iter(|| scene::cluster_boxes(boxes, sl_c, &scene::Progress::hidden()))
        });
    }
    group.finish();
}

// No HTML plots: plotters shares the balancer's font setup, which criterion does not make.
criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = clustering
}
criterion_main!(benches);

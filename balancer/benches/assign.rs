//! `cargo bench -p balancer --bench assign`: one `assign` call of 10,000 requests over 1,000
//! workers with 3 replicas (goal: at most 5 ms), and a full simulation sweep of a 6,000-position
//! walk-through on 120 workers (3 replica counts, 2 strategies, 10 seeds; goal: at most 30 s).

use balancer::{
    Balancer, Config, Placement, Policy, Request, SimulationConfig, Strategy, synthetic_trace,
};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use rayon::prelude::*;

fn requests(count: u64, objects: u32) -> Vec<Request> {
    (0..count)
        .map(|i| Request {
            id: i,
            object: (i * 7919 % objects as u64) as u32,
            weight: 20_000.0 + (i % 97) as f64 * 1_900.0,
            priority: (i % 13) as f64,
        })
        .collect()
}

fn assign(c: &mut Criterion) {
    let placement = Placement::random(20_000, 1_000, 3, 1).unwrap();
    let mut group = c.benchmark_group("assign");
    for strategy in [Strategy::Deterministic, Strategy::Randomized] {
        group.bench_function(
            format!("10000 requests, 1000 workers, 3 replicas, {strategy:?}"),
            |b| {
                b.iter_batched(
                    || {
                        (
                            Balancer::new(
                                placement.clone(),
                                Config {
                                    strategy,
                                    ..Config::default()
                                },
                            )
                            .unwrap(),
                            requests(10_000, 20_000),
                        )
                    },
                    |(mut balancer, requests)| balancer.assign(requests),
                    BatchSize::SmallInput,
                )
            },
        );
    }
    group.finish();
}

fn sweep(c: &mut Criterion) {
    let trace = synthetic_trace("walk", 6_000, 2_000, 1).unwrap();
    let mut group = c.benchmark_group("simulate");
    group.sample_size(10);
    group.bench_function(
        "walk 6000 positions, 120 workers, replicas 1-3, 2 strategies, 10 seeds",
        |b| {
            b.iter(|| {
                let configs: Vec<SimulationConfig> = (1..=3)
                    .flat_map(|replicas| {
                        [Strategy::Deterministic, Strategy::Randomized]
                            .into_iter()
                            .flat_map(move |strategy| {
                                (0..10).map(move |seed| SimulationConfig {
                                    workers: 120,
                                    replicas,
                                    seed,
                                    speeds: Vec::new(),
                                    base_speed: 20e6,
                                    policy: Policy::Balancer(Config {
                                        strategy,
                                        ..Config::default()
                                    }),
                                })
                            })
                    })
                    .collect();
                configs
                    .par_iter()
                    .map(|config| balancer::simulate(&trace, config).unwrap().max_c)
                    .sum::<f64>()
            })
        },
    );
    group.finish();
}

// No HTML plots: plotters shares the balancer's font setup, which criterion does not make.
criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = assign, sweep
}
criterion_main!(benches);

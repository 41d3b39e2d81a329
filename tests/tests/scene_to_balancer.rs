//! From a prepared scene to balanced reliefboard requests: the path the visualization node
//! takes, without rendering.

use balancer::{Balancer, Config, Placement, Request};
use scene::{LoadOptions, ObjectClass, PrepareParams};

#[test]
fn every_suitable_object_of_a_prepared_plant_can_be_requested_and_balanced() {
    let loaded = scene::load_scene(
        "plant",
        &LoadOptions {
            triangles: 200_000,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    let prepared = scene::prepare(
        loaded,
        &PrepareParams {
            t_nz: 60_000,
            min_triangles: 300,
            ..PrepareParams::default()
        },
    )
    .unwrap();
    let suitable: Vec<usize> = (0..prepared.objects.len())
        .filter(|&i| prepared.classes[i] == ObjectClass::Suitable)
        .collect();
    assert!(suitable.len() > 10);

    let workers = 6;
    let placement = Placement::random(prepared.objects.len(), workers, 2, 7).unwrap();
    let mut balancer = Balancer::new(placement, Config::default()).unwrap();
    let requests: Vec<Request> = suitable
        .iter()
        .enumerate()
        .map(|(id, &object)| Request {
            id: id as u64,
            object: object as u32,
            weight: prepared.objects[object].triangles.len() as f64,
            priority: 1.0,
        })
        .collect();
    let total: f64 = requests.iter().map(|r| r.weight).sum();
    let heaviest = requests.iter().map(|r| r.weight).fold(0.0, f64::max);
    let outcome = balancer.assign(requests);
    assert_eq!(outcome.assigned.len(), suitable.len());

    // One frame's burst, balanced by triangles: the busiest worker stays within twice the
    // lower bound max(total / n, heaviest).
    let mut per_worker = vec![0.0; workers];
    for (request, worker) in &outcome.assigned {
        per_worker[*worker as usize] += request.weight;
    }
    let busiest = per_worker.iter().copied().fold(0.0, f64::max);
    let bound = (total / workers as f64).max(heaviest);
    assert!(
        busiest <= 2.0 * bound,
        "busiest {busiest} against lower bound {bound}"
    );

    // Boards arrive; the balancer forgets them.
    for (request, _) in &outcome.assigned {
        balancer.complete(request.id, Some(0.05)).unwrap();
    }
    assert_eq!(balancer.in_flight(), 0);
    assert!(
        balancer
            .workers()
            .iter()
            .all(|w| w.jobs == 0 && w.load == 0.0)
    );
}

//! Preprocessing tests against independent expectations: hand-built meshes with known
//! components, a brute-force clustering reference, and invariants on generated scenes.

mod common;

use common::{box_triangles, object_from_triangles, scene_of, temp_dir, triangle_set};
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use scene::{Aabb, LoadOptions, ObjectClass, PrepareParams, prepare};

#[test]
fn components_of_hand_built_meshes() {
    // Two closed boxes (each 12 triangles on 8 shared corners, but written as separate
    // vertices: welding must join them), one box duplicated face for face, and a lone
    // triangle touching nothing.
    let mut triangles = box_triangles(DVec3::ZERO, DVec3::ONE);
    triangles.extend(box_triangles(
        DVec3::new(5.0, 0.0, 0.0),
        DVec3::new(6.0, 2.0, 3.0),
    ));
    triangles.extend(box_triangles(
        DVec3::new(5.0, 0.0, 0.0),
        DVec3::new(6.0, 2.0, 3.0),
    ));
    triangles.push([
        DVec3::new(10.0, 0.0, 0.0),
        DVec3::new(11.0, 0.0, 0.0),
        DVec3::new(10.0, 1.0, 0.0),
    ]);
    let object = object_from_triangles("parts", &triangles);
    let components = scene::connected_components(&object);
    let expected = [
        (
            Aabb {
                min: DVec3::ZERO,
                max: DVec3::ONE,
            },
            12,
        ),
        (
            Aabb {
                min: DVec3::new(5.0, 0.0, 0.0),
                max: DVec3::new(6.0, 2.0, 3.0),
            },
            12,
        ),
        (
            Aabb {
                min: DVec3::new(10.0, 0.0, 0.0),
                max: DVec3::new(11.0, 1.0, 0.0),
            },
            1,
        ),
    ];
    assert_eq!(components, expected);

    // Two triangles sharing only a vertex are one component; sharing nothing, two.
    let touching = object_from_triangles(
        "touching",
        &[
            [DVec3::ZERO, DVec3::X, DVec3::Y],
            [
                DVec3::X,
                DVec3::new(2.0, 0.0, 0.0),
                DVec3::new(2.0, 1.0, 0.0),
            ],
        ],
    );
    assert_eq!(scene::connected_components(&touching).len(), 1);
    let apart = object_from_triangles(
        "apart",
        &[
            [DVec3::ZERO, DVec3::X, DVec3::Y],
            [
                DVec3::new(1.0001, 0.0, 0.0),
                DVec3::new(2.0, 0.0, 0.0),
                DVec3::new(2.0, 1.0, 0.0),
            ],
        ],
    );
    assert_eq!(scene::connected_components(&apart).len(), 2);
}

/// The textbook greedy: join the pair with the smallest joined longest side, O(n³).
fn brute_force_clustering(boxes: &[Aabb], max_side: f64) -> Vec<Vec<usize>> {
    let mut clusters: Vec<(Aabb, Vec<usize>)> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| (*b, vec![i]))
        .collect();
    loop {
        let mut best: Option<(f64, usize, usize)> = None;
        for i in 0..clusters.len() {
            for j in i + 1..clusters.len() {
                let cost = clusters[i].0.union(clusters[j].0).longest_side();
                if cost <= max_side && best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, i, j));
                }
            }
        }
        let Some((_, i, j)) = best else { break };
        let (bounds, members) = clusters.swap_remove(j);
        clusters[i].0 = clusters[i].0.union(bounds);
        clusters[i].1.extend(members);
    }
    let mut groups: Vec<Vec<usize>> = clusters
        .into_iter()
        .map(|(_, mut m)| {
            m.sort();
            m
        })
        .collect();
    groups.sort();
    groups
}

fn groups_of(outcome: &scene::ClusterOutcome) -> Vec<Vec<usize>> {
    let mut groups = vec![Vec::new(); outcome.group_count];
    for (index, &group) in outcome.group_of.iter().enumerate() {
        groups[group as usize].push(index);
    }
    groups.sort();
    groups
}

#[test]
fn clustering_matches_the_brute_force_greedy() {
    // Random points with random small extents: joined sides are all distinct, so the greedy
    // order has no ties and the result is unique.
    for seed in 0..20u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let count = rng.random_range(2..120);
        let boxes: Vec<Aabb> = (0..count)
            .map(|_| {
                let p = DVec3::new(
                    rng.random_range(0.0..10.0),
                    rng.random_range(0.0..10.0),
                    rng.random_range(0.0..10.0),
                );
                let size = DVec3::new(
                    rng.random_range(0.0..0.3),
                    rng.random_range(0.0..0.3),
                    rng.random_range(0.0..0.3),
                );
                Aabb {
                    min: p,
                    max: p + size,
                }
            })
            .collect();
        let max_side = rng.random_range(0.5..6.0);
        let outcome = scene::cluster_boxes(&boxes, max_side, &scene::Progress::hidden());
        assert_eq!(
            groups_of(&outcome),
            brute_force_clustering(&boxes, max_side),
            "seed {seed}, {count} boxes, sl_c {max_side}"
        );
        assert_eq!(outcome.joins, count - outcome.group_count);
    }
}

#[test]
fn clustering_never_exceeds_the_maximal_side_and_keeps_oversized_boxes_alone() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut boxes: Vec<Aabb> = (0..5000)
        .map(|_| {
            let p = DVec3::new(
                rng.random_range(0.0..50.0),
                rng.random_range(0.0..5.0),
                rng.random_range(0.0..50.0),
            );
            Aabb {
                min: p,
                max: p + DVec3::splat(rng.random_range(0.01..0.8)),
            }
        })
        .collect();
    boxes.push(Aabb {
        min: DVec3::ZERO,
        max: DVec3::splat(9.0),
    }); // larger than sl_c
    let max_side = 4.0;
    let outcome = scene::cluster_boxes(&boxes, max_side, &scene::Progress::hidden());
    let mut bounds = vec![Aabb::EMPTY; outcome.group_count];
    for (b, &g) in boxes.iter().zip(&outcome.group_of) {
        bounds[g as usize] = bounds[g as usize].union(*b);
    }
    let oversized_group = outcome.group_of[boxes.len() - 1];
    assert_eq!(
        outcome
            .group_of
            .iter()
            .filter(|&&g| g == oversized_group)
            .count(),
        1
    );
    for (group, b) in bounds.iter().enumerate() {
        if group as u32 != oversized_group {
            assert!(
                b.longest_side() <= max_side,
                "group {group} has side {}",
                b.longest_side()
            );
        }
    }
    // Greedy stops only when no two clusters fit together: no pair of groups may still join.
    let small: Vec<&Aabb> = bounds
        .iter()
        .filter(|b| b.longest_side() <= max_side)
        .collect();
    for i in 0..small.len() {
        for j in i + 1..small.len() {
            assert!(
                small[i].union(*small[j]).longest_side() > max_side,
                "groups {i} and {j} could still join"
            );
        }
    }
}

/// Parameters under which the small plant needs all three phases.
fn small_params() -> PrepareParams {
    PrepareParams {
        t_nz: 60_000,
        min_triangles: 300,
        ..PrepareParams::default()
    }
}

#[test]
fn plant_needs_clustering_and_keeps_every_triangle_exactly_once() {
    let options = LoadOptions {
        triangles: 200_000,
        ..LoadOptions::default()
    };
    let loaded = scene::load_scene("plant", &options).unwrap();
    let before = triangle_set(&loaded.objects);
    let prepared = prepare(loaded, &small_params()).unwrap();
    let summary = &prepared.summary;
    assert!(
        summary
            .phases
            .iter()
            .any(|p| p.name.starts_with("phase III") && p.ran),
        "{:?}",
        summary.phases
    );
    assert!(summary.suitable > 0 && summary.too_large > 0, "{summary:?}");
    common::assert_same_triangles(&triangle_set(&prepared.objects), &before, "plant");
    for ((object, class), &scale) in prepared
        .objects
        .iter()
        .zip(&prepared.classes)
        .zip(&prepared.map_scales)
    {
        let side = object.bounds().longest_side();
        let sl_c = summary.sl_c * scale as f64;
        match class {
            ObjectClass::Suitable => {
                assert!(
                    side <= sl_c,
                    "{} is suitable with side {side} > sl_c {sl_c} (map scale {scale})",
                    object.name,
                );
                assert!(object.triangles.len() as u64 >= 300);
            }
            ObjectClass::TooLarge => assert!(side > sl_c),
            ObjectClass::TooSimple => assert!((object.triangles.len() as u64) < 300),
        }
    }
}

#[test]
fn forest_is_already_suitable_and_skips_clustering() {
    // 20 trees of 100,000 triangles; the default t_nz of 1,000,000 puts 10 in the near zone.
    let options = LoadOptions {
        triangles: 2_000_000,
        ..LoadOptions::default()
    };
    let loaded = scene::load_scene("forest", &options).unwrap();
    let input_objects = loaded.objects.len();
    let prepared = prepare(loaded, &PrepareParams::default()).unwrap();
    let summary = &prepared.summary;
    assert_eq!(summary.objects, input_objects);
    assert!(
        summary
            .phases
            .iter()
            .filter(|p| p.name != "phase II: near zone")
            .all(|p| !p.ran),
        "{:?}",
        summary.phases
    );
    // Says what really happened: the trees are suitable, the terrain is not and stays whole.
    let expected = format!(
        "{} are already suitable and 1 too large but too sparse to cut",
        input_objects - 1
    );
    assert!(
        summary.phases.iter().any(|p| p.note.contains(&expected)),
        "{:?}",
        summary.phases
    );
    assert_eq!(
        summary.suitable,
        input_objects - 1,
        "every tree suitable, the terrain too large"
    );
    assert_eq!(summary.too_large, 1);
    assert!(summary.dense.is_empty(), "a terrain is no dense mesh");
    assert!(
        summary.sparse.is_none(),
        "nor worth cutting: {:?}",
        summary.sparse
    );
}

#[test]
fn built_in_scenes_are_deterministic_and_near_their_target() {
    for name in ["forest", "plant"] {
        let options = |seed| LoadOptions {
            triangles: 150_000,
            seed,
            ..LoadOptions::default()
        };
        let a = scene::load_scene(name, &options(3)).unwrap();
        let b = scene::load_scene(name, &options(3)).unwrap();
        let c = scene::load_scene(name, &options(4)).unwrap();
        assert_eq!(a.objects, b.objects, "{name}: same seed, same scene");
        assert_ne!(a.objects, c.objects, "{name}: another seed, another scene");
        let total = a.triangle_count() as f64;
        assert!(
            (total / 150_000.0 - 1.0).abs() < 0.25,
            "{name}: {total} triangles for a target of 150000"
        );
    }
}

#[test]
fn a_triangle_soup_is_clustered_into_suitable_objects() {
    // 20,000 separate small triangles in a 100 m cube: each its own component.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let triangles: Vec<[DVec3; 3]> = (0..20_000)
        .map(|_| {
            let p = DVec3::new(
                rng.random_range(0.0..100.0),
                rng.random_range(0.0..100.0),
                rng.random_range(0.0..100.0),
            );
            [
                p,
                p + DVec3::new(0.3, 0.0, 0.0),
                p + DVec3::new(0.0, 0.3, 0.1),
            ]
        })
        .collect();
    let scene = scene_of(vec![object_from_triangles("soup", &triangles)]);
    let before = triangle_set(&scene.objects);
    let params = PrepareParams {
        t_nz: 2_500,
        min_triangles: 20,
        ..PrepareParams::default()
    };
    let prepared = prepare(scene, &params).unwrap();
    assert!(prepared.summary.suitable > 10, "{:?}", prepared.summary);
    common::assert_same_triangles(&triangle_set(&prepared.objects), &before, "soup");
    assert!(
        prepared
            .objects
            .iter()
            .zip(&prepared.classes)
            .all(|(o, c)| *c != ObjectClass::Suitable
                || o.bounds().longest_side() <= prepared.summary.sl_c)
    );
}

#[test]
fn a_huge_dense_mesh_is_cut_into_suitable_pieces() {
    // One connected, finely tessellated 200 m plate: far larger than sl_c, dense enough to cut.
    let n = 300;
    let mut builder = scene::ObjectBuilder::new("plate");
    for i in 0..=n {
        for j in 0..=n {
            builder.vertex(
                DVec3::new(
                    i as f64 * 200.0 / n as f64,
                    ((i * j) % 7) as f64 * 0.01,
                    j as f64 * 200.0 / n as f64,
                ),
                [255; 4],
            );
        }
    }
    for i in 0..n {
        for j in 0..n {
            let at = |i: u32, j: u32| i * (n + 1) + j;
            builder.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
            builder.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
        }
    }
    let scene = scene_of(vec![builder.finish().0]);
    let before = triangle_set(&scene.objects);
    let params = PrepareParams {
        t_nz: 20_000,
        min_triangles: 400,
        ..PrepareParams::default()
    };
    let prepared = prepare(scene, &params).unwrap();
    assert!(
        prepared.summary.phases[0].note.contains("1 cut on a grid"),
        "{:?}",
        prepared.summary.phases
    );
    assert!(prepared.summary.suitable > 4, "{:?}", prepared.summary);
    common::assert_same_triangles(&triangle_set(&prepared.objects), &before, "plate");
    assert_seams_where_pieces_meet(&prepared.objects);
}

/// Every vertex of `pieces` is marked a seam exactly when another piece has a vertex at the
/// same place (the plate's and the sphere's vertices are far apart compared with 1e-4).
fn assert_seams_where_pieces_meet(pieces: &[scene::Object]) {
    let key = |p: DVec3| (p * 1e4).round().to_array().map(|x| x as i64);
    let mut pieces_at: std::collections::HashMap<[i64; 3], std::collections::HashSet<usize>> =
        Default::default();
    for (piece, object) in pieces.iter().enumerate() {
        for v in 0..object.positions.len() {
            pieces_at
                .entry(key(object.world_position(v as u32)))
                .or_default()
                .insert(piece);
        }
    }
    let mut marked = 0;
    for object in pieces {
        assert_eq!(object.seams.len(), object.positions.len());
        for (v, &seam) in object.seams.iter().enumerate() {
            let shared = pieces_at[&key(object.world_position(v as u32))].len() > 1;
            assert_eq!(seam, shared, "{} vertex {v}", object.name);
            marked += seam as usize;
        }
    }
    assert!(marked > 0, "the pieces meet somewhere");
}

/// A closed UV sphere of radius 1 with `n` segments around: `n²` triangles, connected.
fn dense_sphere(n: u32) -> scene::Object {
    let mut builder = scene::ObjectBuilder::new("scan");
    scene::shapes::sphere(&mut builder, DVec3::ZERO, 1.0, n, [255; 4]);
    builder.finish().0
}

#[test]
fn a_dense_scan_too_large_for_a_small_near_zone_is_cut_into_pieces_with_larger_maps() {
    // One connected 160,000-triangle sphere (a scan) beside a separate small suitable
    // object, under a near zone of 40,000 triangles: pieces of side sl_c would hold a few
    // hundred triangles, far from min_triangles.
    let scan = dense_sphere(400);
    let small = {
        let mut small = dense_sphere(80);
        small.origin += DVec3::new(5.0, 0.0, 0.0);
        small.positions.iter_mut().for_each(|p| *p *= 0.05);
        small
    };
    let scene = scene_of(vec![scan, small]);
    let before = triangle_set(&scene.objects);
    let params = PrepareParams {
        t_nz: 40_000,
        ..PrepareParams::default()
    };
    let prepared = prepare(scene, &params).unwrap();
    let summary = &prepared.summary;
    let sl_c = summary.sl_c;
    assert_eq!(
        sl_c,
        scene::max_cluster_side(summary.d_nz, 256, 768, params.fov_y_degrees)
    );
    // The whole sphere (diameter 2) spans 2 / side cubes a side; at sl_c they hold fewer
    // than 4,096 triangles each, so it cannot be cut at sl_c.
    let cubes = |side: f64| (2.0 / side).ceil().max(1.0).powi(3);
    assert!(160_000.0 / cubes(sl_c) < 4096.0);
    let [dense] = &summary.dense[..] else {
        panic!("the scan is cut with larger maps once: {:?}", summary.dense)
    };
    // Doubling the map doubles the side; the scale chosen is at least the first at which
    // the cubes would hold 4,096 on average, and leaves 3/4 of the scan in suitable pieces.
    let scale = dense.map_size / 256;
    assert!([2, 4].contains(&scale), "{dense:?}");
    assert!(
        160_000.0 / cubes(sl_c * scale as f64) >= 4096.0,
        "{dense:?}"
    );
    assert_eq!(dense.objects, 1);
    assert!((dense.sl_c - sl_c * scale as f64).abs() < 1e-12);
    let small_triangles = 80 * 80;
    assert!(summary.suitable >= 4, "{summary:?}");
    assert!(
        (summary.suitable_triangles - small_triangles) * 4 >= 160_000 * 3,
        "3/4 of the scan can become boards: {summary:?}"
    );
    let mut pieces = 0;
    for ((object, class), &map_scale) in prepared
        .objects
        .iter()
        .zip(&prepared.classes)
        .zip(&prepared.map_scales)
    {
        let side = object.bounds().longest_side();
        if side < 0.2 {
            // The small object keeps its own maps: it was suitable as it was.
            assert_eq!((*class, map_scale), (ObjectClass::Suitable, 1));
            continue;
        }
        assert_eq!(map_scale, scale, "a piece of the scan");
        pieces += 1;
        match class {
            ObjectClass::Suitable => {
                assert!(side <= dense.sl_c && side > 0.0);
                assert!(object.triangles.len() as u64 >= params.min_triangles);
            }
            ObjectClass::TooSimple => assert!((object.triangles.len() as u64) < 4096),
            ObjectClass::TooLarge => panic!("a piece larger than its side: {side}"),
        }
    }
    assert!(pieces >= 4);
    common::assert_same_triangles(&triangle_set(&prepared.objects), &before, "scan");
    assert_seams_where_pieces_meet(&prepared.objects);
}

#[test]
fn a_sparse_pipe_run_is_cut_so_each_piece_takes_its_own_level_and_a_cheap_floor_stays_whole() {
    // A pipe run of two legs of 400 m (28,800 triangles, 36 per metre) and a floor of 800
    // triangles as wide, under a near zone of 2,500 triangles (about 70 m of pipe): no map
    // size makes boards of most of the pipe, so it used to stay whole and was drawn at the
    // level of detail of its nearest point from end to end.
    let mut builder = scene::ObjectBuilder::new("pipe");
    let leg = 400.0;
    let points = [
        (DVec3::ZERO, 0.3),
        (DVec3::new(leg, 0.0, 0.0), 0.3),
        (DVec3::new(leg, 0.0, leg), 0.3),
    ];
    scene::shapes::path_tube(&mut builder, &points, 24, 300, false, [255; 4]);
    let pipe = builder.finish().0;
    let pipe_triangles = pipe.triangles.len() as u64;
    assert_eq!(pipe_triangles, 2 * 300 * 2 * 24);
    let mut builder = scene::ObjectBuilder::new("floor");
    scene::shapes::terrain(&mut builder, leg / 2.0, 20, |_, _| -1.0, [255; 4]);
    let floor = builder.finish().0;
    assert_eq!(floor.triangles.len(), 800);
    let scene = scene_of(vec![pipe, floor]);
    let before = triangle_set(&scene.objects);
    let params = PrepareParams {
        t_nz: 2_500,
        ..PrepareParams::default()
    };
    let prepared = prepare(scene, &params).unwrap();
    let summary = &prepared.summary;
    let largest = scene::PrepareParams::MAX_RAISED_MAP_SIZE;
    // The premise: even the largest raised side leaves the pipe's pieces too simple (a cube
    // of side `raised` holds at most two of its sides' length of pipe, at a bend).
    let raised = summary.sl_c * (largest / 256) as f64;
    assert!(
        36.0 * 2.0 * raised < 4096.0,
        "pieces of side {raised} could be suitable"
    );
    assert!(summary.dense.is_empty(), "{:?}", summary.dense);
    let Some(sparse) = &summary.sparse else {
        panic!("the pipe is cut: {:?}", summary.phases)
    };
    assert_eq!((sparse.objects, sparse.map_size), (1, largest));
    // Pieces of the raised side (about 50 m of pipe, 1,800 triangles, or less) would be
    // more draw calls than they are worth: the side doubles until the pieces average half
    // of min_triangles.
    let doublings = (sparse.sl_c / raised).log2();
    assert!(
        doublings >= 1.0 - 1e-9 && (doublings - doublings.round()).abs() < 1e-9,
        "side {} against the raised {raised}",
        sparse.sl_c
    );
    assert!(sparse.pieces as u64 * 2048 <= pipe_triangles, "{sparse:?}");
    // 800 m of pipe in pieces of at most that side.
    assert!(
        sparse.pieces as f64 >= 2.0 * leg / sparse.sl_c,
        "{sparse:?}"
    );
    let mut pieces = 0;
    let mut floors = 0;
    for ((object, class), &map_scale) in prepared
        .objects
        .iter()
        .zip(&prepared.classes)
        .zip(&prepared.map_scales)
    {
        if object.name == "floor" {
            // 800 triangles, less than a suitable object's: cheaper whole in one draw.
            assert_eq!((*class, map_scale), (ObjectClass::TooLarge, 1));
            floors += 1;
        } else if object.name.starts_with("pipe piece") {
            assert_eq!(map_scale, largest / 256);
            assert!(object.bounds().longest_side() <= sparse.sl_c + 1e-9);
            // Geometry at its own level: within the raised side too simple (the premise),
            // beyond it too large.
            assert_ne!(*class, ObjectClass::Suitable, "{}", object.name);
            pieces += 1;
        } else {
            panic!("an object from nowhere: {}", object.name);
        }
    }
    assert_eq!((pieces, floors), (sparse.pieces, 1));
    assert!(
        summary
            .phases
            .iter()
            .any(|p| p.note.contains("1 too sparse for any map cut into")
                && p.note.contains("1 stay whole")),
        "{:?}",
        summary.phases
    );
    common::assert_same_triangles(&triangle_set(&prepared.objects), &before, "pipe");
    assert_seams_where_pieces_meet(&prepared.objects);
}

#[test]
fn numerically_extreme_meshes_give_finite_results() {
    let far = DVec3::splat(1e7);
    // Millimetre-sized boxes ten thousand kilometres out.
    let mut triangles = Vec::new();
    for k in 0..50 {
        let corner = far + DVec3::new(k as f64 * 2e-3, 0.0, 0.0);
        triangles.extend(box_triangles(corner, corner + DVec3::splat(1e-3)));
    }
    let tiny = object_from_triangles("far and tiny", &triangles);
    assert!(
        (tiny.bounds().size().y - 1e-3).abs() < 1e-9,
        "precision kept: {:?}",
        tiny.bounds().size()
    );
    let components = scene::connected_components(&tiny);
    assert_eq!(components.len(), 50);

    // Sizes from 1e-6 to 1e6 in one scene.
    let mut wide = Vec::new();
    for exponent in -6..=6 {
        let size = 10f64.powi(exponent);
        wide.extend(box_triangles(
            DVec3::new(10f64.powi(exponent + 1), 0.0, 0.0),
            DVec3::new(10f64.powi(exponent + 1) + size, size, size),
        ));
    }
    // A single triangle.
    let single = [[DVec3::ZERO, DVec3::X, DVec3::Y]];
    for (name, objects) in [
        ("tiny", vec![tiny.clone()]),
        ("wide", vec![object_from_triangles("wide", &wide)]),
        ("single", vec![object_from_triangles("single", &single)]),
    ] {
        for t_nz in [1, 10, 1_000_000] {
            let params = PrepareParams {
                t_nz,
                min_triangles: 2,
                ..PrepareParams::default()
            };
            let prepared = prepare(scene_of(objects.clone()), &params).unwrap();
            let s = &prepared.summary;
            assert!(
                s.d_nz.is_finite() && s.sl_c.is_finite() && s.d_nz >= 0.0,
                "{name}: {s:?}"
            );
            // Nothing is lost but what a cut finds twice or flat (the micrometre boxes beside
            // the megametre ones collapse onto the same f32 points), and that is counted.
            assert_eq!(
                s.triangles + s.duplicate_faces_dropped + s.degenerate_triangles_dropped,
                objects
                    .iter()
                    .map(|o| o.triangles.len() as u64)
                    .sum::<u64>(),
                "{name}"
            );
            for object in &prepared.objects {
                assert!(
                    object.origin.is_finite() && object.positions.iter().all(|p| p.is_finite()),
                    "{name}"
                );
            }
            assert!(serde_json::to_string(s).unwrap().find("NaN").is_none());
        }
    }
}

#[test]
fn bad_parameters_are_refused() {
    let scene = || {
        scene_of(vec![object_from_triangles(
            "t",
            &[[DVec3::ZERO, DVec3::X, DVec3::Y]],
        )])
    };
    for params in [
        PrepareParams {
            t_nz: 0,
            ..PrepareParams::default()
        },
        PrepareParams {
            map_size: 0,
            ..PrepareParams::default()
        },
        PrepareParams {
            map_size: 1 << 20,
            ..PrepareParams::default()
        },
        PrepareParams {
            resolution: [0, 768],
            ..PrepareParams::default()
        },
        PrepareParams {
            fov_y_degrees: f64::NAN,
            ..PrepareParams::default()
        },
        PrepareParams {
            fov_y_degrees: 180.0,
            ..PrepareParams::default()
        },
    ] {
        assert!(
            matches!(
                prepare(scene(), &params),
                Err(scene::SceneError::BadParameter(_))
            ),
            "{params:?}"
        );
    }
    assert!(matches!(
        scene::load_scene("nowhere", &LoadOptions::default()),
        Err(scene::SceneError::UnknownScene(_))
    ));
    let absurd = LoadOptions {
        triangles: 10,
        ..LoadOptions::default()
    };
    assert!(matches!(
        scene::load_scene("forest", &absurd),
        Err(scene::SceneError::BadParameter(_))
    ));
}

#[test]
fn near_zone_and_cluster_side_follow_their_formulas() {
    // 1,000 unit triangles one metre apart on a line: a ball holding 100 triangles around
    // the densest point spans 99 metres (50 on each side of a centre triangle, minus one).
    let triangles: Vec<[DVec3; 3]> = (0..1000)
        .map(|i| {
            let x = i as f64;
            [
                DVec3::new(x, 0.0, 0.0),
                DVec3::new(x + 0.1, 0.0, 0.0),
                DVec3::new(x, 0.1, 0.0),
            ]
        })
        .collect();
    let objects = vec![object_from_triangles("line", &triangles)];
    let d_nz = scene::near_zone_diameter(&objects, 100);
    assert!((d_nz - 98.0).abs() <= 2.0, "d_nz = {d_nz}");
    // sl_c = 2 p d tan(fov/2) / (sqrt(3) r_y); with p = r_y and fov = 90 degrees: 2 d / sqrt(3).
    let sl_c = scene::max_cluster_side(30.0, 512, 512, 90.0);
    assert!((sl_c - 60.0 / 3f64.sqrt()).abs() < 1e-9);
}

#[test]
fn the_cache_is_hit_on_rerun_and_missed_when_input_or_parameters_change() {
    let dir = temp_dir("cache");
    let params = PrepareParams {
        cache_dir: Some(dir.clone()),
        ..small_params()
    };
    let load = |seed| {
        scene::load_scene(
            "plant",
            &LoadOptions {
                triangles: 200_000,
                seed,
                ..LoadOptions::default()
            },
        )
        .unwrap()
    };
    let first = prepare(load(1), &params).unwrap();
    assert_eq!(first.summary.cache, "miss");
    let second = prepare(load(1), &params).unwrap();
    assert_eq!(second.summary.cache, "hit");
    assert_eq!(
        first.objects, second.objects,
        "a cache hit rebuilds the same objects"
    );
    assert_eq!(
        prepare(load(2), &params).unwrap().summary.cache,
        "miss",
        "other geometry"
    );
    let other = PrepareParams {
        map_size: 320,
        ..params.clone()
    };
    assert_eq!(
        prepare(load(1), &other).unwrap().summary.cache,
        "miss",
        "other sl_c"
    );
    // A forged group count (four billion groups for 200,000 triangles, every triangle's group
    // still in range) is a miss: it would allocate a builder per group.
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        let length = u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
        let mut header: serde_json::Value =
            serde_json::from_slice(&bytes[16..16 + length]).unwrap();
        header["group_count"] = 4_000_000_000u32.into();
        let header = serde_json::to_vec(&header).unwrap();
        let mut forged = bytes[..8].to_vec();
        forged.extend((header.len() as u64).to_le_bytes());
        forged.extend(header);
        forged.extend(&bytes[16 + length..]);
        std::fs::write(path, forged).unwrap();
    }
    assert_eq!(prepare(load(1), &params).unwrap().summary.cache, "miss");
    // A corrupted cache file is a miss, not an error.
    for entry in std::fs::read_dir(&dir).unwrap() {
        std::fs::write(entry.unwrap().path(), b"RBCLUST1 garbage").unwrap();
    }
    assert_eq!(prepare(load(1), &params).unwrap().summary.cache, "miss");
}

/// Regression: a node of the octree that already has children, holding more than a bucket of
/// clusters too long for them, was split again, orphaning its subtree; clusters there were
/// never found and clustering looped forever (the forest at a small `t_nz` hit it). Here many
/// tiny boxes make one octant split, then many boxes longer than its children's half side
/// but centred in it pile up in that octant's node. With max_side large enough for
/// everything, the result must be exactly one group.
#[test]
fn clustering_finds_partners_kept_in_inner_nodes() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut boxes: Vec<Aabb> = Vec::new();
    // Bounds 0..16 on every axis (corners), so the root's children have side 8.
    for corner in [DVec3::ZERO, DVec3::splat(16.0)] {
        boxes.push(Aabb {
            min: corner,
            max: corner,
        });
    }
    // 200 tiny boxes in the low octant: it splits (children of side 4).
    for _ in 0..200 {
        let p = DVec3::new(
            rng.random_range(0.5..7.5),
            rng.random_range(0.5..7.5),
            rng.random_range(0.5..7.5),
        );
        boxes.push(Aabb {
            min: p,
            max: p + DVec3::splat(0.01),
        });
    }
    // 100 boxes of side 5 centred in the same octant: too long for its children (an item
    // descends into a cell only while its side is at most half that cell's), so they stay
    // in the octant's node.
    for _ in 0..100 {
        let c = DVec3::new(
            rng.random_range(2.6..5.4),
            rng.random_range(2.6..5.4),
            rng.random_range(2.6..5.4),
        );
        boxes.push(Aabb {
            min: c - DVec3::splat(2.5),
            max: c + DVec3::splat(2.5),
        });
    }
    let outcome = scene::cluster_boxes(&boxes, 100.0, &scene::Progress::hidden());
    assert_eq!(outcome.group_count, 1);
    assert_eq!(outcome.joins, boxes.len() - 1);
}

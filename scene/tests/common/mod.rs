//! Helpers shared by the scene tests.
#![allow(dead_code)]

use std::path::PathBuf;

use glam::DVec3;
use scene::{Object, ObjectBuilder, Scene};

/// `testdata/NAME`: the small real meshes kept in the repository.
pub fn test_mesh(name: &str) -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../testdata");
    root.join(name)
}

/// A fresh temporary directory for one test.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("reliefboard-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every triangle of the objects as its three world corners, starting at the corner with the
/// smallest generic linear key (so the rotation is stable under rounding, winding kept),
/// sorted by centroid x: the multiset a correct loader or preprocessor must preserve.
pub fn triangle_set(objects: &[Object]) -> Vec<[DVec3; 3]> {
    let key = |p: DVec3| p.x + 1.1 * p.y + 1.3 * p.z;
    let mut set: Vec<[DVec3; 3]> = objects
        .iter()
        .flat_map(|o| {
            o.triangles.iter().map(move |t| {
                let corners = t.map(|v| o.world_position(v));
                let first = (0..3)
                    .min_by(|&i, &j| key(corners[i]).total_cmp(&key(corners[j])))
                    .unwrap();
                [
                    corners[first],
                    corners[(first + 1) % 3],
                    corners[(first + 2) % 3],
                ]
            })
        })
        .collect();
    set.sort_by(|a, b| centroid_x(a).total_cmp(&centroid_x(b)));
    set
}

fn centroid_x(t: &[DVec3; 3]) -> f64 {
    (t[0].x + t[1].x + t[2].x) / 3.0
}

/// Asserts two triangle sets hold the same triangles up to `f32` storage rounding (a relative
/// tolerance of 1e-6 of the scene's extent), matching each triangle to one partner.
pub fn assert_same_triangles(actual: &[[DVec3; 3]], expected: &[[DVec3; 3]], what: &str) {
    assert_eq!(
        actual.len(),
        expected.len(),
        "{what}: triangle counts differ"
    );
    let extent = expected
        .iter()
        .flatten()
        .fold(0.0f64, |m, p| m.max(p.abs().max_element()));
    let tolerance = 1e-6 * extent.max(1e-3);
    let mut matched = vec![false; expected.len()];
    for (index, triangle) in actual.iter().enumerate() {
        let x = centroid_x(triangle);
        let start = expected.partition_point(|e| centroid_x(e) < x - tolerance);
        let found = (start..expected.len())
            .take_while(|&j| centroid_x(&expected[j]) <= x + tolerance)
            .find(|&j| {
                !matched[j] && (0..3).all(|c| triangle[c].distance(expected[j][c]) <= tolerance)
            });
        match found {
            Some(j) => matched[j] = true,
            None => {
                panic!("{what}: triangle {index} {triangle:?} has no partner within {tolerance}")
            }
        }
    }
}

/// An object from world-space triangles (each triangle its own three vertices).
pub fn object_from_triangles(name: &str, triangles: &[[DVec3; 3]]) -> Object {
    let mut builder = ObjectBuilder::new(name);
    for t in triangles {
        let [a, b, c] = t.map(|p| builder.vertex(p, [255, 255, 255, 255]));
        builder.triangle(a, b, c);
    }
    builder.finish().0
}

/// A closed axis-aligned box (12 triangles, shared vertices) from `min` to `max`.
pub fn box_triangles(min: DVec3, max: DVec3) -> Vec<[DVec3; 3]> {
    let corner = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        )
    };
    let faces = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    faces
        .iter()
        .flat_map(|f| {
            [
                [corner(f[0]), corner(f[1]), corner(f[2])],
                [corner(f[0]), corner(f[2]), corner(f[3])],
            ]
        })
        .collect()
}

/// A scene of the given objects.
pub fn scene_of(objects: Vec<Object>) -> Scene {
    Scene {
        source: "test".into(),
        objects,
        degenerate_triangles_dropped: 0,
    }
}

//! Triangles that break rasterisers: slivers with an aspect ratio over a million, triangles
//! thousands of times smaller than a pixel, and nearly coplanar faces overlapping. The maps
//! must have no cracks (every pixel centre inside covered exactly once), no coverage outside
//! the silhouette and no NaN anywhere.

use backend::{Board, EncodedBoard, Maps, PreparedObject, coverage_counts, render_maps};
use glam::DVec3;
use scene::{Object, ObjectBuilder};

/// The square [-1, 1]² at z = 0 cut into `columns` vertical strips of two triangles each:
/// every triangle is 2 tall and 2 / `columns` wide.
fn slivers(columns: u32) -> Object {
    let mut b = ObjectBuilder::new("slivers");
    for i in 0..=columns {
        let x = -1.0 + 2.0 * i as f64 / columns as f64;
        b.vertex(DVec3::new(x, -1.0, 0.0), [200, 200, 200, 255]);
        b.vertex(DVec3::new(x, 1.0, 0.0), [200, 200, 200, 255]);
    }
    for i in 0..columns {
        let (b0, t0, b1, t1) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        b.triangle(b0, b1, t1);
        b.triangle(b0, t1, t0);
    }
    b.finish().0
}

/// The square [-1, 1]² at z = `z` as an `n × n` grid of quads.
fn plate(n: u32, z: f64, color: [u8; 4]) -> ObjectBuilder {
    let mut b = ObjectBuilder::new("plate");
    add_plate(&mut b, n, z, color);
    b
}

fn add_plate(b: &mut ObjectBuilder, n: u32, z: f64, color: [u8; 4]) {
    let first = b.vertex_count() as u32;
    for i in 0..=n {
        for j in 0..=n {
            let p = DVec3::new(
                -1.0 + 2.0 * j as f64 / n as f64,
                -1.0 + 2.0 * i as f64 / n as f64,
                z,
            );
            b.vertex(p, color);
        }
    }
    for i in 0..n {
        for j in 0..n {
            let at = |i: u32, j: u32| first + i * (n + 1) + j;
            b.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
            b.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
        }
    }
}

/// Map coordinates (x right, y up, in [-1, 1]) of pixel `at`'s centre.
fn pixel_xy(at: usize, size: u32) -> (f64, f64) {
    let (column, row) = ((at as u32 % size) as f64, (at as u32 / size) as f64);
    (
        (column + 0.5) / size as f64 * 2.0 - 1.0,
        1.0 - (row + 0.5) / size as f64 * 2.0,
    )
}

/// Seen along -z, the square [-1, 1]² fills map coordinates up to 1/√2 (its bounding sphere
/// has radius √2). Every pixel centre inside is covered exactly once, none outside; centres
/// within a thousandth of a pixel of the edge may go either way.
fn assert_square_covered_once(object: &PreparedObject, size: u32) {
    let counts = coverage_counts(object, DVec3::NEG_Z, size).unwrap();
    let half = 0.5f64.sqrt();
    let slack = 2.0 / size as f64 * 1e-3;
    let mut inside = 0;
    for (at, &count) in counts.iter().enumerate() {
        let (x, y) = pixel_xy(at, size);
        let edge = x.abs().max(y.abs());
        if edge < half - slack {
            assert_eq!(count, 1, "pixel {at} inside covered {count} times");
            inside += 1;
        } else if edge > half + slack {
            assert_eq!(count, 0, "pixel {at} outside covered {count} times");
        }
    }
    assert!(inside > size * size / 3, "{inside} pixels inside");
}

/// No NaN or infinity in any map, covered pixels with depth in [-1, 1] and unit normals, and
/// the same after encoding, decoding and building the board.
fn assert_finite(maps: &Maps) {
    for at in 0..maps.stencil.len() {
        let normal = glam::Vec3::from_array(maps.normal[at]);
        if maps.stencil[at] {
            assert!(
                maps.depth[at].is_finite() && maps.depth[at].abs() <= 1.0 + 1e-5,
                "depth {} at {at}",
                maps.depth[at]
            );
            assert!(
                normal.is_finite() && (normal.length() - 1.0).abs() < 1e-3,
                "normal {normal} at {at}"
            );
        } else {
            assert_eq!(normal, glam::Vec3::ZERO, "normal at uncovered {at}");
        }
    }
    let decoded = EncodedBoard::encode(maps).decode().unwrap();
    assert_eq!(decoded.stencil, maps.stencil);
    let board = Board::from_maps(decoded);
    assert!(
        board.grid.vertices.iter().flatten().all(|v| v.is_finite()),
        "a board vertex is not finite"
    );
}

#[test]
fn slivers_with_an_aspect_ratio_over_a_million_leave_no_crack() {
    let object = PreparedObject::new(&slivers(1_200_000)).unwrap();
    assert_eq!(object.triangles.len(), 2_400_000);
    for size in [64, 257] {
        assert_square_covered_once(&object, size);
    }
    for direction in [
        DVec3::NEG_Z,
        DVec3::new(0.4, -0.3, -1.0),
        DVec3::new(1.0, 0.0, -0.05),
    ] {
        let maps = render_maps(&object, direction, 96, 2).unwrap();
        assert_finite(&maps);
        let counts = coverage_counts(&object, direction, 96).unwrap();
        assert!(
            counts.iter().all(|&c| c <= 1),
            "{direction}: a pixel covered twice"
        );
    }
}

#[test]
fn triangles_far_smaller_than_a_pixel_leave_no_crack() {
    // 2 M triangles over about 23 x 23 pixels: some four thousand triangles a pixel.
    let object = PreparedObject::new(&plate(1000, 0.0, [90, 160, 220, 255]).finish().0).unwrap();
    assert_square_covered_once(&object, 32);
    for direction in [DVec3::NEG_Z, DVec3::new(-0.5, 0.7, -0.6)] {
        assert_finite(&render_maps(&object, direction, 32, 2).unwrap());
    }
}

#[test]
fn nearly_coplanar_overlapping_faces_keep_one_colour_each_pixel_and_no_nan() {
    // Two plates 1e-7 apart (below f32's resolution at 1: they coincide on the GPU's grid),
    // red behind, blue in front, and a third exactly coplanar with the red one, green.
    let mut b = plate(8, 0.0, [255, 0, 0, 255]);
    add_plate(&mut b, 8, 1e-7, [0, 0, 255, 255]);
    add_plate(&mut b, 8, 0.0, [0, 255, 0, 255]);
    let (object, _) = b.finish();
    let object = PreparedObject::new(&object).unwrap();
    for direction in [DVec3::NEG_Z, DVec3::new(0.2, 0.1, -1.0), DVec3::Z] {
        let maps = render_maps(&object, direction, 64, 2).unwrap();
        assert_finite(&maps);
        let covered = maps.stencil.iter().filter(|&&s| s).count();
        assert!(covered > 64 * 64 / 3, "{direction}: {covered} pixels");
        for at in 0..maps.stencil.len() {
            if maps.stencil[at] {
                assert!(
                    [[255, 0, 0, 255], [0, 0, 255, 255], [0, 255, 0, 255]]
                        .contains(&maps.color[at]),
                    "{direction}: pixel {at} is {:?}, a blend",
                    maps.color[at]
                );
            }
        }
    }
}

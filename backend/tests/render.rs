//! The rasteriser and the board against analytic references.

use backend::{
    Board, EncodedBoard, PreparedObject, RenderError, SPLIT_WORK, coverage_counts, render_maps,
    render_mesh, render_mesh_timed, threads_worth,
};
use glam::DVec3;
use scene::{Object, ObjectBuilder};

/// A UV sphere of radius `r` at `center` with `n` segments around (closed, CCW outside).
fn sphere(center: DVec3, r: f64, n: u32) -> Object {
    let mut b = ObjectBuilder::new("sphere");
    scene::shapes::sphere(&mut b, center, r, n, [200, 100, 50, 255]);
    b.finish().0
}

/// A flat grid of `n × n` quads in the plane z = `z`, from (-1,-1) to (1,1), facing +z.
fn plate(n: u32, z: f64, color: [u8; 4]) -> Object {
    let mut b = ObjectBuilder::new("plate");
    for i in 0..=n {
        for j in 0..=n {
            b.vertex(
                DVec3::new(
                    -1.0 + 2.0 * j as f64 / n as f64,
                    -1.0 + 2.0 * i as f64 / n as f64,
                    z,
                ),
                color,
            );
        }
    }
    for i in 0..n {
        for j in 0..n {
            let at = |i: u32, j: u32| i * (n + 1) + j;
            b.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
            b.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
        }
    }
    b.finish().0
}

fn prepared(object: &Object) -> PreparedObject {
    PreparedObject::new(object).unwrap()
}

/// Map coordinates of pixel `at` (centre), x right and y up in [-1, 1].
fn pixel_xy(at: usize, size: u32) -> (f64, f64) {
    let (column, row) = ((at as u32 % size) as f64, (at as u32 / size) as f64);
    (
        (column + 0.5) / size as f64 * 2.0 - 1.0,
        1.0 - (row + 0.5) / size as f64 * 2.0,
    )
}

#[test]
fn a_timed_render_draws_the_same_maps_and_times_each_stage_within_the_whole() {
    let object = prepared(&sphere(DVec3::ZERO, 1.0, 64));
    let direction = DVec3::new(0.3, -0.5, 0.8);
    let plain = render_mesh(&object, object.full_mesh(), direction, 96, 1).unwrap();
    let start = std::time::Instant::now();
    let (timed, stages) = render_mesh_timed(&object, object.full_mesh(), direction, 96, 1).unwrap();
    let whole = start.elapsed();
    // Uncovered depths are NaN, so the maps are compared as the bytes a worker sends.
    assert!(
        EncodedBoard::encode(&timed).bytes == EncodedBoard::encode(&plain).bytes,
        "the timed render drew other maps"
    );
    let sum =
        stages.projection + stages.triangle_pass + stages.grow_at_cuts + stages.per_pixel_pass;
    assert!(sum <= whole, "{stages:?} against {whole:?}");
    assert!(
        !stages.triangle_pass.is_zero() && !stages.per_pixel_pass.is_zero(),
        "{stages:?}"
    );
}

#[test]
fn only_a_large_board_on_an_idle_worker_is_split_over_threads() {
    // A sphere of a few hundred triangles: its boards' work is nearly all pixels.
    let small = prepared(&sphere(DVec3::ZERO, 1.0, 16));
    assert!(small.triangles.len() + 64 * 64 < SPLIT_WORK);
    const { assert!(128 * 128 >= SPLIT_WORK) };
    assert_eq!(
        threads_worth(small.mesh_for_size(64), 64, 4, 0),
        1,
        "too small to pay"
    );
    assert_eq!(
        threads_worth(small.mesh_for_size(128), 128, 4, 0),
        4,
        "large, worker idle"
    );
    assert_eq!(
        threads_worth(small.mesh_for_size(128), 128, 4, 1),
        1,
        "large, another board waits"
    );
    // Triangles count as work too (no levels built: boards draw the full mesh).
    let dense = prepared(&sphere(DVec3::ZERO, 1.0, 192));
    assert!(dense.triangles.len() >= SPLIT_WORK);
    assert_eq!(
        threads_worth(dense.mesh_for_size(32), 32, 4, 0),
        4,
        "many triangles, worker idle"
    );
    assert_eq!(
        threads_worth(dense.mesh_for_size(32), 32, 1, 0),
        1,
        "one thread is all there is"
    );
}

#[test]
fn a_sphere_gives_its_analytic_depth_normals_and_a_hole_free_disk() {
    let size = 128;
    let object = prepared(&sphere(DVec3::new(3.0, -2.0, 5.0), 2.0, 128));
    for threads in [1, 2, 3] {
        let maps = render_maps(&object, DVec3::new(0.0, 0.0, -1.0), size, threads).unwrap();
        // The sphere's box has half-diagonal r·√3, so in map units the sphere's radius is 1/√3.
        let radius = 1.0 / 3f64.sqrt();
        let pixel = 2.0 / size as f64;
        let mut worst_depth: f64 = 0.0;
        let mut worst_angle: f64 = 0.0;
        for at in 0..(size * size) as usize {
            let (x, y) = pixel_xy(at, size);
            let rho = (x * x + y * y).sqrt();
            if rho < radius - 1.5 * pixel {
                assert!(maps.stencil[at], "pinhole at {at} (threads {threads})");
                let depth = -(radius * radius - rho * rho).sqrt();
                worst_depth = worst_depth.max((maps.depth[at] as f64 - depth).abs());
                // Looking along -z with up = +y: right = +x, so the map's (x, y, z) is the
                // object's (x, y, -z); the outward normal there points back at the viewer.
                let expected = DVec3::new(x, y, -depth).normalize();
                let normal = DVec3::from_array(maps.normal[at].map(f64::from));
                worst_angle = worst_angle.max(normal.angle_between(expected).to_degrees());
                assert_eq!(maps.color[at], [200, 100, 50, 255]);
            } else if rho > radius + 1.5 * pixel {
                assert!(!maps.stencil[at], "coverage outside the silhouette at {at}");
            }
        }
        // 128 segments: the polygon deviates from the sphere by r(1 - cos(π/128)) = 3e-4 r;
        // near the rim a pixel's depth changes fast, hence the margin.
        assert!(worst_depth < 0.01, "depth error {worst_depth}");
        assert!(worst_angle < 3.0, "normal error {worst_angle} degrees");
    }
}

#[test]
fn a_box_gives_flat_faces_at_their_analytic_depth() {
    // A unit cube seen along -z: the front face z = +0.5 fills the centre of the view at map
    // depth -0.5/r with r = √3/2 (half the cube's diagonal).
    // Twice: each face with vertices of its own, as some exporters write boxes, and all faces
    // sharing the eight corners, where the crease angle must keep the edges sharp.
    for shared in [false, true] {
        let mut b = ObjectBuilder::new("cube");
        let corner = |i: u32| {
            DVec3::new(
                (i & 1) as f64 - 0.5,
                ((i >> 1) & 1) as f64 - 0.5,
                ((i >> 2) & 1) as f64 - 0.5,
            )
        };
        let common: Vec<u32> = if shared {
            (0..8)
                .map(|i| b.vertex(corner(i), [10, 20, 30, 255]))
                .collect()
        } else {
            Vec::new()
        };
        for f in [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ] {
            let ids: Vec<u32> = if shared {
                f.iter().map(|&i| common[i as usize]).collect()
            } else {
                f.iter()
                    .map(|&i| b.vertex(corner(i), [10, 20, 30, 255]))
                    .collect()
            };
            b.triangle(ids[0], ids[1], ids[2]);
            b.triangle(ids[0], ids[2], ids[3]);
        }
        check_cube(&prepared(&b.finish().0));
    }
}

fn check_cube(object: &PreparedObject) {
    let size = 64;
    let maps = render_maps(object, DVec3::NEG_Z, size, 2).unwrap();
    let half = 0.5 / (3f64.sqrt() / 2.0);
    for at in 0..(size * size) as usize {
        let (x, y) = pixel_xy(at, size);
        let inside = x.abs() < half && y.abs() < half;
        assert_eq!(maps.stencil[at], inside, "pixel {at} at ({x}, {y})");
        if inside {
            assert!(
                (maps.depth[at] as f64 + half).abs() < 1e-5,
                "depth {} at {at}",
                maps.depth[at]
            );
            assert!((DVec3::from_array(maps.normal[at].map(f64::from)) - DVec3::Z).length() < 1e-5);
        }
    }
}

#[test]
fn shared_edges_are_covered_exactly_once() {
    // A fine grid whose vertices fall exactly on pixel centres and edges: every centre inside
    // is covered by exactly one triangle; a closed sphere, by exactly two (front and back).
    let flat = prepared(&plate(16, 0.0, [255; 4]));
    let counts = coverage_counts(&flat, DVec3::NEG_Z, 64).unwrap();
    let inside: Vec<u32> = counts.iter().copied().filter(|c| *c > 0).collect();
    assert!(inside.len() > 1000);
    assert!(
        inside.iter().all(|c| *c == 1),
        "double hits: {:?}",
        inside.iter().filter(|c| **c != 1).count()
    );
    let round = prepared(&sphere(DVec3::ZERO, 1.0, 48));
    for direction in [DVec3::NEG_Z, DVec3::new(0.3, -0.8, 0.2), DVec3::Y] {
        let counts = coverage_counts(&round, direction, 96).unwrap();
        assert!(
            counts.iter().all(|c| *c == 0 || *c == 2),
            "{direction}: counts {:?}",
            counts.iter().filter(|c| **c != 0 && **c != 2).count()
        );
    }
}

#[test]
fn every_axis_direction_works_and_far_tiny_objects_keep_their_shape() {
    let base = prepared(&sphere(DVec3::ZERO, 1.0, 64));
    let reference = render_maps(&base, DVec3::NEG_Z, 64, 1).unwrap().covered();
    for direction in [
        DVec3::X,
        DVec3::NEG_X,
        DVec3::Y,
        DVec3::NEG_Y,
        DVec3::Z,
        DVec3::NEG_Z,
        DVec3::new(1e-9, 1.0, 0.0),
        DVec3::new(0.0, -1.0, 1e-12),
    ] {
        let maps = render_maps(&base, direction, 64, 2).unwrap();
        let b = maps.basis;
        assert!(
            (b.right.length() - 1.0).abs() < 1e-12 && (b.up.length() - 1.0).abs() < 1e-12,
            "{direction}"
        );
        assert!(
            b.right.dot(b.up).abs() < 1e-12
                && b.right.dot(b.forward).abs() < 1e-12
                && b.up.dot(b.forward).abs() < 1e-12
        );
        // A sphere looks the same from everywhere (up to its tessellation).
        let covered = maps.covered() as f64;
        assert!(
            (covered / reference as f64 - 1.0).abs() < 0.03,
            "{direction}: {covered} vs {reference}"
        );
    }
    // A millimetre sphere ten thousand kilometres out renders like one at the origin.
    let far = prepared(&sphere(DVec3::splat(1e7), 1e-3, 64));
    let near = prepared(&sphere(DVec3::ZERO, 1e-3, 64));
    let (a, b) = (
        render_maps(&far, DVec3::new(1.0, 2.0, 3.0), 64, 1).unwrap(),
        render_maps(&near, DVec3::new(1.0, 2.0, 3.0), 64, 1).unwrap(),
    );
    let differ = a
        .stencil
        .iter()
        .zip(&b.stencil)
        .filter(|(x, y)| x != y)
        .count();
    assert!(differ <= 2, "{differ} pixels differ");
}

#[test]
fn bad_requests_are_refused_and_degenerate_objects_render() {
    let object = prepared(&sphere(DVec3::ZERO, 1.0, 16));
    for direction in [
        DVec3::ZERO,
        DVec3::new(f64::NAN, 0.0, 1.0),
        DVec3::new(f64::INFINITY, 0.0, 0.0),
    ] {
        assert!(
            matches!(
                render_maps(&object, direction, 32, 1),
                Err(RenderError::BadDirection(_))
            ),
            "{direction}"
        );
    }
    assert!(matches!(
        render_maps(&object, DVec3::Z, 0, 1),
        Err(RenderError::BadResolution { .. })
    ));
    assert!(matches!(
        render_maps(&object, DVec3::Z, 1 << 20, 1),
        Err(RenderError::BadResolution { .. })
    ));
    // One triangle, and a flat object with zero depth range seen face on.
    let mut b = ObjectBuilder::new("one");
    let (p, q, r) = (
        b.vertex(DVec3::ZERO, [255; 4]),
        b.vertex(DVec3::X, [255; 4]),
        b.vertex(DVec3::Y, [255; 4]),
    );
    b.triangle(p, q, r);
    let single = prepared(&b.finish().0);
    let maps = render_maps(&single, DVec3::NEG_Z, 32, 2).unwrap();
    assert!(maps.covered() > 100);
    let board = Board::from_maps(maps);
    assert_eq!(
        board.depth_range[0], board.depth_range[1],
        "flat: zero depth range"
    );
    let decoded = EncodedBoard::encode(&board.maps).decode().unwrap();
    assert_eq!(decoded.stencil, board.maps.stencil);
    // Seen edge on, it covers nothing, which is a valid (empty) board.
    let edge_on = render_maps(&single, DVec3::X, 32, 1).unwrap();
    assert_eq!(edge_on.covered(), 0);
    assert!(Board::from_maps(edge_on).grid.triangles.is_empty());
}

#[test]
fn the_grid_covers_exactly_the_cells_with_covered_pixels_and_sits_on_the_surface() {
    // Two plates, one in front of the other's left half: along the seam the depth jumps.
    let mut builder = ObjectBuilder::new("two plates");
    for (plate, x0, z) in [
        (plate(8, 0.0, [255, 0, 0, 255]), -1.0, 0.0),
        (plate(8, 0.0, [0, 0, 255, 255]), -1.0, 1.0),
    ] {
        let first = builder.vertex_count() as u32;
        for (i, p) in plate.positions.iter().enumerate() {
            let p = plate.origin + p.as_dvec3();
            let x = if z > 0.0 { x0 + (p.x + 1.0) * 0.5 } else { p.x };
            builder.vertex(DVec3::new(x, p.y, z), plate.colors[i]);
        }
        for &[a, b, c] in &plate.triangles {
            builder.triangle(first + a, first + b, first + c);
        }
    }
    let object = prepared(&builder.finish().0);
    let maps = render_maps(&object, DVec3::NEG_Z, 64, 1).unwrap();
    let size = maps.size as usize;
    for cells in [64u32, 16, 5, 1] {
        let grid = backend::Grid::new(&maps, cells);
        // Counted independently: a cell of `step` pixels is kept when one of them is covered.
        let step = size.div_ceil(cells as usize);
        let per_side = size.div_ceil(step);
        let kept = (0..per_side * per_side)
            .filter(|cell| {
                let (row, column) = (cell / per_side * step, cell % per_side * step);
                (row..(row + step).min(size)).any(|r| {
                    (column..(column + step).min(size)).any(|c| maps.stencil[r * size + c])
                })
            })
            .count();
        assert_eq!(grid.triangles.len(), 2 * kept, "{cells} cells");
        // Every vertex lies on the board and within the covered depths: no skin reaches
        // past the nearest or farthest surface.
        let board = Board::from_maps(maps.clone());
        let [near, far] = board.depth_range;
        for &[x, y, z] in &grid.vertices {
            assert!((-1.0..=1.0).contains(&x) && (-1.0..=1.0).contains(&y));
            assert!(
                z >= near - 1e-6 && z <= far + 1e-6,
                "{z} outside {near}..{far}"
            );
        }
        for triangle in &grid.triangles {
            assert!(triangle.iter().all(|&v| (v as usize) < grid.vertices.len()));
            // Counter-clockwise seen from the viewer (x right, y up): positive area.
            let [a, b, c] = triangle.map(|v| grid.vertices[v as usize]);
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            assert!(area > 0.0, "{cells} cells: {triangle:?}");
        }
    }
    // At one cell per pixel, that is two triangles per covered pixel.
    let board = Board::from_maps(maps);
    assert_eq!(board.grid.triangles.len(), 2 * board.maps.covered());
}

#[test]
fn encoding_round_trips_within_its_quantisation_and_is_small() {
    let object = prepared(&sphere(DVec3::new(1.0, 2.0, 3.0), 5.0, 96));
    let maps = render_maps(&object, DVec3::new(-1.0, -0.5, 0.3), 256, 2).unwrap();
    let encoded = EncodedBoard::encode(&maps);
    assert!(
        encoded.bytes.len() * 5 < EncodedBoard::raw_bytes(256),
        "{} bytes",
        encoded.bytes.len()
    );
    let decoded = encoded.decode().unwrap();
    assert_eq!(decoded.stencil, maps.stencil);
    assert_eq!(decoded.color, maps.color);
    assert_eq!(decoded.basis, maps.basis);
    let (low, high) = maps
        .depth
        .iter()
        .filter(|d| !d.is_nan())
        .fold((f32::MAX, f32::MIN), |(l, h), d| (l.min(*d), h.max(*d)));
    for at in 0..maps.stencil.len() {
        if maps.stencil[at] {
            assert!((decoded.depth[at] - maps.depth[at]).abs() <= (high - low) / 65535.0 + 1e-6);
            let (a, b) = (
                glam::Vec3::from_array(decoded.normal[at]),
                glam::Vec3::from_array(maps.normal[at]),
            );
            assert!(
                a.angle_between(b).to_degrees() < 1.0,
                "normal error at {at}"
            );
        }
    }
    // Corrupt bytes are an error, never a panic.
    for cut in [0, 10, 50, encoded.bytes.len() / 2, encoded.bytes.len() - 1] {
        assert!(
            EncodedBoard {
                bytes: encoded.bytes[..cut].to_vec()
            }
            .decode()
            .is_err(),
            "cut at {cut}"
        );
    }
    let mut flipped = encoded.bytes.clone();
    for i in (130..flipped.len()).step_by(97) {
        flipped[i] ^= 0x5a;
        let _ = EncodedBoard {
            bytes: flipped.clone(),
        }
        .decode();
    }
}

#[test]
fn a_board_comes_from_the_coarsest_level_within_half_a_pixel_and_matches_the_full_mesh() {
    let full = prepared(&sphere(DVec3::new(1.0, 2.0, 3.0), 1.5, 256));
    assert_eq!(full.mesh_for_size(32).triangles.len(), full.triangles.len());
    let object = full.with_levels();
    assert!(
        object.levels().len() >= 4,
        "{} levels",
        object.levels().len()
    );
    let pixel = |size: u32| 2.0 * object.radius / size as f64;
    for size in [32, 64, 256] {
        let level = object.mesh_for_size(size);
        assert!(level.error <= backend::MAX_ERROR_PIXELS * pixel(size));
        // The coarsest such: every level down breaks the bound or loses the silhouette at
        // this size.
        assert!(
            object
                .levels()
                .iter()
                .filter(|l| l.triangles.len() < level.triangles.len())
                .all(
                    |l| l.error > backend::MAX_ERROR_PIXELS * pixel(size) || l.smallest_size > size
                )
        );
        if size <= 64 {
            // A sphere of some ten pixels across needs a few hundred triangles, not 65 k.
            assert!(level.triangles.len() * 8 < object.triangles.len(), "{size}");
        }
        let direction = DVec3::new(0.3, -0.5, -1.0);
        let simplified = render_maps(&object, direction, size, 1).unwrap();
        let reference =
            backend::render_mesh(&object, object.full_mesh(), direction, size, 1).unwrap();
        let (mut both, mut either) = (0, 0);
        let (mut facing_worst, mut sum, mut count) = (0.0f64, 0.0f64, 0);
        let toward_viewer = -direction.normalize();
        for at in 0..reference.stencil.len() {
            let (a, b) = (reference.stencil[at], simplified.stencil[at]);
            both += (a && b) as usize;
            either += (a || b) as usize;
            if a && b {
                // Depth spans [-1, 1] over `size` pixels.
                let d =
                    (reference.depth[at] - simplified.depth[at]).abs() as f64 * 0.5 * size as f64;
                (sum, count) = (sum + d, count + 1);
                // A surface off by e along its normal is off by e / cos along the view: at
                // the silhouette without bound, where the surface faces the viewer by at
                // most twice e.
                let normal = DVec3::from_array(reference.normal[at].map(f64::from));
                if normal.dot(toward_viewer) >= 0.5 {
                    facing_worst = facing_worst.max(d);
                }
            }
        }
        let iou = both as f64 / either as f64;
        assert!(iou >= 0.98, "size {size}: stencil IoU {iou}");
        let bound = 2.0 * backend::MAX_ERROR_PIXELS;
        assert!(
            facing_worst <= bound,
            "size {size}: depth off by {facing_worst} px where the surface faces the viewer"
        );
        assert!(
            sum / count as f64 <= backend::MAX_ERROR_PIXELS,
            "size {size}: mean depth error {} px",
            sum / count as f64
        );
    }
}

/// Views other than the ones the worker checks its levels from.
const OTHER_VIEWS: [DVec3; 3] = [
    DVec3::new(1.0, 0.2, 0.1),
    DVec3::new(-0.1, -1.0, 0.4),
    DVec3::new(0.2, 0.3, 1.0),
];

/// Stencil IoU of `mesh` against the full mesh of `object` at `size`, and its covered pixels
/// over the full mesh's, over [`OTHER_VIEWS`]. `shift` moves `mesh` by that many pixels along
/// each view's image x axis first.
fn against_full(
    object: &PreparedObject,
    mesh: backend::MeshRef<'_>,
    size: u32,
    shift: f64,
) -> (f64, f64) {
    let (mut iou, mut covered, mut full_covered) = (0.0, 0, 0);
    for direction in OTHER_VIEWS {
        let a = backend::render_mesh(object, object.full_mesh(), direction, size, 1).unwrap();
        let mut moved = object.clone();
        let (right, _) = scene::view_axes(direction.normalize());
        let pixel = 2.0 * object.radius / size as f64;
        moved.local_center -= (right * shift * pixel).as_vec3();
        let b = backend::render_mesh(&moved, mesh, direction, size, 1).unwrap();
        let (mut both, mut either) = (0, 0);
        for (x, y) in a.stencil.iter().zip(&b.stencil) {
            both += (*x && *y) as usize;
            either += (*x || *y) as usize;
        }
        iou += both as f64 / either.max(1) as f64;
        covered += b.covered();
        full_covered += a.covered();
    }
    (
        iou / OTHER_VIEWS.len() as f64,
        covered as f64 / full_covered as f64,
    )
}

#[test]
fn foliage_is_thinned_keeping_its_coverage_where_mesh_simplification_loses_it() {
    // 20,000 small separate leaves in a ball.
    let mut b = ObjectBuilder::new("leaves");
    let mut state = 12345u64;
    let mut random = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..20_000 {
        let center = loop {
            let p = DVec3::new(random(), random(), random());
            if p.length() <= 1.0 {
                break p;
            }
        };
        let (u, v) = (
            DVec3::new(random(), random(), random()).normalize() * 0.01,
            DVec3::new(random(), random(), random()).normalize() * 0.01,
        );
        // Corners centre ∓ u ∓ v: the leaf's tips at ±(u + v) and ±(v - u).
        scene::shapes::leaf(&mut b, center, u + v, v - u, [40, 120, 30, 255]);
    }
    let object = prepared(&b.finish().0);
    // meshoptimizer's first level claims to be fine at 32 pixels but thins the ball: whole
    // leaves collapse, which its error (how far the surface moved) does not count.
    let raw = backend::LodChain::build(&object.vertices, &object.triangles);
    let pixel_32 = 2.0 * object.radius / 32.0;
    assert!(
        raw.errors[1] <= backend::MAX_ERROR_PIXELS * pixel_32,
        "{:?}",
        raw.errors
    );
    let first = raw.levels[0].clone();
    let raw_first = backend::MeshRef {
        vertices: &object.vertices,
        triangles: &first,
        error: raw.errors[1],
    };
    let (iou, coverage) = against_full(&object, raw_first, 32, 0.0);
    assert!(
        iou < 0.95 && coverage < 0.95,
        "IoU {iou}, coverage {coverage}"
    );
    // The worker's levels thin the leaves and grow the ones they keep: a quarter of the
    // triangles or fewer at 32 pixels, with the coverage kept and the silhouette no further
    // from the full mesh's than the full mesh moved half a pixel is.
    let object = object.with_levels();
    assert!(object.mesh_for_size(32).triangles.len() * 4 <= object.triangles.len());
    for size in [32, 64, 128, 256] {
        let mesh = object.mesh_for_size(size);
        let (iou, coverage) = against_full(&object, mesh, size, 0.0);
        let (half_pixel, _) = against_full(&object, object.full_mesh(), size, 0.5);
        assert!(
            (coverage - 1.0).abs() <= 0.03 && iou >= half_pixel - 0.02,
            "size {size}: {} triangles, IoU {iou} (half a pixel: {half_pixel}), coverage {coverage}",
            mesh.triangles.len()
        );
    }
}

#[test]
fn a_board_grows_one_pixel_past_a_cut_and_nowhere_else() {
    // A tilted square (its depth changes across it), once whole and once with its x = 1 edge
    // marked as a cut between pieces of a larger mesh.
    let piece = |cut: bool| {
        let n = 6;
        let mut b = ObjectBuilder::new("piece");
        for i in 0..=n {
            for j in 0..=n {
                let (x, y) = (
                    -1.0 + 2.0 * j as f64 / n as f64,
                    -1.0 + 2.0 * i as f64 / n as f64,
                );
                let v = b.vertex(DVec3::new(x, y, 0.3 * x), [200, 100, 50, 255]);
                if cut && j == n {
                    b.mark_seam(v);
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                let at = |i: u32, j: u32| i * (n + 1) + j;
                b.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
                b.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
            }
        }
        prepared(&b.finish().0)
    };
    let size = 64;
    // Seen nearly face on: each row of the square gains exactly the pixel beyond the cut,
    // at the depth of the square's plane extended there; its other three edges stay put.
    let direction = DVec3::new(0.1, 0.05, -1.0);
    let whole = render_maps(&piece(false), direction, size, 1).unwrap();
    let cut = render_maps(&piece(true), direction, size, 1).unwrap();
    // Which way the cut lies on the map: world +x against the map's right.
    let step: i64 = if cut.basis.right.x > 0.0 { 1 } else { -1 };
    let n = size as i64;
    let mut grown_rows = 0;
    for row in 0..n {
        let at = |column: i64| (row * n + column) as usize;
        let columns: Vec<i64> = (0..n).filter(|&c| whole.stencil[at(c)]).collect();
        for column in 0..n {
            if whole.stencil[at(column)] {
                assert!(cut.stencil[at(column)], "a covered pixel stays covered");
                assert_eq!(cut.depth[at(column)], whole.depth[at(column)]);
            }
        }
        let added: Vec<i64> = (0..n)
            .filter(|&c| cut.stencil[at(c)] && !whole.stencil[at(c)])
            .collect();
        let Some(&edge) = (if step > 0 {
            columns.last()
        } else {
            columns.first()
        }) else {
            assert!(added.len() <= 2, "row {row} beyond the square: {added:?}");
            continue;
        };
        assert_eq!(
            added,
            vec![edge + step],
            "row {row}: one pixel past the cut"
        );
        let expected = 2.0 * whole.depth[at(edge)] - whole.depth[at(edge - step)];
        let got = cut.depth[at(edge + step)];
        assert!(
            (got - expected).abs() < 1e-4,
            "row {row}: depth {got}, plane {expected}"
        );
        assert_eq!(cut.color[at(edge + step)], [200, 100, 50, 255]);
        grown_rows += 1;
    }
    assert!(
        grown_rows > size as usize / 4,
        "{grown_rows} rows cross the square"
    );
    // Seen at a grazing angle (75° from its normal) the cut's triangles do not grow: where a
    // cut meets an outline they would widen the silhouette.
    let grazing = DVec3::new(0.0, -0.97, -0.26);
    let whole = render_maps(&piece(false), grazing, size, 1).unwrap();
    let cut = render_maps(&piece(true), grazing, size, 1).unwrap();
    assert!(whole.covered() > 100);
    assert_eq!(cut.stencil, whole.stencil);
}

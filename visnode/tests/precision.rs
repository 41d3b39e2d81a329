//! Numbers that break renderers: a scene ten million units from the origin, and a depth range
//! from a metre to kilometres where boards (which write their own depth) meet terrain.
//! Real renderer (lavapipe in CI), real in-process workers.

mod common;
use std::path::PathBuf;

use glam::DVec3;
use visnode::board::BoardShape;
use visnode::camera::Camera;
use visnode::image_error::Shot;
use visnode::plan::PlanParams;
use visnode::render::{BoardDepth, Image, Renderer};
use visnode::workers::Workers;
use visnode::{Viewer, ViewerOptions};

fn bunny(color: [u8; 4]) -> scene::Object {
    let mut bunny = common::bunny();
    bunny.colors.fill(color);
    bunny
}

/// `object` scaled by `scale` about its origin, then moved so its lowest point is at
/// `base`.
fn placed(object: &scene::Object, scale: f32, base: DVec3) -> scene::Object {
    let mut placed = object.clone();
    for p in &mut placed.positions {
        *p *= scale;
    }
    let bounds = placed.bounds();
    let bottom = DVec3::new(bounds.center().x, bounds.min.y, bounds.center().z);
    placed.origin += base - bottom;
    placed
}

/// Every frame synchronous (boards made for this very camera), no cross-fade: reproducible.
fn viewer(objects: &[scene::Object], suitable: &[bool], resolution: [u32; 2]) -> Viewer {
    viewer_with_grid(objects, suitable, resolution, 32)
}

/// [`viewer`] with boards of at most `grid_cells` cells a side (a cell per pixel below that).
fn viewer_with_grid(
    objects: &[scene::Object],
    suitable: &[bool],
    resolution: [u32; 2],
    grid_cells: u32,
) -> Viewer {
    let renderer = Renderer::new(resolution)
        .expect("the precision tests need a wgpu adapter: install mesa-vulkan-drivers libvulkan1 (lavapipe)");
    let requests = visnode::setup::requests_on(
        Workers::start_local(2, 1).unwrap(),
        &std::sync::Arc::new(objects.to_vec()),
        suitable,
        1,
        BoardShape::Relief {
            grid_cells,
            cell_pixels: 1,
        },
        false,
        &indicatif::ProgressBar::hidden(),
    );
    let options = ViewerOptions {
        plan: PlanParams {
            t_nz: 0,
            ..PlanParams::default()
        },
        fade_frames: 0,
        sync: true,
        ..ViewerOptions::default()
    };
    Viewer::new(
        renderer,
        objects,
        suitable,
        visnode::far_field::boards_or_fallback(requests, true),
        options,
        None,
        &indicatif::ProgressBar::hidden(),
    )
    .unwrap()
}

/// The frame with boards and the all-geometry reference.
fn frames(viewer: &mut Viewer, camera: &Camera, resolution: [u32; 2]) -> (Shot, Shot, usize) {
    let shot = |viewer: &Viewer| Shot::read(&viewer.renderer).unwrap();
    let report = viewer.frame(camera, resolution).unwrap();
    let image = shot(viewer);
    viewer.reference_frame(camera, resolution).unwrap();
    (image, shot(viewer), report.boards)
}

#[test]
fn a_scene_ten_million_units_from_the_origin_renders_as_at_the_origin() {
    let resolution = [320, 240];
    let base = bunny([200, 160, 90, 255]);
    let radius = base.bounds().diagonal() * 0.5;
    let row: Vec<scene::Object> = (0..4)
        .map(|i| placed(&base, 1.0, DVec3::new(i as f64 * 2.5 * radius, 0.0, 0.0)))
        .collect();
    let camera = Camera {
        position: DVec3::new(3.75 * radius, 2.0 * radius, 9.0 * radius),
        target: DVec3::new(3.75 * radius, 0.5 * radius, 0.0),
        fov_y_degrees: 50.0,
    };
    let render = |offset: DVec3| {
        let objects: Vec<scene::Object> = row
            .iter()
            .map(|o| {
                let mut moved = o.clone();
                moved.origin += offset;
                moved
            })
            .collect();
        let mut viewer = viewer(&objects, &[true; 4], resolution);
        let moved = Camera {
            position: camera.position + offset,
            target: camera.target + offset,
            ..camera
        };
        frames(&mut viewer, &moved, resolution)
    };
    let (relief, geometry, boards) = render(DVec3::ZERO);
    assert_eq!(boards, 4, "every object is a board");
    let (far_relief, far_geometry, far_boards) = render(DVec3::splat(1e7));
    assert_eq!(far_boards, 4);
    for (what, near, far) in [
        ("relief", &relief, &far_relief),
        ("geometry", &geometry, &far_geometry),
    ] {
        let psnr = visnode::image_error::compare(near, far, 24).psnr_db();
        eprintln!("{what}: PSNR {psnr:.2} dB between the origin and 1e7 away");
        assert!(psnr >= 40.0, "{what}: {psnr:.2} dB");
    }
}

/// What a pixel shows, from the colours this scene uses: terrain green, objects red.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Class {
    Sky,
    Terrain,
    Object,
}

fn classify(image: &Image) -> Vec<Class> {
    image
        .rgba
        .chunks_exact(4)
        .map(|p| {
            let (r, g) = (p[0] as i32, p[1] as i32);
            if g > r + 40 {
                Class::Terrain
            } else if r > g + 40 {
                Class::Object
            } else {
                Class::Sky
            }
        })
        .collect()
}

/// A 10 km terrain seen from 1.6 m above it, with objects from 1 m to 5 km away, each a
/// board cut through by a wall drawn as geometry: nowhere may a board and the geometry swap
/// their order against the all-geometry reference. Standard Z cannot both keep a near plane
/// close enough for the object 1 m away and resolve tens of metres at 5 km; reverse-Z can.
/// Measured: 1 pixel swapped of 6,652 object pixels with either board depth (at most 32
/// cells a side, a cell per pixel below that).
#[test]
fn boards_and_terrain_keep_their_depth_order_from_a_metre_to_five_kilometres() {
    let resolution = [480, 320];
    let eye = DVec3::new(0.0, 1.6, 0.0);
    // The terrain: a 10 km square of 8 x 8 quads, always geometry.
    let mut terrain = scene::ObjectBuilder::new("terrain");
    let cells = 8;
    for i in 0..=cells {
        for j in 0..=cells {
            let x = -1000.0 + 10_000.0 * i as f64 / cells as f64;
            let z = -5000.0 + 10_000.0 * j as f64 / cells as f64;
            terrain.vertex(DVec3::new(x, 0.0, z), [40, 190, 40, 255]);
        }
    }
    for i in 0..cells {
        for j in 0..cells {
            let at = |i: u32, j: u32| i * (cells + 1) + j;
            terrain.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
            terrain.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
        }
    }
    let mut objects = vec![terrain.finish().0];
    let red = bunny([220, 30, 30, 255]);
    let height = red.bounds().size().y;
    // Each object 0.12 of its distance tall, fanned out across the view; the two nearest
    // float at eye height (standing on the ground they would be below the view).
    let distances = [1.0, 3.0, 12.0, 40.0, 120.0, 400.0, 1200.0, 2500.0, 5000.0];
    // Geometry that cuts through each board: a wall (terrain-coloured, drawn as geometry)
    // through the object's centre, turned 35 degrees from facing the viewer, so the object's
    // surface crosses the wall's depth along a curve on screen.
    let mut walls = scene::ObjectBuilder::new("walls");
    for (k, &distance) in distances.iter().enumerate() {
        let azimuth = (-38.0 + 9.5 * k as f64).to_radians();
        let ground = DVec3::new(azimuth.cos(), 0.0, azimuth.sin()) * distance;
        let size = 0.12 * distance;
        let base = if distance < 10.0 {
            ground + DVec3::new(0.0, eye.y - size * 0.5, 0.0)
        } else {
            ground
        };
        let object = placed(&red, (size / height) as f32, base);
        let center = object.bounds().center();
        let toward = (eye - center).with_y(0.0).normalize();
        let along = glam::DQuat::from_rotation_y(35f64.to_radians()) * toward.cross(DVec3::Y);
        let corner =
            |u: f64, v: f64| center + along * (u * 0.45 * size) + DVec3::Y * (v * 0.3 * size);
        let first = walls.vertex_count() as u32;
        for (u, v) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            walls.vertex(corner(u, v), [40, 190, 40, 255]);
        }
        walls.triangle(first, first + 1, first + 2);
        walls.triangle(first, first + 2, first + 3);
        objects.push(object);
    }
    objects.push(walls.finish().0);
    let mut suitable = vec![true; objects.len()];
    suitable[0] = false;
    suitable[objects.len() - 1] = false;
    let camera = Camera {
        position: eye,
        target: eye + DVec3::new(1.0, -0.02, 0.0),
        fov_y_degrees: 60.0,
    };
    // Either depth a board may take keeps the order: its depth map's, per pixel, and its
    // displaced grid's.
    for depth in [BoardDepth::Pixel, BoardDepth::Grid] {
        let mut viewer = viewer(&objects, &suitable, resolution);
        viewer.renderer.board_depth = depth;
        let (image, reference, boards) = frames(&mut viewer, &camera, resolution);
        assert_eq!(boards, distances.len(), "every object is a board");
        if let Some(dir) = std::env::var_os("RELIEFBOARD_TEST_IMAGES") {
            let side = visnode::image_error::side_by_side(&reference.image(), &image.image());
            visnode::image_error::write_png(
                &side,
                &PathBuf::from(dir).join(format!("depth-order-{depth:?}.png")),
            )
            .unwrap();
        }
        let (checked, swapped, object_pixels) = swapped_pixels(&image, &reference, resolution);
        eprintln!(
            "{depth:?}: {checked} pixels checked ({object_pixels} object pixels), {swapped} show terrain for object or object for terrain"
        );
        assert!(
            object_pixels > 2000,
            "the objects cover {object_pixels} pixels"
        );
        assert!(
            swapped * 1000 <= object_pixels,
            "{depth:?}: {swapped} pixels swapped board and terrain (of {object_pixels} object pixels)"
        );
    }
}

/// Pixels where the image shows terrain for object or object for terrain against the
/// reference: (checked, swapped, object pixels of the reference). Only pixels whose 3x3
/// neighbourhood is one class in the reference count: a board's silhouette may move by a
/// pixel, which is sampling, not depth order.
fn swapped_pixels(image: &Shot, reference: &Shot, resolution: [u32; 2]) -> (usize, usize, usize) {
    let (shown, expected) = (classify(&image.image()), classify(&reference.image()));
    let [width, height] = resolution.map(|r| r as usize);
    let (mut checked, mut swapped, mut object_pixels) = (0, 0, 0);
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let at = y * width + x;
            let uniform = (-1..=1).all(|dy: isize| {
                (-1..=1).all(|dx: isize| {
                    expected[(y as isize + dy) as usize * width + (x as isize + dx) as usize]
                        == expected[at]
                })
            });
            object_pixels += (expected[at] == Class::Object) as usize;
            if !uniform || expected[at] == Class::Sky {
                continue;
            }
            checked += 1;
            swapped += (shown[at] != expected[at]) as usize;
        }
    }
    (checked, swapped, object_pixels)
}

/// Where a wall cuts through a board, the cut follows the depth the board writes: with
/// `--board-depth pixel` the depth map's, so the object's curved surface, on any grid; with
/// `grid` the displaced grid's, so on a one-cell grid (a plane at its corners' depth) the cut
/// is the plane's, a straight line, and many pixels swap; a fine grid follows the surface.
/// Measured: 0, 17.5% and 0.04% of the object's pixels swapped.
#[test]
fn a_wall_cuts_a_board_where_the_depth_it_writes_says() {
    let resolution = [320, 240];
    let object = bunny([220, 30, 30, 255]);
    let center = object.bounds().center();
    let size = object.bounds().diagonal();
    let eye = center + DVec3::new(0.0, 0.2, 1.0).normalize() * size * 4.0;
    // A wall through the centre, turned 35 degrees from facing the viewer.
    let toward = (eye - center).with_y(0.0).normalize();
    let along = glam::DQuat::from_rotation_y(35f64.to_radians()) * toward.cross(DVec3::Y);
    let mut wall = scene::ObjectBuilder::new("wall");
    for (u, v) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        wall.vertex(
            center + along * (u * size) + DVec3::Y * (v * size),
            [40, 190, 40, 255],
        );
    }
    wall.triangle(0, 1, 2);
    wall.triangle(0, 2, 3);
    let objects = [object, wall.finish().0];
    let camera = Camera {
        position: eye,
        target: center,
        fov_y_degrees: 30.0,
    };
    let swapped_share = |grid_cells: u32, depth: BoardDepth| {
        let mut viewer = viewer_with_grid(&objects, &[true, false], resolution, grid_cells);
        viewer.renderer.board_depth = depth;
        let (image, reference, boards) = frames(&mut viewer, &camera, resolution);
        assert_eq!(boards, 1);
        let (_, swapped, object_pixels) = swapped_pixels(&image, &reference, resolution);
        assert!(
            object_pixels > 2000,
            "the object covers {object_pixels} pixels"
        );
        swapped as f64 / object_pixels as f64
    };
    let pixel_coarse = swapped_share(1, BoardDepth::Pixel);
    let grid_coarse = swapped_share(1, BoardDepth::Grid);
    let grid_fine = swapped_share(32, BoardDepth::Grid);
    eprintln!(
        "swapped: pixel depth {pixel_coarse:.4}, grid depth {grid_coarse:.4} (one cell), {grid_fine:.4} (32 cells)"
    );
    assert!(
        pixel_coarse < 0.005,
        "per-pixel depth, one cell: {pixel_coarse:.4}"
    );
    assert!(
        grid_fine < 0.005,
        "the grid's depth, 32 cells: {grid_fine:.4}"
    );
    assert!(
        grid_coarse > 0.02,
        "the grid's depth, one cell: {grid_coarse:.4}"
    );
}

/// The square [-1, 1]² (z = 0) as `columns` strips of two sliver triangles each.
fn sliver_square(columns: u32, origin: DVec3) -> scene::Object {
    let mut b = scene::ObjectBuilder::new("slivers");
    for i in 0..=columns {
        let x = -1.0 + 2.0 * i as f64 / columns as f64;
        b.vertex(origin + DVec3::new(x, -1.0, 0.0), [220, 30, 30, 255]);
        b.vertex(origin + DVec3::new(x, 1.0, 0.0), [220, 30, 30, 255]);
    }
    for i in 0..columns {
        let (b0, t0, b1, t1) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        b.triangle(b0, b1, t1);
        b.triangle(b0, t1, t0);
    }
    b.finish().0
}

/// The same square as an `n × n` grid of quads (triangles far below a pixel).
fn fine_square(n: u32, origin: DVec3) -> scene::Object {
    let mut b = scene::ObjectBuilder::new("fine");
    for i in 0..=n {
        for j in 0..=n {
            let p = DVec3::new(
                -1.0 + 2.0 * j as f64 / n as f64,
                -1.0 + 2.0 * i as f64 / n as f64,
                0.0,
            );
            b.vertex(origin + p, [220, 30, 30, 255]);
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

/// Slivers of aspect ratio 400,000 and triangles a thousandth of a pixel, as boards seen
/// obliquely: the board covers what the geometry covers (no crack inside, nothing outside),
/// give or take the one-pixel rim that sampling moves.
#[test]
fn ill_conditioned_triangles_as_boards_cover_exactly_their_silhouette() {
    let resolution = [320, 240];
    let objects = [
        sliver_square(400_000, DVec3::new(-1.3, 0.0, 0.0)),
        fine_square(600, DVec3::new(1.3, 0.0, 0.0)),
    ];
    let camera = Camera {
        position: DVec3::new(1.5, 1.2, 5.5),
        target: DVec3::ZERO,
        fov_y_degrees: 50.0,
    };
    let mut viewer = viewer(&objects, &[true, true], resolution);
    let (image, reference, boards) = frames(&mut viewer, &camera, resolution);
    assert_eq!(boards, 2);
    let (shown, expected) = (classify(&image.image()), classify(&reference.image()));
    let [width, height] = resolution.map(|r| r as usize);
    let neighbours_all = |classes: &[Class], x: usize, y: usize, class: Class| {
        (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| classes[yy * width + xx] == class))
    };
    let (mut inside, mut cracks, mut outside) = (0, 0, 0);
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let at = y * width + x;
            if neighbours_all(&expected, x, y, Class::Object) {
                inside += 1;
                cracks += (shown[at] != Class::Object) as usize;
            }
            if neighbours_all(&expected, x, y, Class::Sky) && shown[at] != Class::Sky {
                outside += 1;
            }
        }
    }
    eprintln!(
        "{inside} pixels inside: {cracks} cracks, {outside} board pixels outside the silhouette"
    );
    assert!(inside > 5000, "{inside}");
    assert_eq!((cracks, outside), (0, 0));
}

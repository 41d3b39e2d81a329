//! The frame loop on the real renderer (lavapipe in CI) with real in-process workers.

use std::path::PathBuf;

use glam::DVec3;
use visnode::board::BoardShape;
use visnode::camera::Camera;
use visnode::plan::PlanParams;
use visnode::render::{Image, Renderer};
use visnode::workers::Workers;
use visnode::{Viewer, ViewerOptions};

const RESOLUTION: [u32; 2] = [320, 240];

fn shared_data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(name)
}

fn bunny_at(offset: DVec3) -> scene::Object {
    let scene = scene::load_file(&shared_data("bunny.ply"), &scene::LoadOptions::default()).unwrap();
    let mut object = scene::merge_objects("bunny", &scene.objects);
    object.origin += offset;
    object
}

/// A viewer over `objects` (all suitable) with `workers` in-process workers.
fn viewer(objects: &[scene::Object], workers: usize, options: ViewerOptions, shape: BoardShape) -> Viewer {
    let renderer = Renderer::new(RESOLUTION).expect("a wgpu adapter (lavapipe in CI)");
    let suitable = vec![true; objects.len()];
    let requests = visnode::setup::requests_on(
        Workers::start_local(workers, 1).unwrap(),
        objects,
        &suitable,
        2,
        shape,
        false,
        &indicatif::ProgressBar::hidden(),
    );
    Viewer::new(renderer, objects, &suitable, requests, options, &indicatif::ProgressBar::hidden()).unwrap()
}

fn far_options(sync: bool) -> ViewerOptions {
    ViewerOptions {
        plan: PlanParams {
            t_nz: 0,
            min_map_size: 16,
            ..PlanParams::default()
        },
        sync,
        ..ViewerOptions::default()
    }
}

/// Error over the pixels where either image is not sky, so an object small on screen is not
/// drowned in matching background.
fn object_psnr(reference: &Image, image: &Image) -> (f64, usize) {
    let sky = |p: &[u8]| {
        let clear = visnode::render::CLEAR_COLOR.map(|c| (c * 255.0).round() as i32);
        (0..3).all(|k| (p[k] as i32 - clear[k]).abs() <= 1)
    };
    let mut squared = 0.0;
    let mut count = 0;
    for (a, b) in reference.rgba.chunks_exact(4).zip(image.rgba.chunks_exact(4)) {
        if sky(a) && sky(b) {
            continue;
        }
        count += 1;
        for k in 0..3 {
            squared += (a[k] as f64 - b[k] as f64).powi(2);
        }
    }
    let rmse = (squared / (count.max(1) * 3) as f64).sqrt();
    (20.0 * (255.0 / rmse.max(1e-9)).log10(), count)
}

#[test]
fn debug_images() {
    let objects = [bunny_at(DVec3::ZERO)];
    let mut viewer = viewer(&objects, 1, far_options(true), BoardShape::Relief { grid_cells: std::env::var("GRID").map_or(32, |g| g.parse().unwrap()) });
    let center = viewer.object_centers()[0];
    let radius = objects[0].bounds().diagonal() * 0.5;
    let camera = Camera {
        position: center + DVec3::new(0.3, 0.4, 2.5).normalize() * radius * std::env::var("DIST").map_or(2.5, |g| g.parse().unwrap()),
        target: center,
        fov_y_degrees: std::env::var("FOV").map_or(40.0, |g| g.parse().unwrap()),
    };
    let report = viewer.frame(&camera, RESOLUTION).unwrap();
    assert_eq!(report.boards, 1, "{report:?}");
    let image = viewer.renderer.read_frame().unwrap();
    viewer.reference_frame(&camera, RESOLUTION).unwrap();
    let reference = viewer.renderer.read_frame().unwrap();
    let (psnr, pixels) = object_psnr(&reference, &image);
    visnode::image_error::write_png(&visnode::image_error::side_by_side(&reference, &image), std::path::Path::new("/tmp/dbg.png")).unwrap();
    eprintln!("psnr {psnr} over {pixels}");
}

//! The software rasteriser against wgpu rendering the same view (on Mesa's CPU Vulkan driver
//! where there is no GPU): the same silhouette and the same depth. Without an adapter it
//! fails, unless RELIEFBOARD_SKIP_GPU_TESTS=1 asks it to skip.

use backend::{GpuReference, PreparedObject, render_maps};
use glam::DVec3;

fn test_mesh(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../testdata")
        .join(name)
}

#[test]
fn software_maps_match_wgpu_stencil_and_depth() {
    let gpu = match GpuReference::new() {
        Ok(gpu) => gpu,
        Err(error) => {
            backend::no_adapter_in_test("software_maps_match_wgpu_stencil_and_depth", &error);
            return;
        }
    };
    eprintln!("wgpu adapter: {}", gpu.adapter);
    let directions = [
        DVec3::NEG_Z,
        DVec3::new(1.0, -0.4, 0.3),
        DVec3::Y,
        DVec3::new(-0.2, 0.1, 1.0),
    ];
    for name in ["bunny.ply", "teapot.ply", "airplane.ply"] {
        let loaded = scene::load_file(&test_mesh(name), &scene::LoadOptions::default()).unwrap();
        let object = PreparedObject::new(&loaded.objects[0]).unwrap();
        let uploaded = gpu.upload(&object);
        for direction in directions {
            let size = 192;
            let soft = render_maps(&object, direction, size, 2).unwrap();
            let hard = gpu.render(&uploaded, direction, size).unwrap();
            let (mut both, mut either) = (0usize, 0usize);
            let (mut squared, mut low, mut high) = (0.0f64, f32::INFINITY, f32::NEG_INFINITY);
            for at in 0..soft.stencil.len() {
                let (s, h) = (soft.stencil[at], hard.stencil[at]);
                either += (s || h) as usize;
                if s && h {
                    both += 1;
                    squared += ((soft.depth[at] - hard.depth[at]) as f64).powi(2);
                }
                if s {
                    low = low.min(soft.depth[at]);
                    high = high.max(soft.depth[at]);
                }
            }
            let iou = both as f64 / either.max(1) as f64;
            let rmse =
                (squared / both.max(1) as f64).sqrt() / (high - low).max(f32::EPSILON) as f64;
            eprintln!(
                "{name} along {direction}: stencil IoU {iou:.5}, depth RMSE {:.4} % of the range",
                rmse * 100.0
            );
            assert!(
                iou >= 0.99,
                "{name} along {direction}: stencil IoU {iou:.4}"
            );
            assert!(
                rmse < 0.01,
                "{name} along {direction}: depth RMSE {:.3} % of the range",
                rmse * 100.0
            );
        }
    }
}

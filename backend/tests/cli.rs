//! The `backend` binary as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn test_mesh(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../testdata")
        .join(name)
        .display()
        .to_string()
}

/// Runs `backend` with `args` and checks it succeeded.
fn backend_ok(args: &[&str]) -> std::process::Output {
    let output = Command::new(env!("CARGO_BIN_EXE_backend"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

#[test]
fn render_writes_the_four_maps_the_board_and_its_figures() {
    let out = std::env::temp_dir().join(format!("backend-render-{}", std::process::id()));
    backend_ok(&[
        "render",
        "--scene",
        &test_mesh("bunny.ply"),
        "--dir",
        "0.3,-0.2,-1",
        "--size",
        "96",
        "--out",
        out.to_str().unwrap(),
    ]);
    for file in [
        "distance.png",
        "stencil.png",
        "color.png",
        "normal.png",
        "reliefboard.ply",
        "board.json",
    ] {
        assert!(out.join(file).exists(), "{file}");
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("board.json")).unwrap()).unwrap();
    assert_eq!(report["triangles_in"], 3674);
    let covered = report["covered_pixels"].as_u64().unwrap();
    assert!(covered > 1000 && covered < 96 * 96, "{covered}");
    // The grid at one cell per pixel: two triangles per covered pixel, a vertex per corner
    // of a covered pixel (shared between neighbours).
    assert_eq!(report["board_triangles"].as_u64().unwrap(), 2 * covered);
    let corners = report["board_vertices"].as_u64().unwrap();
    assert!(
        corners > covered && corners < 4 * covered,
        "{corners} for {covered}"
    );
    assert!(report["encoded_bytes"].as_u64().unwrap() < report["raw_bytes"].as_u64().unwrap());
    // The exported board loads back as the same mesh.
    let board =
        scene::load_file(&out.join("reliefboard.ply"), &scene::LoadOptions::default()).unwrap();
    assert_eq!(board.objects[0].positions.len() as u64, corners);
    assert_eq!(
        board.triangle_count(),
        report["board_triangles"].as_u64().unwrap()
    );
}

#[test]
fn bad_requests_are_clear_errors() {
    let out = std::env::temp_dir().join(format!("backend-bad-{}", std::process::id()));
    for (args, expected) in [
        (vec!["--dir", "0,0,0"], "must be finite and non-zero"),
        (vec!["--size", "0"], "resolution 0 must lie in"),
        (vec!["--object", "5"], "object 5 does not exist"),
        (vec!["--dir", "1,2"], "three numbers"),
    ] {
        let output = Command::new(env!("CARGO_BIN_EXE_backend"))
            .args([
                "render",
                "--scene",
                &test_mesh("teapot.ply"),
                "--out",
                out.to_str().unwrap(),
            ])
            .args(&args)
            .output()
            .unwrap();
        assert!(!output.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"));
    }
}

#[test]
fn bench_reports_software_and_wgpu_throughput() {
    let output = backend_ok(&[
        "bench",
        "--scene",
        &test_mesh("teapot.ply"),
        "--size",
        "64",
        "--boards",
        "3",
        "--threads",
        "2",
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(report["triangles"], 992);
    for key in ["one_thread", "all_threads"] {
        assert!(
            report[key]["milliseconds_per_board"].as_f64().unwrap() > 0.0,
            "{key}"
        );
    }
    assert_eq!(report["all_threads"]["threads"], 2);
    // Each size's request from the level, by stage: each measured, together within the whole.
    let requests = report["requests"].as_array().unwrap();
    assert!(!requests.is_empty());
    for request in requests {
        // Only asked for with --every-level.
        assert_eq!(request["every_level"], serde_json::json!([]));
        let stages = &request["level_stages"];
        let names = [
            "projection",
            "triangle_pass",
            "grow_at_cuts",
            "per_pixel_pass",
            "encoding",
        ];
        let parts = names.map(|name| stages[name].as_f64().unwrap());
        assert!(parts.iter().all(|&part| part >= 0.0), "{stages}");
        assert!(parts[1] > 0.0, "the triangle pass took no time: {stages}");
        let whole = request["level_milliseconds"].as_f64().unwrap();
        assert!(
            parts.iter().sum::<f64>() <= whole * (1.0 + 1e-9),
            "{stages} add up to more than the whole request, {whole} ms"
        );
    }
    // wgpu is measured where an adapter exists (lavapipe in CI); a failed measurement fails
    // the test unless the GPU tests are explicitly skipped.
    match (&report["wgpu"]["Ok"], &report["wgpu"]["Err"]) {
        (serde_json::Value::Object(gpu), _) => {
            assert!(gpu["milliseconds_per_board_one_thread"].as_f64().unwrap() > 0.0);
            assert!(gpu["speedup_all_threads"].as_f64().unwrap() > 0.0);
        }
        (_, serde_json::Value::String(why)) => {
            backend::no_adapter_in_test("bench_reports_software_and_wgpu_throughput", why)
        }
        other => panic!("unexpected wgpu field: {other:?}"),
    }
}

#[test]
fn bench_times_every_level_and_marks_the_one_the_worker_takes() {
    // A forest tree: foliage, thinned into several levels.
    let output = backend_ok(&[
        "bench",
        "--scene",
        "forest",
        "--triangles",
        "200000",
        "--object",
        "1",
        "--sizes",
        "32,64",
        "--boards",
        "3",
        "--every-level",
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let requests = report["requests"].as_array().unwrap();
    assert_eq!(requests.len(), 2, "one request per side asked for");
    for request in requests {
        let size = request["size"].as_u64().unwrap();
        let levels = request["every_level"].as_array().unwrap();
        assert!(levels.len() >= 3, "{request}");
        let triangles: Vec<u64> = levels
            .iter()
            .map(|l| l["triangles"].as_u64().unwrap())
            .collect();
        assert!(
            triangles.windows(2).all(|w| w[0] > w[1]),
            "finest first: {triangles:?}"
        );
        let chosen: Vec<usize> = (0..levels.len())
            .filter(|&i| levels[i]["chosen"] == true)
            .collect();
        let [chosen] = chosen[..] else {
            panic!("one level is the worker's at {size} px: {chosen:?}")
        };
        let level = &levels[chosen];
        // The worker's request again, from the same level over the same views.
        assert_eq!(level["triangles"], request["level_triangles"]);
        assert_eq!(level["stencil_iou_mean"], request["stencil_iou_mean"]);
        assert_eq!(level["stencil_iou_min"], request["stencil_iou_min"]);
        // The coarsest level allowed at this side.
        assert_eq!(level["allowed"], true, "{level} at {size} px");
        for coarser in &levels[chosen + 1..] {
            assert_eq!(coarser["allowed"], false, "{coarser} at {size} px");
        }
        for level in levels {
            assert!(level["milliseconds"].as_f64().unwrap() > 0.0, "{level}");
            let iou = level["stencil_iou_mean"].as_f64().unwrap();
            assert!((0.5..1.0).contains(&iou), "{level}");
        }
    }
}

#[test]
fn a_scene_cut_as_the_node_cuts_it_gives_its_pieces_by_index() {
    // The plant under a small near zone is cut into many pieces; `--object` picks one.
    let out = std::env::temp_dir().join(format!("backend-pieces-{}", std::process::id()));
    let scene = [
        "--scene",
        "plant",
        "--triangles",
        "200000",
        "--t-nz",
        "20000",
    ];
    let piece = |object: &str| {
        Command::new(env!("CARGO_BIN_EXE_backend"))
            .args(["render", "--size", "32", "--object", object])
            .args(scene)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
    };
    let first = piece("0");
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let too_far = piece("1000000");
    assert!(!too_far.status.success());
    let message = String::from_utf8_lossy(&too_far.stderr);
    let pieces: usize = message
        .split("the scene has ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("names the piece count: {message}"));
    assert!(pieces > 10, "{message}");
    // The whole scene as one object makes no sense once it is cut.
    let whole = piece("all");
    assert!(!whole.status.success());
    assert!(String::from_utf8_lossy(&whole.stderr).contains("pick one with --object"));
    std::fs::remove_dir_all(&out).ok();
}

//! The `visnode` binary as a user runs it.

mod common;
use std::path::PathBuf;
use std::process::Command;

fn visnode(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_visnode"))
        .args(args)
        .output()
        .expect("visnode runs")
}

/// Runs `visnode` with `args` (ending in `--json`), which must succeed, and parses what it
/// printed.
fn visnode_json<T: serde::de::DeserializeOwned>(args: &[&str]) -> T {
    let result = visnode(args);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    serde_json::from_slice(&result.stdout).unwrap()
}

/// A bench run's summary that started no worker and asked for no board, for a reason
/// containing `reason`.
fn assert_started_no_worker(summary: &serde_json::Value, reason: &str) {
    assert_eq!(summary["workers"], 0, "{summary}");
    assert_eq!(summary["requests"]["issued"], 0, "{summary}");
    assert!(
        summary["no_boards_reason"]
            .as_str()
            .unwrap()
            .contains(reason),
        "{summary}"
    );
}

fn test_mesh(name: &str) -> String {
    common::test_mesh(name).display().to_string()
}

#[test]
fn inspect_json_reports_the_summary_of_a_mesh_file() {
    let out = visnode(&[
        "inspect",
        "--scene",
        &test_mesh("bunny.ply"),
        "--t-nz",
        "500",
        "--min-triangles",
        "100",
        "--no-cache",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["input_triangles"], 3674);
    assert_eq!(report["input_objects"], 1);
    let phases: Vec<&str> = report["phases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    // Pieces of side sl_c would hold fewer than 100 triangles: the bunny is cut with
    // larger maps instead, which its own phase reports.
    assert_eq!(
        phases,
        [
            "phase I: components",
            "phase II: near zone",
            "phase III: clustering",
            "dense objects"
        ]
    );
    assert_eq!(report["dense"][0]["objects"], 1);
    assert!(report["dense"][0]["map_size"].as_u64().unwrap() > 256);
    assert!(report["sl_c"].as_f64().unwrap() > 0.0);
    assert!(report["peak_memory_bytes"].as_u64().unwrap() > 0);
    assert!(report["t_nz_default_for"].is_null(), "--t-nz was given");
    assert_eq!(report["t_nz"], 500);
}

/// Without `--t-nz` the near zone gets the budget of the adapter frames are drawn on: 100 k on
/// a CPU adapter such as CI's lavapipe (where small near zones measured faster and better,
/// README), 1 M on a GPU. `inspect` says which adapter chose it, and `bench` draws with the
/// same budget.
#[test]
fn t_nz_defaults_to_the_budget_of_the_adapter() {
    let bunny = test_mesh("bunny.ply");
    let report: serde_json::Value =
        visnode_json(&["inspect", "--scene", &bunny, "--no-cache", "--json"]);
    let adapter = report["t_nz_default_for"].as_str().unwrap().to_owned();
    let expected = if adapter.ends_with(", Cpu)") {
        100_000
    } else {
        1_000_000
    };
    assert_eq!(report["t_nz"], expected, "{adapter}");

    let text = visnode(&["inspect", "--scene", &bunny, "--no-cache"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains(&format!("t_nz = {expected} triangles"))
            && text.contains(&format!("the default for the adapter: {adapter}")),
        "{text}"
    );

    let out = temp_dir("bench-default-t-nz");
    let summary: serde_json::Value = visnode_json(&[
        "bench",
        "--scene",
        &bunny,
        "--resolution",
        "64x48",
        "--timing",
        "frames",
        "--frames",
        "1",
        "--sample-frames",
        "0",
        "--no-cache",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(summary["plan"]["t_nz"], expected, "{summary}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn inspect_png_draws_the_three_classes() {
    let dir = std::env::temp_dir().join(format!("visnode-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("plant.png");
    let out = visnode(&[
        "inspect",
        "--scene",
        "plant",
        "--triangles",
        "200000",
        "--t-nz",
        "60000",
        "--min-triangles",
        "300",
        "--no-cache",
        "--png",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("too large") && text.contains("phase III"),
        "{text}"
    );
    let picture = tiny_skia::Pixmap::load_png(&png).unwrap();
    let has = |rgb: [u8; 3]| {
        picture
            .pixels()
            .iter()
            .any(|p| [p.red(), p.green(), p.blue()] == rgb)
    };
    assert!(has([40, 170, 60]), "suitable (green) objects drawn");
    assert!(has([210, 50, 40]), "too-large (red) objects drawn");
    assert!(has([40, 90, 220]), "too-simple (blue) objects drawn");
}

#[test]
fn bad_input_is_a_clear_error_and_a_failing_exit_code() {
    let dir = std::env::temp_dir().join(format!("visnode-cli-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let broken = dir.join("broken.ply");
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    std::fs::write(&broken, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n0 1 0\n").unwrap();
    for (args, expected) in [
        (
            vec!["inspect", "--scene", broken.to_str().unwrap()],
            "vertex 1: coordinate NaN is not finite",
        ),
        (
            vec!["inspect", "--scene", "no-such-scene"],
            "neither an existing file nor a built-in scene",
        ),
        (vec!["inspect", "--resolution", "0x768"], "1..=65536"),
        (
            vec!["inspect", "--triangles", "100000", "--map-size", "0"],
            "invalid value '0' for '--map-size <MAP_SIZE>': must be a number from 8 to 4096",
        ),
        // NaN, infinite and absurd values are refused by name before anything loads.
        (
            vec!["bench", "--epsilon", "NaN"],
            "invalid value 'NaN' for '--epsilon <EPSILON>': must be a number from 0.01 to 90",
        ),
        (
            vec!["bench", "--max-angle=-5"],
            "for '--max-angle <MAX_ANGLE>': must be a number from 0.01 to 90",
        ),
        (
            vec!["inspect", "--fov", "inf"],
            "for '--fov <FOV_Y_DEGREES>'",
        ),
        (vec!["inspect", "--t-nz", "0"], "for '--t-nz <T_NZ>'"),
        (
            vec!["bench", "--local-workers", "0"],
            "for '--local-workers <LOCAL_WORKERS>'",
        ),
        (
            vec!["bench", "--target-frame-ms", "NaN"],
            "for '--target-frame-ms",
        ),
        (vec!["view", "--replay-frames", "0"], "for '--replay-frames"),
        (
            vec!["bench", "--frames", "99999999999"],
            "for '--frames <FRAMES>'",
        ),
        (
            vec!["bench", "--sweep", "epsilon=5,NaN", "--out", out],
            "--sweep epsilon: invalid value",
        ),
        (
            vec!["cluster", "--workers", "100000"],
            "for '--workers <COUNT>'",
        ),
        (
            vec!["cluster", "--slowdown", "1,inf"],
            "for '--slowdown <SLOWDOWN>'",
        ),
        (
            vec![
                "bench",
                "--epsilon",
                "50",
                "--max-angle",
                "40",
                "--out",
                out,
            ],
            "need --epsilon < --max-angle",
        ),
    ] {
        let out = visnode(&args);
        assert!(!out.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("visnode-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A small forest, drawn with boards from two in-process workers, waiting for each frame's
/// boards (`--sync`) so the run is reproducible.
#[test]
fn bench_writes_frames_summary_samples_and_trace() {
    let out = temp_dir("bench");
    let trace = out.join("trace.jsonl");
    let summary: serde_json::Value = visnode_json(&[
        "bench",
        "--scene",
        "forest",
        "--triangles",
        "600000",
        "--t-nz",
        "250000",
        "--resolution",
        "320x240",
        "--timing",
        "frames",
        "--frames",
        "6",
        "--local-workers",
        "2",
        "--sync",
        "--no-cache",
        "--sample-frames",
        "2",
        "--record-trace",
        trace.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(summary["frames"], 6);
    assert_eq!(summary["workers"], 2);
    assert!(summary["no_boards_reason"].is_null(), "{summary}");
    assert!(
        summary["boards_per_frame"]["mean"].as_f64().unwrap() >= 1.0,
        "{summary}"
    );
    // Synchronous: every frame draws fresh boards, so no board is older than one step of
    // the orbit (60 degrees over 6 frames) and every request was answered.
    assert_eq!(
        summary["requests"]["issued"],
        summary["requests"]["received"]
    );
    // Every request is accounted for: the summary says how many were still pending.
    assert_eq!(summary["requests_pending"], 0, "{summary}");
    assert_eq!(summary["requests"]["failed"], 0, "{summary}");
    assert!(
        summary["error"]["object_psnr_db"].as_f64().unwrap() > 20.0,
        "{summary}"
    );
    // Object pixels are a part of the frame, and the headline is taken over them.
    let share = summary["error"]["object_share"].as_f64().unwrap();
    assert!(share > 0.0 && share < 1.0, "{summary}");
    assert_eq!(summary["samples"], 6, "frames timing samples every frame");
    // The workers run in this process, so they were paused while shots were read back.
    assert!(
        summary["worker_seconds_off_clock"].as_f64().is_some(),
        "{summary}"
    );
    let samples = std::fs::read_to_string(out.join("samples.csv")).unwrap();
    assert_eq!(samples.lines().count(), 7, "header and six samples");
    let frames = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(frames.lines().count(), 7, "header and six frames");
    let pngs = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("frame-")
        })
        .count();
    assert_eq!(pngs, 2);
    let trace = std::fs::read_to_string(&trace).unwrap();
    let records = balancer::Trace::from_json_lines(&trace).unwrap().records;
    assert_eq!(
        records.len() as u64,
        summary["requests"]["issued"].as_u64().unwrap()
    );
}

#[test]
fn bench_of_a_scene_that_fits_the_near_zone_needs_no_worker() {
    let out = temp_dir("bench-near");
    let summary: serde_json::Value = visnode_json(&[
        "bench",
        "--scene",
        &test_mesh("bunny.ply"),
        "--resolution",
        "160x120",
        "--timing",
        "frames",
        "--frames",
        "2",
        "--sample-frames",
        "0",
        "--no-cache",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_started_no_worker(&summary, "near zone");
    // Geometry only: the frame is the reference.
    assert_eq!(summary["error"]["frame_psnr_db"], 99.0);
    assert_eq!(summary["error"]["object_psnr_db"], 99.0);
}

/// At a near-zone budget so small that no part of the plant is suitable for a board (each is
/// longer than sl_c), relief has nothing to ask workers for; it must still draw the walls and
/// pipes through their levels, as LOD does, not every triangle whole (on the 12 M plant at
/// `t_nz` 10 k that was 872 ms a frame against LOD's 90).
#[test]
fn bench_with_no_suitable_object_draws_levels_as_lod_does() {
    let out = temp_dir("bench-unsuitable");
    let runs: Vec<serde_json::Value> = visnode_json(&[
        "bench",
        "--scene",
        "plant",
        "--triangles",
        "200000",
        "--t-nz",
        "10000",
        // sl_c shrinks as the frame grows (a board at d_nz fits the map size): at 640x480
        // some parts are suitable.
        "--resolution",
        "1024x768",
        "--timing",
        "frames",
        "--frames",
        "1",
        "--sample-frames",
        "0",
        "--no-cache",
        "--compare",
        "relief,lod,none",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let [relief, lod, none] = &runs[..] else {
        panic!("three runs: {runs:?}")
    };
    assert_eq!(relief["suitable"], 0, "{relief}");
    assert_started_no_worker(relief, "no object is suitable");
    let triangles = |run: &serde_json::Value| run["triangles_per_frame"]["mean"].as_f64().unwrap();
    assert_eq!(triangles(relief), triangles(lod), "{relief}\n{lod}");
    assert!(
        triangles(relief) < 0.5 * triangles(none),
        "relief {} against geometry only {}",
        triangles(relief),
        triangles(none)
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bench_rejects_bad_flags_clearly() {
    let dir = temp_dir("bench-bad");
    let path = dir.join("path.jsonl");
    std::fs::write(
        &path,
        "{\"position\":[0,0,0],\"target\":[1,0,0],\"fov_y_degrees\":60}\n{\"position\":[0,1e400,0],\"target\":[1,0,0],\"fov_y_degrees\":60}\n",
    )
    .unwrap();
    let bunny = test_mesh("bunny.ply");
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    for (args, expected) in [
        (
            vec!["bench", "--scene", &bunny, "--frames", "0", "--out", out],
            "--frames",
        ),
        (
            vec![
                "bench",
                "--scene",
                &bunny,
                "--sweep",
                "colour=1,2",
                "--out",
                out,
            ],
            "cannot sweep",
        ),
        (
            vec!["bench", "--scene", &bunny, "--epsilon", "50", "--out", out],
            "epsilon",
        ),
        (
            vec!["bench", "--scene", &bunny, "--sync", "--out", out],
            "--sync",
        ),
        (
            vec![
                "bench",
                "--scene",
                &bunny,
                "--compare",
                "relief,nanite",
                "--out",
                out,
            ],
            "nanite",
        ),
        (
            vec![
                "bench",
                "--scene",
                &bunny,
                "--request-timeout-ms",
                "0",
                "--out",
                out,
            ],
            "invalid value '0' for '--request-timeout-ms <REQUEST_TIMEOUT_MS>'",
        ),
        (
            vec![
                "bench",
                "--scene",
                &bunny,
                "--path",
                path.to_str().unwrap(),
                "--resolution",
                "64x48",
                "--out",
                out,
            ],
            "path.jsonl:2",
        ),
    ] {
        let result = visnode(&args);
        assert!(!result.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn bench_flies_one_path_for_every_run_of_a_sweep() {
    // A flythrough keeps above the ground (the objects left unsuitable), which changes with
    // t_nz: floor's run at 4 k cuts the plant into 46 objects, geometry only's at 40 k into
    // 32, with another ground. Every run must fly the first run's path, the one its
    // references were drawn on.
    let out = temp_dir("bench-one-path");
    let runs: Vec<serde_json::Value> = visnode_json(&[
        "bench",
        "--scene",
        "plant",
        "--triangles",
        "500000",
        "--t-nz",
        "40000",
        "--resolution",
        "160x120",
        "--local-workers",
        "1",
        "--no-cache",
        "--compare",
        "floor,none",
        "--sweep",
        "t-nz=4000",
        "--path",
        "flythrough",
        "--timing",
        "frames",
        "--frames",
        "3",
        "--sample-frames",
        "0",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_ne!(
        runs[0]["objects"], runs[1]["objects"],
        "the same cut: no test"
    );
    // Stepped frame by frame, geometry only draws its reference's image but for where the
    // cuts differ (63 dB here); on its own path it scored 18 dB.
    let geometry = &runs[1]["error"];
    assert!(
        geometry["frame_psnr_db"].as_f64().unwrap() > 50.0,
        "{geometry}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// Every kind, on one small forest, in both timing modes: one table, the side-by-side
/// frames and the Pareto plots (with the floor, the frame without far objects, as a line).
#[test]
fn bench_compares_every_kind_in_both_timing_modes() {
    for (timing, steps, samples) in [("wall", "60", 10u64), ("frames", "3", 3)] {
        let out = temp_dir(&format!("bench-compare-{timing}"));
        let runs: Vec<serde_json::Value> = visnode_json(&[
            "bench",
            "--scene",
            "forest",
            "--triangles",
            "300000",
            "--t-nz",
            "60000",
            "--resolution",
            "160x120",
            "--local-workers",
            "2",
            "--no-cache",
            "--compare",
            "relief,lod,octahedral,billboard,none,floor",
            "--timing",
            timing,
            "--frames",
            steps,
            "--path-seconds",
            "1",
            "--sample-hz",
            "10",
            "--sample-frames",
            "2",
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]);
        let kinds: Vec<&str> = runs
            .iter()
            .map(|r| r["impostor"].as_str().unwrap())
            .collect();
        assert_eq!(
            kinds,
            ["relief", "lod", "octahedral", "billboard", "none", "floor"]
        );
        for run in &runs {
            assert_eq!(run["samples"], samples, "{timing}: {run}");
            assert!(run["frames"].as_u64().unwrap() >= 1, "{run}");
            assert!(run["triangles_per_frame"]["mean"].as_f64().unwrap() > 0.0);
        }
        let geometry = &runs[4]["error"];
        if timing == "frames" {
            // Step by step, geometry only draws exactly the reference.
            assert_eq!(geometry["object_psnr_db"], 99.0, "{geometry}");
        } else {
            // On the clock, an exact renderer still shows images as old as its frames: a
            // camera orbiting in one second moves between frame start and sample instant.
            assert!(geometry["image_age_ms"]["mean"].as_f64().unwrap() > 0.0);
            assert!(
                geometry["object_psnr_db"].as_f64().unwrap() < 99.0,
                "{geometry}"
            );
        }
        // Levels of detail hold coarser index lists on the GPU, octahedral impostors their
        // atlases (four suitable trees, 16x16 views of 64 texels: 12 MiB each); geometry only
        // holds none.
        assert!(runs[1]["far_field_bytes"].as_u64().unwrap() > 0);
        assert_eq!(
            runs[2]["far_field_bytes"],
            4 * 1024 * 1024 * 12,
            "{}",
            runs[2]
        );
        assert_eq!(runs[4]["far_field_bytes"], 0);
        // The floor draws the near zone and the ground, not the trees beyond: fewer
        // triangles than geometry only, with nothing held and nothing asked of a worker.
        let triangles =
            |run: &serde_json::Value| run["triangles_per_frame"]["mean"].as_f64().unwrap();
        assert!(triangles(&runs[5]) < triangles(&runs[4]), "{}", runs[5]);
        assert_eq!(runs[5]["far_field_bytes"], 0);
        assert_eq!(runs[5]["requests"]["issued"], 0, "{}", runs[5]);
        let table = std::fs::read_to_string(out.join("compare.csv")).unwrap();
        assert_eq!(table.lines().count(), 7, "{table}");
        for file in ["pareto-object-psnr.png", "pareto-flip.png"] {
            assert!(out.join(file).is_file(), "{file}");
        }
        let frames = std::fs::read_dir(&out)
            .unwrap()
            .filter(|e| {
                let name = e.as_ref().unwrap().file_name();
                name.to_string_lossy().starts_with("compare-")
                    && name.to_string_lossy().ends_with(".png")
            })
            .count();
        assert_eq!(frames, 2);
        let _ = std::fs::remove_dir_all(&out);
    }
}

//! The `visnode` binary as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn visnode(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_visnode"))
        .args(args)
        .output()
        .expect("visnode runs")
}

fn shared_data(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(name)
        .display()
        .to_string()
}

#[test]
fn inspect_json_reports_the_summary_of_a_mesh_file() {
    let out = visnode(&[
        "inspect",
        "--scene",
        &shared_data("bunny.ply"),
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
    assert_eq!(
        phases,
        [
            "phase I: components",
            "phase II: near zone",
            "phase III: clustering"
        ]
    );
    assert!(report["sl_c"].as_f64().unwrap() > 0.0);
    assert!(report["peak_memory_bytes"].as_u64().unwrap() > 0);
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
    std::fs::write(&broken, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n0 1 0\n").unwrap();
    for (args, expected) in [
        (
            vec!["inspect", "--scene", broken.to_str().unwrap()],
            "vertex 1: coordinate NaN is not finite",
        ),
        (
            vec!["inspect", "--scene", "no-such-scene"],
            "neither a file nor a built-in scene",
        ),
        (vec!["inspect", "--resolution", "0x768"], "1..=65536"),
        (vec!["inspect", "--map-size", "0"], "map size"),
    ] {
        let out = visnode(&args);
        assert!(!out.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

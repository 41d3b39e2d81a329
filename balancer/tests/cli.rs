//! The `balancer` binary as a user runs it.

use std::process::Command;

#[test]
fn simulate_writes_csv_json_and_png_reports() {
    let out = std::env::temp_dir().join(format!("balancer-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let status = Command::new(env!("CARGO_BIN_EXE_balancer"))
        .args([
            "simulate",
            "--synthetic",
            "walk",
            "--positions",
            "400",
            "--objects",
            "300",
            "--nodes",
            "8,16",
            "--replicas",
            "2",
        ])
        .args([
            "--seeds",
            "2",
            "--speeds",
            "1,1,1,0.25",
            "--json",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    let rows = summary.as_array().unwrap();
    assert_eq!(
        rows.len(),
        2 * 6,
        "2 node counts x (2 strategies + 4 baselines)"
    );
    assert!(
        rows.iter()
            .all(|r| r["busiest_over_bound_all"].as_f64().unwrap() >= 1.0 - 1e-9),
        "never below the lower bound"
    );
    for file in [
        "summary.json",
        "summary.csv",
        "load-n8-k2.png",
        "busiest-n16-k2.png",
        "summary-k2.png",
        "positions-n8-k2-round-robin.csv",
    ] {
        assert!(out.join(file).exists(), "{file} written");
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_balancer"))
        .args([
            "simulate",
            "--synthetic",
            "walk",
            "--nodes",
            "2",
            "--replicas",
            "3",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("cannot place 3 replicas on 2 workers"));
}

#!/usr/bin/env bash
# Süß chapter 4 scaling on real processes (Figs. 4.14 and 4.18): board latency and angle error
# against the number of workers. On a 2-core machine N busy workers only share the cores, so
# every worker is a weak node whose slowdown sleeps (`backend serve --slowdown F`): it renders
# at full speed, then sleeps (F - 1) times its render time, so 32 workers still share the two
# cores. F = 512 makes the workers the bottleneck on this scene (with F = 32, two workers
# already served every request the node makes).
#   scripts/chapter4-scaling.sh [OUT [PATH_SECONDS [F]]]   (default: scaling-out 20 512)
# Writes OUT/scaling.csv and prints it; each run's summary.json is in OUT/N.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-scaling-out}"
seconds="${2:-20}"
factor="${3:-512}"
cargo build --release -p visnode -p backend
mkdir -p "$out"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
# A 2 M-triangle forest with a 200 k near zone: about 200 suitable objects to board.
scene=(--scene forest --triangles 2000000 --t-nz 200000)
for n in 1 2 4 8 16 32; do
  slowdown=$(printf "%s," $(for _ in $(seq 1 "$n"); do echo "$factor"; done))
  target/release/visnode cluster --workers "$n" --slowdown "${slowdown%,}" \
    bench "${scene[@]}" --path-seconds "$seconds" --sample-hz 2 --sample-frames 0 --no-flip \
    --out "$out/$n" >"$out/$n.log" 2>&1
  echo "$n workers: $(grep -o 'latency p50.*deg' "$out/$n.log")"
done
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
rows = ["workers,boards_received,latency_p50_ms,latency_p90_ms,angle_error_mean_deg,angle_error_p90_deg,object_psnr_db,frame_ms_mean"]
for n in [1, 2, 4, 8, 16, 32]:
    s = json.load(open(f"{out}/{n}/summary.json"))
    rows.append(",".join(str(v) for v in [
        n, s["requests"]["received"], round(s["latency_ms"]["p50"]), round(s["latency_ms"]["p90"]),
        round(s["angle_error_degrees"]["mean"], 2), round(s["angle_error_degrees"]["p90"], 2),
        round(s["error"]["object_psnr_db"], 2), round(s["frame_ms"]["mean"], 1)]))
open(f"{out}/scaling.csv", "w").write("\n".join(rows) + "\n")
print("\n".join(rows))
PY

#!/usr/bin/env bash
# Süß chapter 4 scaling on real processes (Figs. 4.14 and 4.18): board latency, angle error
# and the time to make every board fresh after a fast turn, against the number of workers.
# On a 2-core machine N busy workers only share the cores, so every worker is a weak node
# whose slowdown sleeps (`backend serve --slowdown F`): it renders at full speed, then sleeps
# (F - 1) times its render time before its next board, so its throughput and latency are both
# F times worse while 32 of them still fit on two cores.
#   scripts/chapter4-scaling.sh [OUT [PATH_SECONDS [F [WORKER_COUNTS]]]]
#   (default: scaling-out 20 64 "1 2 4 8 16 32")
# Per worker count: an orbit of PATH_SECONDS (latency, angle error) and a `turn` path of
# 1.5 x PATH_SECONDS (still, a quarter turn, still: seconds until every board is fresh).
# Writes OUT/scaling.csv and the plots OUT/scaling-{latency,angle,refresh}.png; each run's
# summary.json is in OUT/N and OUT/N-turn.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-scaling-out}"
seconds="${2:-20}"
factor="${3:-64}"
counts="${4:-1 2 4 8 16 32}"
cargo build --release -p visnode -p backend -p balancer
mkdir -p "$out"
export GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=536870912
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
# A 2 M-triangle forest with a 200 k near zone: about 200 suitable objects to board.
scene=(--scene forest --triangles 2000000 --t-nz 200000)
turn_seconds=$(python3 -c "print($seconds * 1.5)")
for n in $counts; do
  slowdown=$(printf "%s," $(for _ in $(seq 1 "$n"); do echo "$factor"; done))
  for path in orbit turn; do
    name="$n"; length="$seconds"
    if [ "$path" = turn ]; then name="$n-turn"; length="$turn_seconds"; fi
    target/release/visnode cluster --workers "$n" --slowdown "${slowdown%,}" \
      bench "${scene[@]}" --path "$path" --path-seconds "$length" --sample-hz 2 \
      --sample-frames 0 --no-flip --out "$out/$name" >"$out/$name.log" 2>&1
  done
  echo "$n workers: $(grep -o 'latency p50.*deg' "$out/$n.log"); $(grep -o 'every board fresh.*' "$out/$n-turn.log" || echo 'not every board fresh again before the turn run ended')"
done
python3 - "$out" $counts <<'PY'
import json, sys
out, counts = sys.argv[1], [int(n) for n in sys.argv[2:]]
rows = ["workers,boards_received,latency_p50_ms,latency_p90_ms,latency_mean_ms,angle_error_mean_deg,"
        "angle_p10_deg,angle_p25_deg,angle_p50_deg,angle_p75_deg,angle_p90_deg,object_psnr_db,"
        "frame_ms_mean,refresh_after_turn_s,turn_latency_mean_ms"]
for n in counts:
    s = json.load(open(f"{out}/{n}/summary.json"))
    t = json.load(open(f"{out}/{n}-turn/summary.json"))
    refresh = t.get("refresh_after_turn_s")
    rows.append(",".join(str(v) for v in [
        n, s["requests"]["received"], round(s["latency_ms"]["p50"]), round(s["latency_ms"]["p90"]),
        round(s["latency_ms"]["mean"]), round(s["angle_error_degrees"]["mean"], 2),
        *[round(a, 2) for a in s["angle_error_box_degrees"]],
        round(s["error"]["object_psnr_db"], 2), round(s["frame_ms"]["mean"], 1),
        "" if refresh is None else round(refresh, 2), round(t["latency_ms"]["mean"])]))
open(f"{out}/scaling.csv", "w").write("\n".join(rows) + "\n")
print("\n".join(rows))
PY
target/release/balancer scaling --csv "$out/scaling.csv" --out "$out"
echo "plots in $out"

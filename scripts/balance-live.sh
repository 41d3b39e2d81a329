#!/usr/bin/env bash
# Live balancing on the built-in forest (10 M triangles), `visnode bench`'s defaults but the
# path's length, as issue 15 asks:
#   identical   RUNS runs with 4 identical in-process workers: boards per worker, and each
#               worker's deviation from the mean
#   slow        4 worker processes (`visnode cluster`), the fourth at --slowdown 4: its
#               share against a fast one's (a 4x weaker machine should get about 0.25),
#               once for each way the balancer may use speeds (RULES, `--balancer-speeds`)
# Each run's summary.json holds boards_per_worker; the table goes to OUT/balance.csv.
#   [RULES="offers-and-picks picks ignored"] scripts/balance-live.sh [OUT [RUNS [PATH_SECONDS]]]
#   (default: balance-out 5 12)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-balance-out}"
runs="${2:-5}"
seconds="${3:-12}"
rules="${RULES:-offers-and-picks picks ignored}"
cargo build --release -p visnode -p backend
mkdir -p "$out"
export GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=536870912
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
# Few samples: the references are not what is measured here. t_nz 1 M: the default when
# docs/balancer.md was measured (a CPU adapter's is 100 k now).
common=(--path-seconds "$seconds" --sample-hz 1 --sample-frames 0 --t-nz 1000000)
for run in $(seq 1 "$runs"); do
  target/release/visnode bench "${common[@]}" --out "$out/identical-$run" >"$out/identical-$run.log" 2>&1
  echo "identical $run: $(grep -o 'boards per worker.*' "$out/identical-$run.log")"
done
for rule in $rules; do
  target/release/visnode cluster --workers 4 --slowdown 1,1,1,4 \
    bench "${common[@]}" --balancer-speeds "$rule" --out "$out/slow-$rule" >"$out/slow-$rule.log" 2>&1
  echo "slow, $rule: $(grep -o 'boards per worker.*' "$out/slow-$rule.log")"
done
python3 - "$out" "$runs" $rules <<'PY'
import json, sys
out, runs, rules = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
rows = ["run,boards,per_worker,max_deviation_from_mean,slow_over_fast,latency_p50_ms,latency_p90_ms,angle_error_mean_deg,object_psnr_db"]
for name in [f"identical-{r}" for r in range(1, runs + 1)] + [f"slow-{r}" for r in rules]:
    s = json.load(open(f"{out}/{name}/summary.json"))
    per = s["boards_per_worker"]
    total, mean = sum(per), sum(per) / len(per)
    deviation = max(abs(n - mean) for n in per) / mean
    slow = f"{per[3] / (sum(per[:3]) / 3):.3f}" if name.startswith("slow") else ""
    rows.append(",".join([name, str(total), " ".join(map(str, per)), f"{deviation:.3f}", slow,
        f"{s['latency_ms']['p50']:.0f}", f"{s['latency_ms']['p90']:.0f}",
        f"{s['angle_error_degrees']['mean']:.2f}", f"{s['error']['object_psnr_db']:.2f}"]))
open(f"{out}/balance.csv", "w").write("\n".join(rows) + "\n")
print("\n".join(rows))
PY

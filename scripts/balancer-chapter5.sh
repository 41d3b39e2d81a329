#!/usr/bin/env bash
# Süß chapter 5 on traces recorded from real runs: `visnode bench --record-trace` on the
# forest (10 M) and the plant (12 M), orbit, 20 s of wall clock with 4 in-process workers;
# then `balancer simulate` replays each at 32, 80 and 120 nodes x 1, 2, 3 replicas x
# deterministic and randomized picking x 10 seeds, against the four baselines. Writes
# OUT/<scene>/{summary.csv,load-*.png,load-sorted-*.png,difference-*.png,busiest-*.png}.
#   scripts/balancer-chapter5.sh [OUT]   (default: chapter5-out; about 5 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-chapter5-out}"
cargo build --release -p visnode -p backend -p balancer
mkdir -p "$out"
export GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=536870912
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
for scene in forest plant; do
  case "$scene" in
    forest) triangles=10000000 ;;
    plant) triangles=12000000 ;;
  esac
  if [ ! -s "$out/$scene.jsonl" ]; then
    target/release/visnode bench --scene "$scene" --triangles "$triangles" --path orbit \
      --path-seconds 20 --sample-hz 1 --sample-frames 0 --t-nz 1000000 --record-trace "$out/$scene.jsonl" \
      --out "$out/$scene-run" >"$out/$scene-run.log" 2>&1
  fi
  target/release/balancer simulate --trace "$out/$scene.jsonl" --out "$out/$scene" \
    | tee "$out/$scene.txt"
done

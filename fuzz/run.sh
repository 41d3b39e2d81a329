#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 600), one after another, starting from the
# committed seeds (fuzz/seeds/TARGET) and the working corpus (fuzz/corpus/TARGET, kept between
# runs, not committed). Prints each target's executions, coverage and crashes; a crash's
# input lands in fuzz/artifacts/TARGET/. Needs cargo-fuzz (`cargo install cargo-fuzz`).
#
#   fuzz/run.sh 600            # ten minutes a target
#   fuzz/run.sh 60 load_gltf   # one target
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-600}
shift || true
# cargo-fuzz passes unstable flags to rustc; the stable toolchain accepts them this way.
# No sanitizer: the code under test is safe Rust, and -rss_limit_mb / -malloc_limit_mb /
# -timeout below turn unbounded memory or time into reported crashes.
export RUSTC_BOOTSTRAP=1
targets=${*:-$(cargo fuzz list)}
cargo fuzz build --sanitizer none
mkdir -p logs
for target in $targets; do
  mkdir -p "corpus/$target"
  cargo fuzz run --sanitizer none "$target" "corpus/$target" "seeds/$target" -- \
    -max_total_time="$seconds" -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=10 \
    -print_final_stats=1 >"logs/$target.log" 2>&1 || echo "$target: CRASH (see fuzz/logs/$target.log)"
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "logs/$target.log" | grep -o '[0-9]*$' || echo '?')
  took=$(grep -o 'Done [0-9]* runs in [0-9]* second' "logs/$target.log" | grep -o '[0-9]* second' | grep -o '[0-9]*' || echo '? (stopped at a crash)')
  cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "logs/$target.log" | tail -1 || echo '?')
  corpus=$(find "corpus/$target" -type f | wc -l)
  crashes=$(find "artifacts/$target" -type f 2>/dev/null | wc -l)
  echo "$target: $runs executions in ${took}s, $cov, corpus $corpus inputs, $crashes crash inputs"
done

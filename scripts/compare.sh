#!/usr/bin/env bash
# The README's comparison of every kind, 1024x768, on this machine's adapter:
#   forest-orbit forest-flythrough plant-orbit plant-flythrough   wall clock (a 20 s path,
#                                                                  sampled at 10 Hz)
#   forest-stills plant-stills                                     one step per frame
#                                                                  (image quality alone)
#   forest-sweep                                                   Pareto curves, one knob
#                                                                  per kind
#   dragon-orbit dragon-stills                                     the Stanford dragon alone
#                                                                  (../shared/data, see
#                                                                  testdata/README.md) under
#                                                                  t_nz 20,000
#   dragonforest-orbit                                             the forest with copies of
#                                                                  the dragon beside its
#                                                                  trees, t_nz 100,000
#   dragon-sync                                                    the dragon's stills with
#                                                                  fresh boards (--sync):
#                                                                  a board's own quality
#   forest-pareto plant-pareto                                     relief, lod, octahedral
#                                                                  over t_nz 100 k, 250 k,
#                                                                  1 M (wall clock, orbit)
#   forest-ablation plant-ablation                                 relief with each
#                                                                  mechanism off in turn
#                                                                  (wall clock, orbit,
#                                                                  t_nz 100 k)
# About 1.5 hours on two CPU cores with lavapipe; minutes on a GPU.
#   scripts/compare.sh [OUT [STEP...]]   (default: compare-out, every step but the dragon's)
# scripts/compare-table.py prints the compare.csv files as the README's tables.
# KINDS=relief,none runs only those kinds; VISNODE=PATH runs another build (an earlier
# commit's, for a before-and-after) instead of building this one.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-compare-out}"
shift || true
steps=("$@")
[ ${#steps[@]} -gt 0 ] || steps=(forest-orbit forest-flythrough plant-orbit plant-flythrough
  forest-stills plant-stills forest-sweep)
visnode="${VISNODE:-target/release/visnode}"
[ -n "${VISNODE:-}" ] || cargo build --release -p visnode -p backend
mkdir -p "$out"
# lavapipe's per-frame allocations churn through mmap without this (background.md).
export GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=536870912
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
wall=(--resolution 1024x768 --timing wall --path-seconds 20 --sample-hz 10 --sample-frames 3)
stills=(--resolution 1024x768 --timing frames --frames 60 --sample-frames 3)
all="${KINDS:-relief,lod,octahedral,billboard,none}"
dragon="${DRAGON:-../shared/data/dragon_vrip_res2.ply.gz}"
scene_of() {
  case "$1" in
    forest*) echo "forest --triangles 10000000" ;;
    dragonforest*) echo "forest --triangles 10000000 --forest-mesh $dragon --t-nz 100000" ;;
    dragon*) echo "$dragon --t-nz 20000" ;;
    *) echo "plant --triangles 12000000" ;;
  esac
}
for step in "${steps[@]}"; do
  read -r -a scene <<<"$(scene_of "$step")"
  case "$step" in
    *-orbit | *-flythrough) args=("${wall[@]}" --path "${step#*-}" --compare "$all") ;;
    *-stills) args=("${stills[@]}" --path orbit --compare "$all") ;;
    forest-sweep) args=("${wall[@]}" --path orbit --compare "${KINDS:-relief,lod,octahedral}"
      --sweep t-nz=250000,1000000 --sweep map-size=64,128 --sweep lod-pixels=0.5,4
      --sweep octahedral-views=8,24) ;;
    dragon-sync) args=("${stills[@]}" --path orbit --sync --compare "${KINDS:-relief,lod}") ;;
    *-pareto) args=("${wall[@]}" --path orbit --compare "${KINDS:-relief,lod,octahedral}"
      --sweep t-nz=100000,250000,1000000) ;;
    # At t_nz 100 k, where most objects are boards: the full configuration first, then one
    # mechanism off per run: the pixel-bound refresh (angle only), the screen-following
    # grid (32 cells whatever the size), the upload limit, the unsuitable objects' levels
    # of detail, the cross-fade kept for boards that jump (fade-pixels 0 fades every
    # board that moved), the still camera's larger upload budget (its first boards), the
    # levels of detail of objects waiting for a board, the grid's depth (pixel: the depth
    # map's, per pixel, shading hidden pixels too), levels drawn where cheaper than a
    # board (triangle-cost-pixels 0: a board for every object), each frame drawn for the
    # camera at its start instead of the predicted one, boards' silhouettes cut at one half
    # instead of blended.
    *-ablation) args=("${wall[@]}" --path orbit --t-nz 100000 --compare relief
      --sweep refresh-pixels=2,1000000000 --sweep board-cell-pixels=1
      --sweep upload-ms=1000000 --sweep whole-unsuitable=true --sweep fade-pixels=0
      --sweep still-upload-ms=0 --sweep whole-fallback=true --sweep board-depth=pixel
      --sweep triangle-cost-pixels=0 --sweep predict-camera=false
      --sweep soft-edges=false) ;;
    *) echo "unknown step $step" >&2; exit 2 ;;
  esac
  # The README's tables were measured at t_nz 1 M, visnode's default on every adapter until
  # a CPU adapter's became 100 k: a step that names no budget keeps 1 M, so they reproduce.
  [[ " ${scene[*]} ${args[*]} " == *" --t-nz "* ]] || args+=(--t-nz 1000000)
  "$visnode" bench --scene "${scene[@]}" "${args[@]}" --out "$out/$step" \
    >"$out/$step.log" 2>&1
  echo "$step: $out/$step/compare.csv"
done

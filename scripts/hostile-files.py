#!/usr/bin/env python3
"""Writes small mesh files that describe enormous work, as a new user found them, and
measures `visnode inspect` on each (wall time, peak resident memory, the message):

    scripts/hostile-files.py OUT [--visnode target/release/visnode]

- dag.gltf: 64 nodes, node i with children i+1 and i+2 (a DAG: ~10^13 paths), each with a mesh.
- cycle.gltf: three nodes in a cycle.
- shared.gltf: 100,000 primitives reading one accessor of 30,000 triangles (3 G triangles).
- instances.gltf: one 200,000-triangle mesh instanced by 2,000 nodes (400 M triangles).
- bomb.ply.gz: a valid PLY header, then 3 GB of spaces, gzipped to about 3 MB.

The goal: every file under 20 MB is refused with a clear error, or loaded, within 10 s and
2 GB resident.
"""

import argparse
import base64
import json
import re
import struct
import subprocess
import time
import zlib
from pathlib import Path


def gltf(nodes, primitives, triangles):
    """A glTF document whose one mesh has `primitives` primitives over one accessor of
    `triangles` triangles (a fan of vertices on a circle)."""
    vertices = triangles + 2
    positions = b"".join(struct.pack("<3f", (i % 97) * 0.01, (i // 97) * 0.01, (i * 7 % 13) * 0.01)
                         for i in range(vertices))
    indices = b"".join(struct.pack("<3I", 0, i + 1, i + 2) for i in range(triangles))
    buffer = positions + indices
    return json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}] * primitives}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": vertices, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 1]},
            {"bufferView": 1, "componentType": 5125, "count": triangles * 3, "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "buffers": [{"byteLength": len(buffer),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buffer).decode()}],
    }).encode()


def gzip_bomb(path, inflated):
    header = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
    compressor = zlib.compressobj(9, zlib.DEFLATED, 31)  # 31: gzip framing
    block = b" " * (1 << 24)
    with open(path, "wb") as out:
        out.write(compressor.compress(header))
        for _ in range(inflated // len(block)):
            out.write(compressor.compress(block))
        out.write(compressor.flush())


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("out", type=Path)
    parser.add_argument("--visnode", type=Path, default=Path("target/release/visnode"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    files = {
        "dag.gltf": gltf([{"mesh": 0, "children": [c for c in (i + 1, i + 2) if c < 64]}
                          for i in range(64)], 1, 1),
        "cycle.gltf": gltf([{"mesh": 0, "children": [1]}, {"mesh": 0, "children": [2]},
                            {"mesh": 0, "children": [0]}], 1, 1),
        "shared.gltf": gltf([{"mesh": 0}], 100_000, 30_000),
        "instances.gltf": gltf([{"children": list(range(1, 2001))}] + [{"mesh": 0}] * 2000, 1, 200_000),
    }
    for name, data in files.items():
        (args.out / name).write_bytes(data)
    bomb = args.out / "bomb.ply.gz"
    if not bomb.exists():
        gzip_bomb(bomb, 3 << 30)
    rows = []
    for name in [*files, "bomb.ply.gz"]:
        path = args.out / name
        started = time.monotonic()
        run = subprocess.run(["/usr/bin/time", "-v", str(args.visnode), "inspect", "--no-cache",
                              "--scene", str(path)], capture_output=True, text=True, timeout=600)
        seconds = time.monotonic() - started
        peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr).group(1)) * 1024
        message = next((line for line in run.stderr.splitlines() if line.startswith("error:")), "loaded")
        rows.append({"file": name, "bytes": path.stat().st_size, "seconds": round(seconds, 2),
                     "peak_resident_mb": round(peak / 2**20), "exit": run.returncode, "message": message})
        print(json.dumps(rows[-1]))
    (args.out / "hostile.json").write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()

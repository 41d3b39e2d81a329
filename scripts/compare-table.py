#!/usr/bin/env python3
"""Prints `visnode bench --compare`'s compare.csv files as one Markdown table (the README's).

    scripts/compare-table.py TITLE OUT/STEP/compare.csv[=LABEL] [MORE.csv ...]

One row per run: kind and swept value, frame time (mean / p95), object-pixel PSNR (and the
PSNR nine samples in ten beat), FLIP over object pixels, whole-frame PSNR, the image's age,
triangles per frame, the far field's GPU memory, build and first-board seconds, and the
object MSE split into silhouettes and interiors.
"""
import csv
import sys


def split(r):
    """The object MSE split, or a dash for a build from before the split existed."""
    if not r.get("silhouette_mse"):
        return "-"
    return f"{float(r['silhouette_mse']):.0f} / {float(r['interior_mse']):.0f}"


def row(r, label=""):
    run = r["kind"] + (f" {r['run']}" if r["run"] else "") + label
    flip = float(r["object_flip_mean"])
    return (
        f"| {run} | {float(r['frame_ms_mean']):.0f} / {float(r['frame_ms_p95']):.0f} ms "
        f"| {float(r['object_psnr_db']):.2f} ({float(r['object_psnr_p90_db']):.2f}) dB "
        f"| {flip:.3f} | {float(r['frame_psnr_db']):.2f} dB "
        f"| {float(r['image_age_ms_mean']):.0f} ms "
        f"| {float(r['triangles_per_frame']) / 1e6:.2f} M "
        f"| {float(r['far_field_mib']):.0f} MiB "
        f"| {float(r['build_s']):.1f} + {float(r.get('warmup_s') or 0):.1f} s "
        f"| {split(r)} |"
    )


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    title, files = sys.argv[1], sys.argv[2:]
    print(
        f"| {title} | frame mean / p95 | object PSNR (p90) | FLIP | whole-frame PSNR "
        "| image age | triangles/frame | far-field GPU | build + first boards "
        "| object MSE: silhouettes / interiors |"
    )
    print("| --- " * 10 + "|")
    for path in files:
        # PATH=LABEL appends LABEL to each row's name (e.g. "=, before").
        path, _, label = path.partition("=")
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                print(row(r, label))


if __name__ == "__main__":
    main()

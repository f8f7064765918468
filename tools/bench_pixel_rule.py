#!/usr/bin/env python3
"""Benchmark for the report's pixel rule (issue 14.1): how the figures of the same levels move with
--supersample k, and how a level compares with the same level without its thick edges and points (the
triangles alone) and with peers, all from one switching distance.

usage: tools/bench_pixel_rule.py --original FILE --lod NAME=FILE [--lod NAME=FILE ...] --distance D
                                 [--strip NAME] [--ks 1,2,3,4] [--cli build/lodstream]
                                 [--baseline OTHER/lodstream] [--views 32] [--resolution 512]
                                 [--samples 20000] [--threads 0] [--work DIR] [--out FILE.md]

  --lod NAME=FILE   a level to measure (PLY or OBJ), under a short name; repeat
  --strip NAME      also measure level NAME with its edge and point elements dropped (a binary PLY as
                    simplify writes it), as NAME-tri
  --distance D      switching distance of every level (the reference level's, from its manifest)
  --baseline CLI    a build without --supersample (before the pixel rule), reported as k = "old"

Every report runs with `nice`; prints one markdown table (level x k: silhouette max / p95 / mean px,
mismatch %, thin kept %, ray seconds) and writes it to --out; raw report.json files stay in --work.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from report_meshlab_test import triangle_only_copy  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--original", required=True)
    ap.add_argument("--lod", action="append", required=True)
    ap.add_argument("--distance", type=float, required=True)
    ap.add_argument("--strip", action="append", default=[])
    ap.add_argument("--ks", default="1,2,3,4")
    ap.add_argument("--cli", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "lodstream"))
    ap.add_argument("--baseline")
    ap.add_argument("--views", default="32")
    ap.add_argument("--resolution", default="512")
    ap.add_argument("--samples", default="20000")
    ap.add_argument("--threads", default="0")
    ap.add_argument("--memory", default="4G")
    ap.add_argument("--work")
    ap.add_argument("--out")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="bench_pixel_rule.")
    os.makedirs(work, exist_ok=True)
    levels = []
    for spec in a.lod:
        name, path = spec.split("=", 1)
        levels.append((name, path))
        if name in a.strip:
            tri = os.path.join(work, name + "-tri.ply")
            if not os.path.exists(tri):
                triangle_only_copy(path, tri)
            levels.append((name + "-tri", tri))
    runs = [("old", a.baseline, [])] if a.baseline else []
    runs += [(k, a.cli, ["--supersample", k]) for k in a.ks.split(",")]
    table = {}
    for k, cli, extra in runs:
        out = os.path.join(work, f"k{k}")
        cmd = ["nice", cli, "report", "--original", a.original, "-o", out, "--views", a.views, "--resolution",
               a.resolution, "--samples", a.samples, "--threads", a.threads, "--memory", a.memory, "--progress", "none",
               "--switch-distances", ",".join([str(a.distance)] * len(levels))]
        for _, path in levels:
            cmd += ["--lod", path]
        cmd += extra
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        rep = json.load(open(os.path.join(out, "report.json")))
        for (name, _), lvl in zip(levels, rep["runs"][0]["levels"]):
            table[(name, k)] = lvl
        table[("_perf", k)] = rep["performance"]
        print(f"k={k}: {rep['performance']['rays']} rays in {rep['performance']['ray_seconds']:.1f} s", file=sys.stderr)
    lines = [f"original {a.original}; distance {a.distance}; {a.views} views of {a.resolution}^2",
             "", "| level | triangles | edges | points | k | sil max px | sil p95 px | sil mean px | mismatch % | thin kept % |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    for name, _ in levels:
        for k, _, _ in runs:
            l = table[(name, k)]
            s = l["silhouette"]
            thin = s.get("thin_kept_fraction")
            lines.append(f"| {name} | {l['triangles']} | {l['edges']} | {l['points']} | {k} | {s['max_px']:.3g} | "
                         f"{s['p95_px']:.3g} | {s['mean_px']:.3g} | {100 * s['mismatch_fraction']:.3g} | "
                         + (f"{100 * thin:.3g} |" if thin is not None else "— |"))
    lines.append("")
    lines.append("| k | rays | ray seconds | M rays/s |")
    lines.append("|---|---:|---:|---:|")
    for k, _, _ in runs:
        p = table[("_perf", k)]
        lines.append(f"| {k} | {p['rays']} | {p['ray_seconds']:.1f} | {p['rays_per_second'] / 1e6:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()

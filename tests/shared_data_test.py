#!/usr/bin/env python3
"""Every model in ../shared/data ingests, and `lodstream info --json` agrees with an independent count
(tests/tools/count_mesh.py) on vertices, welded vertices, polygons, triangles, degenerate triangles, lines,
segments made from faces, points and objects. Skipped, with a notice, when ../shared/data is absent.

usage: shared_data_test.py LODSTREAM_BINARY SOURCE_DIR
"""
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "tools"))
import count_mesh  # noqa: E402
from shared_data import shared_data_dir  # noqa: E402

KEYS = ["vertices", "vertices_welded", "polygons", "triangles", "degenerate", "lines", "face_segments", "points",
        "objects"]


def main():
    binary, source = sys.argv[1], sys.argv[2]
    data = shared_data_dir(source)
    if data is None:
        return 0
    files = []
    for root, _, names in os.walk(data):
        for n in names:
            if n.lower().endswith((".obj", ".ply", ".stl")):
                files.append(os.path.join(root, n))
    files.sort()
    failures = 0
    for path in files:
        expect = count_mesh.counts(path)
        run = subprocess.run([binary, "info", path, "--json", "--memory", "256M"], capture_output=True, text=True)
        if run.returncode != 0:
            print(f"FAIL {path}: exit {run.returncode}: {run.stderr.strip()}")
            failures += 1
            continue
        got = json.loads(run.stdout)
        diffs = [f"{k}: lodstream {got[k]} vs independent {expect[k]}" for k in KEYS if got[k] != expect[k]]
        if diffs:
            print(f"FAIL {path}: " + "; ".join(diffs))
            failures += 1
    print(f"{len(files) - failures} passed, {failures} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

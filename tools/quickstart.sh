#!/usr/bin/env bash
# Quick start: installs what is missing, builds Release, and runs lodstream on the sample scene
# shipped in tests/data (a furnished room made of CC0 furniture models): statistics, then five LODs.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/install-deps.sh"
"$root/tools/build.sh" -DLODSTREAM_BUILD_TESTS=OFF -DLODSTREAM_BUILD_TOOLS=OFF
out="$root/out/quickstart"
mkdir -p "$out"
"$root/build/lodstream" info "$root/tests/data/sample-room.ply" --work "$out/work"
"$root/build/lodstream" info "$root/tests/data/sample-room.ply" --work "$out/work" --json > "$out/info.json"
echo
# Five levels of detail, every format, reusing the scene store ingested above.
"$root/build/lodstream" simplify "$root/tests/data/sample-room.ply" -o "$out/lods" --obj --work "$out/work"
echo
# The error of each level, in pixels where a renderer would switch to it (Embree ray casts, Hausdorff).
"$root/build/lodstream" report "$out/lods"
echo
echo "quickstart: ingest statistics in $out/info.json; levels of detail in $out/lods"
echo "  (lodN.ply, lodN.obj, lods.glb with every level chained by MSFT_lod, manifest.json);"
echo "  their error report in $out/lods/report.html (open it in any browser), report.json and lodN.csv"

#!/bin/bash
# Thick edges and points in 3D Tiles (core/thick_primitives.h): what expanding them into triangles costs
# (triangles per level, tools/thick_levels) against what the report measures for the level as simplify
# writes it (edges with thickness, points) and as the tiles draw it (triangles only), at the same
# switching distances. Usage: tools/bench_thick.sh [BUILD_DIR] [INPUT] (default: the sample room).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd); src=$(dirname "$here")
build=${1:-$src/build}; input=${2:-$src/tests/data/sample-room.ply}
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
"$build/lodstream" simplify "$input" -o "$work/out" --no-glb --no-space-check >/dev/null
"$build/thick_levels" "$work/out" "$work/thick"
lods=(); thick=(); n=$(ls "$work/out"/lod*.ply | wc -l)
for ((l = 0; l < n; ++l)); do lods+=(--lod "$work/out/lod$l.ply"); thick+=(--lod "$work/thick/lod$l.ply"); done
d=$(node -e 'console.log(require(process.argv[1]).levels.map((l) => l.switch_distance).join(","))' "$work/out/manifest.json")
"$build/lodstream" report --original "$input" "${lods[@]}" --switch-distances "$d" -o "$work/r-lines" --no-space-check >/dev/null
"$build/lodstream" report --original "$input" "${thick[@]}" --switch-distances "$d" -o "$work/r-thick" --no-space-check >/dev/null
node -e '
const a = require(process.argv[1]).runs[0].levels, b = require(process.argv[2]).runs[0].levels;
console.log("level  form    triangles edges points  mismatch%  silh.mean_px  silh.p95_px  hausdorff.max  hausdorff.mean");
for (let i = 0; i < a.length; ++i)
  for (const [name, l] of [["lines", a[i]], ["thick", b[i]]])
    console.log(`${String(i).padEnd(6)} ${name.padEnd(7)} ${String(l.triangles).padStart(9)} ${String(l.edges).padStart(5)} ` +
                `${String(l.points).padStart(6)}  ${(100 * l.silhouette.mismatch_fraction).toFixed(3).padStart(8)}  ` +
                `${l.silhouette.mean_px.toFixed(3).padStart(12)}  ${l.silhouette.p95_px.toFixed(3).padStart(11)}  ` +
                `${l.hausdorff.max.toPrecision(4).padStart(13)}  ${l.hausdorff.mean.toPrecision(4).padStart(14)}`);' \
  "$work/r-lines/report.json" "$work/r-thick/report.json"

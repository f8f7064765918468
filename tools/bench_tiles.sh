#!/bin/bash
# Benchmark of 3D Tiles output (issue 15): a city from ../shared/data/tools/make-scene.sh simplified at
# --memory 1G with and without --tiles, side by side in one run (time and peak from /usr/bin/time and the
# manifests); tile count, triangles per tile, bytes; the 3D Tiles validator's errors and warnings; bytes
# CesiumJS fetches at three camera distances (tools/cesium_tiles.js: near a building, a district, the
# whole city) beside lods.glb's size. Targets: near and district views fetch at most 10 % of lods.glb;
# tiles add at most 20 % to the run time.
#
# Usage: tools/bench_tiles.sh [BUILD_DIR] [N] [SEED]   (default build, 9 1: the 48.6M-triangle city;
#        N=3 gives about 5M). The scene is built under $BENCH_SCENES (default /work/scenes) with nice and
#        deleted afterwards unless KEEP_SCENE=1; BENCH_SCENE=FILE uses an existing scene instead. Both runs take
#        --tile-triangles $BENCH_TILE_TRIANGLES (default: lodstream's) and the tiles run --tiles-up z (the
#        city is Z-up; BENCH_TILES_UP=y for a Y-up scene) and $BENCH_TILES_OPTS. VALIDATE_GLTF=1 also runs
#        glTF-Validator on every tile (tools/validate_gltf.js). Prints one line per figure.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd); src=$(dirname "$here")
build=${1:-$src/build}; n=${2:-9}; seed=${3:-1}
cli=$build/lodstream
[ -x "$cli" ] || { echo "no lodstream_cli under $build"; exit 2; }
make_scene=$src/../shared/data/tools/make-scene.sh
[ -x "$make_scene" ] || [ -f "$make_scene" ] || { echo "skipped: $make_scene is absent"; exit 0; }
scenes=${BENCH_SCENES:-/work/scenes}; mkdir -p "$scenes"
# BENCH_SCENE: an existing scene file to use instead (never deleted).
scene=${BENCH_SCENE:-$scenes/city-$n-$seed.ply}; keep=${KEEP_SCENE:-0}; [ -n "${BENCH_SCENE:-}" ] && keep=1
work=$(mktemp -d "$scenes/bench-tiles.XXXXXX")
cleanup() { rm -rf "$work"; [ "$keep" = 1 ] || rm -f "$scene"; }
trap cleanup EXIT
[ -f "$scene" ] || nice bash "$make_scene" "$n" "$seed" "$scene" >/dev/null
echo "scene        $scene ($(stat -c %s "$scene") bytes), load $(cut -d' ' -f1-3 /proc/loadavg)"

sizing=(); [ -n "${BENCH_TILE_TRIANGLES:-}" ] && sizing=(--tile-triangles "$BENCH_TILE_TRIANGLES")
run() {  # name, extra options
  local name=$1; shift
  /usr/bin/time -f "%e %M" -o "$work/$name.time" nice "$cli" simplify "$scene" -o "$work/$name" --memory 1G \
    --work "$work/$name.work" --no-space-check "${sizing[@]}" "$@" >/dev/null
  rm -rf "$work/$name.work"
  read -r secs kib < "$work/$name.time"
  echo "$name        $secs s, peak $((kib / 1024)) MiB"
}
run plain
# shellcheck disable=SC2086
run tiles --tiles --tiles-up "${BENCH_TILES_UP:-z}" ${BENCH_TILES_OPTS:-}
m=$work/tiles/manifest.json
node -e '
const m = require(process.argv[1]).tiles;
console.log(`tiles        ${m.tiles} tiles (${m.content_tiles} with content, ${m.tile_encoding}), ${m.triangles} triangles, ` +
            `${Math.round(m.triangles / m.content_tiles)} a tile on average, at most ${m.max_triangles}, ${m.bytes} bytes`);
const st = require(process.argv[1]).stages.filter((x) => x.name === "emit" || x.name === "tiles");
for (const x of st) console.log(`stage        ${x.name} ${JSON.stringify(x)}`);' "$m"
glb=$(stat -c %s "$work/tiles/lods.glb")
echo "lods.glb     $glb bytes"

validator=${LODSTREAM_TILES_VALIDATOR:-${TMPDIR:-/tmp}/3d-tiles-validator}
if [ -f "$validator/.installed" ]; then
  node "$validator/build/main.js" --tilesetFile "$work/tiles/tiles/tileset.json" --reportFile "$work/validator.json" >/dev/null 2>&1 || true
  node -e 'const r = require(process.argv[1]); console.log(`validator    ${r.numErrors} errors, ${r.numWarnings} warnings`)' "$work/validator.json"
else
  echo "validator    skipped: not installed (tools/install_tiles_tools.sh)"
fi
if [ "${VALIDATE_GLTF:-0}" = 1 ]; then
  # shellcheck disable=SC2046
  node "$here/validate_gltf.js" $(find "$work/tiles/tiles" -name '*.glb' | sort) > "$work/gltf.json"; code=$?
  node -e '
const r = require(process.argv[1]), all = "numErrors" in r ? [r] : Object.values(r);
let e = 0, w = 0, i = 0; for (const x of all) { e += x.numErrors; w += x.numWarnings; i += x.numInfos; }
console.log(`glTF-Validator ${all.length} tiles: ${e} errors, ${w} warnings, ${i} infos`);' "$work/gltf.json" || echo "glTF-Validator exit $code"
fi
# Views: near a building (the bounding sphere's center, at 3 % of its radius), a district (25 %), the whole city.
# BENCH_VIEW_TARGET=dense aims the near and district views at the finest level's fullest tile instead (a scene
# whose sphere's center is empty air; tools/cesium_tiles.js), which depends on the tiling.
t=${BENCH_VIEW_TARGET:+:$BENCH_VIEW_TARGET}
if node "$here/cesium_tiles.js" "$work/tiles/tiles" "$work/shots" near:0.03$t district:0.25$t whole:2.5 > "$work/cesium.json"; then
  node -e '
const v = require(process.argv[1]).views, glb = Number(process.argv[2]);
for (const x of v)
  console.log(`cesium       ${x.name.padEnd(9)} distance ${x.distance.toFixed(1)}: ${x.tiles} tiles, ${x.bytes} bytes = ` +
              `${(100 * x.bytes / glb).toFixed(2)} % of lods.glb; loaded ${x.tiles_loaded}, non-blank ${(100 * x.nonblank).toFixed(1)} %, ${x.seconds.toFixed(1)} s`);' \
    "$work/cesium.json" "$glb"
else
  echo "cesium       $(head -c 300 "$work/cesium.json")"
fi
a=$(cut -d' ' -f1 "$work/plain.time"); b=$(cut -d' ' -f1 "$work/tiles.time")
echo "overhead     tiles add $(awk -v a="$a" -v b="$b" 'BEGIN{printf "%.1f", 100 * (b - a) / a}') % to the run time"

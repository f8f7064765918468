#!/bin/bash
# CesiumJS loads the sample room's tileset (upright: --tiles-up z) in headless Chromium
# (tools/cesium_tiles.js): from three distances it reaches tilesLoaded, renders a non-blank image (over 1 %
# of pixels drawn) and fetches at least one tile over the local server; the tiles and bytes fetched are
# printed. Exit 77 ("skipped:") when cesium, puppeteer-core or Chromium are missing.
# Usage: tiles_cesium_test.sh LODSTREAM_CLI SOURCE_DIR
set -uo pipefail
cli=$1; src=$2
if ! command -v node >/dev/null 2>&1; then echo "skipped: node is not installed"; exit 77; fi
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
"$cli" simplify "$src/tests/data/sample-room.ply" -o "$work/out" --tiles --tiles-up z --tile-triangles 3000 --no-ply --no-glb \
  --no-space-check >/dev/null || { echo "FAIL: simplify --tiles"; exit 1; }
r=$(node "$src/tools/cesium_tiles.js" "$work/out/tiles" "$work/shots"); code=$?
echo "$r"
[ $code -eq 77 ] && exit 77
[ $code -ne 0 ] && { echo "FAIL: cesium_tiles.js exit $code"; exit 1; }
printf '%s' "$r" | node -e '
let s = ""; process.stdin.on("data", (d) => s += d).on("end", () => {
  const v = JSON.parse(s).views; let ok = v.length === 3;
  for (const x of v) {
    if (!x.tiles_loaded) { console.log(`FAIL: ${x.name}: tilesLoaded not reached`); ok = false; }
    if (!(x.nonblank > 0.01)) { console.log(`FAIL: ${x.name}: blank image (${x.nonblank})`); ok = false; }
    if (!(x.tiles > 0 && x.bytes > 0)) { console.log(`FAIL: ${x.name}: no tile fetched`); ok = false; }
  }
  process.exit(ok ? 0 : 1);
});'

#!/bin/bash
# 3D Tiles output checked by the official tools: the 3D Tiles validator (CesiumGS/3d-tiles-validator,
# ../shared/tools/3d-tiles-validator/README.md: no errors and no warnings on the tileset, its contents
# included) and the Khronos glTF-Validator on every tile (tools/validate_gltf.js: no errors, no warnings),
# on the sample room cut into several tiles, with thick edges and points (the default) and with
# LINES/POINTS, meshopt tiles (the default), and quantized ones. Prints "skipped:" and exits 77 (ctest SKIP_RETURN_CODE) when node or the validators are not
# installed; nothing is downloaded here (install with tools/install_tiles_tools.sh).
# Usage: tiles_validate_test.sh LODSTREAM_CLI SOURCE_DIR [SCENE]   (SCENE: default the sample room)
set -uo pipefail
cli=$1; src=$2; scene=${3:-$src/tests/data/sample-room.ply}
if ! command -v node >/dev/null 2>&1; then echo "skipped: node is not installed"; exit 77; fi
validator=${LODSTREAM_TILES_VALIDATOR:-${TMPDIR:-/tmp}/3d-tiles-validator}
if [ ! -f "$validator/build/main.js" ] || [ ! -f "$validator/.installed" ]; then
  echo "skipped: the 3D Tiles validator is not installed in $validator (tools/install_tiles_tools.sh)"; exit 77
fi
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
status=0; gltf_skipped=0
for run in triangles lines triangles-quantized; do
  out=$work/$run; lines=${run%%-*}; encoding=meshopt; [ "$run" = triangles-quantized ] && encoding=quantized
  "$cli" simplify "$scene" -o "$out" --tiles --tile-lines "$lines" --tile-encoding $encoding --tile-triangles 10000 --no-ply --no-glb \
    --no-space-check >/dev/null || { echo "FAIL: simplify --tiles --tile-lines $lines --tile-encoding $encoding"; exit 1; }
  node "$validator/build/main.js" --tilesetFile "$out/tiles/tileset.json" --reportFile "$work/$run.json" >/dev/null 2>&1
  report=$(cat "$work/$run.json" 2>/dev/null)
  counts=$(node -e 'const r=require(process.argv[1]);console.log(r.numErrors,r.numWarnings)' "$work/$run.json" 2>/dev/null)
  tiles=$(find "$out/tiles" -name '*.glb' | wc -l)
  echo "3d-tiles-validator ($run, $tiles tiles): errors warnings = $counts"
  if [ "$counts" != "0 0" ]; then echo "$report" | head -c 4000; echo; status=1; fi
  r=$(node "$src/tools/validate_gltf.js" $(find "$out/tiles" -name '*.glb' | sort)); code=$?
  if [ $code -eq 77 ]; then gltf_skipped=1; continue; fi
  counts=$(printf '%s' "$r" | node -e '
let s = ""; process.stdin.on("data", (d) => s += d).on("end", () => {
  const r = JSON.parse(s), all = "numErrors" in r ? [r] : Object.values(r);  // one file: its issues alone
  let e = 0, w = 0; for (const i of all) { e += i.numErrors; w += i.numWarnings; }
  console.log(e, w);
});')
  echo "glTF-Validator ($run, $tiles tiles): errors warnings = $counts"
  if [ $code -ne 0 ] || [ "$counts" != "0 0" ]; then echo "$r" | grep -B2 -A12 '"numErrors": [1-9]\|"numWarnings": [1-9]' | head -60; status=1; fi
done
[ $gltf_skipped -eq 1 ] && echo "notice: glTF-Validator not installed (tools/install-deps.sh --test): tiles checked by the 3D Tiles validator only"
[ $status -eq 0 ] && echo "ok: no errors, no warnings"
exit $status

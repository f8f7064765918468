#!/bin/bash
# Installs what the 3D Tiles checks use (tests/tiles_validate_test.sh, tests/tiles_cesium_test.sh,
# tools/bench_tiles.sh), outside the repository and never at build or test time:
# - the 3D Tiles validator (../shared/tools/3d-tiles-validator/install.sh, into ${TMPDIR:-/tmp}/3d-tiles-validator
#   or $LODSTREAM_TILES_VALIDATOR), when the shared tools are present;
# - npm packages gltf-validator, cesium and puppeteer-core (its browser is the system's Chromium) into
#   $LODSTREAM_NPM_PREFIX (default ~/.cache/lodstream-npm).
# Each step that fails (no network, no npm) prints a warning; the tests then skip what it would have served.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  echo "warning: node and npm are required; nothing installed" >&2; exit 0
fi
shared=$here/../../shared/tools/3d-tiles-validator
if [ -x "$shared/install.sh" ]; then
  "$shared/install.sh" ${LODSTREAM_TILES_VALIDATOR:+"$LODSTREAM_TILES_VALIDATOR"} \
    || echo "warning: the 3D Tiles validator could not be installed; its test will be skipped" >&2
else
  echo "warning: $shared is absent; the 3D Tiles validator test will be skipped" >&2
fi
prefix=${LODSTREAM_NPM_PREFIX:-$HOME/.cache/lodstream-npm}
missing=()
for p in gltf-validator cesium puppeteer-core; do [ -f "$prefix/node_modules/$p/package.json" ] || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]} (npm, into $prefix)"
  PUPPETEER_SKIP_DOWNLOAD=1 npm install --prefix "$prefix" --no-audit --no-fund --no-save --ignore-scripts --loglevel=error \
    "${missing[@]}" || echo "warning: npm could not install ${missing[*]}; the tests that use them will be skipped" >&2
fi

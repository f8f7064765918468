#!/usr/bin/env bash
# Installs lodstream's build and test dependencies from Debian 12 packages, skipping what is present.
# Usage: tools/install-deps.sh [--test]   (--test adds what the test suite needs)
set -euo pipefail
pkgs=(build-essential cmake libembree-dev libtbb-dev libopenmesh-dev libcli11-dev nlohmann-json3-dev libfmt-dev
      libpng-dev libmeshoptimizer-dev)
# --test also: MeshLab for the Hausdorff agreement test (tools/meshlab_hausdorff.py runs meshlabserver under
# xvfb-run, which needs xauth; meshlab's only Recommends, chemical-mime-data, is not needed) and Chromium for
# the report.html render check (tools/check_html.py).
if [ "${1:-}" = "--test" ]; then pkgs+=(googletest libgtest-dev python3 meshlab xvfb xauth chromium); fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# With --test: the Khronos glTF-Validator (npm package gltf-validator), which tests/test_writers.cpp runs
# through tools/validate_gltf.js on the GLB writer's output. Only when node and npm are present (the test
# is skipped otherwise), into a per-user prefix ($LODSTREAM_NPM_PREFIX, default ~/.cache/lodstream-npm),
# and only once. Every 2.x release of the package is a prerelease, so the version is pinned exactly.
if [ "${1:-}" = "--test" ] && command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1; then
  npm_prefix="${LODSTREAM_NPM_PREFIX:-$HOME/.cache/lodstream-npm}"
  if [ ! -f "$npm_prefix/node_modules/gltf-validator/package.json" ]; then
    echo "installing: gltf-validator (npm, into $npm_prefix)"
    npm install --prefix "$npm_prefix" --no-audit --no-fund --no-save --loglevel=error \
      gltf-validator@2.0.0-dev.3.10 >/dev/null ||
      echo "warning: npm could not install gltf-validator; the glTF validation test will be skipped" >&2
  fi
fi

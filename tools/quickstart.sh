#!/usr/bin/env bash
# Quick start: installs what is missing, builds Release, and runs lodstream on the sample scene
# shipped in tests/data (a furnished room made of CC0 furniture models).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/install-deps.sh"
"$root/tools/build.sh" -DLODSTREAM_BUILD_TESTS=OFF -DLODSTREAM_BUILD_TOOLS=OFF
out="$root/out/quickstart"
mkdir -p "$out"
"$root/build/lodstream" info "$root/tests/data/sample-room.ply" --work "$out/work"
"$root/build/lodstream" info "$root/tests/data/sample-room.ply" --work "$out/work" --json > "$out/info.json"
echo
echo "quickstart: ingest statistics in $out/info.json, scene store in $out/work/store"

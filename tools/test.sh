#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test (ctest). Tests that need ../shared/data print
# that they were skipped when it is absent.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/install-deps.sh" --test
"$root/tools/build.sh" -DLODSTREAM_BUILD_TESTS=ON -DLODSTREAM_BUILD_TOOLS=ON
cd "$root/build"
ctest --output-on-failure -j "$(nproc)" --timeout 900

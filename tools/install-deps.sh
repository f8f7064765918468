#!/usr/bin/env bash
# Installs lodstream's build and test dependencies from Debian 12 packages, skipping what is present.
# Usage: tools/install-deps.sh [--test]   (--test adds what the test suite needs)
set -euo pipefail
pkgs=(build-essential cmake libembree-dev libtbb-dev libopenmesh-dev libcli11-dev nlohmann-json3-dev libfmt-dev
      libpng-dev)
if [ "${1:-}" = "--test" ]; then pkgs+=(googletest libgtest-dev python3); fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then exit 0; fi
echo "installing: ${missing[*]}"
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"

#!/usr/bin/env bash
# Installs lodstream's build and test dependencies from Debian 12 packages, skipping what is present.
# Usage: tools/install-deps.sh [--test]   (--test adds what the test suite needs)
set -euo pipefail
pkgs=(build-essential cmake libembree-dev libtbb-dev libopenmesh-dev libcli11-dev nlohmann-json3-dev libfmt-dev
      libpng-dev libjpeg-dev libmeshoptimizer-dev libcpp-httplib-dev)
# --test also: MeshLab for the Hausdorff agreement test (tools/meshlab_hausdorff.py runs meshlabserver under
# xvfb-run, which needs xauth; meshlab's only Recommends, chemical-mime-data, is not needed) and Chromium for
# the report.html render check (tools/check_html.py).
if [ "${1:-}" = "--test" ]; then pkgs+=(googletest libgtest-dev python3 meshlab xvfb xauth chromium); fi
# --test also: Slurm and MUNGE, for the one-node cluster tests/slurm_test.sh starts (`lodstream slurm`).
if [ "${1:-}" = "--test" ]; then pkgs+=(slurm-wlm munge); fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# Another apt-get or dpkg may hold the package locks (on a fresh machine, unattended-upgrades does for
# minutes): wait for them, up to $LODSTREAM_APT_WAIT seconds (default 300), saying what is waited for and
# who holds it, and only then fail (exit 75). Held locks are found in /proc/locks, which lists apt's and
# dpkg's fcntl locks (and flock locks) by device and inode and needs neither root nor opening the lock
# files. The wait is repeated before each apt-get call, and apt-get install itself waits as long again
# (DPkg::Lock::Timeout, dpkg's locks) should another process take one between the check and the call.
# LODSTREAM_APT_LOCKS (paths, space-separated) replaces the lock list: for the test
# (tests/install_deps_test.sh), which holds a lock of its own rather than the system's.
apt_wait=${LODSTREAM_APT_WAIT:-300}
read -r -a apt_locks <<< "${LODSTREAM_APT_LOCKS:-/var/lib/dpkg/lock-frontend /var/lib/dpkg/lock /var/lib/apt/lists/lock /var/cache/apt/archives/lock}"

# Prints "LOCK is held by pid N (COMMAND)" for the first lock another process holds; nothing if none is.
lock_holder() {
  [ -r /proc/locks ] || return 0
  local f dev ino key pid name cmd
  for f in "${apt_locks[@]}"; do
    dev=$(stat -L -c '%d' "$f" 2>/dev/null) || continue
    ino=$(stat -L -c '%i' "$f")
    # /proc/locks names a file MAJOR:MINOR:INODE, major and minor in hex (st_dev packs them as glibc's
    # makedev does).
    key=$(printf '%02x:%02x:%s' $(((dev >> 8) & 0xfff)) $(((dev & 0xff) | ((dev >> 12) & 0xfff00))) "$ino")
    pid=$(awk -v k="$key" '$2 != "->" { for (i = 2; i <= NF; ++i) if ($i == k) { print $(i - 1); exit } }' /proc/locks)
    if [ -n "$pid" ] && [ "$pid" != "$$" ]; then
      name=$(cat "/proc/$pid/comm" 2>/dev/null || echo "not visible from here")
      cmd=$(tr '\0' ' ' < "/proc/$pid/cmdline" 2>/dev/null || true)
      echo "$f is held by pid $pid ($name${cmd:+: ${cmd% }})"
      return 0
    fi
  done
}

wait_for_apt_locks() {
  local start=$SECONDS holder said="" last=0
  while holder=$(lock_holder) && [ -n "$holder" ]; do
    local waited=$((SECONDS - start))
    if [ "$waited" -ge "$apt_wait" ]; then
      echo "install-deps: gave up after ${apt_wait} s: $holder; rerun when it has finished (LODSTREAM_APT_WAIT sets the wait in seconds)" >&2
      exit 75
    fi
    if [ "$holder" != "$said" ] || [ $((waited - last)) -ge 30 ]; then
      echo "install-deps: waiting for the package manager: $holder (waited ${waited} s of at most ${apt_wait} s)" >&2
      said=$holder
      last=$waited
    fi
    sleep 1
  done
}

if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  wait_for_apt_locks
  $sudo apt-get -o "DPkg::Lock::Timeout=$apt_wait" update -qq
  wait_for_apt_locks
  $sudo apt-get -o "DPkg::Lock::Timeout=$apt_wait" install -y -qq --no-install-recommends "${missing[@]}"
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

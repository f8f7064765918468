#!/usr/bin/env bash
# tools/install-deps.sh waits for package locks held by another process, says so, and gives up with a clear
# message after $LODSTREAM_APT_WAIT seconds. Runs without root and without the system's locks: the lock
# list is replaced by files of this test (LODSTREAM_APT_LOCKS), held with flock(1) and with fcntl (as apt
# and dpkg take them), and dpkg-query, apt-get and sudo are stand-ins that report one package missing and
# record how apt-get was called.
# Usage: tests/install_deps_test.sh SOURCE_DIR
set -euo pipefail
src=${1:?usage: install_deps_test.sh SOURCE_DIR}
tmp=$(mktemp -d)
holder=""
child=""
cleanup() {
  for p in $holder $child; do kill "$p" 2>/dev/null || true; done
  rm -rf "$tmp"
}
trap cleanup EXIT
failures=0
fail() { echo "FAIL: $*" >&2; failures=$((failures + 1)); }

mkdir "$tmp/bin"
cat > "$tmp/bin/dpkg-query" <<'EOF'
#!/bin/sh
# Every package but cmake is installed.
for last; do :; done
[ "$last" = cmake ] || printf 'install ok installed'
EOF
cat > "$tmp/bin/apt-get" <<EOF
#!/bin/sh
# Records the call, and whether the test's lock was free at that moment.
if flock -n "$tmp/lock-frontend" true; then state=free; else state=held; fi
echo "\$state \$*" >> "$tmp/apt-get.log"
EOF
printf '#!/bin/sh\nexec "$@"\n' > "$tmp/bin/sudo"
chmod +x "$tmp/bin/"*
lock="$tmp/lock-frontend"
touch "$lock"
export PATH="$tmp/bin:$PATH" LODSTREAM_APT_LOCKS="$lock $tmp/lists-lock-never-created"

run() {  # run WAIT: install-deps.sh with LODSTREAM_APT_WAIT=WAIT; sets rc, err, elapsed (seconds)
  rm -f "$tmp/apt-get.log"
  local t0=$SECONDS
  set +e
  LODSTREAM_APT_WAIT=$1 "$src/tools/install-deps.sh" > "$tmp/out" 2> "$tmp/err"
  rc=$?
  set -e
  elapsed=$((SECONDS - t0))
  err=$(cat "$tmp/err")
}

# Starts a process holding $lock (flock or fcntl) for $2 seconds; returns once the lock is held.
hold() {
  rm -f "$tmp/held"
  if [ "$1" = flock ]; then
    # flock(1) takes the lock and waits for its command, whose pid goes into the file "held".
    flock -x "$lock" sh -c "echo \$\$ > '$tmp/held.new'; mv '$tmp/held.new' '$tmp/held'; exec sleep $2" &
  else
    python3 -c "import fcntl, os, time
f = open('$lock', 'w'); fcntl.lockf(f, fcntl.LOCK_EX)
open('$tmp/held.new', 'w').write(''); os.rename('$tmp/held.new', '$tmp/held'); time.sleep($2)" &
  fi
  holder=$!
  for _ in $(seq 200); do
    if [ -e "$tmp/held" ]; then
      child=$(cat "$tmp/held")
      return 0
    fi
    sleep 0.05
  done
  echo "FAIL: the test could not take its lock" >&2
  exit 1
}

# 1. No lock held: no wait, apt-get update and install with apt's own lock timeout.
run 5
[ "$rc" -eq 0 ] || fail "free lock: exit $rc: $err"
[ -z "$err" ] || fail "free lock: unexpected message: $err"
grep -q '^free -o DPkg::Lock::Timeout=5 update -qq$' "$tmp/apt-get.log" || fail "free lock: no apt-get update with the lock timeout: $(cat "$tmp/apt-get.log" 2>/dev/null)"
grep -q '^free -o DPkg::Lock::Timeout=5 install -y -qq --no-install-recommends cmake$' "$tmp/apt-get.log" ||
  fail "free lock: no apt-get install of the missing package: $(cat "$tmp/apt-get.log" 2>/dev/null)"

# 2. A lock held for 2 s (flock, then fcntl): the script says who holds it, waits, then installs.
for kind in flock fcntl; do
  if [ "$kind" = fcntl ] && ! command -v python3 > /dev/null; then
    echo "skipped: the fcntl lock case needs python3"
    continue
  fi
  hold "$kind" 2
  pid=$holder
  run 60
  wait "$holder" 2>/dev/null || true
  holder=""
  child=""
  [ "$rc" -eq 0 ] || fail "$kind lock released: exit $rc: $err"
  echo "$err" | grep -q "^install-deps: waiting for the package manager: $lock is held by pid $pid (" ||
    fail "$kind lock released: no waiting message naming the lock and its holder: $err"
  [ "$elapsed" -ge 1 ] || fail "$kind lock released: did not wait (${elapsed} s)"
  [ "$(grep -c '^free ' "$tmp/apt-get.log" 2>/dev/null)" = 2 ] ||
    fail "$kind lock released: apt-get ran while the lock was held, or not twice: $(cat "$tmp/apt-get.log" 2>/dev/null)"
done

# 3. A lock held longer than the wait: a one-line failure naming the lock and holder, exit 75, no apt-get.
hold flock 60
run 2
[ "$rc" -eq 75 ] || fail "lock kept: exit $rc, expected 75: $err"
echo "$err" | grep -q "^install-deps: gave up after 2 s: $lock is held by pid $holder (flock" ||
  fail "lock kept: no failure message naming the lock and its holder: $err"
[ "$elapsed" -ge 2 ] && [ "$elapsed" -le 10 ] || fail "lock kept: gave up after ${elapsed} s, expected about 2"
[ ! -e "$tmp/apt-get.log" ] || fail "lock kept: apt-get ran: $(cat "$tmp/apt-get.log")"
echo "--- the messages of the last run:"
cat "$tmp/err"

if [ "$failures" -ne 0 ]; then
  echo "$failures check(s) failed" >&2
  exit 1
fi
echo "install-deps lock wait: all checks passed"

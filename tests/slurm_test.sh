#!/bin/bash
# `lodstream slurm` on a one-node Slurm cluster started here (tools/slurm_local_cluster.sh: munged,
# slurmctld and slurmd as root, in a temporary directory): the sample room and, with ../shared/data, a
# 2 M-triangle city from make-scene.sh, simplified as 1, 3 and 4 tasks (grade, cluster, task and merge
# jobs, no prepare job: the tasks take up the shared stages' units; the 3 tasks' run with --ingest-ranges yes, in a fresh work directory, so that an ingest array
# parses 3 byte ranges and the first grade share joins them into the scene store; the others with the
# default, auto, which for these binary inputs submits no ingest array) must give every output file byte
# for byte as one machine's run (manifest.json: equal but for timings,
# peaks and the tasks' list); the tileset passes the 3D Tiles validator when it is installed; a task killed
# with SIGKILL (LODSTREAM_TEST_KILL_AT, just before its summary) fails the run with 137, `lodstream merge`
# then refuses naming it (exit 66), and `lodstream slurm resubmit` reruns it alone to the same bytes;
# likewise an ingest range killed before its segment is complete: no task runs, a prepare by hand refuses
# naming the range (exit 66), and resubmitting reruns that range alone, then the chain.
# The 3 tasks' run checks the grade and cluster arrays' shares and that the tasks took up the clustering
# merge's units; a grade share or a cluster share killed with SIGKILL is run by the next step (a cluster
# share, a task), and the run ends with exit 0 and one machine's bytes.
# `lodstream slurm report` as 3 tasks on the room's levels (and the city's) must give report.html and the
# CSVs byte for byte as one machine's report, and report.json equal but for timings and counters, each
# task tracing its range of the original's primitives; a report task killed with SIGKILL is named by the
# merge (exit 66) and resubmitted alone to the same report; a sampling unit's holder killed before its
# stamp makes the run exit 137, and resubmitting finishes it to the same report.
# Prints "skipped:" and exits 77 when a cluster cannot start here (not root, Slurm or MUNGE missing).
# Usage: slurm_test.sh LODSTREAM_CLI SOURCE_DIR
set -uo pipefail
cli=$1; src=$2
tmp=$(mktemp -d)
cluster=$tmp/cluster
cleanup() { "$src/tools/slurm_local_cluster.sh" stop "$cluster"; rm -rf "$tmp"; }
trap cleanup EXIT
if ! conf=$("$src/tools/slurm_local_cluster.sh" start "$cluster" 2>"$tmp/cluster.err"); then
  echo "skipped: $(cat "$tmp/cluster.err")"
  exit 77
fi
export "$conf"
echo "cluster up ($conf)"
status=0
fail() { echo "FAIL: $*"; status=1; }

# Every file of one machine's output directory $1 is in $2 with the same bytes, and $2 holds no other
# (but its slurm/ directory); manifest.json equal without timings, peaks, reuse and the tasks' list.
same_outputs() {
  local one=$1 out=$2 f n=0
  diff <(cd "$one" && find . -type f ! -path './slurm/*' | sort) <(cd "$out" && find . -type f ! -path './slurm/*' | sort) \
    || { fail "$out: not the same files as $one"; return; }
  while read -r f; do
    [ "$f" = ./manifest.json ] && continue
    cmp -s "$one/$f" "$out/$f" || fail "$out/$f differs from one machine's"
    n=$((n + 1))
  done < <(cd "$one" && find . -type f | sort)
  python3 - "$one/manifest.json" "$out/manifest.json" <<'EOF' || fail "$out/manifest.json differs from one machine's"
import json, sys
def strip(m):
    for k in ("stages", "seconds", "peak_rss_bytes", "work_dir", "shards"):
        m.pop(k, None)
    return m
a, b = (strip(json.load(open(p))) for p in sys.argv[1:])
if a != b:
    for k in a:
        if a.get(k) != b.get(k): print("manifest differs in", k, file=sys.stderr)
    sys.exit(1)
EOF
  echo "  $out: $n files byte-identical to one machine's, manifest equal"
}

run_scene() {
  local name=$1 scene=$2; shift 2
  local work=$tmp/$name-work one=$tmp/$name-one t0 t1 rc
  t0=$(date +%s.%N)
  "$cli" simplify "$scene" -o "$one" --work "$work" --no-space-check "$@" >/dev/null || { fail "$name: one machine's simplify"; return; }
  t1=$(date +%s.%N)
  echo "$name: one machine $(printf '%.1f' "$(echo "$t1 - $t0" | bc)") s"
  for n in 1 3 4; do
    local out=$tmp/$name-$n w=$work ranges=auto extra=()
    # 4 tasks: --chunk-bytes 64K caps the tasks' paged maps at 8 KiB of pages (stream/paged_vertex_map.h),
    # so that their groups drop their pages and read them again (the bytes never depend on it).
    [ "$n" = 4 ] && extra=(--chunk-bytes 64K)
    # 3 tasks: the input parsed as 3 byte ranges (--ingest-ranges yes); else auto, which for these binary
    # PLY inputs is no range array: the first grade share ingests the input as one machine does.
    [ "$n" = 3 ] && w=$tmp/$name-work-ranges ranges=yes
    # 3 tasks: a prepare script left in the output directory by an older build's submission must go.
    [ "$n" = 3 ] && mkdir -p "$out/slurm" && echo "# an older build's prepare array" >"$out/slurm/prepare.sbatch"
    t0=$(date +%s.%N)
    "$cli" slurm simplify "$scene" -o "$out" --work "$w" --shards "$n" --wait --no-space-check --ingest-ranges "$ranges" "$@" \
      "${extra[@]}" >"$tmp/$name-$n.log" 2>&1
    rc=$?
    t1=$(date +%s.%N)
    echo "$name: $n task(s) through Slurm: exit $rc, $(printf '%.1f' "$(echo "$t1 - $t0" | bc)") s"
    [ $rc -eq 0 ] || { fail "$name --shards $n: exit $rc"; cat "$tmp/$name-$n.log" "$out"/slurm/logs/* 2>/dev/null | tail -30; continue; }
    same_outputs "$one" "$out"
    if [ "$n" = 4 ]; then
      python3 -c 'import json,sys; t=json.load(open(sys.argv[1]))["shards"]["tasks"]; d=sum(x["paged_map"]["drops"] for x in t); assert d > 0, d; print("  4 tasks at --chunk-bytes 64K: their paged maps dropped their pages %d times, read %d pages of %d" % (d, sum(x["paged_map"]["pages_read"] for x in t), t[0]["paged_map"]["pages"]))' \
        "$out/manifest.json" || fail "$name: 4 tasks at --chunk-bytes 64K: no paged map dropped its pages"
      [ -e "$out/slurm/ingest.sbatch" ] && fail "$name: --ingest-ranges auto wrote an ingest array for a binary input"
      grep -q "^ingest  job" "$tmp/$name-$n.log" && fail "$name: --ingest-ranges auto submitted an ingest array for a binary input"
    fi
    if [ "$n" = 3 ]; then
      for r in 0 1 2; do [ "$(cat "$out/slurm/status/ingest-$r.rc" 2>/dev/null)" = 0 ] || fail "$name: ingest range $r did not finish"; done
      ls "$w"/ingest-ranges/*.seg >/dev/null 2>&1 && fail "$name: the first grade share did not join the ingest ranges"
      grep -q "range        0 of 3" "$out/slurm/logs/ingest-0.out" || fail "$name: ingest range 0 did not say what it parsed"
      echo "  3 ingest ranges joined by the first grade share: $(grep -h '^range' "$out"/slurm/logs/ingest-*.out | awk '{print $5}' | paste -sd+) bytes parsed"
      # The grade and cluster arrays: every share finished, did its share, and the next step removed them.
      for kind in grade cluster; do
        for r in 0 1 2; do
          [ "$(cat "$out/slurm/status/$kind-$r.rc" 2>/dev/null)" = 0 ] || fail "$name: $kind share $r did not finish"
          grep -q "^$kind *share $r of 3 in [^,]* (then" "$out/slurm/logs/$kind-$r.out" || fail "$name: $kind share $r did not run its share"
        done
        [ -e "$w/$kind-shares" ] && fail "$name: the step after the $kind array left its spent shares"
        echo "  3 $kind shares: $(grep -h "^stage        $kind " "$out"/slurm/logs/$kind-*.out | awk '{print $3 " s"}' | paste -sd' ')"
      done
      # No prepare job: the tasks took up the clustering merge's units (the cluster stage's stamp lists them).
      [ -e "$out/slurm/prepare.sbatch" ] && fail "$name: a prepare script in a simplify chain (an older submission's kept)"
      python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))["value"]["merge_units"]; assert len(v["map"]["seconds"])==3' \
        "$w/cluster.json" || fail "$name: the cluster stage's stamp does not list 3 merge units"
      echo "  3 tasks' cluster stages (the merge's units): $(grep -h "^stage        cluster " "$out"/slurm/logs/task-*.out | awk '{print $3 " s"}' | paste -sd' ')"
    fi
    python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); assert m["shards"]["count"]==int(sys.argv[2]) and len(m["shards"]["tasks"])==int(sys.argv[2])' \
      "$out/manifest.json" "$n" || fail "$name --shards $n: the manifest does not list every task"
  done
}

room=$src/tests/data/sample-room.ply
run_scene room "$room" --tiles --tile-triangles 10000 --obj

# A task killed with SIGKILL just before its summary: the run fails with 137, merge names the task, and
# resubmitting reruns it alone (the finished tasks are not submitted again) to the same bytes.
out=$tmp/room-kill
LODSTREAM_TEST_KILL_AT=task-1.json "$cli" slurm simplify "$room" -o "$out" --work "$tmp/room-work" --shards 3 --wait --no-space-check \
  --tiles --tile-triangles 10000 --obj >"$tmp/kill.log" 2>&1
rc=$?
[ $rc -eq 137 ] || fail "a task killed with SIGKILL: the run exited $rc, not 137"
grep -q "task 1 failed with exit 137" "$tmp/kill.log" || fail "the run does not name the killed task: $(cat "$tmp/kill.log")"
[ -e "$out/manifest.json" ] && fail "a manifest after a killed task"
msg=$("$cli" merge "$out" 2>&1); rc=$?
[ $rc -eq 66 ] || fail "merge with a task missing: exit $rc, not 66"
echo "$msg" | grep -q "task 1 of 3 has not finished" || fail "merge does not name the missing task: $msg"
echo "killed task: run exit 137; merge: $msg"
"$cli" slurm resubmit "$out" --wait >"$tmp/resubmit.log" 2>&1
rc=$?
[ $rc -eq 0 ] || { fail "resubmit: exit $rc"; cat "$tmp/resubmit.log"; }
grep -q "array 1 of 3" "$tmp/resubmit.log" || fail "resubmit did not submit task 1 alone: $(cat "$tmp/resubmit.log")"
same_outputs "$tmp/room-one" "$out"

# The room as 3 tasks through Slurm with LODSTREAM_TEST_KILL_AT=$2, into $tmp/room-$1 (work directory
# $tmp/room-work-$1, output in $tmp/$1.log); sets out and rc.
run_room_killed() {
  out=$tmp/room-$1
  LODSTREAM_TEST_KILL_AT=$2 "$cli" slurm simplify "$room" -o "$out" --work "$tmp/room-work-$1" \
    --shards 3 --wait --no-space-check --tiles --tile-triangles 10000 --obj >"$tmp/$1.log" 2>&1
  rc=$?
}
# What a failed run said, and the ends of its jobs' logs (the test's directory goes with it).
show_run() { cat "$tmp/$1.log"; tail -n 20 "$tmp/room-$1"/slurm/logs/*.out; }

# A grade share and a cluster share killed in one run (both kill points set): the first cluster share
# (afterany) grades share 1 under the lock before it merges the grading shares, a task (afterany) runs
# cluster share 1 itself, and the run ends with exit 0 and one machine's bytes.
run_room_killed kill-shares grade-share-1,cluster-share-1
[ $rc -eq 0 ] || { fail "a grade and a cluster share killed with SIGKILL: the run exited $rc, not 0"; show_run kill-shares; }
[ "$(cat "$out/slurm/status/grade-1.rc" 2>/dev/null)" = 137 ] || fail "grade share 1 was not killed"
[ "$(cat "$out/slurm/status/cluster-1.rc" 2>/dev/null)" = 137 ] || fail "cluster share 1 was not killed"
for log in "$out"/slurm/logs/task-*.out; do
  grep -q "^stage        grade .*(reused" "$log" || fail "the cluster array did not merge the grading shares ($log)"
done
grep -h "^stage        cluster " "$out"/slurm/logs/task-*.out | grep -qv "(reused" || fail "no task clustered"
same_outputs "$tmp/room-one" "$out"
echo "killed grade and cluster shares: run exit $rc, a cluster share graded share 1 and merged, a task ran cluster share 1"

# A weld unit's holder killed just before the unit's stamp (every grading share that runs unit 1 dies
# there, SIGKILL releasing its claim): a share waiting for the unit runs it in turn, and when none is left
# the next step welds under the lock; the run ends with exit 0 and one machine's bytes.
run_room_killed kill-unit unit-1.json
[ $rc -eq 0 ] || { fail "a weld unit's holder killed with SIGKILL: the run exited $rc, not 0"; show_run kill-unit; }
grep -qx 137 "$out"/slurm/status/grade-*.rc || fail "no grading share was killed at weld unit 1"
same_outputs "$tmp/room-one" "$out"
echo "killed weld unit: run exit $rc, grading shares' exits $(cat "$out"/slurm/status/grade-*.rc | tr '\n' ' ')"

# A grading merge unit's holder killed just before the unit's stamp: every clustering share that runs
# unit 1 dies there (SIGKILL releasing its claim), and so does every task, which runs it in turn; the run
# exits 137 with the other units stamped, and `slurm resubmit` (no kill point now; no task finished, so
# the chain from its start) runs unit 1 alone and ends with one machine's bytes.
run_room_killed kill-merge merge-1.json
[ $rc -eq 137 ] || { fail "a grading merge unit's holder killed with SIGKILL: the run exited $rc, not 137"; show_run kill-merge; }
grep -qx 137 "$out"/slurm/status/cluster-*.rc || fail "no clustering share was killed at merge unit 1"
exits=$(cat "$out"/slurm/status/cluster-*.rc "$out"/slurm/status/task-*.rc | tr '\n' ' ')
units=$(ls "$tmp/room-work-kill-merge/grade-merge/" 2>/dev/null | grep -c '^merge-[0-9]*\.json$')
[ -e "$tmp/room-work-kill-merge/grade-merge/merge-1.json" ] && fail "merge unit 1 was stamped"
[ "$units" -eq 2 ] || fail "not the two other merge units stamped: $units"
"$cli" slurm resubmit "$out" --wait >"$tmp/resubmit-merge.log" 2>&1
rc=$?
[ $rc -eq 0 ] || { fail "resubmit after a killed merge unit: exit $rc"; cat "$tmp/resubmit-merge.log"; }
same_outputs "$tmp/room-one" "$out"
[ -e "$tmp/room-work-kill-merge/grade-merge" ] && fail "the grading merge's units outlived the cluster stage"
echo "killed grading merge unit: run exit 137 with $units units stamped, clustering shares' and tasks' exits $exits; resubmitted: exit $rc"

# An ingest range killed just before its segment is complete, in a fresh work directory.
out=$tmp/room-kill-ingest
LODSTREAM_TEST_KILL_AT=range-1-of-3.seg "$cli" slurm simplify "$room" -o "$out" --work "$tmp/room-work-kill" --shards 3 --wait \
  --no-space-check --ingest-ranges yes --tiles --tile-triangles 10000 --obj >"$tmp/kill-ingest.log" 2>&1
rc=$?
[ $rc -eq 137 ] || fail "an ingest range killed with SIGKILL: the run exited $rc, not 137"
grep -q "ingest range 1 failed with exit 137" "$tmp/kill-ingest.log" || fail "the run does not name the killed range: $(cat "$tmp/kill-ingest.log")"
ls "$out"/slurm/status/task-*.rc >/dev/null 2>&1 && fail "the tasks ran after a failed ingest range"
msg=$("$cli" simplify "$room" -o "$out" --work "$tmp/room-work-kill" --shard-prepare --no-space-check 2>&1); rc=$?
[ $rc -eq 66 ] || fail "a prepare with an ingest range missing: exit $rc, not 66"
echo "$msg" | grep -q "range 1 missing" || fail "the prepare does not name the missing range: $msg"
echo "killed ingest range: run exit 137; prepare: $msg"
"$cli" slurm resubmit "$out" --wait >"$tmp/resubmit-ingest.log" 2>&1
rc=$?
[ $rc -eq 0 ] || { fail "resubmit after a killed ingest range: exit $rc"; cat "$tmp/resubmit-ingest.log"; }
grep -q "ingest  job .* (array 1 of 3)" "$tmp/resubmit-ingest.log" || fail "resubmit did not submit range 1 alone: $(cat "$tmp/resubmit-ingest.log")"
same_outputs "$tmp/room-one" "$out"

# The report in $2 is one machine's ($1): report.html and the CSVs byte for byte, report.json equal but
# for timings and counters; every task traced its range of the original, the ranges together all of it
# (performance.original_primitives); prints each task's stages and the merge's time.
same_report() {
  local one=$1 out=$2 f
  diff <(cd "$one" && find . -type f | sort) <(cd "$out" && find . -type f ! -path './slurm/*' | sort) \
    || { fail "$out: not the same files as $one"; return; }
  while read -r f; do
    [ "$f" = ./report.json ] && continue
    cmp -s "$one/$f" "$out/$f" || fail "$out/$f differs from one machine's"
  done < <(cd "$one" && find . -type f | sort)
  python3 - "$one/report.json" "$out/report.json" <<'EOF' || fail "$out/report.json differs from one machine's"
import json, sys
def strip(j):
    for k in ("stages", "seconds", "peak_rss_bytes", "work_dir", "performance", "shards"):
        j.pop(k, None)
    for r in j["runs"]:
        for l in r["levels"]:
            l.pop("seconds", None)
    return j
a, b = (json.load(open(p)) for p in sys.argv[1:])
total = a["performance"]["original_primitives"]
tasks = b["shards"]["tasks"]
for t in tasks:
    print("  task %d: %.2f s, %d of %d primitives traced (%s)" % (t["index"], t["seconds"], t["original_primitives"], total,
          ", ".join("%s %.2f s cpu %.2f s" % (s["name"], s["seconds"], s.get("cpu_seconds", 0)) for s in t["stages"])))
print("  merge: %.2f s" % b["seconds"])
ranges = sum(t["original_primitives"] for t in tasks) == total and all(t["original_primitives"] < total for t in tasks)
if not ranges: print("the tasks did not trace the original by ranges", file=sys.stderr)
sys.exit(0 if strip(a) == strip(b) and ranges else 1)
EOF
  echo "  $out: report.html and CSVs byte-identical to one machine's, report.json equal"
}

# The report of $1's levels ($2: one machine's simplify output) as 3 tasks through Slurm, against one
# machine's report.
run_report() {
  local name=$1 levels=$2 one=$tmp/$1-report-one out=$tmp/$1-report-3 t0 t1 rc; shift 2
  t0=$(date +%s.%N)
  "$cli" report "$levels" -o "$one" --work "$tmp/$name-work" --no-space-check "$@" >/dev/null || { fail "$name: one machine's report"; return; }
  t1=$(date +%s.%N)
  echo "$name report: one machine $(printf '%.1f' "$(echo "$t1 - $t0" | bc)") s"
  t0=$(date +%s.%N)
  "$cli" slurm report "$levels" -o "$out" --work "$tmp/$name-work" --shards 3 --wait --no-space-check "$@" >"$tmp/$name-report.log" 2>&1
  rc=$?
  t1=$(date +%s.%N)
  echo "$name report: 3 tasks through Slurm: exit $rc, $(printf '%.1f' "$(echo "$t1 - $t0" | bc)") s"
  [ $rc -eq 0 ] || { fail "$name slurm report: exit $rc"; cat "$tmp/$name-report.log" "$out"/slurm/logs/* 2>/dev/null | tail -30; return; }
  same_report "$one" "$out"
}
run_report room "$tmp/room-one" --views 8 --resolution 128 --samples 20000

# A report task killed with SIGKILL just before its summary: the run exits 137, `lodstream merge` refuses
# naming it (exit 66), and `slurm resubmit` reruns it alone to one machine's report.
out=$tmp/room-report-kill
LODSTREAM_TEST_KILL_AT=report-task-1.json "$cli" slurm report "$tmp/room-one" -o "$out" --work "$tmp/room-work" --shards 3 \
  --wait --no-space-check --views 8 --resolution 128 --samples 20000 >"$tmp/report-kill.log" 2>&1
rc=$?
[ $rc -eq 137 ] || { fail "a report task killed with SIGKILL: the run exited $rc, not 137"; cat "$tmp/report-kill.log"; }
msg=$("$cli" merge "$out" 2>&1); rc=$?
[ $rc -eq 66 ] || fail "a report merge with task 1 missing: exit $rc, not 66"
echo "$msg" | grep -q "report task 1 of 3 has not finished" || fail "the merge does not name the missing report task: $msg"
"$cli" slurm resubmit "$out" --wait >"$tmp/report-resubmit.log" 2>&1
rc=$?
[ $rc -eq 0 ] || { fail "resubmit after a killed report task: exit $rc"; cat "$tmp/report-resubmit.log"; }
echo "killed report task: merge refused ($msg); resubmitted: exit $rc"
same_report "$tmp/room-report-one" "$out"

# A sampling unit's holder killed just before the unit's stamp (every report task that runs measure unit 1
# dies there, SIGKILL releasing its claim), in a fresh work directory: the run exits 137 with the other
# measure units stamped, and `slurm resubmit` (no kill point now) runs unit 1 and the rest to one machine's
# report.
out=$tmp/room-report-kill-unit
LODSTREAM_TEST_KILL_AT=measure-1.json "$cli" slurm report "$tmp/room-one" -o "$out" --work "$tmp/room-report-work-unit" \
  --shards 3 --wait --no-space-check --views 8 --resolution 128 --samples 20000 >"$tmp/report-kill-unit.log" 2>&1
rc=$?
[ $rc -eq 137 ] || { fail "a sampling unit's holder killed with SIGKILL: the run exited $rc, not 137"; cat "$tmp/report-kill-unit.log"; }
[ -e "$tmp/room-report-work-unit/report-samples/measure/measure-1.json" ] && fail "measure unit 1 was stamped"
units=$(ls "$tmp/room-report-work-unit/report-samples/measure/" 2>/dev/null | grep -c '^measure-[0-9]*\.json$')
[ "$units" -eq 2 ] || fail "not the two other measure units stamped: $units"
"$cli" slurm resubmit "$out" --wait >"$tmp/report-resubmit-unit.log" 2>&1
rc=$?
[ $rc -eq 0 ] || { fail "resubmit after a killed sampling unit: exit $rc"; cat "$tmp/report-resubmit-unit.log"; }
echo "killed sampling unit: run exit 137 with $units measure units stamped; resubmitted: exit $rc"
same_report "$tmp/room-report-one" "$out"

validator=${LODSTREAM_TILES_VALIDATOR:-${TMPDIR:-/tmp}/3d-tiles-validator}
if command -v node >/dev/null 2>&1 && [ -f "$validator/build/main.js" ] && [ -f "$validator/.installed" ]; then
  node "$validator/build/main.js" --tilesetFile "$tmp/room-3/tiles/tileset.json" --reportFile "$tmp/validator.json" >/dev/null 2>&1
  counts=$(node -e 'const r=require(process.argv[1]);console.log(r.numErrors,r.numWarnings)' "$tmp/validator.json" 2>/dev/null)
  echo "3d-tiles-validator on the 3-task tileset: errors warnings = $counts"
  [ "$counts" = "0 0" ] || fail "the 3-task tileset does not validate"
else
  echo "notice: the 3D Tiles validator is not installed (tools/install_tiles_tools.sh): the tiles are checked byte for byte only"
fi

make_scene=$src/../shared/data/tools/make-scene.sh
if [ -x "$make_scene" ] || [ -f "$make_scene" ]; then
  if bash "$make_scene" 2 1 "$tmp/city.ply" >/dev/null 2>&1; then
    run_scene city "$tmp/city.ply" --tiles
    run_report city "$tmp/city-one" --views 8 --resolution 256 --samples 100000
  else
    fail "make-scene.sh 2 1 failed"
  fi
else
  echo "skipped: the 2 M-triangle city (../shared/data absent)"
fi
[ $status -eq 0 ] && echo "ok"
exit $status

#!/bin/bash
# Sharded simplify against one machine (README "Running on a cluster", figures): one machine's run, then on
# the same work directory the prepare step, the N tasks one after the other and the merge, each timed
# (wall, CPU, peak RSS from /usr/bin/time -v), and the outputs compared byte for byte (cmp; manifest.json
# aside). Tasks run one at a time so that each one's figures are its own on this shared machine; the wall
# time N machines would take is then prepare + the slowest task + merge.
# usage: tools/bench_distributed.sh [--bin LODSTREAM] [--input FILE] [--shards N] [--work DIR] [--out DIR]
#                                   [--prepare-memory SIZE] -- [simplify options, e.g. --memory 1G]
# Defaults: build/lodstream, /work/scenes/city-18.ply (read only), 8 shards, a fresh work and output
# directory under $TMPDIR, --prepare-memory = the simplify options' --memory. Steps: one (one machine's
# whole run), one-emit (the same again on its work directory: emit and write only), prepare (the shared
# stages, reused from one's, plus the representatives), task-I, merge.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=$root/build/lodstream; input=/work/scenes/city-18.ply; shards=8; work=""; out=""; prepare_memory=""
while [ $# -gt 0 ]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --input) input=$2; shift 2 ;;
    --shards) shards=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --prepare-memory) prepare_memory=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
opts=("$@")
if [ -z "$work" ] || [ -z "$out" ]; then tmp=$(mktemp -d); fi
[ -n "$work" ] || work=$tmp/work
[ -n "$out" ] || out=$tmp/out
logs=$out/logs  # each step's output and /usr/bin/time -v report
mkdir -p "$logs"
prep_opts=("${opts[@]}")
[ -n "$prepare_memory" ] && prep_opts+=(--memory "$prepare_memory")

# timed NAME CMD...: one line "NAME wall_s cpu_s peak_MiB exit"
timed() {
  local name=$1; shift
  local rc=0
  /usr/bin/time -v -o "$logs/$name.time" "$@" >"$logs/$name.log" 2>&1 || rc=$?
  awk -v n="$name" -v rc=$rc '
    /Elapsed \(wall clock\)/ { split($NF, t, ":"); w = (length(t) == 3) ? t[1] * 3600 + t[2] * 60 + t[3] : t[1] * 60 + t[2] }
    /User time/ { u = $NF } /System time/ { s = $NF } /Maximum resident/ { m = $NF / 1024 }
    END { printf "%-12s %9.1f %9.1f %9.0f %5d\n", n, w, u + s, m, rc }' "$logs/$name.time" | tee -a "$out/bench.txt"
  [ $rc -eq 0 ] || { tail -5 "$logs/$name.log" >&2; exit $rc; }
}

echo "input $input, $shards shards, options: ${opts[*]:-}; $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$out/bench.txt"
printf "%-12s %9s %9s %9s %5s\n" step wall_s cpu_s peak_MiB exit | tee -a "$out/bench.txt"
# An output directory that already holds one machine's run (same work directory) keeps it: only the
# sharded steps are run again.
if [ -f "$out/one/manifest.json" ]; then
  echo "one machine's run reused from $out/one" | tee -a "$out/bench.txt"
else
  timed one "$bin" simplify "$input" -o "$out/one" --work "$work" --no-space-check "${prep_opts[@]}"
fi
# The one machine's run leaves the shared stages in the work directory: prepare then only adds the
# representatives. Its stages are in one/manifest.json.
python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print("  one machine stages:", ", ".join("%s %.1f s" % (s["name"], s["seconds"]) for s in m["stages"]))' \
  "$out/one/manifest.json" | tee -a "$out/bench.txt"
# The same run again on the same work directory: its stages up to cluster are reused, so this is what
# one machine spends after them (emit and write), to set against the tasks.
timed one-emit "$bin" simplify "$input" -o "$out/one-emit" --work "$work" --no-space-check "${opts[@]}"
timed prepare "$bin" simplify "$input" -o "$out/sharded" --work "$work" --shard-prepare --no-space-check "${prep_opts[@]}"
for ((i = 0; i < shards; i++)); do
  timed "task-$i" "$bin" simplify "$input" -o "$out/sharded" --work "$work" --shard "$i/$shards" --no-space-check "${opts[@]}"
done
timed merge "$bin" merge "$out/sharded"
same=1
for f in $(cd "$out/one" && find . -type f ! -name manifest.json ! -path './logs/*' | sort); do
  cmp -s "$out/one/$f" "$out/sharded/$f" || { echo "DIFFERS: $f" | tee -a "$out/bench.txt"; same=0; }
done
[ $same -eq 1 ] && echo "outputs byte-identical (cmp of every file but manifest.json)" | tee -a "$out/bench.txt"
echo "results in $out/bench.txt; work directory $work"

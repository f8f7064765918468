#!/usr/bin/env bash
# The prepare step of a sharded simplify (README "Running on a cluster") as one job, this build's against a
# peer build's (the code before, say), on the same input: the N grading shares and the N clustering shares
# run once (`simplify --shard-grade I/N`, then `--shard-cluster I/N`), their work directory is saved, and
# before each prepare job (`--shard-prepare --cluster-shards N`) it is restored. Prints each job's wall, CPU
# and peak (/usr/bin/time), its stages, and this build's units (stream/units.h: the clustering merge's,
# the block boxes', the cells by vertex's: each step's slowest unit, what N nodes would wait for, and all
# units' seconds); every cluster map, cell info, block box and cells-by-vertex file must be the peer's bytes.
# Usage: tools/bench_prepare_units.sh INPUT N [--bin BIN] [--peer-bin BIN] [--out DIR] [-- simplify options]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 2 ] || { sed -n 2,9p "$0" >&2; exit 64; }
input=$1; n=$2; shift 2
bin=$root/build/lodstream; peer=""; out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --peer-bin) peer=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
opts=("$@")
[ -n "$out" ] || out=$(mktemp -d)
rm -rf "$out/work" "$out/saved" "$out/ref" "$out/sharded"; mkdir -p "$out/logs" "$out/ref"
echo "input $input, $n shares, options: ${opts[*]:-none}; $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$out/bench.txt"
common=(simplify "$input" -o "$out/sharded" --work "$out/work" --no-space-check "${opts[@]}")
for i in $(seq 0 $((n - 1))); do "$bin" "${common[@]}" --shard-grade "$i/$n" >"$out/logs/grade-$i.out"; done
for i in $(seq 0 $((n - 1))); do "$bin" "${common[@]}" --shard-cluster "$i/$n" >"$out/logs/cluster-$i.out"; done
cp -r "$out/work" "$out/saved"
outputs() { (cd "$out/work" && ls cells-*.map cells-*.info block-bounds.f64 vertex-cells-*.bits 2>/dev/null); }
# prepare NAME BIN: one prepare job from the saved work directory
prepare() {
  local name=$1 b=$2
  rm -rf "$out/work"; cp -r "$out/saved" "$out/work"; sync
  /usr/bin/time -f "%e %U %S %M" -o "$out/logs/$name.time" "$b" "${common[@]}" --shard-prepare --cluster-shards "$n" \
    >"$out/logs/$name.out" 2>&1 || { echo "$name failed:"; tail "$out/logs/$name.out"; exit 1; }
  read -r wall user sys kb <"$out/logs/$name.time"
  printf "%-6s wall %7.2f s  cpu %7.2f s  peak %7.1f MiB\n" "$name" "$wall" "$(echo "$user + $sys" | bc)" "$(echo "$kb / 1024" | bc -l)" | tee -a "$out/bench.txt"
  grep '^stage' "$out/logs/$name.out" | grep -v reused | sed 's/^/  /' | tee -a "$out/bench.txt"
}
if [ -n "$peer" ]; then
  prepare peer "$peer"
  for f in $(outputs); do cp "$out/work/$f" "$out/ref/"; done
fi
prepare this "$bin"
python3 - "$out/work" <<'PY' | tee -a "$out/bench.txt"
import json, os, sys
work = sys.argv[1]
for stamp, key in (("cluster.json", "merge_units"), ("block-bounds.json", "units"), ("shard-vertex-cells.json", "units")):
    try:
        v = json.load(open(os.path.join(work, stamp)))["value"][key]
    except (OSError, KeyError, ValueError, TypeError):
        continue
    for phase, d in v.items():
        if isinstance(d, dict) and "seconds" in d:
            print("  %s %s: %d units, slowest %.2f s, all %.2f s" % (stamp, phase, len(d["seconds"]), max(d["seconds"]), sum(d["seconds"])))
PY
if [ -n "$peer" ]; then
  same=1
  for f in $(outputs); do cmp -s "$out/ref/$f" "$out/work/$f" || { echo "DIFFERS: $f" | tee -a "$out/bench.txt"; same=0; }; done
  [ $same -eq 1 ] && echo "every map, info, box and cells-by-vertex file the peer's bytes" | tee -a "$out/bench.txt"
fi
echo "results in $out/bench.txt"

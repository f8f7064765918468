#!/usr/bin/env bash
# The clustering pass as N shares (stream/cluster_shares.h) against one machine's cluster stage, on one
# input: one machine's simplify (its cluster stage's time is the peer), then on a second work directory
# holding the same stages before clustering (copied) the N shares one after another
# (`simplify --shard-cluster I/N`), then the merge (`--shard-prepare --cluster-shards N`, whose cluster
# stage is the merge; its later stages are not counted). Every cluster map and cell info must be one
# machine's bytes (cmp). Prints each step's wall, CPU and peak (/usr/bin/time), each share's levels (split:
# halo in cells, tries, records held and own; whole: cells), and the sums.
# Usage: tools/bench_cluster_shares.sh INPUT N [--bin BIN] [--out DIR] [-- simplify options, e.g. --memory 1G]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 2 ] || { sed -n 2,9p "$0" >&2; exit 64; }
input=$1; n=$2; shift 2
bin=$root/build/lodstream; out=""
while [ $# -gt 0 ]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
opts=("$@")
[ -n "$out" ] || out=$(mktemp -d)
rm -rf "$out/one" "$out/w1" "$out/w2" "$out/sh"; mkdir -p "$out/logs"
echo "input $input, $n shares, options: ${opts[*]:-none}; $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$out/bench.txt"
timed() {  # timed NAME COMMAND...: one line of wall, CPU and peak
  local name=$1; shift
  /usr/bin/time -f "%e %U %S %M" -o "$out/logs/$name.time" "$@" >"$out/logs/$name.out" 2>&1 || { echo "$name failed:"; tail "$out/logs/$name.out"; exit 1; }
  read -r wall user sys kb <"$out/logs/$name.time"
  printf "%-10s wall %7.2f s  cpu %7.2f s  peak %7.1f MiB\n" "$name" "$wall" "$(echo "$user + $sys" | bc)" "$(echo "$kb / 1024" | bc -l)" | tee -a "$out/bench.txt"
}
timed one "$bin" simplify "$input" -o "$out/one" --work "$out/w1" --no-space-check "${opts[@]}"
python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print("  one machine stages:", ", ".join("%s %.2f s" % (s["name"], s["seconds"]) for s in m["stages"]))' \
  "$out/one/manifest.json" | tee -a "$out/bench.txt"
# The second work directory: the stages before clustering, as the first share would leave them.
mkdir -p "$out/w2"
cp -r "$out/w1/store" "$out/w2/"
for f in "$out"/w1/*; do
  case "$(basename "$f")" in cells-*|cluster.json|store|vertex-cells-*|shard-*|block-*|*.lock) ;; *) cp -r "$f" "$out/w2/" ;; esac
done
for i in $(seq 0 $((n - 1))); do
  timed "share-$i" "$bin" simplify "$input" -o "$out/sh" --work "$out/w2" --shard-cluster "$i/$n" --no-space-check "${opts[@]}"
done
# The shares' stamps (their figures), kept: the merge removes the spent shares.
cp "$out"/w2/cluster-shares/share-*.json "$out/logs/"
timed merge "$bin" simplify "$input" -o "$out/sh" --work "$out/w2" --shard-prepare --cluster-shards "$n" --no-space-check "${opts[@]}"
grep -h "stage        cluster" "$out/logs/merge.out" | sed 's/^/  merge /' | tee -a "$out/bench.txt"
same=1
for f in "$out"/w1/cells-*; do cmp -s "$f" "$out/w2/$(basename "$f")" || { echo "DIFFERS: $(basename "$f")" | tee -a "$out/bench.txt"; same=0; }; done
[ $same -eq 1 ] && echo "cluster maps and infos byte-identical to one machine's (cmp of every cells-L.map and .info)" | tee -a "$out/bench.txt"
python3 - "$out" "$n" <<'PY' | tee -a "$out/bench.txt"
import json, os, sys
out, n = sys.argv[1], int(sys.argv[2])
one = {s["name"]: s for s in json.load(open(os.path.join(out, "one", "manifest.json")))["stages"]}
walls, cpus = [], []
for i in range(n):
    w, u, s, kb = open(os.path.join(out, "logs", "share-%d.time" % i)).read().split()[:4]
    walls.append(float(w)); cpus.append(float(u) + float(s))
    levels = json.load(open(os.path.join(out, "logs", "share-%d.json" % i)))["value"]["levels"]
    print("  share %d: %s" % (i, "; ".join(
        ("level %d whole: %d cells" % (l["level"], l["cells"])) if "cells" in l else
        ("level %d: halo %.0f cells, %d tries, held %d, own %d (%.3f)" % (l["level"], l["halo_cells"], l["tries"], l["held"], l["own"], l["held"] / max(l["own"], 1)))
        for l in levels)))
w, u, s, kb = open(os.path.join(out, "logs", "merge.time")).read().split()[:4]
print("shares: slowest %.2f s, sum %.2f s wall, %.2f CPU s; one machine's cluster stage %.2f s" % (max(walls), sum(walls), sum(cpus), one["cluster"]["seconds"]))
PY
echo "results in $out/bench.txt"

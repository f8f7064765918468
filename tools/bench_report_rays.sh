#!/usr/bin/env bash
# Benchmark: the report's ray throughput (issue 14), `lodstream report` of the sample room's levels
# (tests/data/sample-room.ply simplified with the defaults) with 32 views of 512 × 512 pixels and 1000
# Hausdorff samples, so that the ray casts dominate. Runs alternate between the builds given, N rounds, so
# that every build sees the same machine load; per run it records report.json's "performance" figures:
# rays cast, the seconds spent casting them (the original's chunks and the levels'), rays per second, and
# the CPU seconds other processes used meanwhile. Then the medians per build and --supersample.
#
# usage: tools/bench_report_rays.sh [--runs N] [--build DIR] [--baseline DIR] [--supersample "1 3"]
#                                   [--threads T] [--work DIR]
#   --build DIR:     this build (default build); its report runs once per --supersample value
#   --baseline DIR:  another build (say main's, before the pixel rule: it has no --supersample and casts
#                    one ray a pixel), run once per round with its own defaults
#   --threads T:     report --threads (default 0 = all)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
runs=3; build=build; baseline=""; ks="1 3"; threads=0; work=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --baseline) baseline=$2; shift 2 ;;
    --supersample) ks=$2; shift 2 ;;
    --threads) threads=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench_report_rays: unknown option $1" >&2; exit 64 ;;
  esac
done
[[ "$build" = /* ]] || build="$root/$build"
cli="$build/lodstream"
[ -x "$cli" ] || { echo "bench_report_rays: $cli not found (build first)" >&2; exit 66; }
if [ -n "$baseline" ]; then
  [[ "$baseline" = /* ]] || baseline="$root/$baseline"
  [ -x "$baseline/lodstream" ] || { echo "bench_report_rays: $baseline/lodstream not found" >&2; exit 66; }
fi
work=${work:-$(mktemp -d "${TMPDIR:-/tmp}/bench_report_rays.XXXXXX")}
mkdir -p "$work"
lods="$work/room"
[ -f "$lods/manifest.json" ] || "$cli" simplify "$root/tests/data/sample-room.ply" -o "$lods" --progress none >/dev/null
others_cpu() { awk '/^cpu / {print $2+$3+$4+$7+$8+$9}' /proc/stat; }
results="$work/runs.jsonl"; : > "$results"
one() {  # label binary [extra report options...]
  local label=$1 bin=$2; shift 2
  local out="$work/out-$label"
  rm -rf "$out"
  local before t0 t1 after
  before=$(others_cpu); t0=$(date +%s.%N)
  "$bin" report "$lods" -o "$out" --views 32 --resolution 512 --samples 1000 --threads "$threads" --progress none \
    "$@" > "$out.log"
  t1=$(date +%s.%N); after=$(others_cpu)
  python3 - "$out/report.json" "$label" "$before" "$after" "$t0" "$t1" "$(getconf CLK_TCK)" "$(nproc)" >> "$results" <<'PY'
import json, sys
rep = json.load(open(sys.argv[1])); p = rep["performance"]
wall = float(sys.argv[6]) - float(sys.argv[5])
# Other processes' CPU: the machine's busy time minus at most our own (wall x cores, an upper bound).
busy = (float(sys.argv[4]) - float(sys.argv[3])) / float(sys.argv[7])
print(json.dumps({"label": sys.argv[2], "rays": p["rays"], "ray_seconds": p["ray_seconds"],
                  "rays_per_second": p["rays_per_second"], "wall_s": wall,
                  "machine_busy_cores": busy / wall,
                  "mismatch": [l["silhouette"]["mismatch_fraction"] for r in rep["runs"] for l in r["levels"]]}))
PY
  tail -n 1 "$results"
}
for ((r = 1; r <= runs; r++)); do
  [ -n "$baseline" ] && one baseline "$baseline/lodstream"
  for k in $ks; do one "k$k" "$cli" --supersample "$k"; done
done
python3 - "$results" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
labels = []
for r in rows:
    if r["label"] not in labels: labels.append(r["label"])
base = None
print(f"{'build':10} {'runs':>4} {'rays':>12} {'ray s (med)':>12} {'M rays/s (med)':>15} {'range':>14} {'busy cores':>10}")
for lab in labels:
    rs = [r for r in rows if r["label"] == lab]
    rate = [r["rays_per_second"] / 1e6 for r in rs]
    sec = statistics.median(r["ray_seconds"] for r in rs)
    med = statistics.median(rate)
    if lab == "baseline": base = med
    print(f"{lab:10} {len(rs):4} {rs[0]['rays']:12} {sec:12.2f} {med:15.2f} {min(rate):6.2f}-{max(rate):<7.2f} "
          f"{statistics.median(r['machine_busy_cores'] for r in rs):10.1f}")
if base:
    for lab in labels:
        if lab != "baseline":
            med = statistics.median(r["rays_per_second"] for r in rows if r["label"] == lab) / 1e6
            print(f"{lab}: {med / base:.2f} x the baseline's rays/s")
PY

#!/usr/bin/env bash
# Benchmark of the cluster stage alone: speed, peak memory and bytes per cell. Reuses a work directory
# that one full `lodstream simplify ... --work DIR` has prepared (store, weight index), removes the cluster
# stage's stamp and runs the same command again, so that ingest and grade are reused and the process
# clusters; it is stopped (SIGTERM) as soon as the stage's stamp (cluster.json) appears. Per run: the
# stage's wall time (process start to stamp), its CPU time (user + system of the process, which on a
# shared machine says more than the wall time) and the process's peak RSS (VmHWM, sampled every 0.05 s
# until the stamp appears; ingest and grade, reused, add next to nothing). Binaries given with --bin are run in alternation, run
# after run, so that a busy machine disturbs them alike; medians are printed.
#
# Bytes per cell at the stage's peak = (peak − fixed) / cells over all levels, where "fixed" is the peak
# of the same run at cell sizes so large that each level has a handful of cells (what the stage holds
# that does not grow with cells: the binary, TBB, buffers, windows); pass --fixed-sizes to set them.
#
# usage: tools/bench_cluster.sh --work DIR --input FILE --bin A [--bin B ...] [--runs 3]
#                               [--fixed-sizes 1e6,2e6] [-- extra simplify options, e.g. --memory 1G]
usage() { sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; }
set -euo pipefail

work="" input="" runs=3 fixed_sizes="1e6,2e6" bins=() extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --work) work="$2"; shift 2 ;;
    --input) input="$2"; shift 2 ;;
    --bin) bins+=("$2"); shift 2 ;;
    --runs) runs="$2"; shift 2 ;;
    --fixed-sizes) fixed_sizes="$2"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench_cluster: unknown option $1" >&2; usage >&2; exit 64 ;;
  esac
done
[ -n "$work" ] && [ -n "$input" ] && [ ${#bins[@]} -gt 0 ] || { usage >&2; exit 64; }
[ -f "$work/grade.json" ] || { echo "bench_cluster: run lodstream simplify --work $work once first" >&2; exit 66; }
out=$(mktemp -d "${TMPDIR:-/tmp}/bench_cluster.XXXXXX")
trap 'rm -rf "$out"' EXIT

# CPU seconds (user + system) of a process so far.
cpu_of() { awk -v t="$(getconf CLK_TCK)" '{print ($14 + $15) / t}' "/proc/$1/stat" 2> /dev/null || echo 0; }

# One clustering run: prints "seconds peak_bytes cells_total cpu_seconds".
cluster_once() {
  local bin="$1"; shift
  rm -f "$work/cluster.json"
  local t0 pid hwm=0 now
  t0=$(date +%s.%N)
  "$bin" simplify "$input" -o "$out/o" --work "$work" --progress none "$@" > "$out/log" 2>&1 &
  pid=$!
  while [ ! -f "$work/cluster.json" ]; do
    if ! kill -0 "$pid" 2> /dev/null; then echo "bench_cluster: $bin stopped before clustering:" >&2; cat "$out/log" >&2; exit 1; fi
    now=$(awk '/VmHWM/ {print $2 * 1024}' "/proc/$pid/status" 2> /dev/null || echo 0)
    # A sample counts only if the stamp was still absent after it: the emit stage starts right after.
    [ ! -f "$work/cluster.json" ] && [ -n "$now" ] && [ "$now" -gt "$hwm" ] && hwm=$now
    sleep 0.05
  done
  local t1 cpu
  t1=$(date +%s.%N)
  cpu=$(cpu_of "$pid")
  kill "$pid" 2> /dev/null || true
  wait "$pid" 2> /dev/null || true
  local cells
  cells=$(python3 -c "import json,sys; print(sum(json.load(open(sys.argv[1]))['value']['cells']))" "$work/cluster.json")
  echo "$(echo "$t1 - $t0" | bc) $hwm $cells $cpu"
}

median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

echo "input $input, work $work, options: ${extra[*]:-(defaults)}; load $(cut -d' ' -f1-3 /proc/loadavg)"
for bin in "${bins[@]}"; do : > "$out/$(echo "$bin" | md5sum | cut -c1-8).runs"; done
for ((r = 1; r <= runs; ++r)); do
  for bin in "${bins[@]}"; do
    line=$(cluster_once "$bin" "${extra[@]}")
    echo "run $r $bin: $line (seconds, peak bytes, cells, CPU seconds)"
    echo "$line" >> "$out/$(echo "$bin" | md5sum | cut -c1-8).runs"
  done
done
for bin in "${bins[@]}"; do
  f="$out/$(echo "$bin" | md5sum | cut -c1-8).runs"
  fixed=$(cluster_once "$bin" "${extra[@]}" --cell-sizes "$fixed_sizes" | cut -d' ' -f2)
  secs=$(cut -d' ' -f1 "$f" | median)
  peak=$(cut -d' ' -f2 "$f" | median)
  cells=$(cut -d' ' -f3 "$f" | head -1)
  cpu=$(cut -d' ' -f4 "$f" | median)
  echo "$bin: median ${secs} s (${cpu} CPU-s), peak $((peak >> 20)) MiB, fixed $((fixed >> 20)) MiB, cells $cells," \
       "$(( (peak - fixed) / cells )) bytes per cell at the peak"
done
rm -f "$work/cluster.json"

#!/bin/bash
# The work directory's size over a run (issue 13.4): runs `BIN simplify INPUT -o OUT --work WORK [options]`
# and samples the blocks in use under WORK (`du -s --block-size=1`) every 0.5 s, keeping the sample with
# the most bytes with its entries (top-level names, as the manifest's `work_dir` counts them; every sample,
# with the names present, goes to OUT.samples). Prints the
# peak and the final size with their entries and their ratio to the input's size, the run's wall time and
# the load average at the start and the end, and the output directory's peak and final size. WORK and OUT are removed first.
# usage: bench_workdir.sh --bin BIN --input FILE --work DIR --out DIR [-- simplify options]
set -euo pipefail
bin= input= work= out=
while [ $# -gt 0 ]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --input) input=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "usage: $0 --bin BIN --input FILE --work DIR --out DIR [-- simplify options]" >&2; exit 64 ;;
  esac
done
[ -n "$bin" ] && [ -n "$input" ] && [ -n "$work" ] && [ -n "$out" ] || { echo "$0: --bin, --input, --work and --out are required" >&2; exit 64; }
rm -rf "$work" "$out" "$out.samples"
mkdir -p "$work"
input_bytes=$(stat -c %s "$input")
# (An empty directory, as at the run's start, gives nothing: du of a bare `*` fails, which under pipefail
# would end the script.)
entries() { { (cd "$1" && du -s --block-size=1 -- * 2>/dev/null | sort -k2) || true; } | awk '{printf "%s=%.0f ", $2, $1}'; }
echo "load at start: $(cut -d' ' -f1-3 /proc/loadavg)"
start=$(date +%s.%N)
"$bin" simplify "$input" -o "$out" --work "$work" "$@" > "$out.log" 2>&1 &
pid=$!
peak=0 peak_entries= out_peak=0
while kill -0 "$pid" 2>/dev/null; do
  b=$(du -s --block-size=1 "$work" 2>/dev/null | cut -f1 || true)
  if [ "${b:-0}" -gt "$peak" ]; then peak=$b; peak_entries=$(entries "$work"); fi
  o=$(du -s --block-size=1 "$out" 2>/dev/null | cut -f1 || true)
  [ "${o:-0}" -gt "$out_peak" ] && out_peak=$o
  echo "$(date +%s.%N) ${b:-0} $(ls "$work" 2>/dev/null | tr '\n' ' ')" >> "$out.samples"
  sleep 0.5
done
wait "$pid" && rc=0 || rc=$?
end=$(date +%s.%N)
final=$(du -s --block-size=1 "$work" | cut -f1)
[ "$final" -gt "$peak" ] && peak=$final && peak_entries=$(entries "$work")
echo "load at end: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "exit $rc, wall $(echo "$end - $start" | bc) s, input $input_bytes bytes"
awk -v p="$peak" -v f="$final" -v i="$input_bytes" 'BEGIN { printf "peak %.0f bytes (%.3fx), final %.0f bytes (%.3fx)\n", p, p / i, f, f / i }'
echo "output directory: peak $out_peak bytes, final $(du -s --block-size=1 "$out" | cut -f1) bytes"
echo "at the peak: $peak_entries"
echo "at the end: $(entries "$work")"
exit "$rc"

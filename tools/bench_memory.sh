#!/usr/bin/env bash
# Benchmark of the memory contract (../shared/DESIGN.md "Bounded memory"): runs `lodstream simplify` on one
# scene under each given --memory and checks that the run either finishes with its peak within the cap, or
# stops with exit 64 ("needs more memory than --memory allows") without passing it. The peak is the child's
# ru_maxrss as this parent sees it (its VmHWM, which lodstream never resets: the figure /usr/bin/time -v
# prints); a finished run's manifest.json holds the same figure and the sampled per-stage peaks. A large scene is the point:
# `../shared/data/tools/make-scene.sh 18 1 city18.ply` (193 M triangles, 4.1 GB) takes 2–3 minutes a run.
#
# usage: tools/bench_memory.sh --scene FILE [--memory 1G,3G] [--build build] [--work DIR]
#                              [-- extra simplify options, e.g. --cell-sizes 0.4,2.4,21,62,183]
# Prints one line per budget (outcome, wall time, per-stage peaks, the run's peak) and exits 1 if
# any run went past its cap or failed otherwise.
usage() { sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; }
set -euo pipefail

scene="" budgets="1G,3G" build="build" work="" extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) scene="$2"; shift 2 ;;
    --memory) budgets="$2"; shift 2 ;;
    --build) build="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench_memory: unknown option $1" >&2; usage >&2; exit 64 ;;
  esac
done
[ -n "$scene" ] || { usage >&2; exit 64; }
[ -f "$scene" ] || { echo "bench_memory: no scene at $scene" >&2; exit 66; }
here=$(cd "$(dirname "$0")/.." && pwd)
bin="$here/$build/lodstream"
[ -x "$bin" ] || { echo "bench_memory: build $build first ($bin is missing)" >&2; exit 64; }
[ -n "$work" ] || work=$(mktemp -d "${TMPDIR:-/tmp}/bench_memory.XXXXXX")
mkdir -p "$work"
echo "scene   $scene ($(du -h "$scene" | cut -f1))"
echo "work    $work"
echo "options ${extra[*]:-(defaults)}"

status=0
IFS=, read -r -a list <<< "$budgets"
for budget in "${list[@]}"; do
  out="$work/out-$budget"
  rm -rf "$out" "$work/jobs-$budget"
  mkdir -p "$work/jobs-$budget"
  python3 - "$budget" "$out" "$work/run-$budget.log" "$bin" simplify "$scene" -o "$out" --memory "$budget" \
      --work "$work/jobs-$budget" --progress none "${extra[@]}" <<'EOF' || status=1
import json, os, re, resource, subprocess, sys, time
budget, out, log, cmd = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
units = {'K': 1 << 10, 'M': 1 << 20, 'G': 1 << 30, 'T': 1 << 40}
m = re.fullmatch(r'(\d+)([KMGT]?)', budget)
cap = int(m.group(1)) * units.get(m.group(2), 1)
t0 = time.time()
with open(log, 'w') as f:
    p = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
# This script's only child: its peak resident set, as the kernel reports it to the parent.
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
wall = time.time() - t0
mib = lambda b: f'{b / 2**20:.0f}'
text = open(log).read()
if p.returncode == 0:
    man = json.load(open(os.path.join(out, 'manifest.json')))
    stages = ' '.join(f"{s['name']} {mib(s['peak_rss_bytes'])}" for s in man['stages'])
    over = peak > cap
    print(f"--memory {budget}: finished in {wall:.0f} s; peak {mib(peak)} MiB (manifest {mib(man['peak_rss_bytes'])});"
          f" sampled stage peaks (MiB): {stages}"
          f"{'  OVER THE CAP' if over else ''}")
    sys.exit(1 if over else 0)
last = text.strip().splitlines()[-1] if text.strip() else ''
refused = p.returncode == 64 and 'needs' in last and '--memory' in last
over = peak > cap
print(f"--memory {budget}: exit {p.returncode} after {wall:.0f} s; peak {mib(peak)} MiB"
      f"{'  OVER THE CAP' if over else ''}\n  {last}")
sys.exit(0 if refused and not over else 1)
EOF
done
exit $status

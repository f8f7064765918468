#!/usr/bin/env bash
# Benchmark for issue 16.6: what vertex colours cost simplify, and GLB ingest beside cat and PLY ingest.
#   1. tools/recolor_scene.cpp (built here with g++) writes, from a make-scene.sh PLY, the same scene
#      with one colour per object (OUT-colors.ply) and the same scene as a GLB (OUT.glb);
#   2. bench_ingest (build/bench_ingest) runs `cat` and `lodstream info` on the PLY and the GLB,
#      alternately, --runs times each: medians and throughputs;
#   3. `lodstream simplify --memory M` (default 1G) on the plain and the coloured PLY, alternately (plain first), --runs
#      times each, under nice: wall and CPU seconds (user + system of the child) of the whole run and the
#      emit stage's seconds from manifest.json; medians and the coloured / plain ratios of each pair.
# The machine is shared: the ratios of runs made back to back are the figure to quote, not the times.
#
# usage: tools/bench_colors.sh [--runs N] [--memory 1G] [--scene /work/scenes/city-9.ply] [--build build]
#                              [--work DIR] [--skip-ingest] [--skip-simplify] [--no-nice]
# --no-nice: run at normal priority (on a machine crowded by other jobs, niced runs barely progress; CPU
# seconds, the figure to quote, hardly depend on it).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
runs=3
memory=1G
scene=/work/scenes/city-9.ply
build=build
work=""
skip_ingest=0
skip_simplify=0
nice=nice
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --memory) memory=$2; shift 2 ;;
    --scene) scene=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --skip-ingest) skip_ingest=1; shift ;;
    --skip-simplify) skip_simplify=1; shift ;;
    --no-nice) nice=env; shift ;;
    *) sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 64 ;;
  esac
done
[[ $build = /* ]] || build=$root/$build
[[ -n $work ]] || work=$(mktemp -d "${TMPDIR:-/tmp}/bench_colors.XXXXXX")
mkdir -p "$work"
echo "work: $work"

g++ -O2 -std=c++20 -o "$work/recolor_scene" "$root/tools/recolor_scene.cpp"
stem=$work/$(basename "${scene%.ply}")
[[ -s $stem-colors.ply ]] || nice "$work/recolor_scene" ply "$scene" "$stem-colors.ply"
[[ -s $stem.glb ]] || nice "$work/recolor_scene" glb "$scene" "$stem.glb"

if [[ $skip_ingest = 0 ]]; then
  echo "== ingest: cat and lodstream info, PLY and GLB of the same scene"
  $nice "$build/bench_ingest" --runs "$runs" --lodstream "$build/lodstream" "$scene" "$stem.glb" | tee "$work/ingest.txt"
fi

if [[ $skip_simplify = 0 ]]; then
  echo "== simplify: plain and coloured PLY, alternately"
  python3 - "$build/lodstream" "$scene" "$stem-colors.ply" "$work" "$runs" "$memory" "$nice" <<'EOF'
import json, os, resource, statistics, subprocess, sys, time
lod, plain, colored, work, runs, memory, nice = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]), sys.argv[6], sys.argv[7]
def run(inp, tag, i):
    out = os.path.join(work, f"out-{tag}")
    subprocess.run(["rm", "-rf", out], check=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.monotonic()
    subprocess.run([nice, lod, "simplify", inp, "-o", out, "--memory", memory, "--progress", "none"], check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.monotonic() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    m = json.load(open(os.path.join(out, "manifest.json")))
    emit = sum(s["seconds"] for s in m["stages"] if s["name"] == "emit")
    with open("/proc/loadavg") as f:
        load = float(f.read().split()[0])
    r = {"tag": tag, "run": i, "wall": wall, "cpu": cpu, "emit": emit, "load": load}
    print(json.dumps(r), flush=True)
    with open(os.path.join(work, "simplify.jsonl"), "a") as f:
        f.write(json.dumps(r) + "\n")
    return r
pairs = []
for i in range(runs):
    pairs.append((run(plain, "plain", i), run(colored, "colors", i)))
med = statistics.median
for k in ("wall", "cpu", "emit"):
    p = [a[k] for a, _ in pairs]; c = [b[k] for _, b in pairs]; r = [b[k] / a[k] for a, b in pairs]
    print(f"{k:5}: plain median {med(p):.2f} s, colours median {med(c):.2f} s, ratio per pair "
          + ", ".join(f"{x:.3f}" for x in r) + f", median ratio {med(r):.3f}")
EOF
fi

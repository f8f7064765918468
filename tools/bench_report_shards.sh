#!/bin/bash
# `report` as N tasks against one machine's report, on one machine (tasks one after another, no
# scheduler): wall and CPU seconds of one machine's measure, of each task's stages and of the merge, the
# primitives of the original each task traced, the bytes the tasks hand to the merge, the sampling units'
# times, what N nodes would wait for (the slowest sampling units, the slowest task's measure, the merge),
# and whether the outputs are one machine's bytes. CPU
# seconds are the figure to quote on a busy machine. The levels are made once (kept in WORKDIR/lods).
# Usage: tools/bench_report_shards.sh LODSTREAM SCENE WORKDIR [N] [report options...]
set -euo pipefail
cli=$1 scene=$2 dir=$3 n=${4:-3}
shift 4 || shift $#
opts=("$@")
[ ${#opts[@]} -gt 0 ] || opts=(--views 8 --resolution 256 --samples 100000)
mkdir -p "$dir"
[ -f "$dir/lods/manifest.json" ] ||
  "$cli" simplify "$scene" -o "$dir/lods" --work "$dir/work" --no-space-check --progress none >/dev/null
rm -rf "$dir/one" "$dir/sharded"
"$cli" report "$dir/lods" -o "$dir/one" --work "$dir/work" --no-space-check --progress none "${opts[@]}" >/dev/null
# A fresh work directory for the tasks' shared stages (the store is linked, not ingested again).
rm -rf "$dir/task-work" && mkdir -p "$dir/task-work"
cp -al "$dir/work/store" "$dir/task-work/store"
handed=0
for ((i = 0; i < n; i++)); do
  "$cli" report "$dir/lods" -o "$dir/sharded" --work "$dir/task-work" --shard "$i/$n" --no-space-check --progress none "${opts[@]}" >/dev/null
done
handed=$(du -sb "$dir/sharded/shards" | cut -f1)
"$cli" merge "$dir/sharded" --progress none >/dev/null
python3 - "$dir/one" "$dir/sharded" "$n" "$handed" "$dir/task-work/report-samples" <<'PY'
import filecmp, glob, json, os, sys
one, sharded, n, handed, units = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
a, b = (json.load(open(os.path.join(d, "report.json"))) for d in (one, sharded))
def stage(stages, name):
    return next(((s["seconds"], s.get("cpu_seconds", 0)) for s in stages if s["name"] == name), (0, 0))
w, c = stage(a["stages"], "measure")
lw, lc = stage(a["stages"], "load")
prims = a["performance"].get("original_primitives", 0)
print("one machine: %.2f s; load %.2f s wall %.2f s cpu; measure %.2f s wall %.2f s cpu; %d chunk scenes of the original (%d chunks), peak %.0f MiB"
      % (a["seconds"], lw, lc, w, c, a["performance"]["chunk_scenes"], a["performance"]["original_chunks"], a["peak_rss_bytes"] / 2**20))
def phases(ps):
    names = ("chunk_build", "rays_on_original", "queries_on_original", "level_build", "rays_on_level", "queries_on_level")
    cpu = {p["name"]: 0.0 for p in ps}
    for p in ps: cpu[p["name"]] += p["cpu_seconds"]
    return ", ".join("%s %.2f" % (k, cpu.get(k, 0)) for k in names)
print("  one machine's measure cpu by part: " + phases(a["performance"]["phases"]))
tasks = b["shards"]["tasks"]
total_cpu = 0
for t in tasks:
    mw, mc = stage(t["stages"], "measure")
    tl, tlc = stage(t["stages"], "load")
    total_cpu += mc + tlc
    print("task %d of %d: %.2f s, load (with the sampling units it ran) %.2f s cpu %.2f s, measure %.2f s wall %.2f s cpu "
          "(%.0f%% of one machine's measure cpu), %d of %d primitives traced, peak %.0f MiB"
          % (t["index"], n, t["seconds"], tl, tlc, mw, mc, 100 * mc / c if c else 0, t.get("original_primitives", prims), prims,
             t["peak_rss_bytes"] / 2**20))
    if "phases" in t: print("  by part: " + phases(t["phases"]))
# The sampling units the tasks took up (here one after another: the first task ran them all).
def unit_times(kind):
    return [json.load(open(f))["value"] for f in sorted(glob.glob(os.path.join(units, kind, kind + "-*.json")))]
measure, sample = unit_times("measure"), unit_times("sample")
vertex = json.load(open(os.path.join(units, "vertices.json"))) if os.path.exists(os.path.join(units, "vertices.json")) else {"seconds": 0, "cpu_seconds": 0}
sampling = 0
if measure:
    span = lambda us: "%.2f-%.2f s" % (min(u["seconds"] for u in us), max(u["seconds"] for u in us))
    sampling = max(u["seconds"] for u in measure) + vertex["seconds"] + max(u["seconds"] for u in sample)
    print("sampling units (%d): measure %s, the vertex samples %.2f s, sample %s; on %d nodes %.2f s (one machine draws them in its load, %.2f s)"
          % (len(measure), span(measure), vertex["seconds"], span(sample), len(measure), sampling, lw))
mw, mc = stage(b["stages"], "merge")
print("merge: %.2f s (merge stage %.2f s cpu %.2f s), peak %.0f MiB; the tasks handed it %.1f MB"
      % (b["seconds"], mw, mc, b["peak_rss_bytes"] / 2**20, handed / 1e6))
slowest_measure = max(stage(t["stages"], "measure")[0] for t in tasks)
print("on %d nodes: sampling units + slowest measure + merge = %.2f s against one machine's %.2f s; tasks' load and measure cpu summed: %.2f s against %.2f s"
      % (n, sampling + slowest_measure + b["seconds"], a["seconds"], total_cpu, c + lc))
files = sorted(f for f in os.listdir(one) if f != "report.json")
same = all(filecmp.cmp(os.path.join(one, f), os.path.join(sharded, f), shallow=False) for f in files)
strip = lambda j: {k: v for k, v in j.items() if k not in ("stages", "seconds", "peak_rss_bytes", "work_dir", "performance", "shards")}
for j in (a, b):
    for r in j["runs"]:
        for l in r["levels"]: l.pop("seconds", None)
print("outputs: %s" % ("one machine's bytes (%d files), report.json equal" % len(files) if same and strip(a) == strip(b) else "DIFFER"))
PY

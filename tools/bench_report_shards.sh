#!/bin/bash
# `report` as N tasks against one machine's report, on one machine (tasks one after another, no
# scheduler): wall and CPU seconds of one machine's measure, of each task's stages and of the merge, and
# whether the outputs are one machine's bytes. CPU seconds are the figure to quote on a busy machine.
# Usage: tools/bench_report_shards.sh LODSTREAM SCENE WORKDIR [N] [report options...]
set -euo pipefail
cli=$1 scene=$2 dir=$3 n=${4:-3}
shift 4 || shift $#
opts=("$@")
[ ${#opts[@]} -gt 0 ] || opts=(--views 8 --resolution 256 --samples 100000)
mkdir -p "$dir"
"$cli" simplify "$scene" -o "$dir/lods" --work "$dir/work" --no-space-check --progress none >/dev/null
"$cli" report "$dir/lods" -o "$dir/one" --work "$dir/work" --no-space-check --progress none "${opts[@]}" >/dev/null
for ((i = 0; i < n; i++)); do
  "$cli" report "$dir/lods" -o "$dir/sharded" --work "$dir/work" --shard "$i/$n" --no-space-check --progress none "${opts[@]}" >/dev/null
done
"$cli" merge "$dir/sharded" --progress none >/dev/null
python3 - "$dir/one" "$dir/sharded" "$n" <<'PY'
import filecmp, json, os, sys
one, sharded, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
a, b = (json.load(open(os.path.join(d, "report.json"))) for d in (one, sharded))
def stage(j, name):
    return next(((s["seconds"], s.get("cpu_seconds", 0)) for s in j["stages"] if s["name"] == name), (0, 0))
w, c = stage(a, "measure")
print("one machine: %.2f s, measure %.2f s wall %.2f s cpu" % (a["seconds"], w, c))
tasks = b["shards"]["tasks"]
for t in tasks:
    m = next(s for s in t["stages"] if s["name"] == "measure")
    l = next(s for s in t["stages"] if s["name"] == "load")
    print("task %d of %d: %.2f s, load %.2f s cpu %.2f s, measure %.2f s wall %.2f s cpu (%.0f%% of one machine's measure cpu)"
          % (t["index"], n, t["seconds"], l["seconds"], l.get("cpu_seconds", 0), m["seconds"], m.get("cpu_seconds", 0),
             100 * m.get("cpu_seconds", 0) / c if c else 0))
mw, mc = stage(b, "merge")
print("merge: %.2f s (merge stage %.2f s cpu %.2f s)" % (b["seconds"], mw, mc))
files = sorted(f for f in os.listdir(one) if f != "report.json")
same = all(filecmp.cmp(os.path.join(one, f), os.path.join(sharded, f), shallow=False) for f in files)
strip = lambda j: {k: v for k, v in j.items() if k not in ("stages", "seconds", "peak_rss_bytes", "work_dir", "performance", "shards")}
for j in (a, b):
    for r in j["runs"]:
        for l in r["levels"]: l.pop("seconds", None)
print("outputs: %s" % ("one machine's bytes (%d files), report.json equal" % len(files) if same and strip(a) == strip(b) else "DIFFER"))
PY

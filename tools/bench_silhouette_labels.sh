#!/usr/bin/env bash
# Silhouette labels against none at matched triangle counts and matched switching distances (README
# "Silhouette labels"): for a model, simplify without labels (default levels), then with labels aiming at
# the same triangle counts (--target-triangles, ±15 %), and report both on the same views from the
# baseline's switching distances (report --lod ... --switch-distances). Prints one row per level and run.
# Usage: tools/bench_silhouette_labels.sh MODEL [INTERVAL_PX] [FACTOR] [LEVELS] [VIEWS]
# Environment: LODSTREAM (the CLI; default build/lodstream), OUT (scratch directory; default a temporary one).
set -euo pipefail
model=$1 interval=${2:-5} factor=${3:-0.5} levels=${4:-3} views=${5:-16}
cli=${LODSTREAM:-build/lodstream}
out=${OUT:-$(mktemp -d)}
mkdir -p "$out"
"$cli" simplify "$model" -o "$out/base" --levels "$levels" --no-glb --progress none >/dev/null
read -r targets distances < <(python3 - "$out/base/manifest.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
print(",".join(str(l["triangles"]) for l in m["levels"]), ",".join(repr(l["switch_distance"]) for l in m["levels"]))
PY
)
"$cli" simplify "$model" -o "$out/labels" --target-triangles "$targets" --silhouette-interval "$interval" \
  --silhouette-factor "$factor" --no-glb --progress none >/dev/null
for run in base labels; do
  lods=()
  for f in "$out/$run"/lod*.ply; do lods+=(--lod "$f"); done
  "$cli" report --original "$model" "${lods[@]}" --switch-distances "$distances" --views "$views" \
    -o "$out/report-$run" --html-views 0 --samples 50000 --progress none >/dev/null
done
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
print("run     level  triangles  sil_p95_px  sil_mean_px  mismatch  hausdorff_mean  hausdorff_max")
for run in ("base", "labels"):
    r = json.load(open(f"{out}/report-{run}/report.json"))["runs"][0]["levels"]
    for i, l in enumerate(r):
        s = l["silhouette"]
        print(f"{run:7} {i:5}  {l['triangles']:9}  {s['p95_px']:10.3f}  {s['mean_px']:11.3f}  {s['mismatch_fraction']:8.4f}"
              f"  {l['hausdorff']['mean']:14.6g}  {l['hausdorff']['max']:13.6g}")
PY

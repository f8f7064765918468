#!/usr/bin/env bash
# Figures for `lodstream grid --cylindrical` (README "grid --cylindrical"): the three busts of
# ../shared/data/scans (Nefertiti about Z, the ogre and the bunny about Y) scanned by build/scan_cylindrical
# at 512 x 512, then subdivided at tolerances given as fractions of each scan's largest radius, with the
# default split (greatest) and gaps (extra-vertices), and with --merge. For each: polygons and triangles
# against the raw grid (one quad, two triangles, per cell with four returns), the measured max and RMS
# radius error (summary.json: along each sample's ray, on the written float vertices), and the seconds of
# the "subdivide" + "index" stages (median of --runs).
#
# usage: tools/bench_grid_cylindrical.sh [--build build] [--data ../shared/data] [--fractions 0.001,0.005,0.02]
#                                        [--runs 3] [--work DIR]
# Prints a markdown table (also WORK/table.md).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
build=build
data="$root/../shared/data"
fractions=0.001,0.005,0.02
runs=3
work=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) build=$2; shift 2 ;;
    --data) data=$2; shift 2 ;;
    --fractions) fractions=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
[[ "$build" = /* ]] || build="$root/$build"
[[ -x "$build/scan_cylindrical" && -x "$build/lodstream" ]] || { echo "build $build first (LODSTREAM_BUILD_TOOLS=ON)" >&2; exit 66; }
[[ -d "$data/scans" ]] || { echo "skipped: $data/scans is absent" >&2; exit 0; }
work=${work:-$(mktemp -d)}
mkdir -p "$work"

{
  echo "| model | grid | tolerance (% of largest radius) | variant | polygons | triangles | raw quads / triangles | triangles kept | max radius error | RMS | seconds |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
} > "$work/table.md"

for spec in nefertiti:z ogre:y stanford-bunny:y; do
  model=${spec%%:*}
  axis=${spec##*:}
  "$build/scan_cylindrical" "$data/scans/$model.obj" "$work/$model" --axis "$axis" > "$work/$model.scan.txt"
  step=$(sed -n 's/.*--height-step \([^ ]*\) (PGM: --z-scale \([^)]*\)).*/\1/p' "$work/$model.scan.txt")
  scale=$(sed -n 's/.*--height-step \([^ ]*\) (PGM: --z-scale \([^)]*\)).*/\2/p' "$work/$model.scan.txt")
  rmax=$(sed -n 's/.*largest radius \([^ ]*\).*/\1/p' "$work/$model.scan.txt")
  for f in ${fractions//,/ }; do
    tol=$(python3 -c "print('%.9g' % ($f * $rmax))")
    for variant in default merge; do
      extra=()
      [[ $variant = merge ]] && extra=(--merge)
      for ((r = 0; r < runs; ++r)); do
        "$build/lodstream" grid "$work/$model.pgm" -o "$work/out-$model-$f-$variant-$r" --cylindrical --axis "$axis" \
          --height-step "$step" --z-scale "$scale" --tolerance "$tol" "${extra[@]}" --no-obj --no-ply > /dev/null
      done
      python3 - "$work" "$model" "$f" "$variant" "$runs" "$tol" >> "$work/table.md" <<'EOF'
import json, statistics, sys
work, model, f, variant, runs, tol = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4], int(sys.argv[5]), sys.argv[6]
ss = [json.load(open(f"{work}/out-{model}-{sys.argv[3]}-{variant}-{r}/summary.json")) for r in range(runs)]
s = ss[0]
secs = statistics.median(sum(x["seconds"] for x in t["stages"] if x["name"] in ("subdivide", "index")) for t in ss)
c = s["cylinder"]
cells = s["rect_polygons"]  # not the raw count: computed below from the grid
raw_cells = c["columns"] * (c["rows"] - 1) - s["hole_cells"] if c["closed"] else (c["columns"] - 1) * (c["rows"] - 1) - s["hole_cells"]
print(f"| {model} | {s['input']['width']} x {s['input']['height']} ({c['rows']} rows kept) | {100 * f:g} ({float(tol):.4g}) | {variant} "
      f"| {s['polygons']:,} | {s['triangles']:,} | {raw_cells:,} / {2 * raw_cells:,} | {100 * s['triangles'] / (2 * raw_cells):.1f} % "
      f"| {s['max_radius_error']:.4g} | {s['rms_radius_error']:.3g} | {secs:.3f} |")
EOF
    done
  done
done
cat "$work/table.md"

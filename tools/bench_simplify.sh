#!/usr/bin/env bash
# Benchmark: `lodstream simplify` (five LOD levels, out of core) against two peers that each make ONE
# level of about the size of lodstream's level 0 from the same file, in the same run:
#   - meshopt_simplifySloppy (meshoptimizer, in core; tools/peer_sloppy.cpp, build target peer_sloppy),
#     target = level 0's triangle count; its time includes loading the file;
#   - MeshLab's "Simplification: Clustering Decimation" (uniform grid, absolute cell size = level 0's
#     cell size) via meshlabserver under xvfb-run (Debian packages meshlab, xvfb, xauth).
# Every command runs under /usr/bin/time -v (wall time, max RSS); the table shows medians over the runs
# and the ratio peer time / lodstream time. The scene is read once first so every run finds it in the
# page cache. Each run also reports the CPU seconds other processes used meanwhile ("others"): on a
# shared machine, runs with a large value are disturbed and should be repeated.
#
# usage: tools/bench_simplify.sh [--runs N] [--memory 1G] [--scene /work/scenes/city.ply] [--build build]
#                                [--target-triangles N --cell-size C] [--work DIR] [--keep]
#                                [--skip-lodstream] [--skip-sloppy] [--skip-meshlab]
# --target-triangles / --cell-size: fallback targets for the peers, used while `lodstream simplify`
#   is not available (or fails, or with --skip-lodstream).
# --work DIR: where outputs and logs go (default: a new directory under ${TMPDIR:-/tmp}); it keeps
#   runs.jsonl (one JSON object per tool and run) and summary.json. --keep keeps the meshes written.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
runs=3
memory=1G
scene=/work/scenes/city.ply
build=build
fallback_tris=""
fallback_cell=""
work=""
keep=0
skip_lod=0
skip_sloppy=0
skip_meshlab=0

usage() { sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --memory) memory=$2; shift 2 ;;
    --scene) scene=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --target-triangles) fallback_tris=$2; shift 2 ;;
    --cell-size) fallback_cell=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    --skip-lodstream) skip_lod=1; shift ;;
    --skip-sloppy) skip_sloppy=1; shift ;;
    --skip-meshlab) skip_meshlab=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench_simplify: unknown argument $1" >&2; usage >&2; exit 2 ;;
  esac
done
[[ "$build" = /* ]] || build="$root/$build"
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || { echo "bench_simplify: --runs must be a positive integer" >&2; exit 2; }

if [[ ! -f "$scene" ]]; then
  if [[ "$scene" == /work/scenes/city.ply && -x /work/shared/data/tools/make-scene.sh ]]; then
    echo "building $scene with make-scene.sh 9 1 ..." >&2
    mkdir -p /work/scenes
    /work/shared/data/tools/make-scene.sh 9 1 "$scene"
  else
    echo "bench_simplify: scene $scene not found" >&2; exit 1
  fi
fi

if [[ ! -x /usr/bin/time ]]; then
  if [[ $(id -u) -eq 0 ]]; then
    echo "installing package time ..." >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends time >/dev/null ||
      { apt-get update >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends time >/dev/null; }
  fi
  [[ -x /usr/bin/time ]] || { echo "bench_simplify: /usr/bin/time missing (apt-get install time)" >&2; exit 1; }
fi

if [[ -z "$work" ]]; then work=$(mktemp -d "${TMPDIR:-/tmp}/bench_simplify.XXXXXX"); fi
mkdir -p "$work"
work=$(cd "$work" && pwd)
results="$work/runs.jsonl"
: > "$results"

have_sloppy=1
if [[ $skip_sloppy -eq 1 ]]; then have_sloppy=0
elif [[ ! -x "$build/peer_sloppy" ]]; then
  echo "meshopt_simplifySloppy: not available ($build/peer_sloppy missing: install libmeshoptimizer-dev and rebuild)" >&2
  have_sloppy=0
fi
have_meshlab=1
if [[ $skip_meshlab -eq 1 ]]; then have_meshlab=0
elif ! command -v meshlabserver >/dev/null || ! command -v xvfb-run >/dev/null; then
  echo "meshlab: not available (apt-get install -y --no-install-recommends meshlab xvfb xauth)" >&2
  have_meshlab=0
fi
stdbuf_cmd=()
command -v stdbuf >/dev/null && stdbuf_cmd=(stdbuf -oL -eL)

# cpu_busy: CPU seconds the whole machine has been busy (all cores, /proc/stat, USER_HZ = 100).
cpu_busy() { awk '/^cpu /{printf "%.2f\n", ($2 + $3 + $4 + $7 + $8 + $9) / 100}' /proc/stat; }

# time_fields FILE: prints "WALL_S MAXRSS_BYTES CPU_S" (CPU_S = user + system) from a /usr/bin/time -v report.
time_fields() {
  python3 - "$1" <<'EOF'
import re, sys
t = open(sys.argv[1], errors="replace").read()
m = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", t)
wall = 0.0
if m:
    for part in m.group(1).split(":"):
        wall = wall * 60 + float(part)
r = re.search(r"Maximum resident set size \(kbytes\): (\d+)", t)
u = re.search(r"User time \(seconds\): ([\d.]+)", t)
s = re.search(r"System time \(seconds\): ([\d.]+)", t)
cpu = (float(u.group(1)) if u else 0.0) + (float(s.group(1)) if s else 0.0)
print(f"{wall:.3f} {int(r.group(1)) * 1024 if r else 0} {cpu:.2f}")
EOF
}

# record TOOL RUN WALL RSS TRIS CPU BUSY [EXTRA_JSON]
# CPU: the tool's user + system seconds; BUSY: the whole machine's busy CPU seconds meanwhile; their
# difference, other_cpu_s, is what other processes used: well above 0 means the run was disturbed.
record() {
  python3 - "$@" >> "$results" <<'EOF'
import json, sys
tool, run, wall, rss, tris, cpu, busy = sys.argv[1:8]
d = {"tool": tool, "run": int(run), "wall_s": float(wall), "peak_rss_bytes": int(rss),
     "triangles_out": int(tris) if tris not in ("", "None") else None,
     "cpu_s": float(cpu), "other_cpu_s": round(max(0.0, float(busy) - float(cpu)), 2)}
if len(sys.argv) > 8 and sys.argv[8]:
    d.update(json.loads(sys.argv[8]))
print(json.dumps(d))
EOF
}
other_of() { python3 -c 'import sys; print(f"{max(0.0, float(sys.argv[1]) - float(sys.argv[2])):.1f}")' "$1" "$2"; }
busy_since() { python3 -c 'import sys; print(f"{float(sys.argv[2]) - float(sys.argv[1]):.2f}")' "$1" "$(cpu_busy)"; }

echo "scene   $scene ($(du -h "$scene" | cut -f1))"
echo "work    $work"
echo "runs    $runs"
echo "warming the page cache ..."
cat "$scene" > /dev/null

lod_note_printed=0
for run in $(seq 1 "$runs"); do
  echo "--- run $run/$runs"
  target_tris="$fallback_tris"
  cell="$fallback_cell"

  # lodstream simplify (five levels)
  if [[ $skip_lod -eq 0 ]]; then
    out="$work/lodstream_out"
    rm -rf "$out"
    b0=$(cpu_busy)
    set +e
    /usr/bin/time -v -o "$work/lodstream.time" "$build/lodstream" simplify "$scene" -o "$out" \
      --memory "$memory" --progress none > "$work/lodstream.log" 2>&1
    rc=$?
    set -e
    busy=$(busy_since "$b0")
    if [[ $rc -eq 0 && -f "$out/manifest.json" ]]; then
      read -r wall rss cpu < <(time_fields "$work/lodstream.time")
      # level 0 = the finest level; its triangle count and cell size are the peers' targets
      lod_json=$(python3 - "$out/manifest.json" <<'EOF'
import json, sys
m = json.load(open(sys.argv[1]))
levels = m.get("levels", m) if isinstance(m, dict) else m
if isinstance(levels, dict):
    levels = [dict(v, level=int(k)) if isinstance(v, dict) else v for k, v in levels.items()]
lv = [l for l in levels if isinstance(l, dict)]
l0 = next((l for l in lv if l.get("level") == 0), lv[0])
print(json.dumps({"level0_triangles": int(l0["triangles"]), "level0_cell_size": float(l0["cell_size"]),
                  "levels": [{"level": l.get("level", i), "cell_size": l.get("cell_size"),
                              "triangles": l.get("triangles")} for i, l in enumerate(lv)]}))
EOF
)
      target_tris=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["level0_triangles"])' "$lod_json")
      cell=$(python3 -c 'import json,sys; print(repr(json.loads(sys.argv[1])["level0_cell_size"]))' "$lod_json")
      record lodstream "$run" "$wall" "$rss" "$target_tris" "$cpu" "$busy" "$lod_json"
      echo "lodstream simplify: ${wall} s (cpu ${cpu} s, others $(other_of "$busy" "$cpu") s), $((rss / 1048576)) MiB, level 0: $target_tris triangles, cell $cell"
    else
      if [[ $lod_note_printed -eq 0 ]]; then
        echo "lodstream simplify: not available (exit $rc; see $work/lodstream.log)"
        lod_note_printed=1
      fi
    fi
  fi
  if [[ -z "$target_tris" || -z "$cell" ]]; then
    echo "bench_simplify: no targets for the peers: lodstream simplify gave none and --target-triangles / --cell-size are not both set" >&2
    exit 1
  fi

  # meshopt_simplifySloppy, in core, one level
  if [[ $have_sloppy -eq 1 ]]; then
    b0=$(cpu_busy)
    set +e
    /usr/bin/time -v -o "$work/sloppy.time" "$build/peer_sloppy" "$scene" "$target_tris" \
      --out "$work/sloppy.ply" > "$work/sloppy.json" 2> "$work/sloppy.log"
    rc=$?
    set -e
    busy=$(busy_since "$b0")
    if [[ $rc -eq 0 ]]; then
      read -r wall rss cpu < <(time_fields "$work/sloppy.time")
      line=$(tail -n 1 "$work/sloppy.json")
      tris=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["triangles_out"])' "$line")
      record meshopt_simplifySloppy "$run" "$wall" "$rss" "$tris" "$cpu" "$busy" \
        "$(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print(json.dumps({k: d[k] for k in ("load_s","simplify_s","write_s","total_s","target_triangles")}))' "$line")"
      echo "meshopt_simplifySloppy: ${wall} s (cpu ${cpu} s, others $(other_of "$busy" "$cpu") s), $((rss / 1048576)) MiB, $tris triangles (target $target_tris) $line"
    else
      echo "meshopt_simplifySloppy: failed (exit $rc; see $work/sloppy.log)"
    fi
    [[ $keep -eq 1 ]] || rm -f "$work/sloppy.ply"
  fi

  # MeshLab clustering decimation, one level, absolute cell size
  if [[ $have_meshlab -eq 1 ]]; then
    mlx="$work/clustering.mlx"
    cat > "$mlx" <<EOF
<!DOCTYPE FilterScript>
<FilterScript>
 <filter name="Simplification: Clustering Decimation">
  <Param type="RichAbsPerc" value="$cell" min="0" max="1e+09" name="Threshold" description="Cell Size" tooltip="The size of the cell of the clustering grid (absolute units)."/>
  <Param type="RichBool" value="false" name="Selected" description="Affect only selected faces" tooltip="If selected the filter affect only the selected faces"/>
 </filter>
</FilterScript>
EOF
    rm -f "$work/meshlab.ply"
    b0=$(cpu_busy)
    t0=$(date +%s.%N)
    set +e
    # Each output line gets the seconds since t0, to separate the loading from the filter + save.
    /usr/bin/time -v -o "$work/meshlab.time" xvfb-run -a "${stdbuf_cmd[@]}" meshlabserver -i "$scene" \
      -o "$work/meshlab.ply" -s "$mlx" 2>&1 |
      python3 -u -c '
import sys, time
t0 = float(sys.argv[1])
for l in sys.stdin:
    print(f"{time.time() - t0:9.3f} {l}", end="", flush=True)' "$t0" > "$work/meshlab.log"
    rc=${PIPESTATUS[0]}
    set -e
    busy=$(busy_since "$b0")
    read -r wall rss cpu < <(time_fields "$work/meshlab.time")
    parsed=$(python3 - "$work/meshlab.log" <<'EOF'
import json, re, sys
load = None; tris = None; vin = None
for l in open(sys.argv[1], errors="replace"):
    m = re.match(r"\s*([\d.]+) Mesh .* loaded has (\d+) vn (\d+) fn", l)
    if m: load = float(m.group(1)); vin = int(m.group(2))
    m = re.match(r"\s*([\d.]+) Mesh .* saved as .* \((\d+) vn (\d+) fn\)", l)
    if m: tris = int(m.group(3))
print(json.dumps({"load_s": load, "triangles_out": tris, "cell_size": None}))
EOF
)
    tris=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["triangles_out"])' "$parsed")
    load=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["load_s"])' "$parsed")
    if [[ $rc -eq 0 && "$tris" != "None" ]]; then
      record meshlab_clustering "$run" "$wall" "$rss" "$tris" "$cpu" "$busy" "{\"load_s\": ${load/None/null}, \"cell_size\": $cell}"
      echo "meshlab clustering: ${wall} s (loaded after ${load} s; cpu ${cpu} s, others $(other_of "$busy" "$cpu") s), $((rss / 1048576)) MiB, $tris triangles (cell $cell)"
    else
      echo "meshlab clustering: failed (exit $rc; see $work/meshlab.log)"
    fi
    [[ $keep -eq 1 ]] || rm -f "$work/meshlab.ply"
  fi
done

python3 - "$results" "$work/summary.json" <<'EOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
tools = []
for r in rows:
    if r["tool"] not in tools:
        tools.append(r["tool"])
def med(vals):
    vals = [v for v in vals if v is not None]
    return statistics.median(vals) if vals else None
summary = {}
for t in tools:
    rs = [r for r in rows if r["tool"] == t]
    summary[t] = {"runs": len(rs), "wall_s": med([r["wall_s"] for r in rs]),
                  "peak_rss_mb": med([r["peak_rss_bytes"] / 1048576 for r in rs]),
                  "triangles_out": med([r["triangles_out"] for r in rs]),
                  "all_wall_s": [r["wall_s"] for r in rs],
                  "all_peak_rss_mb": [round(r["peak_rss_bytes"] / 1048576, 1) for r in rs],
                  "all_other_cpu_s": [r.get("other_cpu_s") for r in rs]}
    if any("load_s" in r for r in rs):
        summary[t]["load_s"] = med([r.get("load_s") for r in rs])
lod = summary.get("lodstream", {}).get("wall_s")
print()
print(f"{'tool':<24} {'runs':>4} {'wall s':>9} {'peak RSS MB':>12} {'triangles out':>14} {'time / lodstream':>17}")
for t in tools:
    s = summary[t]
    ratio = f"{s['wall_s'] / lod:.2f}x" if lod and t != "lodstream" else ("1.00x" if lod else "n/a")
    s["time_ratio_to_lodstream"] = (s["wall_s"] / lod) if lod else None
    tri = f"{int(s['triangles_out']):,}" if s["triangles_out"] is not None else "?"
    print(f"{t:<24} {s['runs']:>4} {s['wall_s']:>9.2f} {s['peak_rss_mb']:>12.0f} {tri:>14} {ratio:>17}")
print()
for t in tools:
    s = summary[t]
    extra = f"  (load: median {s['load_s']:.2f} s)" if s.get("load_s") is not None else ""
    print(f"{t}: wall {s['all_wall_s']} s, peak RSS {s['all_peak_rss_mb']} MB, "
          f"other processes' CPU {s['all_other_cpu_s']} s{extra}")
if "lodstream" in summary:
    lv = [r for r in rows if r["tool"] == "lodstream"][-1].get("levels", [])
    print("lodstream levels (last run): " + ", ".join(f"L{l['level']}: {l['triangles']:,} tris @ {l['cell_size']}" for l in lv))
if "meshopt_simplifySloppy" in summary:
    sl = [r for r in rows if r["tool"] == "meshopt_simplifySloppy"]
    if any(r["triangles_out"] is not None and r["triangles_out"] < 0.5 * r["target_triangles"] for r in sl):
        print("note: meshopt_simplifySloppy fell far short of its target; meshoptimizer 0.18 quantizes to at most "
              "1024 cells per axis of the bounding box, which bounds its finest level")
json.dump(summary, open(sys.argv[2], "w"), indent=1)
EOF
echo "results: $results, $work/summary.json"

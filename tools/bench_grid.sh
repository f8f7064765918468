#!/usr/bin/env bash
# Benchmark: triangles needed to keep the vertical error within 1, 5 and 20 m on a Terrain-RGB tile (the
# Fuji tile of ../shared/data/terrain by default), for every `lodstream grid` variant (split rule × divide
# × gap handling), beside the two terrain meshers users pick today, run with node on the same tile:
#   - Martini (npm @mapbox/martini, RTIN) and Delatin (npm delatin, greedy Delaunay), via
#     tools/terrain_peers.js, which also measures each mesh's real max error on every sample (Martini's
#     threshold does not bound it, so Martini is shown as called, and with the largest threshold whose
#     measured error is within e: "martini (bounded)").
# The npm packages (and pngjs to decode the PNG) are installed on first use into the per-user prefix that
# tools/install-deps.sh uses ($LODSTREAM_NPM_PREFIX, default ~/.cache/lodstream-npm).
# lodstream runs as `lodstream grid TILE -o OUT --tolerance E --split S --divide D --gaps G` (binary from
# --build DIR; OUT is a directory); triangles, measured max error and seconds come from OUT/summary.json
# (time: its "subdivide" + "index" stages, heights to indexed triangles; the total is kept in
# WORK/lodstream.jsonl). Peers' times are medians over --peer-runs runs of the same (Martini's includes its
# constructor: see tools/terrain_peers.js); lodstream's the median of --runs.
#
# usage: tools/bench_grid.sh [--tile PNG] [--build build] [--errors 1,5,20] [--runs 1] [--peer-runs 3]
#                            [--splits center,first,greatest,curvature,random] [--divides 4,2]
#                            [--gaps none,extra-vertices,fill] [--merges off,on] [--work DIR] [--skip-peers]
#                            [--skip-lodstream]      (--merges on: also with --merge)
# Prints a markdown table (also in WORK/table.md); raw results in WORK/peers.jsonl and WORK/lodstream.jsonl.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
tile=""
build=build
errors=1,5,20
runs=1
peer_runs=3
splits=center,first,greatest,curvature,random
divides=4,2
merges=off,on
gaps=""
work=""
skip_peers=0
skip_lod=0

usage() { sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --tile) tile=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --errors) errors=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --peer-runs) peer_runs=$2; shift 2 ;;
    --splits) splits=$2; shift 2 ;;
    --divides) divides=$2; shift 2 ;;
    --gaps) gaps=$2; shift 2 ;;
    --merges) merges=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --skip-peers) skip_peers=1; shift ;;
    --skip-lodstream) skip_lod=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench_grid: unknown argument $1" >&2; usage >&2; exit 2 ;;
  esac
done
[[ "$build" = /* ]] || build="$root/$build"
[[ "$runs" =~ ^[1-9][0-9]*$ && "$peer_runs" =~ ^[1-9][0-9]*$ ]] ||
  { echo "bench_grid: --runs and --peer-runs must be positive integers" >&2; exit 2; }
if [[ -z "$tile" ]]; then
  shared="${LODSTREAM_SHARED_DATA:-$root/../shared/data}"
  tile="$shared/terrain/fuji-terrain-rgb.png"
fi
[[ -f "$tile" ]] || { echo "bench_grid: tile $tile not found (--tile PNG)" >&2; exit 1; }
command -v python3 >/dev/null || { echo "bench_grid: python3 is needed for the table" >&2; exit 1; }

if [[ -z "$work" ]]; then work=$(mktemp -d "${TMPDIR:-/tmp}/bench_grid.XXXXXX"); fi
mkdir -p "$work"
work=$(cd "$work" && pwd)
: > "$work/peers.jsonl"
: > "$work/lodstream.jsonl"
notes=()

# ---- peers
if [[ $skip_peers -eq 0 ]]; then
  if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    notes+=("Martini and Delatin skipped: node and npm are not installed")
  else
    npm_prefix="${LODSTREAM_NPM_PREFIX:-$HOME/.cache/lodstream-npm}"
    need=()
    for p in @mapbox/martini@0.2.0 delatin@0.2.0 pngjs@7.0.0; do
      [[ -f "$npm_prefix/node_modules/${p%@*}/package.json" ]] || need+=("$p")
    done
    if [[ ${#need[@]} -gt 0 ]]; then
      echo "installing: ${need[*]} (npm, into $npm_prefix)" >&2
      # Saved (exact versions) in the prefix's package.json, so that a later npm install there keeps them.
      npm install --prefix "$npm_prefix" --save-exact --no-audit --no-fund --loglevel=error "${need[@]}" >&2 ||
        echo "bench_grid: npm could not install ${need[*]}" >&2
    fi
    echo "running Martini and Delatin on $(basename "$tile") ..." >&2
    set +e
    LODSTREAM_NPM_PREFIX="$npm_prefix" node "$root/tools/terrain_peers.js" "$tile" --errors "$errors" \
      --runs "$peer_runs" > "$work/peers.jsonl" 2> "$work/peers.log"
    rc=$?
    set -e
    if [[ $rc -ne 0 ]]; then
      notes+=("Martini and Delatin skipped: terrain_peers.js exited $rc ($(head -c 300 "$work/peers.jsonl" "$work/peers.log" | tr '\n' ' '))")
      : > "$work/peers.jsonl"
    fi
  fi
fi

# ---- lodstream
bin="$build/lodstream"
if [[ $skip_lod -eq 0 ]]; then
  help=""
  [[ -x "$bin" ]] && help=$("$bin" grid --help 2>&1 || true)
  # An older binary answers `grid --help` with its general help: require the grid options.
  if ! grep -q -- "--tolerance" <<<"$help" || ! grep -q -- "--split" <<<"$help"; then
    msg="lodstream rows skipped: \`lodstream grid\` is not available in $build (build it, or pass --build DIR)"
    echo "bench_grid: $msg" >&2
    notes+=("$msg")
  else
    # The gap modes as the CLI spells them.
    if [[ -z "$gaps" ]]; then
      if grep -q "extra_vertices" <<<"$help"; then gaps=none,extra_vertices,fill; else gaps=none,extra-vertices,fill; fi
    fi
    IFS=, read -r -a e_list <<<"$errors"
    IFS=, read -r -a s_list <<<"$splits"
    IFS=, read -r -a d_list <<<"$divides"
    IFS=, read -r -a g_list <<<"$gaps"
    IFS=, read -r -a m_list <<<"$merges"
    # An older binary has no --merge: off only.
    grep -q -- "--merge" <<<"$help" || m_list=(off)
    total=$(( ${#e_list[@]} * ${#s_list[@]} * ${#d_list[@]} * ${#g_list[@]} * ${#m_list[@]} ))
    n=0
    cat "$tile" > /dev/null  # into the page cache before the first timed run
    for s in "${s_list[@]}"; do for d in "${d_list[@]}"; do for g in "${g_list[@]}"; do for m in "${m_list[@]}"; do
    for e in "${e_list[@]}"; do
      n=$((n + 1))
      mflag=()
      [[ "$m" == on ]] && mflag=(--merge)
      echo "[$n/$total] lodstream grid --tolerance $e --split $s --divide $d --gaps $g ${mflag[*]+"${mflag[*]}"}" >&2
      for ((r = 1; r <= runs; r++)); do
        out="$work/grid-$s-$d-$g-$m-$e"
        t0=$(date +%s.%N)
        set +e
        "$bin" grid "$tile" -o "$out" --tolerance "$e" --split "$s" --divide "$d" --gaps "$g" \
          ${mflag[@]+"${mflag[@]}"} > "$work/run.stdout" 2> "$work/run.stderr"
        rc=$?
        set -e
        t1=$(date +%s.%N)
        python3 - "$work/run.stdout" "$out" "$rc" "$s" "$d" "$g" "$e" "$t0" "$t1" "$work/run.stderr" "$m" \
          >> "$work/lodstream.jsonl" <<'EOF'
import json, os, sys
stdout, out, rc, split, divide, gaps, e, t0, t1, stderr, merge = sys.argv[1:]
summary = None
def objects(text):
    # Every JSON object in the text: the whole of it, or one per line.
    try:
        yield json.loads(text)
    except ValueError:
        for line in text.splitlines():
            line = line.strip()
            if line.startswith('{'):
                try:
                    yield json.loads(line)
                except ValueError:
                    pass
def find(o):
    if isinstance(o, dict):
        if 'triangles' in o:
            return o
        for v in o.values():
            r = find(v)
            if r:
                return r
    return None
candidates = [open(stdout).read()]
for p in (os.path.join(out, 'summary.json'), out + '.json', os.path.splitext(out)[0] + '.json'):
    if os.path.isfile(p):
        candidates.append(open(p).read())
for text in candidates:
    for o in objects(text):
        summary = find(o)
        if summary:
            break
    if summary:
        break
row = {'tool': 'lodstream', 'split': split, 'divide': int(divide), 'gaps': gaps, 'merge': merge == 'on', 'max_error': float(e),
       'exit': int(rc), 'wall_seconds': float(t1) - float(t0)}
if summary:
    row['triangles'] = summary.get('triangles')
    row['measured_max_error'] = summary.get('max_error', summary.get('measured_max_error'))
    row['seconds'] = summary.get('seconds', row['wall_seconds'])
    row['cracks'] = summary.get('cracks', 0)
    # The meshing alone, comparable with the peers' times: heights to indexed triangles, the "subdivide" and
    # "index" stages (an older binary has no "index" stage: its subdivide alone).
    stages = {st.get('name'): st.get('seconds') for st in summary.get('stages', []) if isinstance(st, dict)}
    if stages.get('subdivide') is not None:
        row['mesh_seconds'] = stages['subdivide'] + (stages.get('index') or 0)
else:
    row['error'] = (open(stderr).read().strip().splitlines() or ['no JSON summary found'])[-1][:300]
print(json.dumps(row))
EOF
        rm -rf "$out"
      done
    done; done; done; done; done
  fi
fi

# ---- table
printf '%s\n' "${notes[@]+"${notes[@]}"}" > "$work/notes.txt"
python3 - "$work" "$errors" "$(basename "$tile")" <<'EOF' | tee "$work/table.md"
import json, statistics, sys
work, errors, tile = sys.argv[1], [float(x) for x in sys.argv[2].split(',')], sys.argv[3]
def load(name):
    rows = []
    for line in open(f'{work}/{name}'):
        line = line.strip()
        if line.startswith('{'):
            rows.append(json.loads(line))
    return rows
peers, lod = load('peers.jsonl'), load('lodstream.jsonl')
table = {}  # label -> {error: (triangles, seconds, measured)}
order = []
def put(label, e, tris, secs, measured, cracks=0):
    if label not in table:
        table[label] = {}
        order.append(label)
    table[label][e] = (tris, secs, measured, cracks)
names = {'martini': 'Martini (RTIN), getMesh(e)', 'martini-bounded': 'Martini (RTIN), bounded',
         'delatin': 'Delatin (greedy Delaunay)'}
for r in peers:
    if r['tool'] in names:
        put(names[r['tool']], float(r['max_error']), r['triangles'], r['seconds'], r.get('measured_max_error'))
groups = {}
for r in lod:
    groups.setdefault((r['split'], r['divide'], r['gaps'], r.get('merge', False), r['max_error']), []).append(r)
for (s, d, g, m, e), rs in groups.items():
    ok = [r for r in rs if r.get('triangles') is not None and r['exit'] == 0]
    label = f'lodstream grid --split {s} --divide {d} --gaps {g}' + (' --merge' if m else '')
    if ok:
        put(label, e, ok[0]['triangles'], statistics.median(r.get('mesh_seconds', r['seconds']) for r in ok),
            ok[0].get('measured_max_error'), ok[0].get('cracks') or 0)
    else:
        put(label, e, None, None, rs[0].get('error', f"exit {rs[0]['exit']}"))
def fmt_e(e): return f'{e:g} m'
print(f'Triangles needed for a max vertical error of {", ".join(fmt_e(e) for e in errors)} on {tile}; time in seconds '
      '(heights to indexed triangles: PNG decoding excluded; Martini with its constructor, medians of the peers\' '
      'runs; lodstream\'s "subdivide" + "index" stages, reading, measuring and writing excluded). † = measured max error above the target; '
      '‡ = open cracks (T-junction gaps) left in the surface.')
print()
head = '| tool / variant | ' + ' | '.join(f'{fmt_e(e)}: triangles | {fmt_e(e)}: s' for e in errors) + ' |'
print(head)
print('|---|' + '---:|---:|' * len(errors))
for label in order:
    cells = []
    for e in errors:
        v = table[label].get(e)
        if v is None:
            cells += ['–', '–']
        elif v[0] is None:
            cells += [f'failed ({v[2]})', '–']
        else:
            tris, secs, measured, cracks = v
            mark = ''
            if isinstance(measured, (int, float)) and measured > e * (1 + 1e-9):
                mark = f' † ({measured:.1f} m)'
            if cracks:
                mark += f' ‡ {cracks:,} cracks'
            cells += [f'{tris:,}{mark}', f'{secs:.3f}']
    print(f'| {label} | ' + ' | '.join(cells) + ' |')
notes = [n for n in open(f'{work}/notes.txt').read().splitlines() if n]
if notes:
    print()
    for n in notes:
        print(f'- {n}')
EOF
echo "bench_grid: results in $work" >&2

#!/usr/bin/env bash
# Benchmark of out-of-core scaling (issue "out of core at any size"): `lodstream simplify` (default five
# levels) on city scenes from ../shared/data/tools/make-scene.sh of growing size, each under its own
# --memory cap, optionally followed by `lodstream report` of the levels. Per run it records what an
# operator sees from outside: wall time and peak resident memory as /usr/bin/time -v reports them (the
# process never resets its high-water mark), the work directory's size (its largest, sampled every 5 s,
# and at the end), the output directory's largest (the levels' scratch files are there), the input's size, and the time per input triangle, with its ratio to the first scene's;
# the stages' wall times and peaks from manifest.json, and the load average at the start and the end.
#
# usage: tools/bench_scale.sh [--scenes 9:1G,18:1G,41:4G] [--report 18:2G] [--build build]
#                             [--dir /work/scenes] [--delete] [--keep] [--work DIR]
#   --scenes N:CAP,...  make-scene.sh size N (9: 48.6 M, 18: 193 M, 41: 998 M triangles) and the cap (a
#                       scene may come twice with two caps)
#   --report N:CAP,...  also run `lodstream report` of scene N's levels under CAP (default: none)
#   --dir DIR           where scenes are built (city-N.ply; reused when present)
#   --delete            delete each scene after its runs (the N = 41 scene is 21 GB)
#   --keep              keep each run's work directory (e.g. for tools/bench_cluster.sh)
#   --work DIR          outputs, work directories and logs (default: a new directory under ${TMPDIR:-/tmp})
# Prints one line per run and a Markdown table; writes runs.jsonl into the work directory. Exit 1 when a
# run failed or went past its cap.
usage() { sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; }
set -euo pipefail

scenes="9:1G,18:1G,41:4G" reports="" build="build" dir="/work/scenes" delete=0 keep=0 work=""
while [ $# -gt 0 ]; do
  case "$1" in
    --scenes) scenes="$2"; shift 2 ;;
    --report) reports="$2"; shift 2 ;;
    --build) build="$2"; shift 2 ;;
    --dir) dir="$2"; shift 2 ;;
    --delete) delete=1; shift ;;
    --keep) keep=1; shift ;;
    --work) work="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench_scale: unknown option $1" >&2; usage >&2; exit 64 ;;
  esac
done
root=$(cd "$(dirname "$0")/.." && pwd)
[[ "$build" = /* ]] || build="$root/$build"
bin="$build/lodstream"
[ -x "$bin" ] || { echo "bench_scale: build first ($bin is missing)" >&2; exit 64; }
[ -x /usr/bin/time ] || { echo "bench_scale: /usr/bin/time is missing (apt-get install time)" >&2; exit 64; }
make_scene="$root/../shared/data/tools/make-scene.sh"
[ -x "$make_scene" ] || { echo "bench_scale: $make_scene is missing" >&2; exit 66; }
[ -n "$work" ] || work=$(mktemp -d "${TMPDIR:-/tmp}/bench_scale.XXXXXX")
mkdir -p "$work" "$dir"
echo "work $work"

declare -A report_cap=()
if [ -n "$reports" ]; then
  IFS=, read -r -a rl <<< "$reports"
  for r in "${rl[@]}"; do report_cap[${r%%:*}]=${r##*:}; done
fi

# run LABEL CAP WORKDIR -- COMMAND...: runs COMMAND under /usr/bin/time -v, sampling the work directory's
# size, and appends one JSON line to runs.jsonl.
run() {
  local label=$1 cap=$2 wdir=$3 scene=$4; shift 5
  local log="$work/$label.log" timelog="$work/$label.time"
  python3 - "$label" "$cap" "$wdir" "$scene" "$log" "$timelog" "$work/runs.jsonl" "$@" <<'EOF'
import json, os, re, subprocess, sys, time
label, cap_s, wdir, scene, log, timelog, jsonl = sys.argv[1:8]
cmd = ['/usr/bin/time', '-v', '-o', timelog] + sys.argv[8:]
units = {'K': 1 << 10, 'M': 1 << 20, 'G': 1 << 30, 'T': 1 << 40}
m = re.fullmatch(r'(\d+)([KMGT]?)', cap_s)
cap = int(m.group(1)) * units.get(m.group(2), 1)
def du(path):
    total = 0
    for dp, _, fs in os.walk(path):
        for f in fs:
            try: total += os.lstat(os.path.join(dp, f)).st_blocks * 512
            except OSError: pass
    return total
t0 = time.time()
load0 = open('/proc/loadavg').read().split()[0]
with open(log, 'w') as f:
    p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)
    biggest = 0
    next_du = 0
    # The output directory too: the levels' scratch files and the GLB's gathered data are written there.
    odir = sys.argv[8:][sys.argv[8:].index('-o') + 1] if '-o' in sys.argv[8:] else None
    out_biggest = 0
    while p.poll() is None:
        if time.time() >= next_du:
            biggest = max(biggest, du(wdir)); next_du = time.time() + 5
            if odir: out_biggest = max(out_biggest, du(odir))
        time.sleep(0.5)
wall = time.time() - t0
end = du(wdir); biggest = max(biggest, end)
tv = open(timelog).read()
rss = int(re.search(r'Maximum resident set size \(kbytes\): (\d+)', tv).group(1)) * 1024
el = re.search(r'Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)', tv).group(1).split(':')
wall_time = sum(float(x) * 60 ** i for i, x in enumerate(reversed(el)))
cpu = sum(float(re.search(rf'{k} time \(seconds\): ([\d.]+)', tv).group(1)) for k in ('User', 'System'))
rec = {'label': label, 'cap': cap, 'exit': p.returncode, 'wall_s': round(wall_time, 1), 'cpu_s': round(cpu, 1), 'peak_rss': rss,
       'work_bytes_max': biggest, 'work_bytes_end': end, 'out_bytes_max': out_biggest, 'input_bytes': os.path.getsize(scene),
       'load': [float(load0), float(open('/proc/loadavg').read().split()[0])]}
out = [a for a in sys.argv[8:]]
if '-o' in out:
    o = out[out.index('-o') + 1]
    for name in ('manifest.json', 'report.json'):
        path = os.path.join(o, name)
        if os.path.exists(path) and os.path.getmtime(path) >= t0:
            j = json.load(open(path))
            if name == 'manifest.json':
                rec['triangles'] = j.get('input', {}).get('triangles') or j.get('scene', {}).get('triangles')
            rec['stages'] = {s['name']: [round(s['seconds'], 1), round(s.get('cpu_seconds', 0), 1), s['peak_rss_bytes']]
                             for s in j.get('stages', [])}
with open(jsonl, 'a') as f:
    f.write(json.dumps(rec) + '\n')
g = lambda b: f'{b / 2**30:.2f} GiB'
over = rss > cap
print(f"{label}: exit {p.returncode}, {rec['wall_s']} s ({rec['cpu_s']} CPU-s), peak {g(rss)} (cap {cap_s}){'  OVER THE CAP' if over else ''}, "
      f"work dir max {g(biggest)} = {biggest / rec['input_bytes']:.2f}x input, output dir max {g(out_biggest)}")
if p.returncode != 0:
    print('  ' + (open(log).read().strip().splitlines() or [''])[-1])
sys.exit(1 if p.returncode != 0 or over else 0)
EOF
}

status=0
IFS=, read -r -a list <<< "$scenes"
for s in "${list[@]}"; do
  n=${s%%:*} cap=${s##*:}
  scene="$dir/city-$n.ply"
  if [ ! -f "$scene" ]; then
    echo "building $scene (make-scene.sh $n 1) ..."
    "$make_scene" "$n" 1 "$scene" >/dev/null
  fi
  cat "$scene" > /dev/null  # page cache, as for every peer in bench_simplify.sh (when it fits)
  wdir="$work/work-$n-$cap" out="$work/out-$n-$cap"
  rm -rf "$wdir" "$out"
  run "simplify-$n-$cap" "$cap" "$wdir" "$scene" -- "$bin" simplify "$scene" -o "$out" --memory "$cap" \
      --work "$wdir" --progress none || status=1
  if [ -n "${report_cap[$n]:-}" ] && [ -f "$out/manifest.json" ]; then
    run "report-$n-${report_cap[$n]}" "${report_cap[$n]}" "$wdir" "$scene" -- "$bin" report "$out" -o "$out/report" \
        --memory "${report_cap[$n]}" --work "$wdir" --progress none || status=1
    unset "report_cap[$n]"
  fi
  [ "$keep" = 1 ] || rm -rf "$wdir"
  if [ "$delete" = 1 ]; then rm -f "$scene"; fi
done

python3 - "$work/runs.jsonl" <<'EOF'
import json, sys
runs = [json.loads(l) for l in open(sys.argv[1])]
base = next((r for r in runs if r['label'].startswith('simplify') and r.get('triangles') and r['exit'] == 0), None)
print('\n| run | cap | exit | wall | CPU s | peak (time -v) | work dir max / input | output dir max | ns per input triangle: wall, CPU | vs first: wall, CPU | load (start, end) | stages: wall s / CPU s / peak MiB |')
print('|---|---|---|---|---|---|---|---|---|---|---|---|')
for r in runs:
    tri = r.get('triangles')
    ns = r['wall_s'] / tri * 1e9 if tri else None
    cns = r['cpu_s'] / tri * 1e9 if tri else None
    ratio = ns / (base['wall_s'] / base['triangles'] * 1e9) if ns and base else None
    cratio = cns / (base['cpu_s'] / base['triangles'] * 1e9) if cns and base else None
    print(f"| {r['label']} | {r['cap'] / 2**30:.2f} GiB | {r['exit']} | {r['wall_s']} s | {r['cpu_s']} | {r['peak_rss'] / 2**30:.2f} GiB | "
          f"{r['work_bytes_max'] / 2**30:.2f} / {r['input_bytes'] / 2**30:.2f} GiB = {r['work_bytes_max'] / r['input_bytes']:.2f}x | "
          f"{r.get('out_bytes_max', 0) / 2**30:.2f} GiB | "
          f"{f'{ns:.0f}, {cns:.0f}' if ns else '-'} | {f'{ratio:.2f}x, {cratio:.2f}x' if ratio else '-'} | {r['load'][0]:.1f}, {r['load'][1]:.1f} | "
          + ', '.join(f"{k} {v[0]} / {v[1]} / {v[2] >> 20}" for k, v in r.get('stages', {}).items()) + ' |')
EOF
exit $status

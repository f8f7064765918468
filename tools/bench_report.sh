#!/usr/bin/env bash
# Benchmark: `lodstream report` on the five levels of a simplify output (default: the city scene), with
# --memory 4G, once with all threads and once with --threads 1 (the per-core figures), N runs each.
# Prints per run the wall time and the peak resident memory (/usr/bin/time -v; report.json's peak_rss_bytes
# is the same VmHWM), the chunks the original was traced in (1 = in core; more when it does not fit
# --memory), primary rays per second and point queries per second (report.json
# "performance": rays and queries over the wall time spent casting and querying), and the CPU seconds
# other processes used meanwhile, the CPU seconds of the run and of each part of its measure stage
# (report.json performance.phases: chunk reads and builds, rays and point queries on the original and on
# the levels, the comparison); then the medians.
#
# usage: tools/bench_report.sh [--runs N] [--build DIR] [--lods DIR] [--memory 4G] [--work DIR] [--threads "0 1"]
#   --lods DIR: a simplify output directory (default: made first, from /work/scenes/city.ply, into the
#               work directory)
#   --threads LIST: thread counts to run (0 = all; default "0 1")
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
runs=3; build=build; lods=""; memory=4G; work=""; thread_list="0 1"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --lods) lods=$2; shift 2 ;;
    --memory) memory=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --threads) thread_list=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench_report: unknown option $1" >&2; exit 64 ;;
  esac
done
[[ "$build" = /* ]] || build="$root/$build"
cli="$build/lodstream"
[ -x "$cli" ] || { echo "bench_report: $cli not found (build first: tools/build.sh)" >&2; exit 66; }
[ -x /usr/bin/time ] || { echo "bench_report: /usr/bin/time missing (apt-get install time)" >&2; exit 66; }
work=${work:-$(mktemp -d "${TMPDIR:-/tmp}/bench_report.XXXXXX")}
mkdir -p "$work"
if [ -z "$lods" ]; then
  lods="$work/city-lods"
  [ -f "$lods/manifest.json" ] || "$cli" simplify /work/scenes/city.ply -o "$lods" --memory 1G --progress none >/dev/null
fi
# Busy CPU jiffies of the whole machine (/proc/stat); minus our own CPU time, what others used.
others_cpu() { awk '/^cpu / {print $2+$3+$4+$7+$8+$9}' /proc/stat; }
results="$work/runs.jsonl"; : > "$results"
for threads in $thread_list; do
  for ((r = 1; r <= runs; r++)); do
    out="$work/report-t$threads-$r"
    rm -rf "$out"
    before=$(others_cpu); t0=$(date +%s.%N)
    /usr/bin/time -v "$cli" report "$lods" -o "$out" --memory "$memory" --threads "$threads" --progress none \
      > "$out.log" 2> "$out.time"
    t1=$(date +%s.%N); after=$(others_cpu)
    python3 - "$out/report.json" "$out.time" "$threads" "$r" "$before" "$after" "$t0" "$t1" "$(getconf CLK_TCK)" >> "$results" <<'PY'
import json, re, sys
rep = json.load(open(sys.argv[1])); tv = open(sys.argv[2]).read()
m = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (?:(\d+):)?(\d+):([\d.]+)", tv)
wall = int(m.group(1) or 0) * 3600 + int(m.group(2)) * 60 + float(m.group(3))
cpu = re.search(r"User time \(seconds\): ([\d.]+)", tv), re.search(r"System time \(seconds\): ([\d.]+)", tv)
own = float(cpu[0].group(1)) + float(cpu[1].group(1))
others = (float(sys.argv[6]) - float(sys.argv[5])) / float(sys.argv[9]) - own
p = rep["performance"]
print(json.dumps({"threads": int(sys.argv[3]) or "all", "run": int(sys.argv[4]), "wall_s": wall,
                  "peak_gb": int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", tv).group(1)) * 1024 / 1e9,
                  "rays_per_s": p["rays_per_second"], "queries_per_s": p["queries_per_second"],
                  "levels": len(rep["runs"][0]["levels"]), "others_cpu_s": round(max(others, 0), 1),
                  "chunks": p.get("original_chunks", 1), "level_chunks": p.get("level_chunks", 1),
                  "cpu_s": round(own, 1),
                  "stages": {s["name"]: round(s["seconds"], 2) for s in rep["stages"]},
                  "phases_cpu_s": {q["name"]: round(q["cpu_seconds"], 1) for q in p.get("phases", [])}}))
PY
    tail -1 "$results"
  done
done
python3 - "$results" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("\n| threads | runs | wall (median) | peak | chunks | primary rays/s | point queries/s |")
print("|---|---|---|---|---|---|---|")
for t in ("all", 1):
    rs = [r for r in rows if r["threads"] == t]
    if not rs: continue
    med = lambda k: statistics.median(r[k] for r in rs)
    print(f"| {t} | {len(rs)} | {med('wall_s'):.1f} s | {max(r['peak_gb'] for r in rs):.2f} GB | {rs[0]['chunks']} | "
          f"{med('rays_per_s')/1e6:.2f} M | {med('queries_per_s')/1e6:.3f} M |")
PY

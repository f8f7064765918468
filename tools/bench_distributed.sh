#!/bin/bash
# Sharded simplify against one machine (README "Running on a cluster", figures). Two modes:
#
# --slurm (the issue's benchmark): one machine's whole run from an empty work directory, then the same
#   input through `lodstream slurm simplify --shards N --wait` on a one-node Slurm cluster started for the
#   run (tools/slurm_local_cluster.sh; as root) from another empty work directory: ingest array, grade
#   array, cluster array, prepare,
#   task array, merge, the jobs sharing this machine's cores as Slurm schedules them. Prints both wall
#   times and their ratio, every job's peak (the largest stage peak in its log) against the cap, the input
#   primitives each task's emit read, and the largest size of the shared directories (work and output,
#   sampled every 2 s), when each step ended, and the slowest job of each step one after another (what N
#   nodes would take when no job waits for another's core), then compares the outputs byte for byte.
# default (tasks one after another): one machine's run, then on the same work directory the prepare step,
#   the N tasks one after the other and the merge, each timed (wall, CPU, peak RSS from /usr/bin/time -v),
#   so that each task's figures are its own on this shared machine; the wall time N machines would take is
#   then prepare + the slowest task + merge.
# usage: tools/bench_distributed.sh [--slurm] [--bin LODSTREAM] [--input FILE] [--shards N] [--work DIR]
#                                   [--out DIR] [--prepare-memory SIZE] -- [simplify options, e.g. --memory 1G]
# Defaults: build/lodstream, /work/scenes/city-18.ply (read only), 8 shards, a fresh work and output
# directory under $TMPDIR, --prepare-memory = the simplify options' --memory. Steps (default mode): one
# (one machine's whole run), one-emit (the same again on its work directory: emit and write only), prepare
# (the shared stages, reused from one's, plus the representatives), task-I, merge.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=$root/build/lodstream; input=/work/scenes/city-18.ply; shards=8; work=""; out=""; prepare_memory=""; slurm=0
while [ $# -gt 0 ]; do
  case "$1" in
    --slurm) slurm=1; shift ;;
    --bin) bin=$2; shift 2 ;;
    --input) input=$2; shift 2 ;;
    --shards) shards=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --prepare-memory) prepare_memory=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
opts=("$@")
if [ -z "$work" ] || [ -z "$out" ]; then tmp=$(mktemp -d); fi
[ -n "$work" ] || work=$tmp/work
[ -n "$out" ] || out=$tmp/out
logs=$out/logs  # each step's output and /usr/bin/time -v report
mkdir -p "$logs"
prep_opts=("${opts[@]}")
[ -n "$prepare_memory" ] && prep_opts+=(--memory "$prepare_memory")

# timed NAME CMD...: one line "NAME wall_s cpu_s peak_MiB exit"
timed() {
  local name=$1; shift
  local rc=0
  /usr/bin/time -v -o "$logs/$name.time" "$@" >"$logs/$name.log" 2>&1 || rc=$?
  awk -v n="$name" -v rc=$rc '
    /Elapsed \(wall clock\)/ { split($NF, t, ":"); w = (length(t) == 3) ? t[1] * 3600 + t[2] * 60 + t[3] : t[1] * 60 + t[2] }
    /User time/ { u = $NF } /System time/ { s = $NF } /Maximum resident/ { m = $NF / 1024 }
    END { printf "%-12s %9.1f %9.1f %9.0f %5d\n", n, w, u + s, m, rc }' "$logs/$name.time" | tee -a "$out/bench.txt"
  [ $rc -eq 0 ] || { tail -5 "$logs/$name.log" >&2; exit $rc; }
}

echo "input $input, $shards shards, options: ${opts[*]:-}; $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$out/bench.txt"
printf "%-12s %9s %9s %9s %5s\n" step wall_s cpu_s peak_MiB exit | tee -a "$out/bench.txt"
# same_outputs A B: cmp of every file of A (manifest.json and logs aside) with B's
same_outputs() {
  local same=1 f
  for f in $(cd "$1" && find . -type f ! -name manifest.json ! -path './logs/*' ! -path './slurm/*' | sort); do
    cmp -s "$1/$f" "$2/$f" || { echo "DIFFERS: $f" | tee -a "$out/bench.txt"; same=0; }
  done
  [ $same -eq 1 ] && echo "outputs byte-identical (cmp of every file but manifest.json)" | tee -a "$out/bench.txt"
  return 0
}

if [ $slurm -eq 1 ]; then
  cluster=$out/cluster
  conf=$("$root/tools/slurm_local_cluster.sh" start "$cluster") || { echo "bench_distributed: no Slurm cluster here" >&2; exit 77; }
  export "${conf?}"
  trap '"$root/tools/slurm_local_cluster.sh" stop "$cluster"' EXIT
  # An output directory that already holds one machine's run keeps it (its line from the earlier bench.txt).
  if [ -f "$out/one/manifest.json" ] && [ -f "$out/one.txt" ]; then
    cat "$out/one.txt" | tee -a "$out/bench.txt"
    echo "  (one machine's run reused from $out/one)" | tee -a "$out/bench.txt"
  else
    timed one "$bin" simplify "$input" -o "$out/one" --work "$work-one" --no-space-check "${opts[@]}"
    grep '^one ' "$out/bench.txt" >"$out/one.txt"
    echo "  one machine: work directory $(du -sb "$work-one" | cut -f1) bytes at the end" | tee -a "$out/bench.txt"
    rm -rf "$work-one"
  fi
  python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print("  one machine stages:", ", ".join("%s %.1f s" % (s["name"], s["seconds"]) for s in m["stages"]))' \
    "$out/one/manifest.json" | tee -a "$out/bench.txt"
  rm -rf "$work" "$out/sharded"
  # The shared directories' size, sampled while the jobs run: a line a sample, the total of the blocks the
  # disk holds for them (du counts a file linked twice once), their apparent size (the files' lengths,
  # @apparent=bytes: holes and files sized ahead of being filled count whole; what this bench reported
  # until 2026-12-06), then each entry of the two directories as name=bytes held.
  ( while :; do
      { du -sB1 "$work" "$out/sharded" 2>/dev/null | awk '{s += $1} END {printf "%.0f", s}'
        du -sb "$work" "$out/sharded" 2>/dev/null | awk '{s += $1} END {printf " @apparent=%.0f", s}'
        du -sB1 "$work"/* "$out/sharded"/* 2>/dev/null | awk '{n = $2; sub(".*/", "", n); printf " %s=%s", n, $1}'
        echo; } || true
      sleep 2
    done ) >"$logs/shared-bytes.txt" &
  sampler=$!
  # Stopped also when a step fails and the script exits (as the cluster is).
  trap 'kill $sampler 2>/dev/null || true; "$root/tools/slurm_local_cluster.sh" stop "$cluster"' EXIT
  timed slurm "$bin" slurm simplify "$input" -o "$out/sharded" --shards "$shards" --work "$work" --wait --no-space-check "${opts[@]}"
  kill $sampler 2>/dev/null || true
  python3 - "$out" "$shards" "$logs/shared-bytes.txt" "$work" <<'PY' | tee -a "$out/bench.txt"
import json, os, re, sys
out, n, sizes, work = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
walls = {}
for line in open(os.path.join(out, "bench.txt")):
    f = line.split()
    if len(f) == 5 and f[0] in ("one", "slurm"): walls[f[0]] = float(f[1])
print("wall: one machine %.1f s, %d tasks through Slurm %.1f s: %.2fx" % (walls["one"], n, walls["slurm"], walls["slurm"] / walls["one"]))
logs = os.path.join(out, "sharded", "slurm", "logs")
slowest = {}  # per step (ingest, grade, cluster, prepare, task, merge): its slowest job's stage seconds
for name in sorted(os.listdir(logs)):
    unit = {"B": 2**-20, "KiB": 2**-10, "MiB": 1, "GiB": 2**10}
    peaks = [float(v) * unit[u] for v, u in re.findall(r"peak ([0-9.]+) (B|KiB|MiB|GiB)\b", open(os.path.join(logs, name)).read())]
    stages = re.findall(r"^stage\s+(\S+)\s+([0-9.]+) s", open(os.path.join(logs, name)).read(), re.M)
    print("  job %-14s peak %7.1f MiB  %s" % (name[:-4], max(peaks, default=0), ", ".join("%s %s s" % s for s in stages)))
    step = name[:-4].split("-")[0]
    slowest[step] = max(slowest.get(step, 0.0), sum(float(v) for _, v in stages))
# The steps as the status files' times mark their ends (seconds from the submission), and the slowest job of
# each step one after another: what N nodes would take when no job waits for another's core.
status = os.path.join(out, "sharded", "slurm", "status")
t0 = os.path.getmtime(os.path.join(out, "sharded", "slurm", "submit.json"))
ends = {}
for f in os.listdir(status):
    if f.endswith(".rc"):
        step = f[:-3].split("-")[0]  # grade-3.rc -> grade, merge.rc -> merge
        ends[step] = max(ends.get(step, 0.0), os.path.getmtime(os.path.join(status, f)) - t0)
order = [k for k in ("ingest", "grade", "cluster", "prepare", "task", "merge") if k in slowest]
print("  steps end at (s from the submission): " + ", ".join("%s %.0f" % (k, ends[k]) for k in order if k in ends))
print("  slowest job of each step, one after another: " + " + ".join("%s %.1f" % (k, slowest[k]) for k in order) +
      " = %.1f s (one machine %.1f s)" % (sum(slowest[k] for k in order), walls["one"]))
# The clustering merge's units (stream/cluster_merge.h): each phase's slowest unit (what N nodes would
# wait for), all units' seconds summed (one process running them alone), and how many processes ran them.
try:
    mu = json.load(open(os.path.join(work, "cluster.json")))["value"]["merge_units"]
    for phase in ("centers", "map", "pairs", "sums"):
        if phase not in mu: continue
        sec, by = mu[phase]["seconds"], mu[phase]["by"]
        print("  clustering merge, %d %s units: slowest %.2f s, all %.2f s, run by %d processes" %
              (mu["units"], phase, max(sec), sum(sec), len(set(by))))
    records = os.path.getsize(os.path.join(work, "order.u32")) // 4
    for c in mu.get("centers_passes", []):  # the levels split by records (stream/cluster_shares.h)
        print("  level %d split by records: centers pass %.2f s (%s), %d centers, %.1f %% of the records skipped (voxel %g)" %
              (c["level"], c["seconds"], c["runner"], c["centers"], 100.0 * c["skipped"] / records, c["voxel"]))
except (OSError, KeyError, ValueError) as e:
    print("  clustering merge units: none recorded (%s)" % e)
# The wide levels' pass A as units (stream/wide_units.h), as the clustering merge's.
try:
    wu = json.load(open(os.path.join(work, "wide-units.json")))["value"]["units"]
    if wu["levels"]:
        print("  wide levels %s: %d units of pass A, slowest %.2f s, all %.2f s, run by %d processes" %
              (",".join(str(l) for l in wu["levels"]), wu["units"], max(wu["seconds"]), sum(wu["seconds"]), len(set(wu["by"]))))
except (OSError, KeyError, ValueError) as e:
    print("  wide levels' units: none recorded (%s)" % e)
# The tasks' step on N nodes: each shared stage the tasks take up in units (N units a stage, one a task)
# lasts about its slowest unit, the stages one after another, then every task emits its share. On one node
# the first tasks take every unit, so the step's slowest job is no measure of N nodes.
try:
    stages = []
    cj = json.load(open(os.path.join(work, "cluster.json")))["value"]["merge_units"]
    stages += [("merge " + k, cj[k]["seconds"]) for k in ("centers", "map", "pairs", "sums") if k in cj]
    for name, f in (("bounds", "block-bounds.json"), ("cells by vertex", "shard-vertex-cells.json"), ("wide", "wide-units.json")):
        if os.path.exists(os.path.join(work, f)):
            u = json.load(open(os.path.join(work, f)))["value"]["units"]
            stages.append((name, u["unit"]["seconds"] if "unit" in u else u["seconds"]))
    emits = []
    for name in os.listdir(logs):
        if name.startswith("task-"):
            e = re.findall(r"^stage\s+emit\s+([0-9.]+) s", open(os.path.join(logs, name)).read(), re.M)
            emits += [float(x) for x in e]
    units = sum(max(sec, default=0) for _, sec in stages)
    print("  tasks' step on %d nodes: slowest unit of each stage %s = %.1f s, then the slowest emit %.1f s: %.1f s" %
          (n, " + ".join("%s %.2f" % (k, max(sec, default=0)) for k, sec in stages), units, max(emits, default=0), units + max(emits, default=0)))
except (OSError, KeyError, ValueError) as e:
    print("  tasks' step on N nodes: not estimated (%s)" % e)
m = json.load(open(os.path.join(out, "sharded", "manifest.json")))
for t in m["shards"]["tasks"]:
    p = t.get("paged_map")
    paged = ("; paged maps %d: %d of %d pages read (%d reads), %d drops, largest group %d pages, largest held %.1f MiB" %
             (p["maps"], p["pages_read"], p["pages"], p["reads"], p["drops"], p["largest_group_pages"], p["largest_bytes"] / 2**20)
             if p else "")
    print("  task %2d: %.1f s, peak %.1f MiB, input primitives read by its emit %d%s" %
          (t["index"], t["seconds"], t["peak_rss_bytes"] / 2**20, t["input_primitives_read"], paged))
total = m["input"]["triangles"] + m["input"]["lines"] + m["input"]["points"]
reads = [t["input_primitives_read"] for t in m["shards"]["tasks"]]
print("  input primitives %d; tasks' reads: sum %.2fx the input, largest %.2fx" % (total, sum(reads) / total, max(reads) / total))
samples = []  # (total, {entry: bytes})
for line in open(sizes).read().replace("\0", " ").splitlines():
    f = line.split()
    if f and re.fullmatch(r"[0-9.e+]+", f[0]):
        samples.append((int(float(f[0])), {k: int(v) for k, v in (x.split("=", 1) for x in f[1:] if "=" in x)}))
peak = max(samples, default=(0, {}), key=lambda x: x[0])
print("  shared directories (work + output), largest sample of the disk they hold: %.2f GB (input %.2f GB, %.2fx)" %
      (peak[0] / 1e9, m["input"]["bytes"] / 1e9, peak[0] / max(m["input"]["bytes"], 1)))
big = sorted(((k, v) for k, v in peak[1].items() if not k.startswith("@")), key=lambda x: -x[1])[:6]
print("    at that sample: " + ", ".join("%s %.2f GB" % (k, v / 1e9) for k, v in big))
apparent = max((x[1].get("@apparent", 0) for x in samples), default=0)
print("    largest apparent size (files' lengths, holes and space sized ahead counted whole, as reported until 2026-12-06): %.2f GB (%.2fx)" %
      (apparent / 1e9, apparent / max(m["input"]["bytes"], 1)))
PY
  same_outputs "$out/one" "$out/sharded"
  echo "results in $out/bench.txt"
  exit 0
fi

# An output directory that already holds one machine's run (same work directory) keeps it: only the
# sharded steps are run again.
if [ -f "$out/one/manifest.json" ]; then
  echo "one machine's run reused from $out/one" | tee -a "$out/bench.txt"
else
  timed one "$bin" simplify "$input" -o "$out/one" --work "$work" --no-space-check "${prep_opts[@]}"
fi
# The one machine's run leaves the shared stages in the work directory: prepare then only adds the
# representatives. Its stages are in one/manifest.json.
python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print("  one machine stages:", ", ".join("%s %.1f s" % (s["name"], s["seconds"]) for s in m["stages"]))' \
  "$out/one/manifest.json" | tee -a "$out/bench.txt"
# The same run again on the same work directory: its stages up to cluster are reused, so this is what
# one machine spends after them (emit and write), to set against the tasks.
timed one-emit "$bin" simplify "$input" -o "$out/one-emit" --work "$work" --no-space-check "${opts[@]}"
timed prepare "$bin" simplify "$input" -o "$out/sharded" --work "$work" --shard-prepare --no-space-check "${prep_opts[@]}"
for ((i = 0; i < shards; i++)); do
  timed "task-$i" "$bin" simplify "$input" -o "$out/sharded" --work "$work" --shard "$i/$shards" --no-space-check "${opts[@]}"
done
timed merge "$bin" merge "$out/sharded"
same_outputs "$out/one" "$out/sharded"
echo "results in $out/bench.txt; work directory $work"

#!/usr/bin/env python3
"""Sweep of the silhouette labels' interval D and factor f (issue 14, item 2: "default on or off by measurement").

usage: tools/bench_labels_sweep.py [--build DIR] [--work DIR] [--views K] [--resolution H] [--samples N]
                                   [--threads T] [--configs D:f,...] [--tolerance P] [--out FILE.md] MODEL...
       tools/bench_labels_sweep.py --from-json WORK/sweep.json [--configs D:f,...]   (the table again)

For each MODEL, as tools/bench_peers.py does it (its Bench class: the same reference, matching and report):
the reference is `lodstream simplify` with its defaults (no labels) at --resolution H; sloppy
(meshopt_simplifySloppy) and every labels configuration D:f (`--silhouette-interval D --silhouette-factor f`)
are matched to the reference's triangle counts within --tolerance (search on the cell sizes, at most 12
steps); one `report` measures every level of every run from the reference's switching distances.
Per configuration, over the levels where every configuration, the reference and sloppy are matched: on how many its
silhouette p95 and mismatch are both at most sloppy's (the target of issue 14), both at most the
reference's, its Hausdorff mean against the reference's (median ratio, and levels lower), its thin-feature
share against the reference's (mean). Writes WORK/sweep.json and WORK/sweep.md (also printed).
"""
import argparse
import datetime
import json
import os
import resource
import shutil
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_peers as bp  # noqa: E402


def model_rows(b, model, configs):
    a = b.a
    name = os.path.splitext(os.path.basename(model))[0]
    d = os.path.join(a.work, name)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    b.tmpdir = d
    t0 = time.time()
    ref = b.simplify(model, os.path.join(d, "lodstream"), [])
    want = [L["triangles"] for L in ref]
    dists = [L["switch_distance"] for L in ref]
    runs = {"lodstream": [{"triangles": w} for w in want]}
    for D, f in configs:
        m = f"D{D:g}-f{f:g}"
        runs[m] = b.match_lodstream(model, d, m, ["--silhouette-interval", str(D), "--silhouette-factor", str(f)], ref)
    src = os.path.join(d, "original.ply")
    bp.to_ply(model, src)
    os.makedirs(os.path.join(d, "sloppy"))
    runs["sloppy"] = [b.sloppy(src, w, os.path.join(d, "sloppy", f"lod{i}.ply")) for i, w in enumerate(want)]
    measured = [(m, i) for m, rs in runs.items() for i, r in enumerate(rs) if r and r["triangles"] > 0]
    levels = b.report(model, [os.path.join(d, m, f"lod{i}.ply") for m, i in measured], [dists[i] for _, i in measured],
                      os.path.join(d, "report"))
    rows = []
    for (m, i), L in zip(measured, levels):
        s, h = L["silhouette"], L["hausdorff"]
        rows.append({"model": name, "level": i, "run": m, "target": want[i], "triangles": L["triangles"],
                     "matched": m == "lodstream" or bp.within(L["triangles"], want[i], a.tolerance),
                     "sil_p95": s["p95_px"], "mismatch": s["mismatch_fraction"], "thin_kept": s["thin_kept_fraction"],
                     "thin_pixels": s["thin_pixels"], "hd_mean": h["mean_percent_diagonal"]})
    print(f"bench_labels_sweep: {name} done in {time.time() - t0:.0f} s", file=sys.stderr)
    return rows


def table(rows, configs):
    key = {(r["model"], r["level"], r["run"]): r for r in rows}
    names = ["lodstream", "sloppy"] + [f"D{D:g}-f{f:g}" for D, f in configs]
    # The levels where every run is matched, so that every row counts the same levels.
    levels = sorted(lv for lv in {(r["model"], r["level"]) for r in rows}
                    if all(key.get(lv + (n,)) and key[lv + (n,)]["matched"] for n in names))
    out = ["| D px | f | levels | p95 and mismatch ≤ sloppy | p95 and mismatch ≤ no labels | Hd mean < no labels | "
           "Hd mean / no labels (median) | mismatch / no labels (median) | thin kept, mean (no labels) |",
           "|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    def ok(x, y):
        return x["sil_p95"] <= y["sil_p95"] and x["mismatch"] <= y["mismatch"]
    for run in ["lodstream"] + [f"D{D:g}-f{f:g}" for D, f in configs]:
        trip = []
        for lv in levels:
            x, ref, sl = key.get(lv + (run,)), key.get(lv + ("lodstream",)), key.get(lv + ("sloppy",))
            if x and ref and sl and x["matched"] and sl["matched"]:
                trip.append((x, ref, sl))
        if not trip:
            continue
        n = len(trip)
        vs_sloppy = sum(ok(x, s) for x, _, s in trip)
        vs_ref = sum(ok(x, r) for x, r, _ in trip)
        hd_lower = sum(x["hd_mean"] < r["hd_mean"] for x, r, _ in trip)
        hd = statistics.median(x["hd_mean"] / r["hd_mean"] for x, r, _ in trip if r["hd_mean"] > 0)
        mis = statistics.median(x["mismatch"] / r["mismatch"] for x, r, _ in trip if r["mismatch"] > 0)
        thin = [(x, r) for x, r, _ in trip if r["thin_pixels"] > 0]
        tk = statistics.mean(x["thin_kept"] for x, _ in thin) if thin else float("nan")
        tr = statistics.mean(r["thin_kept"] for _, r in thin) if thin else float("nan")
        D, f = ("—", "no labels") if run == "lodstream" else run[1:].split("-f")
        out.append(f"| {D} | {f} | {n} | {vs_sloppy} ({100 * vs_sloppy / n:.0f} %) | {vs_ref} ({100 * vs_ref / n:.0f} %) | "
                   f"{hd_lower} | {hd:.2f} | {mis:.2f} | {100 * tk:.1f} % ({100 * tr:.1f} %) |")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("models", nargs="*")
    ap.add_argument("--from-json", help="only the table, from an earlier run's WORK/sweep.json")
    ap.add_argument("--build", default=os.path.join(bp.ROOT, "build"))
    ap.add_argument("--work")
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--resolution", type=int, default=512)
    ap.add_argument("--samples", type=int, default=100000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--configs", default="2:0.5,5:0.5,10:0.5,5:0.25,5:0.75,10:0.25",
                    help="D:f pairs, comma-separated (default 2:0.5,5:0.5,10:0.5,5:0.25,5:0.75,10:0.25)")
    ap.add_argument("--tolerance", type=float, default=0.05)
    ap.add_argument("--out")
    a = ap.parse_args()
    configs = [(float(c.split(":")[0]), float(c.split(":")[1])) for c in a.configs.split(",")]
    if a.from_json:
        rows = json.load(open(a.from_json))
        print(f"From {a.from_json}: {len({(r['model'], r['level']) for r in rows})} levels of "
              f"{len({r['model'] for r in rows})} models.\n\n" + "\n".join(table(rows, configs)))
        return
    if not a.models:
        ap.error("give models, or --from-json")
    a.build = os.path.abspath(a.build)
    a.memory, a.max_steps = None, 12
    a.work = os.path.abspath(a.work or tempfile.mkdtemp(prefix="bench_labels_sweep."))
    os.makedirs(a.work, exist_ok=True)
    print(f"bench_labels_sweep: work directory {a.work}", file=sys.stderr)
    b = bp.Bench(a)
    start = time.time()
    rows = []
    for m in a.models:
        rows += model_rows(b, os.path.abspath(m), configs)
        json.dump(rows, open(os.path.join(a.work, "sweep.json"), "w"), indent=1)
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = " ".join(open("/proc/loadavg").read().split()[:3])
    head = (f"Run {datetime.datetime.utcnow():%Y-%m-%d %H:%M} UTC: `tools/bench_labels_sweep.py`, report --views {a.views} "
            f"--resolution {a.resolution} --samples {a.samples}; {len({(r['model'], r['level']) for r in rows})} levels of "
            f"{len(a.models)} models ({', '.join(sorted({r['model'][:24] for r in rows}))}); {time.time() - start:.0f} s wall, "
            f"{cpu.ru_utime + cpu.ru_stime:.0f} CPU seconds, load average at the end {load}.")
    text = "\n".join([head, ""] + table(rows, configs)) + "\n"
    open(os.path.join(a.work, "sweep.md"), "w").write(text)
    if a.out:
        shutil.copy(os.path.join(a.work, "sweep.md"), a.out)
    print(text)


if __name__ == "__main__":
    main()

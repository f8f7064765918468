#!/usr/bin/env python3
"""Two-sided Hausdorff distance between two triangle meshes, measured by MeshLab 2020.09 (reference values).

Usage: tools/meshlab_hausdorff.py A.ply B.ply [-n SAMPLES] [--seed S] [--faces-only] [--raw] [--keep DIR]
Prints one JSON object:
  {"a_to_b": {"min", "max", "mean", "rms", "samples"}, "b_to_a": {...}, "meshlab_seconds": ..., ...}
distances in the input's units. Exit 77 ("skipped: ..." on stderr) when meshlabserver or xvfb-run is missing,
1 on failure. Inputs: PLY (ascii or binary, any element layout) or OBJ (v/f lines only).

What the script hands to MeshLab (unless --raw): a triangle-only binary PLY copy of each mesh, with
  - only the faces (polygons fan-triangulated); every other element (lodstream's `edge` and `point`) dropped.
    This is required, not cosmetic: MeshLab 2020.09 ABORTS (SIGABRT, exit 134, "import_ply.h:736 Assertion
    `pi.mask & Mask::IOM_EDGEINDEX' failed") on a PLY with a non-empty `edge` element whose vertex1/vertex2
    are `uint`, as lodstream writes them; with `int` it loads them. An empty `edge` element is harmless;
  - vertices at identical positions welded and vertices no face uses removed (see "1 Vertex" below:
    MeshLab would otherwise sample every vertex record, including duplicates split by normals and the
    vertices of lodstream's edges and points);
  - all positions multiplied by the same power of two so that the larger bounding-box diagonal lies in
    [1024, 2048). MeshLab prints its figures with printf("%f"), i.e. 6 decimals; the scaling keeps ~9
    significant digits. A power-of-two scale is exact in floating point and every operation of the filter
    commutes with it, so the figures are unchanged apart from the factor, which is divided out again.
  - with --seed S > 0, faces and vertices written in a random order (seeded). MeshLab's random generator
    has a fixed seed (identical figures on every run); permuting the input is how to get independent
    samplings to see the Monte Carlo spread.

=== MeshLab 2020.09 "Hausdorff Distance" filter: the spec our geometric error has to mirror ===
Sources read: meshlab src/meshlabplugins/filter_sampling/filter_sampling.cpp (FP_HAUSDORFF_DISTANCE) and
vcglib vcg/complex/algorithms/point_sampling.h (SurfaceSampling, HausdorffSampler), vcg/simplex/face/distance.h
(PointDistanceBase); checked against the strings and symbols of Debian's libfilter_sampling.so
(meshlab 2020.09+dfsg1-2) and by running meshlabserver.

Parameters (mlx names; `meshlabserver -d FILE` only prints the display names):
  SampledMesh, TargetMesh  RichMesh, value = index of the layer in load order: `-i a -i b` gives a = 0, b = 1.
  SaveSample               bool (false): adds two point-cloud layers with the samples and closest points.
  SampleVert (true), SampleEdge (false), SampleFauxEdge (false), SampleFace (false)   bools.
  SampleNum                int N (default: vertex count of the current mesh).
  MaxDist                  RichAbsPerc: the mlx value is ABSOLUTE, in scene units (the % is only a GUI view;
                           default = sampled mesh's bbox diagonal / 2). A sample whose closest point is
                           not within MaxDist is DROPPED: not counted in samples, min, max, mean or RMS
                           (checked: MaxDist 0.1 on a 74 mm part cut 264k samples to 163k, max = 0.099999).
                           This script passes 2 x the diagonal of the union of both bounding boxes, so
                           nothing is dropped. The bbox diagonal plays no other part in the figures.
One run samples the SampledMesh only, in this order, each with the same N (so about 3N samples in all):
  1 Vertex (VertexUniform): if N >= vertex count, every vertex record once (unreferenced vertices and
    duplicate positions included); otherwise a random subset of N distinct vertex records (shuffle).
  2 Edge (EdgeUniform): the unique edges of the FACES (FillUniqueEdgeVector: pairs of vertex indices, so
    an edge between two copies of a split vertex counts separately from its twin; PLY `edge` elements are
    loaded into the mesh's edge list but never sampled). With SampleFauxEdge = false the faux edges
    (internal diagonals of polygons MeshLab triangulated on import) are skipped; this script sets it true.
    Deterministic, no randomness (the edge order is a sort by vertex address): L = total edge length, step = L / N (float); walking the edges in
    sorted order with a carried remainder r, an edge of length l gets k = floor((l + r) / step) samples,
    r = l + r - k*step, placed at the evenly spaced interior points i/(k+1), i = 1..k (never on the
    vertices; short edges can get none). Total ~N (float rounding: 99,955 of 100,000 seen).
  3 Face (Montecarlo): exactly N points, triangle chosen with probability area / total area, uniform
    random barycentric point inside it. Zero-area triangles get none.
Samples are pooled: samples = (vertex + edge + face samples kept), min and max over all of them,
mean = sum(d) / samples, RMS = sqrt(sum(d^2) / samples), each sample weighted equally. So with vertex and
edge sampling on, mean and RMS are NOT area-weighted: they lean towards corners and edges, where the error
of a simplified mesh is largest, and they depend on N, because every vertex is sampled whatever N is
(measured, KiCad DSUB-62 part vs its lod3, A->B mean: 1.776 at N = 100k, 1.513 at N = 1M, 1.064 with
--faces-only at either N). The max is what vertex and edge samples are for (they hit the exact maxima at
corners). To agree within 5%: compare our max with this script's default run, and our area-weighted mean
and RMS with a --faces-only run (pure area-weighted Monte Carlo, N samples, converged to ~0.3% at 100k);
or mirror the pooled estimator exactly (same N, same vertex set: after welding, see above).
Distance: unsigned Euclidean distance from the sample to the closest point on the TargetMesh's TRIANGLES
(uniform grid + exact point-triangle distance). The target's vertices are used only when it has no faces
at all; its edges and points are ignored. Triangles with an exactly zero normal (degenerate) are treated
as the segment between their bounding box's min and max corners. All in float (CMeshO is float).
Output: nothing on stdout; meshlabserver's stderr gets (and `-l FILE` gets, repeated) the filter log:
     Sampled %i pts (rng: 0) on <sampled label> searched closest on <target label>
     min : %f   max %f   mean : %f   RMS : %f           <- absolute, what this script reads
  Values w.r.t. BBox Diag (%f)                           <- diagonal of the SAMPLED mesh
     min : %f   max %f   mean : %f   RMS : %f           <- the same divided by that diagonal
Random numbers: one Mersenne Twister with a fixed seed per process; the second filter of a script goes on
with the sequence the first one left. Runs are therefore repeatable bit for bit (checked, 3 runs each).
Spread over --seed 0..3 (input permutations), 4 model/LOD pairs: max within 0.5% at N = 100k and 0.03% at
1M; mean and RMS within 0.7% at 100k and 0.42% at 1M. meshlabserver takes 0.5-1.4 s at N = 100k and
3-7.5 s at N = 1M for 20k-94k triangle meshes (both directions, one process).
PLY import in MeshLab 2020.09: `vertex`, `face` (list uchar uint accepted) and `edge` (vertex1, vertex2 as
int; uint aborts, see above) elements are read; unknown elements and properties (lodstream's `point`,
`thickness`) are skipped; no cleaning, so vertices used only by edges or points stay and would be
vertex-sampled (--raw). Welding matters for the pooled figures: on the DSUB lod2, B->A mean 0.04093 as
written (5,617 vertex records) vs 0.04189 welded (1,662 positions); the max moved by 0.3%.
"""
import argparse
import json
import os
import random
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time

PLY_TYPES = {
    "char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
    "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
    "float": "f", "float32": "f", "double": "d", "float64": "d",
}


def read_ply(path):
    """Returns (positions [(x,y,z)], faces [(i,j,k,...)]) from a PLY file; other elements are skipped."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file")
    body = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in data[:end].decode("latin-1").splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if tok[1] == "list":
                elements[-1][2].append((tok[4], "list", PLY_TYPES[tok[2]], PLY_TYPES[tok[3]]))
            else:
                elements[-1][2].append((tok[2], PLY_TYPES[tok[1]], None, None))
    positions, faces = [], []
    if fmt == "ascii":
        words = data[body:].split()
        pos = 0
        for name, count, props in elements:
            for _ in range(count):
                row = {}
                for pname, kind, ctype, itype in props:
                    if kind == "list":
                        n = int(words[pos]); pos += 1
                        row[pname] = [int(w) for w in words[pos:pos + n]]; pos += n
                    else:
                        row[pname] = float(words[pos]); pos += 1
                if name == "vertex":
                    positions.append((row["x"], row["y"], row["z"]))
                elif name == "face":
                    faces.append(tuple(row.get("vertex_indices", row.get("vertex_index", []))))
        return positions, faces
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        raise ValueError(f"{path}: unknown PLY format {fmt}")
    bo = "<" if fmt == "binary_little_endian" else ">"
    pos = body
    for name, count, props in elements:
        if all(kind != "list" for _, kind, _, _ in props):
            rec = struct.Struct(bo + "".join(kind for _, kind, _, _ in props))
            if name == "vertex":
                names = [p[0] for p in props]
                ix, iy, iz = names.index("x"), names.index("y"), names.index("z")
                positions = [(r[ix], r[iy], r[iz]) for r in rec.iter_unpack(data[pos:pos + rec.size * count])]
            pos += rec.size * count
            continue
        # Fast path: a face element that is one list of triangles (lodstream and most writers).
        if name == "face" and len(props) == 1:
            _, _, ctype, itype = props[0]
            rec = struct.Struct(bo + ctype + "3" + itype)
            chunk = data[pos:pos + rec.size * count]
            if len(chunk) == rec.size * count and chunk[0::rec.size] == bytes([3]) * count and ctype in "bB":
                faces = [r[1:] for r in rec.iter_unpack(chunk)]
                pos += rec.size * count
                continue
        rows = []
        for _ in range(count):
            row = {}
            for pname, kind, ctype, itype in props:
                if kind == "list":
                    (n,) = struct.unpack_from(bo + ctype, data, pos); pos += struct.calcsize(ctype)
                    row[pname] = struct.unpack_from(bo + itype * n, data, pos); pos += struct.calcsize(itype) * n
                else:
                    (row[pname],) = struct.unpack_from(bo + kind, data, pos); pos += struct.calcsize(kind)
            rows.append(row)
        if name == "vertex":
            positions = [(r["x"], r["y"], r["z"]) for r in rows]
        elif name == "face":
            faces = [tuple(r.get("vertex_indices", r.get("vertex_index", ()))) for r in rows]
    return positions, faces


def read_obj(path):
    positions, faces = [], []
    with open(path, "r", errors="replace") as f:
        for line in f:
            if line.startswith("v "):
                x, y, z = line.split()[1:4]
                positions.append((float(x), float(y), float(z)))
            elif line.startswith("f "):
                idx = []
                for w in line.split()[1:]:
                    i = int(w.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(positions) + i)
                faces.append(tuple(idx))
    return positions, faces


def read_mesh(path):
    return read_obj(path) if path.lower().endswith(".obj") else read_ply(path)


def triangles_only(positions, faces, weld):
    """Fan-triangulates, drops faces with < 3 corners, welds identical positions, drops unused vertices."""
    remap, out_pos, tris = {}, [], []
    for f in faces:
        if len(f) < 3:
            continue
        ids = []
        for i in f:
            key = positions[i] if weld else i
            j = remap.get(key)
            if j is None:
                j = remap[key] = len(out_pos)
                out_pos.append(positions[i])
            ids.append(j)
        for k in range(1, len(ids) - 1):
            tris.append((ids[0], ids[k], ids[k + 1]))
    return out_pos, tris


def bbox(positions):
    lo = [min(p[i] for p in positions) for i in range(3)]
    hi = [max(p[i] for p in positions) for i in range(3)]
    return lo, hi


def diag(lo, hi):
    return sum((hi[i] - lo[i]) ** 2 for i in range(3)) ** 0.5


def write_ply(path, positions, tris, scale, rng):
    order = list(range(len(positions)))
    tris = list(tris)
    if rng is not None:
        rng.shuffle(order)
        rng.shuffle(tris)
    new_index = [0] * len(positions)
    for new, old in enumerate(order):
        new_index[old] = new
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        vrec = struct.Struct("<3f")
        f.write(b"".join(vrec.pack(*(c * scale for c in positions[old])) for old in order))
        frec = struct.Struct("<B3i")
        f.write(b"".join(frec.pack(3, new_index[a], new_index[b], new_index[c]) for a, b, c in tris))


MLX_FILTER = """ <filter name="Hausdorff Distance">
  <Param type="RichMesh" value="{sampled}" name="SampledMesh"/>
  <Param type="RichMesh" value="{target}" name="TargetMesh"/>
  <Param type="RichBool" value="false" name="SaveSample"/>
  <Param type="RichBool" value="{vert}" name="SampleVert"/>
  <Param type="RichBool" value="{edge}" name="SampleEdge"/>
  <Param type="RichBool" value="true" name="SampleFauxEdge"/>
  <Param type="RichBool" value="true" name="SampleFace"/>
  <Param type="RichInt" value="{n}" name="SampleNum"/>
  <Param type="RichAbsPerc" value="{maxdist!r}" min="0" max="{maxdist!r}" name="MaxDist"/>
 </filter>
"""

RESULT_RE = re.compile(
    r"Sampled (\d+) pts \(rng: \d+\) on (.+?) searched closest on (.+?)\s*\n"
    r"(?:LOG: \d+)?\s*min : (\S+)\s+max (\S+)\s+mean : (\S+)\s+RMS : (\S+)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a", help="mesh A (PLY or OBJ)")
    ap.add_argument("b", help="mesh B (PLY or OBJ)")
    ap.add_argument("-n", "--samples", type=int, default=100000, help="SampleNum N (default 100000)")
    ap.add_argument("--seed", type=int, default=0,
                    help="permute vertices and faces of the copies with this seed (0: keep the order)")
    ap.add_argument("--faces-only", action="store_true",
                    help="sample faces only (pure area-weighted Monte Carlo), no vertex and edge samples")
    ap.add_argument("--raw", action="store_true",
                    help="give MeshLab the input files themselves (PLY only): no copy, no weld, no scaling")
    ap.add_argument("--no-weld", action="store_true", help="keep duplicate positions as separate vertices")
    ap.add_argument("--scale", type=float, default=0,
                    help="scale factor for the copies (default: the power of two that puts the diagonal in [1024, 2048))")
    ap.add_argument("--keep", metavar="DIR", help="write the copies, script and log here and keep them")
    ap.add_argument("--timeout", type=float, default=1800, help="seconds before meshlabserver is stopped")
    args = ap.parse_args()

    missing = [t for t in ("meshlabserver", "xvfb-run") if shutil.which(t) is None]
    if missing:
        print(f"skipped: {' and '.join(missing)} not found (Debian: apt-get install meshlab xvfb xauth)",
              file=sys.stderr)
        return 77

    work = args.keep or tempfile.mkdtemp(prefix="meshlab_hausdorff_")
    os.makedirs(work, exist_ok=True)
    try:
        info = {}
        if args.raw:
            for p in (args.a, args.b):
                if not p.lower().endswith(".ply"):
                    raise ValueError("--raw needs PLY inputs")
            paths = [os.path.join(work, "A.ply"), os.path.join(work, "B.ply")]
            for src, dst in zip((args.a, args.b), paths):  # links: MeshLab names layers by file name
                os.symlink(os.path.abspath(src), dst)
            meshes = [read_mesh(p) for p in paths]
            scale = 1.0
            boxes = [bbox(m[0]) for m in meshes]
            for key, (pos, faces) in zip(("a", "b"), meshes):
                info[key] = {"vertices": len(pos), "faces": len(faces)}
        else:
            meshes = [triangles_only(*read_mesh(p), weld=not args.no_weld) for p in (args.a, args.b)]
            for p, (pos, tris) in zip((args.a, args.b), meshes):
                if not tris:
                    raise ValueError(f"{p}: no faces")
            boxes = [bbox(m[0]) for m in meshes]
            big = max(diag(*b) for b in boxes)
            scale = 1.0
            if args.scale:
                scale = args.scale
            elif big > 0:
                while big * scale >= 2048.0:
                    scale /= 2.0
                while big * scale < 1024.0:
                    scale *= 2.0
            rng = random.Random(args.seed) if args.seed else None
            paths = [os.path.join(work, "A.ply"), os.path.join(work, "B.ply")]
            for path, (pos, tris), key in zip(paths, meshes, ("a", "b")):
                write_ply(path, pos, tris, scale, rng)
                info[key] = {"vertices": len(pos), "triangles": len(tris)}
        lo = [min(boxes[0][0][i], boxes[1][0][i]) for i in range(3)]
        hi = [max(boxes[0][1][i], boxes[1][1][i]) for i in range(3)]
        maxdist = 2.0 * diag(lo, hi) * scale + 1.0
        for key, b in zip(("a", "b"), boxes):
            info[key]["bbox_diag"] = diag(*b)

        mlx = os.path.join(work, "hausdorff.mlx")
        with open(mlx, "w") as f:
            f.write("<!DOCTYPE FilterScript>\n<FilterScript>\n")
            ve = "false" if args.faces_only else "true"
            for sampled, target in ((0, 1), (1, 0)):
                f.write(MLX_FILTER.format(sampled=sampled, target=target, n=args.samples, maxdist=maxdist,
                                          vert=ve, edge=ve))
            f.write("</FilterScript>\n")
        log = os.path.join(work, "meshlab.log")
        cmd = ["xvfb-run", "-a", "meshlabserver", "-l", log, "-i", paths[0], "-i", paths[1], "-s", mlx]
        env = dict(os.environ)
        env.setdefault("XDG_RUNTIME_DIR", work)
        t0 = time.monotonic()
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env,
                              timeout=args.timeout, cwd=work)
        seconds = time.monotonic() - t0
        text = proc.stdout.decode("utf-8", "replace")
        if os.path.exists(log):
            with open(log, "r", errors="replace") as f:
                text += "\n" + f.read()
        labels = [os.path.basename(p) for p in paths]
        found = {}
        for m in RESULT_RE.finditer(text):
            n, sampled, target = int(m.group(1)), m.group(2), m.group(3)
            vals = [float(f"{float(v) / scale:.9g}") for v in m.group(4, 5, 6, 7)]
            found[(sampled, target)] = {"min": vals[0], "max": vals[1], "mean": vals[2], "rms": vals[3],
                                        "samples": n}
        a_to_b = found.get((labels[0], labels[1]))
        b_to_a = found.get((labels[1], labels[0]))
        if proc.returncode != 0 or a_to_b is None or b_to_a is None:
            sys.stderr.write(text[-4000:])
            print(f"error: meshlabserver exited {proc.returncode} without both Hausdorff results "
                  f"(command: {' '.join(cmd)})", file=sys.stderr)
            return 1
        out = {"a_to_b": a_to_b, "b_to_a": b_to_a, "meshlab_seconds": round(seconds, 3),
               "sample_num": args.samples, "faces_only": args.faces_only, "seed": args.seed, "raw": args.raw, "scale": scale,
               "max_dist": maxdist / scale, "a": info["a"], "b": info["b"]}
        print(json.dumps(out))
        return 0
    except (OSError, ValueError, KeyError, IndexError, struct.error, subprocess.TimeoutExpired) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Independent counts of a mesh file, written without looking at lodstream's readers, to check
`lodstream info --json` against. Standard library only.

Prints one JSON object: vertices (as stored: STL welded by exact position), vertices_welded, polygons,
triangles, degenerate, lines, face_segments, points, objects (objects owning at least one primitive).

The rule for a face (README, "Polygons"): its ring is the corners less every corner equal to the one
before it (cyclically, the first corner kept). A ring of one vertex is nothing; of two vertices, the line
segment it describes; of m >= 3 distinct vertices, m - 2 triangles; a ring that names a vertex twice
further on (it touches itself) gives the fan of its own order, each fan triangle naming a vertex twice
becoming the segment between its two vertices. `degenerate` counts the triangle slots a face lost, so that
sum(n - 2) over faces = triangles + degenerate.
"""
import json
import struct
import sys


def split_face(face):
    """(triangles, degenerate, segments) of one face of n >= 3 corners."""
    n = len(face)
    ring = [face[0]]
    for corner in face[1:]:
        if corner != ring[-1]:
            ring.append(corner)
    while len(ring) > 1 and ring[-1] == ring[0]:
        ring.pop()
    m = len(ring)
    if m <= 2:
        return 0, n - 2, 1 if m == 2 else 0
    if len(set(ring)) == m:
        return m - 2, n - m, 0
    triangles = segments = 0
    for i in range(1, m - 1):
        if len({ring[0], ring[i], ring[i + 1]}) == 3:
            triangles += 1
        else:
            segments += 1
    return triangles, n - m + segments, segments


def obj_counts(path):
    positions = []
    polygons = triangles = degenerate = lines = face_segments = points = 0
    used_objects = set()
    current = ""
    pending = ""
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("utf-8", "replace")
            if "#" in line:
                line = line[: line.index("#")]
            line = line.rstrip("\r\n").rstrip()
            if line.endswith("\\"):
                pending += line[:-1] + " "
                continue
            line, pending = pending + line, ""
            parts = line.split()
            if not parts:
                continue
            key = parts[0]
            if key == "v":
                positions.append(tuple(float(x) for x in parts[1:4]))
                continue
            if key in ("o", "g"):
                current = line.strip()[len(key):].strip()
                continue
            if key not in ("f", "l", "p"):
                continue
            refs = []
            for token in parts[1:]:
                i = int(token.split("/")[0])
                refs.append(i - 1 if i > 0 else len(positions) + i)
            if key == "f" and len(refs) == 2:
                key = "l"  # exporters write loose edges as two-corner faces: kept as a line segment
            if key == "f":
                polygons += 1
                k, d, segs = split_face(refs)
                triangles += k
                degenerate += d
                lines += segs
                face_segments += segs
                if k or segs:
                    used_objects.add(current)
            elif key == "l":
                segs = sum(1 for a, b in zip(refs, refs[1:]) if a != b)
                lines += segs
                if segs:
                    used_objects.add(current)
            else:
                points += len(refs)
                used_objects.add(current)
    return dict(vertices=len(positions), vertices_welded=len(set(positions)), polygons=polygons,
                triangles=triangles, degenerate=degenerate, lines=lines, face_segments=face_segments,
                points=points, objects=len(used_objects))


PLY_TYPES = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
             "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
             "float": "f", "float32": "f", "double": "d", "float64": "d"}


def ply_counts(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header") + len(b"end_header")
    while data[end:end + 1] in (b"\r", b"\n"):
        end += 1
        if data[end - 1:end] == b"\n":
            break
    header = data[:end].decode("ascii").splitlines()
    fmt = None
    elements = []
    for line in header:
        w = line.split()
        if not w:
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            elements.append((w[1], int(w[2]), []))
        elif w[0] == "property":
            elements[-1][2].append(w[1:])
    positions, faces, edges = [], [], []
    if fmt == "ascii":
        tokens = iter(data[end:].split())
        for name, count, props in elements:
            for _ in range(count):
                rec = {}
                for p in props:
                    if p[0] == "list":
                        n = int(next(tokens))
                        rec[p[3]] = [int(float(next(tokens))) for _ in range(n)]
                    else:
                        rec[p[1]] = float(next(tokens))
                collect(name, rec, positions, faces, edges)
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        at = end
        for name, count, props in elements:
            for _ in range(count):
                rec = {}
                for p in props:
                    if p[0] == "list":
                        cf, itf = PLY_TYPES[p[1]], PLY_TYPES[p[2]]
                        (n,) = struct.unpack_from(order + cf, data, at)
                        at += struct.calcsize(cf)
                        rec[p[3]] = list(struct.unpack_from(order + itf * n, data, at))
                        at += struct.calcsize(itf) * n
                    else:
                        tf = PLY_TYPES[p[0]]
                        (rec[p[1]],) = struct.unpack_from(order + tf, data, at)
                        at += struct.calcsize(tf)
                collect(name, rec, positions, faces, edges)
    triangles = degenerate = face_segments = 0
    edges += [(f[0], f[1]) for f in faces if len(f) == 2]  # two-index faces are kept as line segments
    faces = [f for f in faces if len(f) != 2]
    for face in faces:
        k, d, segs = split_face(face)
        triangles += k
        degenerate += d
        face_segments += segs
    lines = sum(1 for a, b in edges if a != b) + face_segments
    return dict(vertices=len(positions), vertices_welded=len(set(positions)), polygons=len(faces),
                triangles=triangles, degenerate=degenerate, lines=lines, face_segments=face_segments,
                points=0, objects=1 if triangles or lines else 0)


def collect(name, rec, positions, faces, edges):
    if name == "vertex":
        positions.append((float(rec["x"]) + 0.0, float(rec["y"]) + 0.0, float(rec["z"]) + 0.0))
    elif name == "face":
        faces.append(rec.get("vertex_indices", rec.get("vertex_index")))
    elif name == "edge":
        edges.append((int(rec["vertex1"]), int(rec["vertex2"])))


def stl_counts(path):
    with open(path, "rb") as f:
        data = f.read()
    corners = []
    objects = []
    if len(data) >= 84 and 84 + 50 * struct.unpack_from("<I", data, 80)[0] == len(data):
        (n,) = struct.unpack_from("<I", data, 80)
        for t in range(n):
            v = struct.unpack_from("<9f", data, 84 + 50 * t + 12)
            corners += [(v[0] + 0.0, v[1] + 0.0, v[2] + 0.0), (v[3] + 0.0, v[4] + 0.0, v[5] + 0.0),
                        (v[6] + 0.0, v[7] + 0.0, v[8] + 0.0)]
            objects.append("")
    else:
        name = ""
        for line in data.decode("utf-8", "replace").splitlines():
            w = line.split()
            if not w:
                continue
            k = w[0].lower()
            if k == "solid":
                name = line.strip()[5:].strip()
            elif k == "vertex":
                corners.append(tuple(float(x) + 0.0 for x in w[1:4]))
            elif k == "endfacet":
                objects.append(name)
    ids = {}
    for p in corners:
        ids.setdefault(p, len(ids))
    triangles = degenerate = 0
    used = set()
    for t in range(len(corners) // 3):
        a, b, c = (ids[corners[3 * t + k]] for k in range(3))
        if a == b or b == c or a == c:
            degenerate += 1
        else:
            triangles += 1
            used.add(objects[t])
    # STL has no indices: a facet with two equal corners is a sliver the welding found, dropped as before.
    return dict(vertices=len(ids), vertices_welded=len(ids), polygons=len(corners) // 3,
                triangles=triangles, degenerate=degenerate, lines=0, face_segments=0, points=0,
                objects=len(used))


def counts(path):
    lower = path.lower()
    if lower.endswith(".obj"):
        return obj_counts(path)
    if lower.endswith(".ply"):
        return ply_counts(path)
    if lower.endswith(".stl"):
        return stl_counts(path)
    raise SystemExit("unknown format: " + path)


if __name__ == "__main__":
    print(json.dumps(counts(sys.argv[1])))

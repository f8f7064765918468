#!/usr/bin/env python3
"""Build tests/data/sample-room.ply: a furnished living room / home office made only of real models.

Every mesh in the scene is a real CC0 model from the Sweet Home 3D BlendSwap-CC-0 furniture library
(Debian package sweethome3d-furniture), read from the OBJ files of the project's shared test data
(../shared/data/furniture-cc0 beside the repository). Nothing is invented: there are no walls, no floor and
no procedural shapes. Each model is placed by a rigid transform only:

  1. Y-up to Z-up:  (x, y, z) -> (x, -z, y)   (a proper rotation, so handedness and winding are kept)
  2. centimetres to metres: divide by 100
  3. the model's footprint is centred on the origin and its lowest point put at z = 0
  4. rotation about +Z by the angle of the layout entry (counter-clockwise, degrees)
  5. translation to the layout position; an object standing on another one (a lamp on a table) is
     lowered onto the highest horizontal face of its support found under it

Every face of every chosen model is kept, degenerate and duplicate ones included: this is a test file for a
LOD tool and the point is real data. Polygons are kept as polygons (PLY face lists); only polygons of more
than 255 corners, which a uchar count cannot hold, are fan-triangulated. Face lines of OBJ with fewer than
3 corners have no area in any sense and are skipped (they are counted and reported). Unreferenced vertices of
a model are kept too, so every vertex of a chosen model is in the output.

The output is binary little-endian PLY: float x, y, z per vertex and `list uchar int vertex_indices` per
face, in metres, Z up. The script is deterministic: the same input gives the same bytes on every run.

usage: python3 tools/make_sample_scene.py [FURNITURE_DIR] [-o OUT.ply]
"""

import argparse
import math
import os
import struct
import sys
from array import array

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_FURNITURE = os.path.join(REPO, "..", "shared", "data", "furniture-cc0")
DEFAULT_OUT = os.path.join(REPO, "tests", "data", "sample-room.ply")
MAX_BYTES = 5 * 1000 * 1000          # the file must stay at most 5 MB
TRIANGLE_RANGE = (200_000, 300_000)  # wanted size of the scene, in triangles after fan triangulation

# The room: about 7.2 m (x, west to east) by 5.6 m (y, south to north), floor at z = 0, corner at the origin.
# Living area in the west half (TV on the north wall, sofa facing it), a desk and shelves in the north-east,
# a second desk on the east wall and a dining table in the south-east.  Before rotation a model's front looks
# toward -Y (Sweet Home 3D models face +Z in their Y-up frame); a rotation of 90 turns it toward +X, 180
# toward +Y, 270 toward -X.  Chairs stand pulled out, clear of their tables, so no two bounding boxes meet.
#
# Entry: (name, model folder, x, y, rotation in degrees, support name or None)
#   x, y     centre of the footprint in metres (for an object on a support, the point it stands on)
#   support  an earlier entry's name: the object stands on the highest horizontal face of that entry under it
LAYOUT = [
    # --- living area (west half): sofa facing the TV on the north wall, two armchairs around a low table
    ("tv_stand",      "shelves",         1.80, 5.405,   0, None),
    ("tv",            "led_tv",          1.80, 5.42,    0, "tv_stand"),
    ("speaker_left",  "speaker3",        1.15, 5.45,    0, None),
    ("speaker_right", "speaker3",        2.45, 5.45,    0, None),
    ("bookcase_west", "bookcase",        0.50, 5.42,    0, None),
    ("palm",          "plant",           3.20, 5.20,   30, None),
    ("sofa",          "couch",           1.80, 2.60,  180, None),
    ("low_table",     "bedsideTable2",   1.80, 3.75,   45, None),
    ("armchair_west", "armchair2",       0.55, 3.90,   90, None),
    ("armchair_east", "armchair2",       3.05, 3.90,  270, None),
    ("side_table",    "bedsideTable2",   0.45, 2.60,    0, None),
    ("floor_lantern", "lantern",         3.15, 2.60,    0, None),
    ("pot_plant",     "littlePlant",     0.45, 2.60,    0, "side_table"),
    ("cards",         "cardGame",        1.74, 3.80,   20, "low_table"),
    ("coffee",        "caffe_final",     1.88, 3.66,    0, "low_table"),
    # --- office (north-east): a desk with a swivel chair, cabinet, shelves on the east wall
    ("desk_main",     "lbDesk",          5.00, 5.20,    0, None),
    ("desk_chair",    "designChair",     5.00, 4.43,  165, None),
    ("drawers",       "drawersCabinet",  6.20, 5.29,    0, None),
    ("bookcase_east", "bookcase",        7.02, 5.00,  270, None),
    ("tall_shelves",  "verticalShelves", 7.005, 3.95, 270, None),
    ("bin",           "dustbin",         4.00, 5.35,    0, None),
    ("briefcase",     "briefcase",       6.30, 4.00,  -15, None),
    ("desk_lamp",     "desklamp",        4.45, 5.38,    0, "desk_main"),
    ("headphones",    "headphones",      4.80, 5.42,   90, "desk_main"),
    ("calendar",      "kalender",        5.62, 5.45,  -20, "desk_main"),
    ("cactus",        "cactus",          5.35, 5.45,    0, "desk_main"),
    ("marker",        "textMarker",      5.15, 5.00,   60, "desk_main"),
    ("scissors",      "cissors_swap",    5.45, 5.05,   10, "desk_main"),
    # --- second workplace on the east wall: a computer desk with a hutch and a chair
    ("desk_hutch",    "desk",            6.93, 2.90,  270, None),
    ("hutch_chair",   "osakaChair",      6.20, 2.90,   90, None),
    ("hutch_lamp",    "desklamp",        6.95, 3.40,    0, "desk_hutch"),
    ("ruler",         "ruler",           6.85, 3.05,   90, "desk_hutch"),
    # --- dining (south-east): a round table, four chairs, drinks on the table
    ("dining_table",  "oakTable",        5.00, 1.20,    0, None),
    ("chair_south",   "chair2",          5.00, 0.30,  180, None),
    ("chair_north",   "chair2",          5.00, 2.10,    0, None),
    ("chair_west",    "chair2",          4.10, 1.20,   90, None),
    ("chair_east",    "chair2",          5.90, 1.20,  270, None),
    ("glass_1",       "beerGlass",       4.80, 1.05,   30, "dining_table"),
    ("glass_2",       "beerGlass",       5.20, 1.40,  200, "dining_table"),
    ("milk",          "tetrapak",        5.05, 1.25,    0, "dining_table"),
]


# ----------------------------------------------------------------------------------------------- OBJ input

class ObjError(Exception):
    pass


def read_obj(path):
    """Return (vertices, faces, skipped) of an OBJ file.

    vertices: flat list [x0, y0, z0, x1, ...] as read (floats); faces: list of tuples of 0-based indices;
    skipped: number of `f` statements with fewer than 3 corners.  Reads `v` (first three coordinates; an
    optional w or colour after them is ignored) and `f` with any of the forms v, v/vt, v//vn, v/vt/vn and
    negative (relative) indices.  Every other statement (vt, vn, o, g, s, usemtl, mtllib, l, p, ...) is
    skipped.  Lines ending with a backslash continue on the next line.
    """
    verts = []
    faces = []
    skipped = 0
    with open(path, "rb") as fh:
        data = fh.read()
    lines = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
    pending = b""
    for lineno, raw in enumerate(lines, 1):
        line = pending + raw
        if line.endswith(b"\\"):
            pending = line[:-1] + b" "
            continue
        pending = b""
        hash_at = line.find(b"#")
        if hash_at >= 0:
            line = line[:hash_at]
        tok = line.split()
        if not tok:
            continue
        kind = tok[0]
        if kind == b"v":
            if len(tok) < 4:
                raise ObjError("%s:%d: vertex with fewer than 3 coordinates" % (path, lineno))
            try:
                verts.append(float(tok[1]))
                verts.append(float(tok[2]))
                verts.append(float(tok[3]))
            except ValueError:
                raise ObjError("%s:%d: bad vertex coordinate" % (path, lineno))
        elif kind == b"f":
            nv = len(verts) // 3
            poly = []
            for t in tok[1:]:
                head = t.split(b"/", 1)[0]
                try:
                    k = int(head)
                except ValueError:
                    raise ObjError("%s:%d: bad face index %r" % (path, lineno, t))
                if k > 0:
                    k -= 1
                elif k < 0:
                    k += nv
                    if k < 0:
                        raise ObjError("%s:%d: relative index %d before the first vertex" % (path, lineno, int(head)))
                else:
                    raise ObjError("%s:%d: face index 0" % (path, lineno))
                poly.append(k)
            if len(poly) < 3:
                skipped += 1
                continue
            faces.append(tuple(poly))
    nv = len(verts) // 3
    for f in faces:
        for k in f:
            if k >= nv:
                raise ObjError("%s: face index %d past the last vertex (%d vertices)" % (path, k + 1, nv))
    return verts, faces, skipped


def find_obj(furniture_dir, folder):
    d = os.path.join(furniture_dir, folder)
    if not os.path.isdir(d):
        raise ObjError("model folder not found: %s" % d)
    named = os.path.join(d, folder + ".obj")
    if os.path.isfile(named):
        return named
    objs = sorted(f for f in os.listdir(d) if f.lower().endswith(".obj"))
    if not objs:
        raise ObjError("no OBJ file in %s" % d)
    return os.path.join(d, objs[0])


class Model:
    """One model in Z-up metres, footprint centred on the origin, standing on z = 0."""

    def __init__(self, furniture_dir, folder):
        self.folder = folder
        self.path = find_obj(furniture_dir, folder)
        raw, self.faces, self.skipped = read_obj(self.path)
        n = len(raw) // 3
        # Y-up centimetres -> Z-up metres: (x, y, z) -> (x, -z, y) / 100
        xs = [raw[3 * i] / 100.0 for i in range(n)]
        ys = [-raw[3 * i + 2] / 100.0 for i in range(n)]
        zs = [raw[3 * i + 1] / 100.0 for i in range(n)]
        # Place by the referenced vertices, so that a stray unreferenced vertex cannot move the model.
        used = sorted(set(k for f in self.faces for k in f))
        if not used:
            raise ObjError("%s has no faces" % self.path)
        lo = [min(xs[i] for i in used), min(ys[i] for i in used), min(zs[i] for i in used)]
        hi = [max(xs[i] for i in used), max(ys[i] for i in used), max(zs[i] for i in used)]
        cx, cy, cz = (lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, lo[2]
        self.x = [v - cx for v in xs]
        self.y = [v - cy for v in ys]
        self.z = [v - cz for v in zs]
        self.size = (hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])
        self.triangles = sum(len(f) - 2 for f in self.faces)

    @property
    def nverts(self):
        return len(self.x)


# ----------------------------------------------------------------------------------------------- placement

def cos_sin(deg):
    """cos and sin of an angle in degrees, exact for multiples of 90 and correctly rounded for 30/45/60 steps."""
    d = deg % 360
    exact = {0: (1.0, 0.0), 90: (0.0, 1.0), 180: (-1.0, 0.0), 270: (0.0, -1.0)}
    if d in exact:
        return exact[d]
    h = math.sqrt(0.5)
    r3 = math.sqrt(3.0) / 2.0
    table = {30: (r3, 0.5), 45: (h, h), 60: (0.5, r3), 120: (-0.5, r3), 135: (-h, h), 150: (-r3, 0.5),
             210: (-r3, -0.5), 225: (-h, -h), 240: (-0.5, -r3), 300: (0.5, -r3), 315: (h, -h), 330: (r3, -0.5)}
    if d in table:
        return table[d]
    a = math.radians(d)
    return math.cos(a), math.sin(a)


class Instance:
    def __init__(self, name, model, x, y, rot, support):
        self.name, self.model, self.rot, self.support = name, model, rot, support
        self.tx, self.ty, self.tz = x, y, 0.0
        self.c, self.s = cos_sin(rot)
        m = model
        c, s = self.c, self.s
        # rotated, not yet translated
        self.rx = [c * px - s * py for px, py in zip(m.x, m.y)]
        self.ry = [s * px + c * py for px, py in zip(m.x, m.y)]

    def world(self):
        return ([v + self.tx for v in self.rx], [v + self.ty for v in self.ry], [v + self.tz for v in self.model.z])

    def bbox(self):
        used = self.model_used()
        xs, ys, zs = self.rx, self.ry, self.model.z
        lo = (min(xs[i] for i in used) + self.tx, min(ys[i] for i in used) + self.ty, min(zs[i] for i in used) + self.tz)
        hi = (max(xs[i] for i in used) + self.tx, max(ys[i] for i in used) + self.ty, max(zs[i] for i in used) + self.tz)
        return lo, hi

    def model_used(self):
        m = self.model
        if not hasattr(m, "_used"):
            m._used = sorted(set(k for f in m.faces for k in f))
        return m._used


def surface_below(support, px, py):
    """Height of the highest near-horizontal face of `support` (placed) above the point (px, py), or None."""
    xs, ys, zs = support.world()
    best = None
    for f in support.model.faces:
        a = f[0]
        for j in range(1, len(f) - 1):
            b, c = f[j], f[j + 1]
            ax, ay, az = xs[a], ys[a], zs[a]
            e1x, e1y, e1z = xs[b] - ax, ys[b] - ay, zs[b] - az
            e2x, e2y, e2z = xs[c] - ax, ys[c] - ay, zs[c] - az
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nn == 0.0 or abs(nz) < 0.95 * nn:
                continue
            den = e1x * e2y - e2x * e1y
            if den == 0.0:
                continue
            qx, qy = px - ax, py - ay
            u = (qx * e2y - e2x * qy) / den
            v = (e1x * qy - qx * e1y) / den
            if u < 0.0 or v < 0.0 or u + v > 1.0:
                continue
            z = az + u * e1z + v * e2z
            if best is None or z > best:
                best = z
    return best


def place_on(item, support):
    """Stand `item` on the highest horizontal face of `support` under its footprint (centre and corners)."""
    lo, hi = item.bbox()
    cx, cy = item.tx, item.ty
    hx, hy = 0.6 * (hi[0] - lo[0]) / 2.0, 0.6 * (hi[1] - lo[1]) / 2.0
    mx, my = (lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0
    heights = []
    for px, py in ((cx, cy), (mx - hx, my - hy), (mx + hx, my - hy), (mx - hx, my + hy), (mx + hx, my + hy)):
        z = surface_below(support, px, py)
        if z is None:
            raise SystemExit("layout error: %s is not fully on %s (nothing under %.3f, %.3f)"
                             % (item.name, support.name, px, py))
        heights.append(z)
    item.tz = max(heights)


def overlap(a, b, axes=3):
    alo, ahi = a
    blo, bhi = b
    vol = 1.0
    for k in range(axes):
        d = min(ahi[k], bhi[k]) - max(alo[k], blo[k])
        if d <= 0.0:
            return 0.0
        vol *= d
    return vol


def check_layout(instances):
    """No gross overlaps: bounding boxes of different objects may not intersect, except an object and its
    support; an object on a support must stand inside the support's footprint."""
    boxes = {i.name: i.bbox() for i in instances}
    problems = []
    for n, a in enumerate(instances):
        for b in instances[n + 1:]:
            if a.support == b.name or b.support == a.name:
                continue
            v = overlap(boxes[a.name], boxes[b.name])
            if v > 1e-6:
                problems.append("%s and %s overlap (%.4f m3 of bounding box)" % (a.name, b.name, v))
        if a.support:
            (lo, hi), (slo, shi) = boxes[a.name], boxes[a.support]
            if lo[0] < slo[0] or lo[1] < slo[1] or hi[0] > shi[0] or hi[1] > shi[1]:
                problems.append("%s sticks out of its support %s" % (a.name, a.support))
    if problems:
        raise SystemExit("layout error:\n  " + "\n  ".join(problems))


# ----------------------------------------------------------------------------------------------- output

def build(furniture_dir, layout):
    models = {}
    instances = []
    by_name = {}
    for name, folder, x, y, rot, support in layout:
        if folder not in models:
            models[folder] = Model(furniture_dir, folder)
        if name in by_name:
            raise SystemExit("layout error: duplicate name %s" % name)
        inst = Instance(name, models[folder], x, y, rot, support)
        if support is not None:
            if support not in by_name:
                raise SystemExit("layout error: %s stands on %s, which is not placed before it" % (name, support))
            place_on(inst, by_name[support])
        by_name[name] = inst
        instances.append(inst)
    check_layout(instances)
    return models, instances


def ply_bytes(models, instances, comments):
    verts = array("f")
    body = bytearray()
    nfaces = 0
    ntris = 0
    base = 0
    for inst in instances:
        xs, ys, zs = inst.world()
        for v in zip(xs, ys, zs):
            verts.extend(v)
        for f in inst.model.faces:
            n = len(f)
            if n <= 255:
                body += struct.pack("<B%di" % n, n, *[base + k for k in f])
                nfaces += 1
            else:  # a uchar count cannot hold it: fan-triangulate this polygon only
                for j in range(1, n - 1):
                    body += struct.pack("<B3i", 3, base + f[0], base + f[j], base + f[j + 1])
                    nfaces += 1
            ntris += n - 2
        base += inst.model.nverts
    if sys.byteorder != "little":
        verts.byteswap()
    header = ["ply", "format binary_little_endian 1.0"]
    header += ["comment " + c for c in comments]
    header += ["element vertex %d" % base, "property float x", "property float y", "property float z",
               "element face %d" % nfaces, "property list uchar int vertex_indices", "end_header"]
    head = ("\n".join(header) + "\n").encode("ascii")
    return head + verts.tobytes() + bytes(body), base, nfaces, ntris


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("furniture_dir", nargs="?", default=DEFAULT_FURNITURE,
                    help="folder of the furniture-cc0 models (default: ../shared/data/furniture-cc0 beside the repository)")
    ap.add_argument("-o", "--output", default=DEFAULT_OUT, help="output PLY (default: tests/data/sample-room.ply)")
    args = ap.parse_args(argv)

    models, instances = build(args.furniture_dir, LAYOUT)

    counts = {}
    for inst in instances:
        counts[inst.model.folder] = counts.get(inst.model.folder, 0) + 1
    listing = " ".join("%s*%d" % (k, counts[k]) for k in sorted(counts, key=str.lower))
    comments = [
        "lodstream sample scene: a furnished living room and home office, metres, Z up",
        "made by tools/make_sample_scene.py from real models only, by rigid instancing",
        "source: Sweet Home 3D BlendSwap-CC-0 furniture library (Debian sweethome3d-furniture), CC0 1.0",
        "models (folder*instances): " + listing,
    ]
    data, nv, nf, nt = ply_bytes(models, instances, comments)
    if len(data) > MAX_BYTES:
        raise SystemExit("output would be %d bytes, more than %d" % (len(data), MAX_BYTES))
    if not TRIANGLE_RANGE[0] <= nt <= TRIANGLE_RANGE[1]:
        raise SystemExit("scene has %d triangles, outside %d..%d" % (nt, TRIANGLE_RANGE[0], TRIANGLE_RANGE[1]))
    out_dir = os.path.dirname(os.path.abspath(args.output))
    os.makedirs(out_dir, exist_ok=True)
    with open(args.output, "wb") as fh:
        fh.write(data)

    skipped = sum(m.skipped for m in models.values())
    lo = [min(i.bbox()[0][k] for i in instances) for k in range(3)]
    hi = [max(i.bbox()[1][k] for i in instances) for k in range(3)]
    print("wrote %s: %d bytes, %d vertices, %d faces, %d triangles after fan triangulation"
          % (args.output, len(data), nv, nf, nt))
    print("%d instances of %d models; %d OBJ face lines of fewer than 3 corners skipped"
          % (len(instances), len(models), skipped))
    print("bounding box (m): x %.3f..%.3f  y %.3f..%.3f  z %.3f..%.3f"
          % (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    for k in sorted(counts, key=str.lower):
        m = models[k]
        print("  %-22s x%d  %7d triangles each  %.2f x %.2f x %.2f m"
              % (k, counts[k], m.triangles, m.size[0], m.size[1], m.size[2]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Writes tests/data/grids/sample-room-heights.asc: a top-down range grid of tests/data/sample-room.ply.

Real range data for `lodstream grid` (tests/test_grid.cpp): the furnished room seen straight from above,
one sample every 6 cm, each the height (metres, millimetre precision) of the highest surface a vertical
ray through the sample's centre hits, or NODATA where the ray hits nothing (the scene has no floor). Its
steps (table tops, shelves, chair backs) give large polygons with many extra vertices. The faces are
fan-triangulated for the rays; an edge hit counts. Standard library only, deterministic.
Usage: tests/tools/make_room_grid.py [ROOM.ply [OUT.asc]]
"""
import math
import os
import struct
import sys

here = os.path.dirname(os.path.abspath(__file__))
src = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "data", "sample-room.ply")
out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(here, "..", "data", "grids", "sample-room-heights.asc")
CELL = 0.06
X0, Y0 = 0.0, 0.0  # centre of the south-west sample
NCOLS, NROWS = 122, 95  # x 0 .. 7.26 m, y 0 .. 5.64 m: the room's bounding box (7.202 x 5.602) and a margin
NODATA = -1

with open(src, "rb") as f:
    data = f.read()
end = data.index(b"end_header\n") + len(b"end_header\n")
header = data[:end].decode().splitlines()
counts = {}
for line in header:
    p = line.split()
    if p[0] == "element":
        counts[p[1]] = int(p[2])
assert "property float x" in header and "property list uchar int vertex_indices" in header, "unexpected layout"
nv, nf = counts["vertex"], counts["face"]
xyz = struct.unpack_from("<%df" % (3 * nv), data, end)
at = end + 12 * nv

top = [[None] * NCOLS for _ in range(NROWS)]


def ray(a, b, c):
    ax, ay, az = xyz[3 * a:3 * a + 3]
    bx, by, bz = xyz[3 * b:3 * b + 3]
    cx, cy, cz = xyz[3 * c:3 * c + 3]
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    if area == 0:
        return  # vertical: a ray from above grazes it, the faces around it give the height
    i0 = max(0, math.ceil((min(ax, bx, cx) - X0) / CELL))
    i1 = min(NCOLS - 1, math.floor((max(ax, bx, cx) - X0) / CELL))
    r0 = max(0, math.ceil((min(ay, by, cy) - Y0) / CELL))
    r1 = min(NROWS - 1, math.floor((max(ay, by, cy) - Y0) / CELL))
    for r in range(r0, r1 + 1):
        y = Y0 + r * CELL
        for i in range(i0, i1 + 1):
            x = X0 + i * CELL
            wa = ((cx - bx) * (y - by) - (cy - by) * (x - bx)) / area
            wb = ((ax - cx) * (y - cy) - (ay - cy) * (x - cx)) / area
            wc = 1 - wa - wb
            if wa < 0 or wb < 0 or wc < 0:
                continue
            z = wa * az + wb * bz + wc * cz
            row = top[NROWS - 1 - r]
            if row[i] is None or z > row[i]:
                row[i] = z


for _ in range(nf):
    n = data[at]
    ids = struct.unpack_from("<%di" % n, data, at + 1)
    at += 1 + 4 * n
    for k in range(1, n - 1):
        ray(ids[0], ids[k], ids[k + 1])

lines = ["ncols %d" % NCOLS, "nrows %d" % NROWS, "xllcenter %g" % X0, "yllcenter %g" % Y0, "cellsize %g" % CELL,
         "NODATA_value %d" % NODATA]
for row in top:
    lines.append(" ".join(str(NODATA) if z is None else "%.3f" % max(z, 0.0) for z in row))
with open(out, "w") as f:
    f.write("\n".join(lines) + "\n")

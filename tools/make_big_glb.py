#!/usr/bin/env python3
"""Writes a synthetic GLB for memory measurements of the glTF reader: one N x N grid mesh (float32
positions, uint32 TRIANGLES indices) drawn by two nodes (the second translated), written in row blocks so
the script itself stays small. N=3000 gives about 330 MB (9 M vertices, 18 M triangles per instance).
Usage: tools/make_big_glb.py OUT.glb [N]
"""
import json
import struct
import sys
from array import array

out, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 3000
nv, nt = n * n, 2 * (n - 1) * (n - 1)
vbytes, ibytes = 12 * nv, 12 * nt
doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
       "nodes": [{"name": "grid", "mesh": 0}, {"name": "grid moved", "mesh": 0, "translation": [0, 0, 10]}],
       "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
       "accessors": [{"bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3",
                      "min": [0, 0, 0], "max": [n - 1, n - 1, 0]},
                     {"bufferView": 1, "componentType": 5125, "count": 3 * nt, "type": "SCALAR"}],
       "bufferViews": [{"buffer": 0, "byteLength": vbytes}, {"buffer": 0, "byteOffset": vbytes, "byteLength": ibytes}],
       "buffers": [{"byteLength": vbytes + ibytes}]}
text = json.dumps(doc).encode()
text += b" " * (-len(text) % 4)
total = 12 + 8 + len(text) + 8 + vbytes + ibytes
with open(out, "wb") as f:
    f.write(struct.pack("<4sII", b"glTF", 2, total))
    f.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
    f.write(struct.pack("<II", vbytes + ibytes, 0x004E4942))
    for y in range(n):
        row = array("f", [0.0]) * (3 * n)
        row[0::3] = array("f", range(n))
        row[1::3] = array("f", [float(y)] * n)
        f.write(row.tobytes())
    for y in range(n - 1):
        a = array("I", range(y * n, y * n + n - 1))
        b = array("I", (i + 1 for i in a))
        c = array("I", (i + n for i in a))
        d = array("I", (i + n + 1 for i in a))
        tri = array("I", [0]) * (6 * (n - 1))
        tri[0::6], tri[1::6], tri[2::6], tri[3::6], tri[4::6], tri[5::6] = a, b, c, b, d, c
        f.write(tri.tobytes())

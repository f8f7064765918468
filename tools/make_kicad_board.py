#!/usr/bin/env python3
"""Builds a small KiCad board as a glTF 2.0 scene (GLB) from real KiCad 3D models: a green FR-4 board with
components placed on it, each component one glTF mesh drawn by several nodes (instancing), its parts one
primitive per VRML material, with the VRML diffuseColor/transparency as the glTF base colour.

The models come from Debian's kicad-packages3d (KiCad 6 library, VRML 2.0 as written by kicad StepUp):
fetched with `apt-get download` and the few files needed extracted with dpkg-deb, or read from --models
DIR (a directory holding the .wrl files). Only the subset of VRML that StepUp writes is read: Shape nodes
with `appearance Appearance { material DEF name Material { diffuseColor r g b transparency t ... } }` or
`material USE name`, and `geometry IndexedFaceSet { coordIndex [...] coord Coordinate { point [...] } }`;
polygons are split as fans. VRML units are 0.1 inch: positions are scaled to millimetres.

Usage: tools/make_kicad_board.py OUT.glb [--models DIR]
Licence of the models: CC-BY-SA 4.0 with the KiCad library exception (see tests/data/gltf/LICENSE.md).
"""
import json
import os
import re
import struct
import subprocess
import sys
import tempfile

MODELS = [
    "Resistor_SMD.3dshapes/R_0603_1608Metric.wrl",
    "Capacitor_SMD.3dshapes/C_0603_1608Metric.wrl",
    "LED_SMD.3dshapes/LED_0603_1608Metric.wrl",
    "Package_SO.3dshapes/SOIC-8_3.9x4.9mm_P1.27mm.wrl",
    "Package_TO_SOT_SMD.3dshapes/SOT-23.wrl",
    "Connector_PinHeader_2.54mm.3dshapes/PinHeader_1x04_P2.54mm_Vertical.wrl",
]
# (model index, x mm, y mm, rotation about z in quarter turns): a 40 x 30 mm board.
PLACEMENT = (
    [(0, 4 + 3 * i, 4, 0) for i in range(8)] +          # R1-R8
    [(1, 4 + 3 * i, 8, 0) for i in range(8)] +          # C1-C8
    [(2, 4 + 3 * i, 12, 1) for i in range(4)] +         # D1-D4, turned
    [(3, 10, 20, 0), (3, 20, 20, 1)] +                  # U1, U2
    [(4, 28, 13, 0), (4, 32, 13, 2), (4, 28, 17, 3)] +  # Q1-Q3
    [(5, 35, 24, 0)]                                    # J1
)
INCH_TENTH_MM = 2.54


def fetch(models_dir):
    if models_dir:
        return models_dir
    tmp = tempfile.mkdtemp(prefix="kicad3d.")
    subprocess.run(["apt-get", "download", "kicad-packages3d"], cwd=tmp, check=True, stdout=subprocess.DEVNULL)
    deb = [f for f in os.listdir(tmp) if f.endswith(".deb")][0]
    members = ["./usr/share/kicad/3dmodels/" + m for m in MODELS]
    tar = subprocess.Popen(["dpkg-deb", "--fsys-tarfile", os.path.join(tmp, deb)], stdout=subprocess.PIPE)
    subprocess.run(["tar", "-x", "-C", tmp] + members, stdin=tar.stdout, check=True)
    tar.wait()
    return os.path.join(tmp, "usr/share/kicad/3dmodels")


def parse_wrl(text):
    """Returns (materials {name: (rgba)}, shapes [(material name, positions [x,y,z...], triangles [i...])])."""
    text = re.sub(r"#[^\n]*", "", text)
    materials, shapes = {}, []
    for m in re.finditer(r"DEF\s+(\S+)\s+Material\s*\{([^}]*)\}", text):
        body = m.group(2)
        d = re.search(r"diffuseColor\s+([-\d.eE+]+)\s+([-\d.eE+]+)\s+([-\d.eE+]+)", body)
        t = re.search(r"transparency\s+([-\d.eE+]+)", body)
        rgb = [float(x) for x in d.groups()] if d else [0.8, 0.8, 0.8]
        materials[m.group(1)] = rgb + [1 - float(t.group(1)) if t else 1.0]
    for s in re.finditer(r"IndexedFaceSet\s*\{(.*?)\}\s*\}\s*appearance\s+Appearance\s*\{\s*material\s+USE\s+(\S+)\s*\}",
                         text, re.S):
        body, mat = s.group(1), s.group(2)
        idx = [int(x) for x in re.search(r"coordIndex\s*\[([^\]]*)\]", body).group(1).replace(",", " ").split()]
        pts = [float(x) * INCH_TENTH_MM for x in re.search(r"point\s*\[([^\]]*)\]", body).group(1).replace(",", " ").split()]
        tris, poly = [], []
        for i in idx + [-1]:
            if i >= 0:
                poly.append(i)
                continue
            for k in range(1, len(poly) - 1):
                tris += [poly[0], poly[k], poly[k + 1]]
            poly = []
        shapes.append((mat, pts, tris))
    return materials, shapes


def main():
    args = sys.argv[1:]
    if not args or args[0].startswith("-"):
        sys.exit(__doc__)
    out = args[0]
    models_dir = args[args.index("--models") + 1] if "--models" in args else None
    root = fetch(models_dir)
    bin_ = bytearray()
    doc = {"asset": {"version": "2.0", "generator": "lodstream tools/make_kicad_board.py",
                     "copyright": "KiCad 3D models, CC-BY-SA 4.0 with the KiCad library exception"},
           "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
           "accessors": [], "bufferViews": [], "buffers": []}
    mat_ids = {}

    def material(name, rgba):
        key = (name, tuple(round(c, 4) for c in rgba))
        if key not in mat_ids:
            m = {"name": name, "pbrMetallicRoughness": {"baseColorFactor": rgba, "metallicFactor": 0.0,
                                                        "roughnessFactor": 0.6}, "doubleSided": True}
            if rgba[3] < 1:
                m["alphaMode"] = "BLEND"
            mat_ids[key] = len(doc["materials"])
            doc["materials"].append(m)
        return mat_ids[key]

    def add_view(data, target):
        while len(bin_) % 4:
            bin_.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data), "target": target})
        bin_.extend(data)
        return len(doc["bufferViews"]) - 1

    def primitive(pts, tris, mat):
        used = sorted(set(tris))
        remap = {v: i for i, v in enumerate(used)}
        p = [c for v in used for c in pts[3 * v:3 * v + 3]]
        lo = [min(p[k::3]) for k in range(3)]
        hi = [max(p[k::3]) for k in range(3)]
        pv = add_view(struct.pack("<%df" % len(p), *p), 34962)
        doc["accessors"].append({"bufferView": pv, "componentType": 5126, "count": len(used), "type": "VEC3",
                                 "min": lo, "max": hi})
        iv = add_view(struct.pack("<%dI" % len(tris), *[remap[v] for v in tris]), 34963)
        doc["accessors"].append({"bufferView": iv, "componentType": 5125, "count": len(tris), "type": "SCALAR"})
        n = len(doc["accessors"])
        return {"attributes": {"POSITION": n - 2}, "indices": n - 1, "material": mat}

    # The board: a 40 x 30 x 1.6 mm box, top at z = 0 (the components' VRML origin is the board's top).
    bx, by, bz = 40.0, 30.0, -1.6
    corners = [x for z in (bz, 0.0) for y in (0.0, by) for x2 in (0.0, bx) for x in (x2, y, z)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    box = [i for a, b, c, d in quads for i in (a, b, c, a, c, d)]
    doc["meshes"].append({"name": "board", "primitives": [primitive(corners, box, material("FR4", [0.07, 0.3, 0.12, 1.0]))]})
    doc["nodes"].append({"name": "board", "mesh": 0})
    doc["scenes"][0]["nodes"].append(0)

    names = []
    for path in MODELS:
        with open(os.path.join(root, path)) as f:
            materials, shapes = parse_wrl(f.read())
        prims = []
        by_mat = {}
        for mat, pts, tris in shapes:  # one primitive per material: shapes of one material merged
            base, acc = by_mat.setdefault(mat, ([], []))
            off = len(base) // 3
            base.extend(pts)
            acc.extend(t + off for t in tris)
        for mat, (pts, tris) in by_mat.items():
            if tris:
                prims.append(primitive(pts, tris, material(mat, materials.get(mat, [0.8, 0.8, 0.8, 1.0]))))
        name = os.path.basename(path)[:-4]
        names.append(name)
        doc["meshes"].append({"name": name, "primitives": prims})
    quarter = [[0, 0, 0, 1], [0, 0, 0.7071067811865476, 0.7071067811865476], [0, 0, 1, 0],
               [0, 0, -0.7071067811865476, 0.7071067811865476]]
    for k, (model, x, y, turns) in enumerate(PLACEMENT):
        node = {"name": "%s #%d" % (names[model], k), "mesh": 1 + model, "translation": [x, y, 0]}
        if turns:
            node["rotation"] = quarter[turns]
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]))
        doc["nodes"].append(node)
    while len(bin_) % 4:
        bin_.append(0)
    doc["buffers"].append({"byteLength": len(bin_)})
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    with open(out, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text) + 8 + len(bin_)))
        f.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
        f.write(struct.pack("<II", len(bin_), 0x004E4942) + bin_)
    tris = sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc["meshes"] for p in m["primitives"])
    print("%s: %d meshes (%d triangles), %d nodes, %d materials, %d bytes" %
          (out, len(doc["meshes"]), tris, len(doc["nodes"]), len(doc["materials"]), os.path.getsize(out)))


if __name__ == "__main__":
    main()

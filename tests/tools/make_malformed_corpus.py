#!/usr/bin/env python3
"""Writes the malformed-input corpus tests/data/malformed/ (read by tests/test_malformed.cpp).

Each file is small and broken in one way; its name says how. EXPECTED.tsv is written by hand (it holds
the exit code and a substring of the one-line message for every file) and is not touched here. Files the
fuzzers found (tools/fuzz/README.md) are kept as they are and not regenerated.
Usage: tests/tools/make_malformed_corpus.py [DIR]
"""
import os
import random
import struct
import sys

out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "data", "malformed")
os.makedirs(out, exist_ok=True)


def w(name, data):
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(out, name), "wb") as f:
        f.write(data)


def garbage(n, seed):
    r = random.Random(seed)
    return bytes(r.randrange(256) for _ in range(n))


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"

# ----------------------------------------------------------------------------------------------- OBJ
w("obj_empty.obj", b"")
w("obj_truncated_mid_vertex.obj", TRI + "f 1 2 3\nv 4 5")
w("obj_truncated_mid_face.obj", TRI + "f 1 2 3\nf 1 2 3 4/")
w("obj_index_past_last_vertex.obj", TRI + "f 1 2 3\nf 1 2 4\n")
w("obj_index_far_forward.obj", TRI + "f 1 2 3\n# a reference far past the end\nf 3000000000 1 2\n")
w("obj_index_zero.obj", TRI + "f 0 1 2\n")
w("obj_negative_index_before_start.obj", TRI + "f -1 -2 -3\nf -1 -2 -4\n")
w("obj_negative_index_in_first_line.obj", "f -1 -2 -3\n" + TRI)
w("obj_index_too_many_digits.obj", TRI + "f 1 2 1234567890123456789012\n")
w("obj_bad_reference.obj", TRI + "f 1 2 3x\n")
w("obj_nan_coordinate.obj", TRI + "v nan 0 0\n")
w("obj_inf_coordinate.obj", TRI + "v 0 -inf 0\n")
w("obj_overflow_coordinate.obj", TRI + "v 0 0 1e400\n")
w("obj_bad_coordinate.obj", TRI + "v 0 0 zero\n")
w("obj_two_coordinates.obj", TRI + "v 0 0\n")
w("obj_one_corner_face.obj", TRI + "f 1\n")
w("obj_garbage_bytes.obj", garbage(200, 1))
w("obj_nul_in_comment.obj", TRI + "# fine\n# not \x00 fine\nf 1 2 3\n")
w("obj_control_byte_after_valid_lines.obj", TRI + "f 1 2 3\nv 1 1 1\x07\n")

# ----------------------------------------------------------------------------------------------- PLY
VERT3 = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
FACE = "property list uchar int vertex_indices\n"


def ply_header(fmt, body):
    return f"ply\nformat {fmt} 1.0\n{body}end_header\n"


def verts_le(vs, e="<"):
    return b"".join(struct.pack(e + "3f", *v) for v in vs)


V3 = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
w("ply_empty.ply", b"")
w("ply_truncated_header.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n")
w("ply_truncated_header_mid_line.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nprop")
w("ply_no_end_header.ply", "ply\nformat ascii 1.0\n" + VERT3 + "0 0 0\n1 0 0\n0 1 0\n")
# Fixed-size records: the header count is checked against the file size before any data is read.
w("ply_truncated_binary_vertices.ply",
  ply_header("binary_little_endian", VERT3).encode() + verts_le(V3)[:-7])
# Variable-size records: the truncation is found in the data.
w("ply_truncated_binary_faces.ply",
  ply_header("binary_little_endian", VERT3 + "element face 2\n" + FACE).encode() + verts_le(V3) +
  struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B3i", 3, 0, 1, 2)[:-3])
w("ply_truncated_ascii.ply",
  ply_header("ascii", VERT3) + "0.000000 0.000000 0.000000\n1.000000 0.000000 0.000000\n")
w("ply_face_count_exceeds_data.ply",
  ply_header("binary_little_endian", VERT3 + "element face 100\n" + FACE).encode() + verts_le(V3) +
  struct.pack("<B3i", 3, 0, 1, 2))
big = ply_header("ascii", "comment a 1 KB file that claims three billion vertices\n" +
                 VERT3.replace("vertex 3", "vertex 3000000000") + "element face 1\n" + FACE)
big += "0 0 0\n" * ((1024 - len(big)) // 6)
w("ply_vertex_count_billions.ply", big)
w("ply_count_overflows_uint64.ply", ply_header("ascii", VERT3.replace("vertex 3", "vertex 99999999999999999999")))
w("ply_index_out_of_range_ascii.ply", ply_header("ascii", VERT3 + "element face 1\n" + FACE) +
  "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
w("ply_negative_index_binary.ply",
  ply_header("binary_little_endian", VERT3 + "element face 1\n" + FACE).encode() + verts_le(V3) +
  struct.pack("<B3i", 3, 0, -1, 2))
w("ply_index_out_of_range_binary_be.ply",
  ply_header("binary_big_endian", VERT3 + "element face 1\nproperty list ushort uint vertex_indices\n").encode() +
  verts_le(V3, ">") + struct.pack(">H3I", 3, 0, 1, 4000000000))
w("ply_negative_list_count.ply",
  ply_header("binary_little_endian", VERT3 + "element face 1\nproperty list char int vertex_indices\n").encode() +
  verts_le(V3) + struct.pack("<b3i", -3, 0, 1, 2))
w("ply_one_index_face.ply", ply_header("ascii", VERT3 + "element face 1\n" + FACE) + "0 0 0\n1 0 0\n0 1 0\n1 0\n")
w("ply_nan_ascii.ply", ply_header("ascii", VERT3) + "0 0 0\n1 nan 0\n0 1 0\n")
w("ply_inf_ascii.ply", ply_header("ascii", VERT3) + "0 0 0\n1 0 0\ninf 1 0\n")
w("ply_nan_binary.ply", ply_header("binary_little_endian", VERT3).encode() +
  verts_le([(0, 0, 0), (1, 0, 0), (0, float("nan"), 0)]))
w("ply_inf_binary_double.ply",
  ply_header("binary_big_endian", VERT3.replace("float", "double")).encode() +
  b"".join(struct.pack(">3d", *v) for v in [(0, 0, 0), (float("inf"), 0, 0), (0, 1, 0)]))
w("ply_ascii_header_over_binary.ply", ply_header("ascii", VERT3).encode() + verts_le(V3))
w("ply_garbage_bytes.ply", garbage(200, 2))
w("ply_garbage_after_header.ply", ply_header("binary_little_endian", VERT3).encode() + verts_le(V3) + b"\x00" * 5)
w("ply_bad_value_ascii.ply", ply_header("ascii", VERT3) + "0 0 0\n1 0 0\n0 one 0\n")
w("ply_extra_value_ascii.ply", ply_header("ascii", VERT3) + "0 0 0\n1 0 0 0\n0 1 0\n")
w("ply_unknown_format.ply", "ply\nformat binary_middle_endian 1.0\n" + VERT3 + "end_header\n")
w("ply_no_vertex_element.ply", ply_header("ascii", "element point 1\nproperty float x\n") + "0\n")
w("ply_list_coordinate.ply", ply_header("ascii", VERT3.replace("property float z", "property list uchar float z")))

# ----------------------------------------------------------------------------------------------- STL


def stl_binary(tris, count=None, header=b"binary stl"):
    b = header.ljust(80, b" ") + struct.pack("<I", len(tris) if count is None else count)
    for t in tris:
        b += struct.pack("<3f", 0, 0, 1) + b"".join(struct.pack("<3f", *v) for v in t) + b"\0\0"
    return b


T = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
FACET = "facet normal 0 0 1\n outer loop\n  vertex {}\n  vertex 1 0 0\n  vertex 0 1 0\n endloop\nendfacet\n"
w("stl_empty.stl", b"")
w("stl_binary_count_exceeds_size.stl", stl_binary([T, T], count=1000))
w("stl_binary_count_below_size.stl", stl_binary([T, T, T], count=1))
w("stl_binary_count_billions.stl", stl_binary([T], count=4000000000))
w("stl_binary_truncated_header.stl", b"binary STL header cut short".ljust(50, b"\0"))
w("stl_binary_truncated_record.stl", stl_binary([T, T])[:-20])
w("stl_binary_nan.stl", stl_binary([T, [(0, 0, 0), (1, float("nan"), 0), (0, 1, 0)]]))
w("stl_binary_inf.stl", stl_binary([[(0, 0, 0), (1, 0, 0), (0, 1, float("-inf"))], T]))
w("stl_ascii_truncated_in_facet.stl", "solid s\n" + FACET.format("0 0 0") + "facet normal 0 0 1\n outer loop\n  vertex 0 0")
w("stl_ascii_no_endsolid_mid_loop.stl", "solid s\n" + FACET.format("0 0 0") + "facet normal 0 0 1\n outer loop\n")
w("stl_ascii_nan.stl", "solid s\n" + FACET.format("0 0 0") + FACET.format("nan 0 0") + "endsolid s\n")
w("stl_ascii_inf.stl", "solid s\n" + FACET.format("0 inf 0") + "endsolid s\n")
w("stl_ascii_bad_keyword.stl", "solid s\n" + FACET.format("0 0 0").replace("endloop", "endlop") + "endsolid s\n")
w("stl_ascii_four_vertices.stl", "solid s\n" + FACET.format("0 0 0").replace(" endloop", "  vertex 1 1 1\n endloop") +
  "endsolid s\n")
w("stl_ascii_binary_bytes.stl", b"solid s\n" + garbage(120, 3))
w("stl_garbage_bytes.stl", garbage(200, 4))

# ---------------------------------------------------------------------------------------------- glTF
import json


def glb(doc, binary, length=None, json_length=None):
    binary = binary + b"\0" * (-len(binary) % 4)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text) if json_length is None else json_length, 0x4E4F534A) + text
    if binary:
        body += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body) if length is None else length) + body


GLTF_BIN = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 2) + b"\0\0"


def gltf_doc(**changes):
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
           "buffers": [{"byteLength": 44}]}
    doc.update(changes)
    return doc


d = gltf_doc()
d["accessors"][0]["count"] = 1000
w("gltf_accessor_past_view.glb", glb(d, GLTF_BIN))
w("gltf_index_out_of_range.glb", glb(gltf_doc(), struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 7)))
w("gltf_cyclic_nodes.glb", glb(gltf_doc(nodes=[{"mesh": 0, "children": [1]}, {"children": [2]}, {"children": [1]}]), GLTF_BIN))
w("gltf_header_length_lies.glb", glb(gltf_doc(), GLTF_BIN, length=4000))
def fix_length(b):  # the header's total length made to agree with the (cut) file, so a chunk is what lies
    return b[:8] + struct.pack("<I", len(b)) + b[12:]


w("gltf_json_chunk_length_lies.glb", fix_length(glb(gltf_doc(), GLTF_BIN, json_length=100000)[:400]))
w("gltf_truncated_bin_chunk.glb", fix_length(glb(gltf_doc(), GLTF_BIN)[:-30]))
w("gltf_buffer_byte_length_lies.glb", glb(gltf_doc(buffers=[{"byteLength": 1 << 40}]), GLTF_BIN))
w("gltf_missing_buffer_file.gltf", json.dumps(gltf_doc(buffers=[{"byteLength": 44, "uri": "no-such-file.bin"}])))
w("gltf_bad_json.gltf", json.dumps(gltf_doc())[:-20])
w("gltf_bad_data_uri.gltf", json.dumps(gltf_doc(buffers=[{"byteLength": 44, "uri": "data:application/octet-stream;base64,AA*A"}])))
w("gltf_required_draco.glb", glb(gltf_doc(extensionsRequired=["KHR_draco_mesh_compression"]), GLTF_BIN))
w("gltf_not_glb_magic.glb", b"GLTF" + GLTF_BIN)

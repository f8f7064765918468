// Reads one level-of-detail mesh file wholly into memory, for consumers of finished levels (the error
// report, tests, tools). Unlike the ingest readers (io/reader.h) it is not streamed: a level is small next to
// the scene it came from, so the file is mapped once and parsed in one pass into core::LodMesh.
//
// Formats, chosen by content ("ply\n" or "ply\r\n" magic), else by the .obj extension:
//   PLY (Greg Turk, "The PLY Polygon File Format"): ascii, binary_little_endian, binary_big_endian; elements
//     in any order; any numeric type for every property.
//       vertex   x, y, z; red, green, blue (and alpha) as colours when all three are there (integers as
//                0..255, floats as 0..1); other properties skipped
//       face, edge, point: `material_index` when present, with the material table of io/ply_writer.h's
//                `comment material` lines (what io/ply_writer.cpp writes reads back with its materials)
//       face     list vertex_indices (or vertex_index), fan-triangulated; a two-index face is an edge
//       edge     vertex1, vertex2, optional thickness (0 when absent); without vertex1/vertex2, skipped
//       point    vertex, optional size (kept only when every point has one): this project's own element
//                (see io/ply_writer.h); without vertex, skipped
//     Any other element is skipped. The files io/ply_writer.cpp writes read back bit for bit.
//   OBJ (Wavefront): `v x y z` (w or colour ignored); `f` with v, v/vt, v//vn, v/vt/vn corners, negative
//     (relative) indices, fan-triangulated (two corners: an edge); `l` polylines as segments of thickness 0;
//     `p` points; a trailing backslash continues a statement; everything else skipped.
//
// The result satisfies core::convention_violation(mesh) == "": coordinates finite as float, every index in
// range, no index repeated within a triangle or an edge (such primitives are dropped and counted in
// LodFileStats), thickness and point sizes finite and >= 0. Normals are left empty (the report recomputes what it needs).
#pragma once

#include <cstdint>
#include <string>

#include "core/mesh.h"

namespace lodstream::io {

struct LodFileStats {
  std::string format;                 // "ply-ascii", "ply-binary-le", "ply-binary-be" or "obj"
  uint64_t faces = 0;                 // PLY face records, OBJ f statements
  uint64_t degenerate_triangles = 0;  // fan triangles dropped for a repeated vertex index
  uint64_t degenerate_edges = 0;      // edges and segments dropped because both ends are one vertex
  uint64_t skipped = 0;               // records of other PLY elements, other OBJ statements
};

// Reads `path` into a mesh. Memory: the mapped file plus the arrays of the result (reserved from the header
// counts only once the file size is known to hold them).
// Throws lodstream::Failure with
//   Status::no_input  the file is missing, unreadable or a directory ("PATH: cannot open: ...");
//   Status::bad_data  malformed content: "PATH:LINE: ..." for OBJ, PLY headers and ascii PLY data,
//                     "PATH: byte OFFSET: ..." for binary PLY data;
//   Status::usage     neither PLY nor .obj ("PATH: unsupported LOD format ...").
core::LodMesh read_lod_mesh(const std::string& path);
core::LodMesh read_lod_mesh(const std::string& path, LodFileStats* stats);

}  // namespace lodstream::io

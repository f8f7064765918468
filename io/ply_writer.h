// Binary PLY writer for one level of detail (core::LodMesh), following the PLY format as described by
// Greg Turk ("The PLY Polygon File Format", 1994) and written by most tools today.
//
// The file is `format binary_little_endian 1.0` with these elements, always in this order and always
// present (count 0 when empty), so that the schema does not depend on the contents:
//   element vertex N   property float x, y, z (and float nx, ny, nz when the mesh has normals; uchar red,
//                      green, blue, alpha when it has vertex colours)
//   element face F     property list uchar uint vertex_indices          (triangles, 3 indices each)
//   element edge E     property uint vertex1, uint vertex2, float thickness
//   element point P    property uint vertex, float size
// With a material table, face, edge and point end with `property uint material_index`, and the table is
// written as comment lines, one per material in id order:
//   comment material I r g b a metallic roughness OPAQUE|MASK|BLEND double-sided(0|1) name
// PLY has no standard element for points: `point` is this project's own element, one vertex index per point
// primitive and its size, the diameter in scene units of what collapsed into it (core/mesh.h; 0: drawn one
// pixel wide) (readers that do not know it skip it; the file also says so in a comment line).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace lodstream::io {

class FileWriter;

// What this writer and io/polygon_writer.cpp share: the `element vertex` header lines (float x, y, z, and
// nx, ny, nz with normals) and the little-endian vertex records (`normals` empty or one xyz per vertex).
std::string ply_vertex_header(uint64_t count, bool normals, bool colors = false);
void write_ply_vertices(FileWriter& out, std::span<const float> positions, std::span<const float> normals,
                        std::span<const uint8_t> colors = {});

// Writes `mesh` to `path` (through `<path>.partial`, renamed when complete). Each comment becomes a
// `comment ...` header line; line breaks and other control characters in it are replaced by spaces.
// Throws Failure(io_error) when the file cannot be written, Failure(internal) when the mesh breaks the
// conventions of core/mesh.h (array sizes, indices out of range).
// The header write_ply writes (vertex records 24 bytes with normals, else 12, and 4 more with colours;
// faces 13 bytes: uchar 3 and three uint ids; edges 12: two uint ids and a float thickness; points 8: a uint
// id and a float size; each 4 more with a material table, the uint material_index), for a level written
// record by record elsewhere (stream/level_files.cpp).
std::string ply_level_header(const std::vector<std::string>& comments, uint64_t vertices, bool normals, uint64_t triangles,
                             uint64_t edges, uint64_t points, const std::vector<core::Material>& materials = {},
                             bool colors = false);

void write_ply(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments);

}  // namespace lodstream::io

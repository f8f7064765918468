// Writers for meshes of n-gons (the polygons of `lodstream grid`: rectangles with extra vertices on their
// sides, and vertical fill polygons), as Wavefront OBJ (`v`, `vn`, `f` with any number of indices) and
// binary little-endian PLY (Greg Turk, "The PLY Polygon File Format"):
//   element vertex N   property float x, y, z (and float nx, ny, nz when the mesh has normals)
//   element face F     property list uchar uint vertex_indices, or list uint uint when a polygon has more
//                      than 255 vertices (the count type is the only part of the header that depends on
//                      the contents)
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace lodstream::io {

struct PolygonMesh {
  std::vector<float> positions;      // xyz per vertex, finite
  std::vector<float> normals;        // empty, or xyz per vertex
  std::vector<uint64_t> offsets;     // polygons + 1 entries: polygon p is indices[offsets[p] .. offsets[p+1])
  std::vector<uint32_t> indices;     // vertex ids, counter-clockwise seen from the front, at least 3 per polygon

  uint64_t vertex_count() const { return positions.size() / 3; }
  uint64_t polygon_count() const { return offsets.empty() ? 0 : offsets.size() - 1; }
};

// What breaks the conventions above (array shapes, indices in range, polygons of fewer than 3 vertices),
// or "" when nothing does.
std::string polygon_convention_violation(const PolygonMesh& mesh);

// Both write through `<path>.partial`, renamed when complete; each comment becomes a header comment line
// (control characters replaced by spaces). Throws Failure(io_error) when the file cannot be written,
// Failure(internal) when the mesh breaks the conventions.
void write_polygon_obj(const std::string& path, const PolygonMesh& mesh, const std::vector<std::string>& comments);
void write_polygon_ply(const std::string& path, const PolygonMesh& mesh, const std::vector<std::string>& comments);

}  // namespace lodstream::io

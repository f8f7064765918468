// Binary little-endian PLY writer for one level of detail (see io/ply_writer.h for the elements written).
// Follows the PLY format (Greg Turk, "The PLY Polygon File Format"); `element point` is this project's own.
#include "io/ply_writer.h"

#include <bit>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::io {

std::string ply_vertex_header(uint64_t count, bool normals, bool colors) {
  std::string h = "element vertex " + std::to_string(count) + "\n";
  h += "property float x\nproperty float y\nproperty float z\n";
  if (normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) h += "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n";
  return h;
}

void write_ply_vertices(FileWriter& out, std::span<const float> positions, std::span<const float> normals,
                        std::span<const uint8_t> colors) {
  const bool with_normals = !normals.empty(), with_colors = !colors.empty();
  for (uint64_t v = 0; v < positions.size() / 3; ++v) {
    char record[28];
    std::memcpy(record, &positions[3 * v], 12);
    size_t n = 12;
    if (with_normals) std::memcpy(record + n, &normals[3 * v], 12), n += 12;
    if (with_colors) std::memcpy(record + n, &colors[4 * v], 4), n += 4;
    out.write(record, n);
  }
}

static_assert(std::endian::native == std::endian::little, "the PLY writer copies little-endian memory as is");

namespace {

// A comment as one header line: control characters (line breaks included) become spaces.
std::string comment_line(const std::string& text) {
  std::string line = "comment ";
  for (char c : text) line += static_cast<unsigned char>(c) < 0x20 || c == 0x7f ? ' ' : c;
  line += '\n';
  return line;
}

// "material I r g b a metallic roughness alpha-mode double-sided name": the table, since PLY has none.
std::string material_comment(size_t i, const core::Material& m) {
  char numbers[160];
  std::snprintf(numbers, sizeof numbers, "material %zu %.9g %.9g %.9g %.9g %.9g %.9g %s %d ", i, m.base_color[0],
                m.base_color[1], m.base_color[2], m.base_color[3], m.metallic, m.roughness,
                m.alpha == core::Material::Alpha::opaque ? "OPAQUE" : m.alpha == core::Material::Alpha::mask ? "MASK" : "BLEND",
                m.double_sided ? 1 : 0);
  return numbers + m.name;
}

}  // namespace

std::string ply_level_header(const std::vector<std::string>& comments, uint64_t vertices, bool normals, uint64_t triangles,
                             uint64_t edges, uint64_t points, const std::vector<core::Material>& materials, bool colors) {
  const bool with_materials = !materials.empty();
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& c : comments) header += comment_line(c);
  header += "comment element point: one vertex index per point primitive, and its size (diameter, 0 = one pixel)\n";
  for (size_t i = 0; i < materials.size(); ++i) header += comment_line(material_comment(i, materials[i]));
  header += ply_vertex_header(vertices, normals, colors);
  header += "element face " + std::to_string(triangles) + "\n";
  header += "property list uchar uint vertex_indices\n";
  if (with_materials) header += "property uint material_index\n";
  header += "element edge " + std::to_string(edges) + "\n";
  header += "property uint vertex1\nproperty uint vertex2\nproperty float thickness\n";
  if (with_materials) header += "property uint material_index\n";
  header += "element point " + std::to_string(points) + "\n";
  header += "property uint vertex\nproperty float size\n";
  if (with_materials) header += "property uint material_index\n";
  header += "end_header\n";
  return header;
}

void write_ply(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments) {
  if (const std::string v = core::convention_violation(mesh); !v.empty())
    fail(Status::internal, path + ": cannot write level: " + v);
  const bool normals = !mesh.normals.empty(), colors = !mesh.colors.empty(), materials = !mesh.materials.empty();

  const std::string header = ply_level_header(comments, mesh.vertex_count(), normals, mesh.triangle_count(), mesh.edge_count(),
                                              mesh.point_count(), mesh.materials, colors);

  FileWriter out(path, 1 << 20, Sync::durable);
  out.write(header);

  // vertex: x y z [nx ny nz], 12 or 24 bytes
  write_ply_vertices(out, mesh.positions, mesh.normals, mesh.colors);
  // face: count 3 (uchar), then 3 uint indices: 13 bytes [+ uint material_index]
  for (uint64_t t = 0; t < mesh.triangle_count(); ++t) {
    char record[17];
    record[0] = 3;
    std::memcpy(record + 1, &mesh.triangles[3 * t], 12);
    if (materials) std::memcpy(record + 13, &mesh.triangle_materials[t], 4);
    out.write(record, materials ? 17 : 13);
  }
  // edge: vertex1 vertex2 (uint) thickness (float): 12 bytes [+ uint material_index]
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    char record[16];
    std::memcpy(record, &mesh.edges[2 * e], 8);
    std::memcpy(record + 8, &mesh.thickness[e], 4);
    if (materials) std::memcpy(record + 12, &mesh.edge_materials[e], 4);
    out.write(record, materials ? 16 : 12);
  }
  // point: vertex (uint) size (float, 0 when the mesh has no sizes): 8 bytes [+ uint material_index]
  for (uint64_t p = 0; p < mesh.point_count(); ++p) {
    char record[12];
    const float size = mesh.point_size.empty() ? 0.0f : mesh.point_size[p];
    std::memcpy(record, &mesh.points[p], 4);
    std::memcpy(record + 4, &size, 4);
    if (materials) std::memcpy(record + 8, &mesh.point_materials[p], 4);
    out.write(record, materials ? 12 : 8);
  }
  out.commit();
}

}  // namespace lodstream::io

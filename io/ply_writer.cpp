// Binary little-endian PLY writer for one level of detail (see io/ply_writer.h for the elements written).
// Follows the PLY format (Greg Turk, "The PLY Polygon File Format"); `element point` is this project's own.
#include "io/ply_writer.h"

#include <bit>
#include <cstdint>
#include <cstring>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::io {

std::string ply_vertex_header(uint64_t count, bool normals) {
  std::string h = "element vertex " + std::to_string(count) + "\n";
  h += "property float x\nproperty float y\nproperty float z\n";
  if (normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  return h;
}

void write_ply_vertices(FileWriter& out, std::span<const float> positions, std::span<const float> normals) {
  const bool with_normals = !normals.empty();
  for (uint64_t v = 0; v < positions.size() / 3; ++v) {
    float record[6];
    std::memcpy(record, &positions[3 * v], 12);
    if (with_normals) std::memcpy(record + 3, &normals[3 * v], 12);
    out.write(record, with_normals ? 24 : 12);
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

// point: vertex (uint) size (float, 0 when the mesh has no sizes): 8 bytes
void write_ply_points(FileWriter& out, const core::LodMesh& mesh) {
  for (uint64_t p = 0; p < mesh.point_count(); ++p) {
    char record[8];
    const float size = mesh.point_size.empty() ? 0.0f : mesh.point_size[p];
    std::memcpy(record, &mesh.points[p], 4);
    std::memcpy(record + 4, &size, 4);
    out.write(record, sizeof record);
  }
}

}  // namespace

std::string ply_level_header(const std::vector<std::string>& comments, uint64_t vertices, bool normals, uint64_t triangles,
                             uint64_t edges, uint64_t points) {
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& c : comments) header += comment_line(c);
  header += "comment element point: one vertex index per point primitive, and its size (diameter, 0 = one pixel)\n";
  header += ply_vertex_header(vertices, normals);
  header += "element face " + std::to_string(triangles) + "\n";
  header += "property list uchar uint vertex_indices\n";
  header += "element edge " + std::to_string(edges) + "\n";
  header += "property uint vertex1\nproperty uint vertex2\nproperty float thickness\n";
  header += "element point " + std::to_string(points) + "\n";
  header += "property uint vertex\nproperty float size\n";
  header += "end_header\n";
  return header;
}

void write_ply(const std::string& path, const core::LodMesh& mesh, const std::vector<std::string>& comments) {
  if (const std::string v = core::convention_violation(mesh); !v.empty())
    fail(Status::internal, path + ": cannot write level: " + v);
  const bool normals = !mesh.normals.empty();

  const std::string header =
      ply_level_header(comments, mesh.vertex_count(), normals, mesh.triangle_count(), mesh.edge_count(), mesh.point_count());

  FileWriter out(path, 1 << 20, Sync::durable);
  out.write(header);

  // vertex: x y z [nx ny nz], 12 or 24 bytes
  write_ply_vertices(out, mesh.positions, mesh.normals);
  // face: count 3 (uchar), then 3 uint indices: 13 bytes
  for (uint64_t t = 0; t < mesh.triangle_count(); ++t) {
    char record[13];
    record[0] = 3;
    std::memcpy(record + 1, &mesh.triangles[3 * t], 12);
    out.write(record, sizeof record);
  }
  // edge: vertex1 vertex2 (uint) thickness (float): 12 bytes
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    char record[12];
    std::memcpy(record, &mesh.edges[2 * e], 8);
    std::memcpy(record + 8, &mesh.thickness[e], 4);
    out.write(record, sizeof record);
  }
  write_ply_points(out, mesh);
  out.commit();
}

}  // namespace lodstream::io

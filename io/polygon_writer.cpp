// OBJ and binary PLY writers for meshes of n-gons (see io/polygon_writer.h).
#include "io/polygon_writer.h"

#include <algorithm>
#include <bit>
#include <charconv>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/ply_writer.h"

namespace lodstream::io {

static_assert(std::endian::native == std::endian::little, "the PLY writer copies little-endian memory as is");

namespace {

std::string clean(const std::string& text) {
  std::string s;
  for (char c : text) s += static_cast<unsigned char>(c) < 0x20 || c == 0x7f ? ' ' : c;
  return s;
}

void check(const std::string& path, const PolygonMesh& mesh) {
  if (const std::string v = polygon_convention_violation(mesh); !v.empty())
    fail(Status::internal, path + ": cannot write polygons: " + v);
}

}  // namespace

std::string polygon_convention_violation(const PolygonMesh& mesh) {
  if (mesh.positions.size() % 3 != 0) return "positions are not xyz triples";
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) return "normals do not match positions";
  if (mesh.vertex_count() > UINT32_MAX) return "more vertices than 32-bit indices can address";
  if (!mesh.offsets.empty() && (mesh.offsets.front() != 0 || mesh.offsets.back() != mesh.indices.size()))
    return "offsets do not span the indices";
  if (mesh.offsets.empty() && !mesh.indices.empty()) return "indices without offsets";
  for (size_t p = 0; p + 1 < mesh.offsets.size(); ++p)
    if (mesh.offsets[p + 1] < mesh.offsets[p] + 3) return "polygon " + std::to_string(p) + " has fewer than 3 vertices";
  for (uint32_t id : mesh.indices)
    if (id >= mesh.vertex_count()) return "vertex index " + std::to_string(id) + " out of range";
  return {};
}

void write_polygon_obj(const std::string& path, const PolygonMesh& mesh, const std::vector<std::string>& comments) {
  check(path, mesh);
  const bool normals = !mesh.normals.empty();
  FileWriter out(path, 1 << 20, Sync::durable);
  for (const std::string& c : comments) out.write("# " + clean(c) + "\n");
  char buf[64];
  auto number = [&](auto x) {
    const char* end = std::to_chars(buf, buf + sizeof buf, x).ptr;
    out.write(buf, static_cast<size_t>(end - buf));
  };
  auto xyz = [&](const char* tag, const std::vector<float>& a) {
    for (uint64_t v = 0; v < mesh.vertex_count(); ++v) {
      out.write(tag);
      for (int c = 0; c < 3; ++c) {
        out.write(" ");
        number(a[3 * v + c]);
      }
      out.write("\n");
    }
  };
  xyz("v", mesh.positions);
  if (normals) xyz("vn", mesh.normals);
  for (uint64_t p = 0; p < mesh.polygon_count(); ++p) {
    out.write("f");
    for (uint64_t k = mesh.offsets[p]; k < mesh.offsets[p + 1]; ++k) {
      const uint64_t id = uint64_t{mesh.indices[k]} + 1;
      out.write(" ");
      number(id);
      if (normals) {
        out.write("//");
        number(id);
      }
    }
    out.write("\n");
  }
  out.commit();
}

void write_polygon_ply(const std::string& path, const PolygonMesh& mesh, const std::vector<std::string>& comments) {
  check(path, mesh);
  const bool normals = !mesh.normals.empty();
  uint64_t largest = 0;
  for (uint64_t p = 0; p < mesh.polygon_count(); ++p) largest = std::max(largest, mesh.offsets[p + 1] - mesh.offsets[p]);
  const bool wide = largest > 255;
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& c : comments) header += "comment " + clean(c) + "\n";
  header += ply_vertex_header(mesh.vertex_count(), normals);
  header += "element face " + std::to_string(mesh.polygon_count()) + "\n";
  header += wide ? "property list uint uint vertex_indices\n" : "property list uchar uint vertex_indices\n";
  header += "end_header\n";
  FileWriter out(path, 1 << 20, Sync::durable);
  out.write(header);
  write_ply_vertices(out, mesh.positions, mesh.normals);
  for (uint64_t p = 0; p < mesh.polygon_count(); ++p) {
    const uint32_t n = static_cast<uint32_t>(mesh.offsets[p + 1] - mesh.offsets[p]);
    if (wide) {
      out.write(&n, 4);
    } else {
      const uint8_t n8 = static_cast<uint8_t>(n);
      out.write(&n8, 1);
    }
    out.write(&mesh.indices[mesh.offsets[p]], 4 * uint64_t{n});
  }
  out.commit();
}

}  // namespace lodstream::io

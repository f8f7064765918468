// A level's files welded from its region parts (see stream/level_files.h).
#include "stream/level_files.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <limits>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"

namespace lodstream::stream {

namespace {

// Scratch records.
constexpr size_t kVertexBytes = 24;    // position, normal
constexpr size_t kTriangleBytes = 24;  // 3 vertex keys
constexpr size_t kEdgeBytes = 44;      // 2 vertex keys, thickness, 2 positions
constexpr size_t kPointBytes = 24;     // vertex key, position, size
constexpr uint64_t kChunkRecords = 1 << 16;

// Calls visit(records, n) over the `count` records of `bytes` bytes of `path`, in windows.
template <class Visit>
void for_records(const std::string& path, uint64_t count, size_t bytes, Visit&& visit) {
  if (count == 0) return;
  io::MappedFile f(path);
  if (f.size() != count * bytes) fail(Status::io_error, path + ": size does not match");
  for (uint64_t first = 0; first < count; first += kChunkRecords) {
    const uint64_t n = std::min(kChunkRecords, count - first);
    const io::Window w = f.map(first * bytes, (first + n) * bytes);
    visit(w.data(), n);
  }
}

uint64_t key_at(const char* p) {
  uint64_t k;
  std::memcpy(&k, p, 8);
  return k;
}

void grow(float (*b)[3], const float* p) {
  for (int k = 0; k < 3; ++k) b[0][k] = std::min(b[0][k], p[k]), b[1][k] = std::max(b[1][k], p[k]);
}

}  // namespace

LevelFiles::LevelFiles(std::string scratch, uint64_t cells)
    : scratch_(std::move(scratch)), first_vertex_(cells, UINT32_MAX), first_triangle_vertex_(cells, UINT32_MAX) {
  vertex_out_.open(path("vertices"));
  triangle_out_.open(path("triangles"));
  edge_out_.open(path("edges"));
  point_out_.open(path("points"));
  for (auto& kind : bounds_)
    for (int k = 0; k < 3; ++k)
      kind[0][k] = std::numeric_limits<float>::infinity(), kind[1][k] = -std::numeric_limits<float>::infinity();
}

LevelFiles::~LevelFiles() {
  std::error_code ec;
  for (const char* what : {"vertices", "triangles", "edges", "points"}) std::filesystem::remove(path(what), ec);
}

void LevelFiles::add(const RegionPart& part) {
  for (size_t i = 0; i < part.owned_key.size(); ++i) {
    const uint64_t key = part.owned_key[i];
    const uint32_t cell = static_cast<uint32_t>(key >> 32);
    const float* n = &part.owned_normals[3 * i];
    const bool by_triangles = n[0] != 0 || n[1] != 0 || n[2] != 0;  // triangle vertices have unit normals
    if (vertices_ >= UINT32_MAX) fail(Status::io_error, "a level has more vertices than 32-bit indices address");
    if ((key & 0xFFFFFFFF) == 0) {
      first_vertex_[cell] = static_cast<uint32_t>(vertices_);
      if (by_triangles) first_triangle_vertex_[cell] = static_cast<uint32_t>(triangle_vertices_);
    }
    ++vertices_;
    if (by_triangles) ++triangle_vertices_, grow(bounds_[0], &part.owned_positions[3 * i]);
    vertex_out_.write(&part.owned_positions[3 * i], 12);
    vertex_out_.write(n, 12);
  }
  const core::LodMesh& m = part.mesh;
  for (uint64_t t = 0; t < m.triangle_count(); ++t)
    for (int k = 0; k < 3; ++k) triangle_out_.write(&part.vertex_key[m.triangles[3 * t + k]], 8);
  for (uint64_t e = 0; e < m.edge_count(); ++e) {
    for (int k = 0; k < 2; ++k) edge_out_.write(&part.vertex_key[m.edges[2 * e + k]], 8);
    edge_out_.write(&m.thickness[e], 4);
    for (int k = 0; k < 2; ++k) {
      const float* p = &m.positions[3 * uint64_t{m.edges[2 * e + k]}];
      edge_out_.write(p, 12);
      grow(bounds_[1], p);
    }
  }
  for (uint64_t p = 0; p < m.point_count(); ++p) {
    const uint32_t v = m.points[p];
    const float size = m.point_size.empty() ? 0.0f : m.point_size[p];
    point_out_.write(&part.vertex_key[v], 8);
    point_out_.write(&m.positions[3 * uint64_t{v}], 12);
    point_out_.write(&size, 4);
    grow(bounds_[2], &m.positions[3 * uint64_t{v}]);
  }
  triangles_ += m.triangle_count(), edges_ += m.edge_count(), points_ += m.point_count();
}

void LevelFiles::close() {
  vertex_out_.commit();
  triangle_out_.commit();
  edge_out_.commit();
  point_out_.commit();
}

uint32_t LevelFiles::vertex_id(uint64_t key) const {
  const uint32_t first = first_vertex_[key >> 32];
  if (first == UINT32_MAX) fail(Status::internal, "emit: a part uses a vertex no region owns");
  return first + static_cast<uint32_t>(key);
}

uint32_t LevelFiles::triangle_vertex_id(uint64_t key) const {
  const uint32_t first = first_triangle_vertex_[key >> 32];
  if (first == UINT32_MAX) fail(Status::internal, "emit: a triangle uses a vertex without a normal");
  return first + static_cast<uint32_t>(key);
}

void LevelFiles::write_ply(const std::string& out_path, const std::vector<std::string>& comments) const {
  io::FileWriter out(out_path, 1 << 20, io::Sync::durable);
  out.write(io::ply_level_header(comments, vertices_, true, triangles_, edges_, points_));
  for_records(path("vertices"), vertices_, kVertexBytes, [&](const char* r, uint64_t n) { out.write(r, n * kVertexBytes); });
  for_records(path("triangles"), triangles_, kTriangleBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      char record[13];
      record[0] = 3;
      for (int k = 0; k < 3; ++k) {
        const uint32_t id = vertex_id(key_at(r + i * kTriangleBytes + 8 * k));
        std::memcpy(record + 1 + 4 * k, &id, 4);
      }
      out.write(record, sizeof record);
    }
  });
  for_records(path("edges"), edges_, kEdgeBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      const char* e = r + i * kEdgeBytes;
      const uint32_t ids[2] = {vertex_id(key_at(e)), vertex_id(key_at(e + 8))};
      out.write(ids, 8);
      out.write(e + 16, 4);
    }
  });
  for_records(path("points"), points_, kPointBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      const uint32_t id = vertex_id(key_at(r + i * kPointBytes));
      out.write(&id, 4);
      out.write(r + i * kPointBytes + 20, 4);
    }
  });
  out.commit();
}

void LevelFiles::write_obj(const std::string& out_path, const std::vector<std::string>& comments) const {
  io::ObjStream out(out_path, comments);
  for (const char* tag : {"v", "vn"})
    for_records(path("vertices"), vertices_, kVertexBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) {
        float xyz[3];
        std::memcpy(xyz, r + i * kVertexBytes + (tag[1] ? 12 : 0), 12);
        out.vec3(tag, xyz);
      }
    });
  for_records(path("triangles"), triangles_, kTriangleBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      uint64_t ids[3];
      for (int k = 0; k < 3; ++k) ids[k] = vertex_id(key_at(r + i * kTriangleBytes + 8 * k));
      out.face(ids, true);
    }
  });
  for_records(path("edges"), edges_, kEdgeBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) out.line(vertex_id(key_at(r + i * kEdgeBytes)), vertex_id(key_at(r + i * kEdgeBytes + 8)));
  });
  for_records(path("points"), points_, kPointBytes, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) out.point(vertex_id(key_at(r + i * kPointBytes)));
  });
  out.commit();
}

io::GlbStreamedLevel LevelFiles::glb(const std::string& name, double screen_coverage) const {
  io::GlbStreamedLevel g;
  g.name = name;
  g.screen_coverage = screen_coverage;
  g.triangle_vertices = triangle_vertices_, g.triangles = triangles_, g.edges = edges_, g.points = points_;
  g.normals = true;
  for (int k = 0; k < 3; ++k) {
    g.triangle_min[k] = bounds_[0][0][k], g.triangle_max[k] = bounds_[0][1][k];
    g.edge_min[k] = bounds_[1][0][k], g.edge_max[k] = bounds_[1][1][k];
    g.point_min[k] = bounds_[2][0][k], g.point_max[k] = bounds_[2][1][k];
  }
  // The triangle vertices: the vertices with a normal, positions (offset 0) or normals (12).
  auto triangle_vertices = [this](size_t offset) {
    return [this, offset](const io::GlbStreamedLevel::Write& write) {
      for_records(path("vertices"), vertices_, kVertexBytes, [&](const char* r, uint64_t n) {
        for (uint64_t i = 0; i < n; ++i) {
          float nrm[3];
          std::memcpy(nrm, r + i * kVertexBytes + 12, 12);
          if (nrm[0] != 0 || nrm[1] != 0 || nrm[2] != 0) write(r + i * kVertexBytes + offset, 12);
        }
      });
    };
  };
  g.triangle_positions = triangle_vertices(0);
  g.triangle_normals = triangle_vertices(12);
  g.triangle_indices = [this](const io::GlbStreamedLevel::Write& write) {
    for_records(path("triangles"), triangles_, kTriangleBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
          const uint32_t id = triangle_vertex_id(key_at(r + i * kTriangleBytes + 8 * k));
          write(&id, 4);
        }
    });
  };
  g.edge_positions = [this](const io::GlbStreamedLevel::Write& write) {
    for_records(path("edges"), edges_, kEdgeBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) write(r + i * kEdgeBytes + 20, 24);
    });
  };
  g.edge_thickness = [this](const io::GlbStreamedLevel::Write& write) {
    for_records(path("edges"), edges_, kEdgeBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) {
        float t[2];
        std::memcpy(&t[0], r + i * kEdgeBytes + 16, 4);
        t[1] = t[0];
        write(t, 8);
      }
    });
  };
  g.point_positions = [this](const io::GlbStreamedLevel::Write& write) {
    for_records(path("points"), points_, kPointBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) write(r + i * kPointBytes + 8, 12);
    });
  };
  g.point_size = [this](const io::GlbStreamedLevel::Write& write) {
    for_records(path("points"), points_, kPointBytes, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) write(r + i * kPointBytes + 20, 4);
    });
  };
  return g;
}

void OpenLevels::add(size_t level, const RegionPart& part) {
  std::unique_ptr<LevelFiles>& files = open_[level];
  if (!files) files = std::make_unique<LevelFiles>(work_.scratch(stem_ + std::to_string(level)), cells_.at(level));
  files->add(part);
}

std::unique_ptr<LevelFiles> OpenLevels::take(size_t level) {
  const auto it = open_.find(level);
  if (it == open_.end()) fail(Status::internal, "emit: level " + std::to_string(level) + " has no region");
  std::unique_ptr<LevelFiles> files = std::move(it->second);
  open_.erase(it);
  files->close();
  return files;
}

}  // namespace lodstream::stream

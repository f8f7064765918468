// A level's files welded from its region parts (see stream/level_files.h).
#include "stream/level_files.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>

#include <tbb/task_group.h>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"

namespace lodstream::stream {

namespace {

// Scratch records: a vertex is its position and normal (24 bytes), then its RGBA with colours; a triangle
// its 3 vertex keys (24), then its material with materials; an edge its 2 vertex keys, thickness and 2
// positions (44), then its material, then the RGBA of both ends; a point its vertex key, position and size
// (24), then its material, then its RGBA.
constexpr size_t kVertexBytes = 24, kTriangleBytes = 24, kEdgeBytes = 44, kPointBytes = 24;
constexpr uint64_t kChunkRecords = 1 << 16;
// The output one pass of a per-material GLB block holds (see level_files.h).
constexpr uint64_t kSweepBytes = 16 << 20;

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

uint32_t u32_at(const char* p) {
  uint32_t k;
  std::memcpy(&k, p, 4);
  return k;
}

void grow(float (*b)[3], const float* p) {
  for (int k = 0; k < 3; ++k) b[0][k] = std::min(b[0][k], p[k]), b[1][k] = std::max(b[1][k], p[k]);
}

void grow_material(std::vector<float>& bounds, uint32_t m, const float* p) {
  float* b = &bounds[6 * uint64_t{m}];
  for (int k = 0; k < 3; ++k) b[k] = std::min(b[k], p[k]), b[3 + k] = std::max(b[3 + k], p[k]);
}

// A per-material GLB block over a scratch file (level_files.h): `emit(record, out)` writes `out_bytes`
// bytes for a record; the material of a record is the uint32 at `material_at` (none: every record is
// material 0). Asked for materials in increasing order, as io::GlbBuilder does.
class MaterialSweep {
 public:
  using Emit = std::function<void(const char* record, char* out)>;
  MaterialSweep(std::string path, uint64_t count, size_t record_bytes, size_t material_at, bool materials,
                std::vector<uint64_t> counts, size_t out_bytes, Emit emit)
      : path_(std::move(path)), count_(count), record_bytes_(record_bytes), material_at_(material_at),
        materials_(materials), counts_(std::move(counts)), out_bytes_(out_bytes), emit_(std::move(emit)) {}

  void write(uint32_t m, const io::GlbStreamedLevel::Write& write) {
    if (!materials_ || counts_[m] * out_bytes_ > kSweepBytes) {
      std::vector<char> out(out_bytes_ * kChunkRecords);
      for_records(path_, count_, record_bytes_, [&](const char* r, uint64_t n) {
        size_t k = 0;
        for (uint64_t i = 0; i < n; ++i) {
          const char* record = r + i * record_bytes_;
          if (materials_ && u32_at(record + material_at_) != m) continue;
          emit_(record, out.data() + k * out_bytes_);
          ++k;
        }
        if (k > 0) write(out.data(), k * out_bytes_);
      });
      return;
    }
    if (m < first_ || m >= end_) gather(m);
    write(buffer_.data() + offset_[m - first_], counts_[m] * out_bytes_);
  }

 private:
  // One pass: the output of materials [m, end) that fits in kSweepBytes, each material's in file order.
  void gather(uint32_t m) {
    first_ = m;
    uint64_t bytes = counts_[m] * out_bytes_;
    end_ = m + 1;
    while (end_ < counts_.size() && bytes + counts_[end_] * out_bytes_ <= kSweepBytes) bytes += counts_[end_++] * out_bytes_;
    offset_.assign(end_ - first_, 0);
    for (uint32_t i = first_ + 1; i < end_; ++i) offset_[i - first_] = offset_[i - 1 - first_] + counts_[i - 1] * out_bytes_;
    std::vector<uint64_t> at(offset_);
    buffer_.resize(bytes);
    for_records(path_, count_, record_bytes_, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) {
        const char* record = r + i * record_bytes_;
        const uint32_t mm = u32_at(record + material_at_);
        if (mm < first_ || mm >= end_) continue;
        emit_(record, buffer_.data() + at[mm - first_]);
        at[mm - first_] += out_bytes_;
      }
    });
  }

  std::string path_;
  uint64_t count_;
  size_t record_bytes_, material_at_;
  bool materials_;
  std::vector<uint64_t> counts_;
  size_t out_bytes_;
  Emit emit_;
  uint32_t first_ = 0, end_ = 0;  // the materials in buffer_
  std::vector<uint64_t> offset_;
  std::vector<char> buffer_;
};

}  // namespace

LevelFiles::LevelFiles(std::string scratch, uint64_t cells, std::vector<core::Material> materials, bool colors,
                       std::string suffix)
    : scratch_(std::move(scratch)), suffix_(std::move(suffix)), first_vertex_(cells, UINT32_MAX), first_triangle_vertex_(cells, UINT32_MAX),
      materials_(std::move(materials)), colors_(colors) {
  const size_t m = materials_.empty() ? 0 : 4, c = colors_ ? 4 : 0;
  vertex_bytes_ = kVertexBytes + c, triangle_bytes_ = kTriangleBytes + m;
  edge_bytes_ = kEdgeBytes + m + 2 * c, point_bytes_ = kPointBytes + m + c;
  vertex_out_.open(path("vertices"));
  triangle_out_.open(path("triangles"));
  edge_out_.open(path("edges"));
  point_out_.open(path("points"));
  for (auto& kind : bounds_)
    for (int k = 0; k < 3; ++k)
      kind[0][k] = std::numeric_limits<float>::infinity(), kind[1][k] = -std::numeric_limits<float>::infinity();
  if (!materials_.empty()) {
    const size_t n = materials_.size();
    material_triangles_.assign(n, 0), material_edges_.assign(n, 0), material_points_.assign(n, 0);
    for (auto* b : {&material_edge_bounds_, &material_point_bounds_}) {
      b->resize(6 * n);
      for (size_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k)
          (*b)[6 * i + k] = std::numeric_limits<float>::infinity(), (*b)[6 * i + 3 + k] = -std::numeric_limits<float>::infinity();
    }
  }
}

LevelFiles::~LevelFiles() {
  std::error_code ec;
  for (const char* what : {"vertices", "triangles", "edges", "points"}) std::filesystem::remove(path(what), ec);
}

void LevelFiles::add(const RegionPart& part) {
  const core::LodMesh& m = part.mesh;
  const bool materials = !materials_.empty();
  if (colors_ && (part.owned_colors.size() != 4 * part.owned_key.size() || m.colors.size() != 4 * m.vertex_count()))
    fail(Status::internal, "emit: a part without its vertex colours");
  if (materials && m.materials.size() != materials_.size()) fail(Status::internal, "emit: a part without its materials");
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
    if (colors_) vertex_out_.write(&part.owned_colors[4 * i], 4);
  }
  for (uint64_t t = 0; t < m.triangle_count(); ++t) {
    for (int k = 0; k < 3; ++k) triangle_out_.write(&part.vertex_key[m.triangles[3 * t + k]], 8);
    if (materials) triangle_out_.write(&m.triangle_materials[t], 4), ++material_triangles_[m.triangle_materials[t]];
  }
  for (uint64_t e = 0; e < m.edge_count(); ++e) {
    for (int k = 0; k < 2; ++k) edge_out_.write(&part.vertex_key[m.edges[2 * e + k]], 8);
    edge_out_.write(&m.thickness[e], 4);
    for (int k = 0; k < 2; ++k) {
      const float* p = &m.positions[3 * uint64_t{m.edges[2 * e + k]}];
      edge_out_.write(p, 12);
      grow(bounds_[1], p);
      if (materials) grow_material(material_edge_bounds_, m.edge_materials[e], p);
    }
    if (materials) edge_out_.write(&m.edge_materials[e], 4), ++material_edges_[m.edge_materials[e]];
    if (colors_)
      for (int k = 0; k < 2; ++k) edge_out_.write(&m.colors[4 * uint64_t{m.edges[2 * e + k]}], 4);
  }
  for (uint64_t i = 0; i < m.point_count(); ++i) {
    const uint32_t v = m.points[i];
    const float size = m.point_size.empty() ? 0.0f : m.point_size[i];
    point_out_.write(&part.vertex_key[v], 8);
    point_out_.write(&m.positions[3 * uint64_t{v}], 12);
    point_out_.write(&size, 4);
    grow(bounds_[2], &m.positions[3 * uint64_t{v}]);
    if (materials) {
      point_out_.write(&m.point_materials[i], 4), ++material_points_[m.point_materials[i]];
      grow_material(material_point_bounds_, m.point_materials[i], &m.positions[3 * uint64_t{v}]);
    }
    if (colors_) point_out_.write(&m.colors[4 * uint64_t{v}], 4);
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
  const bool materials = !materials_.empty();
  io::FileWriter out(out_path, 1 << 20, io::Sync::durable);
  out.write(io::ply_level_header(comments, vertices_, true, triangles_, edges_, points_, materials_, colors_));
  // The vertex records are the PLY's: x y z nx ny nz [red green blue alpha].
  for_records(path("vertices"), vertices_, vertex_bytes_, [&](const char* r, uint64_t n) { out.write(r, n * vertex_bytes_); });
  for_records(path("triangles"), triangles_, triangle_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      char record[17];
      record[0] = 3;
      for (int k = 0; k < 3; ++k) {
        const uint32_t id = vertex_id(key_at(r + i * triangle_bytes_ + 8 * k));
        std::memcpy(record + 1 + 4 * k, &id, 4);
      }
      if (materials) std::memcpy(record + 13, r + i * triangle_bytes_ + kTriangleBytes, 4);
      out.write(record, materials ? 17 : 13);
    }
  });
  for_records(path("edges"), edges_, edge_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      const char* e = r + i * edge_bytes_;
      const uint32_t ids[2] = {vertex_id(key_at(e)), vertex_id(key_at(e + 8))};
      out.write(ids, 8);
      out.write(e + 16, 4);
      if (materials) out.write(e + kEdgeBytes, 4);
    }
  });
  for_records(path("points"), points_, point_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      const uint32_t id = vertex_id(key_at(r + i * point_bytes_));
      out.write(&id, 4);
      out.write(r + i * point_bytes_ + 20, 4);
      if (materials) out.write(r + i * point_bytes_ + kPointBytes, 4);
    }
  });
  out.commit();
}

void LevelFiles::write_obj(const std::string& out_path, const std::vector<std::string>& comments) const {
  const bool materials = !materials_.empty();
  io::ObjStream out(out_path, comments, materials_);
  for (const char* tag : {"v", "vn"})
    for_records(path("vertices"), vertices_, vertex_bytes_, [&](const char* r, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i) {
        const char* v = r + i * vertex_bytes_;
        float xyz[3];
        std::memcpy(xyz, v + (tag[1] ? 12 : 0), 12);
        if (colors_ && !tag[1]) out.vertex(xyz, reinterpret_cast<const uint8_t*>(v + kVertexBytes));
        else out.vec3(tag, xyz);
      }
    });
  for_records(path("triangles"), triangles_, triangle_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      uint64_t ids[3];
      for (int k = 0; k < 3; ++k) ids[k] = vertex_id(key_at(r + i * triangle_bytes_ + 8 * k));
      if (materials) out.use(u32_at(r + i * triangle_bytes_ + kTriangleBytes));
      out.face(ids, true);
    }
  });
  for_records(path("edges"), edges_, edge_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      const char* e = r + i * edge_bytes_;
      if (materials) out.use(u32_at(e + kEdgeBytes));
      out.line(vertex_id(key_at(e)), vertex_id(key_at(e + 8)));
    }
  });
  for_records(path("points"), points_, point_bytes_, [&](const char* r, uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
      if (materials) out.use(u32_at(r + i * point_bytes_ + kPointBytes));
      out.point(vertex_id(key_at(r + i * point_bytes_)));
    }
  });
  out.commit();
}

io::GlbStreamedLevel LevelFiles::glb(const std::string& name, double screen_coverage) const {
  const bool materials = !materials_.empty();
  io::GlbStreamedLevel g;
  g.name = name;
  g.screen_coverage = screen_coverage;
  g.triangle_vertices = triangle_vertices_, g.triangles = triangles_, g.edges = edges_, g.points = points_;
  g.normals = true;
  g.colors = colors_;
  for (int k = 0; k < 3; ++k) {
    g.triangle_min[k] = bounds_[0][0][k], g.triangle_max[k] = bounds_[0][1][k];
    g.edge_min[k] = bounds_[1][0][k], g.edge_max[k] = bounds_[1][1][k];
    g.point_min[k] = bounds_[2][0][k], g.point_max[k] = bounds_[2][1][k];
  }
  g.materials = materials_;
  g.material_triangles = material_triangles_, g.material_edges = material_edges_, g.material_points = material_points_;
  g.material_edge_bounds = material_edge_bounds_, g.material_point_bounds = material_point_bounds_;
  // The triangle vertices: the vertices with a normal, positions (offset 0), normals (12) or colours (24).
  auto triangle_vertices = [this](size_t offset, size_t bytes) {
    return [this, offset, bytes](const io::GlbStreamedLevel::Write& write) {
      for_records(path("vertices"), vertices_, vertex_bytes_, [&](const char* r, uint64_t n) {
        for (uint64_t i = 0; i < n; ++i) {
          float nrm[3];
          std::memcpy(nrm, r + i * vertex_bytes_ + 12, 12);
          if (nrm[0] != 0 || nrm[1] != 0 || nrm[2] != 0) write(r + i * vertex_bytes_ + offset, bytes);
        }
      });
    };
  };
  g.triangle_positions = triangle_vertices(0, 12);
  g.triangle_normals = triangle_vertices(12, 12);
  if (colors_) g.triangle_colors = triangle_vertices(kVertexBytes, 4);
  // Each per-material block sweeps its scratch file (MaterialSweep), its state shared by the block's copies.
  auto sweep = [&](const char* what, uint64_t count, size_t record_bytes, size_t material_at, const std::vector<uint64_t>& counts,
                   uint64_t total, size_t out_bytes, MaterialSweep::Emit emit) {
    auto s = std::make_shared<MaterialSweep>(path(what), count, record_bytes, material_at, materials,
                                             materials ? counts : std::vector<uint64_t>{total}, out_bytes, std::move(emit));
    return [s](uint32_t m, const io::GlbStreamedLevel::Write& write) { s->write(m, write); };
  };
  g.triangle_indices = sweep("triangles", triangles_, triangle_bytes_, kTriangleBytes, material_triangles_, triangles_, 12,
                             [this](const char* r, char* out) {
                               for (int k = 0; k < 3; ++k) {
                                 const uint32_t id = triangle_vertex_id(key_at(r + 8 * k));
                                 std::memcpy(out + 4 * k, &id, 4);
                               }
                             });
  const size_t edge_colors_at = kEdgeBytes + (materials ? 4 : 0);
  g.edge_positions = sweep("edges", edges_, edge_bytes_, kEdgeBytes, material_edges_, edges_, 24,
                           [](const char* r, char* out) { std::memcpy(out, r + 20, 24); });
  g.edge_thickness = sweep("edges", edges_, edge_bytes_, kEdgeBytes, material_edges_, edges_, 8, [](const char* r, char* out) {
    std::memcpy(out, r + 16, 4);
    std::memcpy(out + 4, r + 16, 4);
  });
  if (colors_)
    g.edge_colors = sweep("edges", edges_, edge_bytes_, kEdgeBytes, material_edges_, edges_, 8,
                          [edge_colors_at](const char* r, char* out) { std::memcpy(out, r + edge_colors_at, 8); });
  const size_t point_colors_at = kPointBytes + (materials ? 4 : 0);
  g.point_positions = sweep("points", points_, point_bytes_, kPointBytes, material_points_, points_, 12,
                            [](const char* r, char* out) { std::memcpy(out, r + 8, 12); });
  if (colors_)
    g.point_colors = sweep("points", points_, point_bytes_, kPointBytes, material_points_, points_, 4,
                           [point_colors_at](const char* r, char* out) { std::memcpy(out, r + point_colors_at, 4); });
  g.point_size = sweep("points", points_, point_bytes_, kPointBytes, material_points_, points_, 4,
                        [](const char* r, char* out) { std::memcpy(out, r + 20, 4); });
  return g;
}

void OpenLevels::add(size_t level, const RegionPart& part) {
  std::unique_ptr<LevelFiles>& files = open_[level];
  if (!files && work_)
    files = std::make_unique<LevelFiles>(work_->scratch(stem_ + std::to_string(level)), cells_.at(level), materials_, colors_);
  else if (!files)
    files = std::make_unique<LevelFiles>(output_dir_ + "/" + stem_ + std::to_string(level) + ".scratch-", cells_.at(level),
                                         materials_, colors_, ".partial");
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

std::vector<std::string> write_level_outputs(const LevelFiles& level, const std::string& dir, const std::string& stem,
                                             const std::vector<std::string>& comments, bool ply, bool obj, io::GlbBuilder* glb,
                                             double lower) {
  tbb::task_group writers;
  if (ply) writers.run([&] { level.write_ply(dir + "/" + stem + ".ply", comments); });
  if (obj) writers.run([&] { level.write_obj(dir + "/" + stem + ".obj", comments); });
  if (glb) writers.run([&] { glb->add(level.glb(stem, lower)); });
  writers.wait();
  std::vector<std::string> files;
  if (ply) files.push_back(stem + ".ply");
  if (obj) files.push_back(stem + ".obj");
  if (obj && level.has_materials()) files.push_back(stem + ".mtl");
  return files;
}

}  // namespace lodstream::stream

// Binary glTF 2.0 (GLB) writer for a chain of levels of detail (see io/glb_writer.h for the layout).
// Follows the glTF 2.0 specification (Khronos; GLB container: 12-byte header, JSON chunk padded with spaces,
// BIN chunk padded with zeros, every chunk 4-byte aligned) and the MSFT_lod vendor extension
// (KhronosGroup/glTF extensions/2.0/Vendor/MSFT_lod: `ids` on the highest level, lower levels in order;
// extras.MSFT_screencoverage with one value per level, highest level first).
//
// One level at a time (GlbBuilder): a level's accessors and buffer views are planned (counts, byte lengths,
// POSITION min/max, offsets from the running BIN size) and its blocks streamed, in the same order, to a
// scratch file; the JSON, which needs every level's plan, is written last, in front of a copy of the
// scratch file. So neither the binary data nor more than one level's mesh is ever held whole in memory.
#include "io/glb_writer.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::io {

static_assert(std::endian::native == std::endian::little, "the GLB writer copies little-endian memory as is");

namespace {

using Json = nlohmann::ordered_json;

constexpr uint32_t kMagic = 0x46546C67;      // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr int kFloat = 5126, kUnsignedInt = 5125, kUnsignedByte = 5121;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kPoints = 0, kLines = 1, kTriangles = 4;

uint64_t align4(uint64_t n) { return (n + 3) & ~uint64_t{3}; }

// The triangles' own vertex array: the vertex ids they use in order of first use, and the triangles
// renumbered into that array.
struct CompactTriangles {
  std::vector<uint32_t> vertices;
  std::vector<uint32_t> indices;
};

CompactTriangles compact_triangles(const core::LodMesh& mesh, const std::vector<uint32_t>& triangles) {
  CompactTriangles c;
  if (triangles.empty()) return c;
  constexpr uint32_t kUnset = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> slot(mesh.vertex_count(), kUnset);
  c.indices.reserve(triangles.size());
  for (uint32_t id : triangles) {
    if (slot[id] == kUnset) {
      slot[id] = static_cast<uint32_t>(c.vertices.size());
      c.vertices.push_back(id);
    }
    c.indices.push_back(slot[id]);
  }
  return c;
}

// The primitives of one material: a mesh without materials is one part (the mesh's own arrays, no copy);
// with materials, one part per material used, its triangles, edges (with their thickness) and points in
// mesh order.
struct Part {
  const std::vector<uint32_t>* triangles;
  const std::vector<uint32_t>* edges;
  const std::vector<float>* thickness;
  const std::vector<uint32_t>* points;
  const std::vector<float>* point_size;  // empty: the level has no point sizes
  uint32_t material;
};
struct Parts {
  std::vector<Part> parts;
  std::vector<std::vector<uint32_t>> triangles, edges, points;  // per material, when split
  std::vector<std::vector<float>> thickness, point_size;
};

void split_by_material(const core::LodMesh& mesh, Parts* out) {
  if (mesh.materials.empty()) {
    out->parts.push_back({&mesh.triangles, &mesh.edges, &mesh.thickness, &mesh.points, &mesh.point_size, 0});
    return;
  }
  const size_t n = mesh.materials.size();
  out->triangles.resize(n), out->edges.resize(n), out->points.resize(n), out->thickness.resize(n), out->point_size.resize(n);
  for (uint64_t t = 0; t < mesh.triangle_count(); ++t)
    out->triangles[mesh.triangle_materials[t]].insert(out->triangles[mesh.triangle_materials[t]].end(),
                                                      &mesh.triangles[3 * t], &mesh.triangles[3 * t] + 3);
  for (uint64_t e = 0; e < mesh.edge_count(); ++e) {
    const uint32_t m = mesh.edge_materials[e];
    out->edges[m].insert(out->edges[m].end(), &mesh.edges[2 * e], &mesh.edges[2 * e] + 2);
    out->thickness[m].push_back(mesh.thickness[e]);
  }
  const bool sizes = !mesh.point_size.empty();
  for (uint64_t i = 0; i < mesh.point_count(); ++i) {
    const uint32_t m = mesh.point_materials[i];
    out->points[m].push_back(mesh.points[i]);
    if (sizes) out->point_size[m].push_back(mesh.point_size[i]);
  }
  for (size_t m = 0; m < n; ++m)
    if (!out->triangles[m].empty() || !out->edges[m].empty() || !out->points[m].empty())
      out->parts.push_back({&out->triangles[m], &out->edges[m], &out->thickness[m], &out->points[m], &out->point_size[m],
                            static_cast<uint32_t>(m)});
}

Json material_json(const core::Material& m) {
  Json j;
  if (!m.name.empty()) j["name"] = m.name;
  Json& pbr = j["pbrMetallicRoughness"];
  pbr["baseColorFactor"] = Json::array();
  for (float c : m.base_color) pbr["baseColorFactor"].push_back(static_cast<double>(c));
  pbr["metallicFactor"] = static_cast<double>(m.metallic);
  pbr["roughnessFactor"] = static_cast<double>(m.roughness);
  if (m.alpha == core::Material::Alpha::mask) j["alphaMode"] = "MASK", j["alphaCutoff"] = static_cast<double>(m.alpha_cutoff);
  if (m.alpha == core::Material::Alpha::blend) j["alphaMode"] = "BLEND";
  j["doubleSided"] = m.double_sided;
  return j;
}

// Bounding box of the positions of `ids` (each id a vertex of `mesh`), as JSON min and max arrays.
void bounds(const core::LodMesh& mesh, const std::vector<uint32_t>& ids, Json* min, Json* max) {
  float lo[3], hi[3];
  for (int c = 0; c < 3; ++c) {
    lo[c] = std::numeric_limits<float>::infinity();
    hi[c] = -std::numeric_limits<float>::infinity();
  }
  for (uint32_t id : ids)
    for (int c = 0; c < 3; ++c) {
      const float x = mesh.positions[3 * uint64_t{id} + c];
      if (x < lo[c]) lo[c] = x;
      if (x > hi[c]) hi[c] = x;
    }
  *min = Json::array();
  *max = Json::array();
  for (int c = 0; c < 3; ++c) {
    min->push_back(static_cast<double>(lo[c]));  // exact: every float is a double
    max->push_back(static_cast<double>(hi[c]));
  }
}

// Accessors and buffer views as the first pass plans them; the second pass checks that it writes exactly
// the planned byte lengths, in the same order.
class Plan {
 public:
  // A buffer view of `count` elements of `components` 4-byte values, and its accessor; returns the accessor.
  int add(uint64_t count, int components, int component_type, const char* type, int target) {
    const uint64_t bytes = count * components * 4;  // 4 bytes: one float or uint32, or one RGBA8 colour
    const int view = static_cast<int>(views_.size());
    Json v;
    v["buffer"] = 0;
    v["byteOffset"] = bin_bytes_;
    v["byteLength"] = bytes;
    v["target"] = target;
    views_.push_back(std::move(v));
    view_bytes_.push_back(bytes);
    bin_bytes_ += align4(bytes);
    Json a;
    a["bufferView"] = view;
    a["componentType"] = component_type;
    a["count"] = count;
    a["type"] = type;
    accessors_.push_back(std::move(a));
    return static_cast<int>(accessors_.size()) - 1;
  }
  int add_positions(uint64_t count, const float* lo, const float* hi) {
    const int a = add(count, 3, kFloat, "VEC3", kArrayBuffer);
    Json& accessor = accessors_[static_cast<size_t>(a)];
    accessor["min"] = Json::array();
    accessor["max"] = Json::array();
    for (int c = 0; c < 3; ++c) {
      accessor["min"].push_back(static_cast<double>(lo[c]));
      accessor["max"].push_back(static_cast<double>(hi[c]));
    }
    return a;
  }
  int add_positions(const core::LodMesh& mesh, const std::vector<uint32_t>& ids) {
    const int a = add(ids.size(), 3, kFloat, "VEC3", kArrayBuffer);
    Json& accessor = accessors_[static_cast<size_t>(a)];
    // Both keys first, so that neither pointer below is taken before the other key's insertion (which may
    // move an ordered_json's members), and so that their order does not rest on the unspecified order of
    // argument evaluation: "max" before "min", as GCC's right-to-left order wrote them all along.
    accessor["max"] = Json::array();
    accessor["min"] = Json::array();
    bounds(mesh, ids, &accessor["min"], &accessor["max"]);
    return a;
  }
  // Vertex colours: normalized unsigned bytes, RGBA (glTF COLOR_0).
  int add_colors(uint64_t count) {
    const int a = add(count, 1, kUnsignedByte, "VEC4", kArrayBuffer);
    accessors_[static_cast<size_t>(a)]["normalized"] = true;
    return a;
  }
  Json& accessors() { return accessors_; }
  Json& views() { return views_; }
  const std::vector<uint64_t>& view_bytes() const { return view_bytes_; }
  uint64_t bin_bytes() const { return bin_bytes_; }

 private:
  Json accessors_ = Json::array();
  Json views_ = Json::array();
  std::vector<uint64_t> view_bytes_;
  uint64_t bin_bytes_ = 0;
};

// The BIN chunk's contents, block by block, checked against the plan.
class BinWriter {
 public:
  BinWriter(FileWriter& out, const std::vector<uint64_t>& view_bytes) : out_(out), view_bytes_(view_bytes) {}
  // Positions (or normals, `from`) of the vertices `ids`.
  void vec3(const std::vector<float>& from, const std::vector<uint32_t>& ids) {
    for (uint32_t id : ids) out_.write(&from[3 * uint64_t{id}], 12);
    end_block(ids.size() * 12);
  }
  // RGBA colours of the vertices `ids`.
  void rgba(const std::vector<uint8_t>& from, const std::vector<uint32_t>& ids) {
    for (uint32_t id : ids) out_.write(&from[4 * uint64_t{id}], 4);
    end_block(ids.size() * 4);
  }
  void u32(const std::vector<uint32_t>& values) {
    out_.write(values.data(), values.size() * 4);
    end_block(values.size() * 4);
  }
  void f32(const std::vector<float>& values) {
    out_.write(values.data(), values.size() * 4);
    end_block(values.size() * 4);
  }
  // Each value twice (a thickness for both ends of its edge).
  void f32_twice(const std::vector<float>& values) {
    for (float t : values) {
      const float pair[2] = {t, t};
      out_.write(pair, sizeof pair);
    }
    end_block(values.size() * 8);
  }
  // A block written by `fill`, `bytes` long.
  void stream(uint64_t bytes, const GlbStreamedLevel::Block& fill) {
    uint64_t written = 0;
    fill([&](const void* data, size_t n) {
      out_.write(data, n);
      written += n;
    });
    if (written != bytes) fail(Status::internal, out_.path() + ": GLB data does not match its plan");
    end_block(bytes);
  }
  size_t blocks() const { return block_; }

 private:
  void end_block(uint64_t bytes) {
    if (block_ >= view_bytes_.size() || view_bytes_[block_] != bytes)
      fail(Status::internal, out_.path() + ": GLB data does not match its plan");
    static constexpr char zeros[4] = {0, 0, 0, 0};
    out_.write(zeros, align4(bytes) - bytes);
    ++block_;
  }
  FileWriter& out_;
  const std::vector<uint64_t>& view_bytes_;
  size_t block_ = 0;
};

void write_u32(FileWriter& out, uint64_t value) {
  const uint32_t v = static_cast<uint32_t>(value);
  out.write(&v, 4);
}

void check_level(const std::string& path, const GlbLevel& level) {
  if (level.mesh == nullptr) fail(Status::internal, path + ": level '" + level.name + "' has no mesh");
  if (!std::isfinite(level.screen_coverage))
    fail(Status::internal, path + ": level '" + level.name + "' has a non-finite screen coverage");
  if (const std::string v = core::convention_violation(*level.mesh); !v.empty())
    fail(Status::internal, path + ": cannot write level: " + v);
}

}  // namespace

struct GlbBuilder::State {
  std::string path, scratch, generator;
  Sync sync = Sync::durable;
  Plan plan;
  Json nodes = Json::array();
  Json meshes = Json::array();
  std::vector<core::Material> materials;  // the table of the first level that has one
  std::vector<double> coverage;
  FileWriter bin;  // the scratch file, opened with the first block
  std::unique_ptr<BinWriter> blocks;

  // A level's node (with its mesh when it has primitives) and coverage, after its buffer views were planned
  // from `first_view` on; returns the writer of its blocks, or null when it planned none.
  BinWriter* add_node(const std::string& name, double screen_coverage, Json primitives, size_t first_view) {
    // The whole file must stay within 4 GiB (a 32-bit length field); the BIN chunk alone already tells.
    if (plan.bin_bytes() > UINT32_MAX) fail(Status::io_error, path + ": the levels do not fit in one GLB file (4 GiB at most)");
    Json node;
    node["name"] = name;
    if (!primitives.empty()) {
      node["mesh"] = meshes.size();
      Json m;
      m["name"] = name;
      m["primitives"] = std::move(primitives);
      meshes.push_back(std::move(m));
    }
    nodes.push_back(std::move(node));
    coverage.push_back(screen_coverage);
    if (plan.view_bytes().size() == first_view) return nullptr;
    if (!blocks) {
      bin.open(scratch, 1 << 20);
      blocks = std::make_unique<BinWriter>(bin, plan.view_bytes());
    }
    return blocks.get();
  }
};

GlbBuilder::GlbBuilder(std::string path, std::string scratch, std::string generator, Sync sync)
    : state_(std::make_unique<State>()) {
  state_->sync = sync;
  state_->path = std::move(path);
  state_->scratch = std::move(scratch);
  state_->generator = std::move(generator);
}

GlbBuilder::~GlbBuilder() {
  std::error_code ec;
  std::filesystem::remove(state_->scratch, ec);  // committed by finish() but not yet removed when it failed
}

void GlbBuilder::add(const GlbLevel& level) {
  State& s = *state_;
  check_level(s.path, level);
  const core::LodMesh& mesh = *level.mesh;
  Plan& plan = s.plan;
  const size_t first_view = plan.view_bytes().size();
  if (!mesh.materials.empty()) {
    if (s.materials.empty()) s.materials = mesh.materials;
    else if (s.materials != mesh.materials) fail(Status::internal, s.path + ": levels with different material tables");
  }
  Parts parts;
  split_by_material(mesh, &parts);
  const bool colors = !mesh.colors.empty();
  Json primitives = Json::array();
  std::vector<CompactTriangles> c(parts.parts.size());
  for (size_t i = 0; i < parts.parts.size(); ++i) {
    const Part& part = parts.parts[i];
    if (part.triangles->empty()) continue;
    c[i] = compact_triangles(mesh, *part.triangles);
    Json p;
    p["attributes"]["POSITION"] = plan.add_positions(mesh, c[i].vertices);
    if (!mesh.normals.empty()) p["attributes"]["NORMAL"] = plan.add(c[i].vertices.size(), 3, kFloat, "VEC3", kArrayBuffer);
    if (colors) p["attributes"]["COLOR_0"] = plan.add_colors(c[i].vertices.size());
    p["indices"] = plan.add(c[i].indices.size(), 1, kUnsignedInt, "SCALAR", kElementArrayBuffer);
    p["material"] = part.material;
    p["mode"] = kTriangles;
    primitives.push_back(std::move(p));
  }
  for (const Part& part : parts.parts) {
    if (part.edges->empty()) continue;
    Json p;
    p["attributes"]["POSITION"] = plan.add_positions(mesh, *part.edges);  // both ends of every edge
    p["attributes"]["_THICKNESS"] = plan.add(part.edges->size(), 1, kFloat, "SCALAR", kArrayBuffer);
    if (colors) p["attributes"]["COLOR_0"] = plan.add_colors(part.edges->size());
    p["material"] = part.material;
    p["mode"] = kLines;
    primitives.push_back(std::move(p));
  }
  for (const Part& part : parts.parts) {
    if (part.points->empty()) continue;
    Json p;
    p["attributes"]["POSITION"] = plan.add_positions(mesh, *part.points);
    if (!part.point_size->empty()) p["attributes"]["_SIZE"] = plan.add(part.points->size(), 1, kFloat, "SCALAR", kArrayBuffer);
    if (colors) p["attributes"]["COLOR_0"] = plan.add_colors(part.points->size());
    p["material"] = part.material;
    p["mode"] = kPoints;
    primitives.push_back(std::move(p));
  }
  BinWriter* blocks = s.add_node(level.name, level.screen_coverage, std::move(primitives), first_view);
  if (!blocks) return;
  BinWriter& bin = *blocks;
  for (size_t i = 0; i < parts.parts.size(); ++i) {
    if (parts.parts[i].triangles->empty()) continue;
    bin.vec3(mesh.positions, c[i].vertices);
    if (!mesh.normals.empty()) bin.vec3(mesh.normals, c[i].vertices);
    if (colors) bin.rgba(mesh.colors, c[i].vertices);
    bin.u32(c[i].indices);
  }
  for (const Part& part : parts.parts) {
    if (part.edges->empty()) continue;
    bin.vec3(mesh.positions, *part.edges);
    bin.f32_twice(*part.thickness);
    if (colors) bin.rgba(mesh.colors, *part.edges);
  }
  for (const Part& part : parts.parts) {
    if (part.points->empty()) continue;
    bin.vec3(mesh.positions, *part.points);
    if (!part.point_size->empty()) bin.f32(*part.point_size);
    if (colors) bin.rgba(mesh.colors, *part.points);
  }
  if (bin.blocks() != plan.view_bytes().size()) fail(Status::internal, s.path + ": GLB data does not match its plan");
}

void GlbBuilder::add(const GlbStreamedLevel& level) {
  State& s = *state_;
  if (!std::isfinite(level.screen_coverage))
    fail(Status::internal, s.path + ": level '" + level.name + "' has a non-finite screen coverage");
  const size_t nm = level.materials.size();
  if (nm > 0) {
    if (level.material_triangles.size() != nm || level.material_edges.size() != nm || level.material_points.size() != nm ||
        level.material_edge_bounds.size() != 6 * nm || level.material_point_bounds.size() != 6 * nm)
      fail(Status::internal, s.path + ": level '" + level.name + "': per-material counts do not match its material table");
    if (s.materials.empty()) s.materials = level.materials;
    else if (s.materials != level.materials) fail(Status::internal, s.path + ": levels with different material tables");
  }
  // Per material (one "material" 0 without a table): its counts and bounds.
  const std::vector<uint64_t> one_t{level.triangles}, one_e{level.edges}, one_p{level.points};
  const std::vector<uint64_t>& tri = nm ? level.material_triangles : one_t;
  const std::vector<uint64_t>& edg = nm ? level.material_edges : one_e;
  const std::vector<uint64_t>& pts = nm ? level.material_points : one_p;
  auto bounds = [&](const std::vector<float>& per_material, const float* lo, const float* hi, size_t m, bool max) {
    return nm ? &per_material[6 * m + (max ? 3 : 0)] : max ? hi : lo;
  };
  Plan& plan = s.plan;
  const size_t first_view = plan.view_bytes().size();
  Json primitives = Json::array();
  // Accessors are planned one block kind at a time (so the BIN holds each kind's blocks in material order).
  if (level.triangles > 0) {
    const int position = plan.add_positions(level.triangle_vertices, level.triangle_min, level.triangle_max);
    const int normal = level.normals ? plan.add(level.triangle_vertices, 3, kFloat, "VEC3", kArrayBuffer) : -1;
    const int color = level.colors ? plan.add_colors(level.triangle_vertices) : -1;
    for (size_t m = 0; m < tri.size(); ++m) {
      if (tri[m] == 0) continue;
      Json p;
      p["attributes"]["POSITION"] = position;
      if (normal >= 0) p["attributes"]["NORMAL"] = normal;
      if (color >= 0) p["attributes"]["COLOR_0"] = color;
      p["indices"] = plan.add(3 * tri[m], 1, kUnsignedInt, "SCALAR", kElementArrayBuffer);
      p["material"] = m;
      p["mode"] = kTriangles;
      primitives.push_back(std::move(p));
    }
  }
  if (level.edges > 0) {
    const size_t first = primitives.size();
    for (size_t m = 0; m < edg.size(); ++m) {
      if (edg[m] == 0) continue;
      Json p;
      p["attributes"]["POSITION"] = plan.add_positions(2 * edg[m], bounds(level.material_edge_bounds, level.edge_min, level.edge_max, m, false),
                                                       bounds(level.material_edge_bounds, level.edge_min, level.edge_max, m, true));
      primitives.push_back(std::move(p));
    }
    for (size_t m = 0, i = first; m < edg.size(); ++m)
      if (edg[m] > 0) primitives[i++]["attributes"]["_THICKNESS"] = plan.add(2 * edg[m], 1, kFloat, "SCALAR", kArrayBuffer);
    if (level.colors)
      for (size_t m = 0, i = first; m < edg.size(); ++m)
        if (edg[m] > 0) primitives[i++]["attributes"]["COLOR_0"] = plan.add_colors(2 * edg[m]);
    for (size_t m = 0, i = first; m < edg.size(); ++m)
      if (edg[m] > 0) primitives[i]["material"] = m, primitives[i++]["mode"] = kLines;
  }
  if (level.points > 0) {
    const size_t first = primitives.size();
    for (size_t m = 0; m < pts.size(); ++m) {
      if (pts[m] == 0) continue;
      Json p;
      p["attributes"]["POSITION"] = plan.add_positions(pts[m], bounds(level.material_point_bounds, level.point_min, level.point_max, m, false),
                                                       bounds(level.material_point_bounds, level.point_min, level.point_max, m, true));
      primitives.push_back(std::move(p));
    }
    if (level.point_size)
      for (size_t m = 0, i = first; m < pts.size(); ++m)
        if (pts[m] > 0) primitives[i++]["attributes"]["_SIZE"] = plan.add(pts[m], 1, kFloat, "SCALAR", kArrayBuffer);
    if (level.colors)
      for (size_t m = 0, i = first; m < pts.size(); ++m)
        if (pts[m] > 0) primitives[i++]["attributes"]["COLOR_0"] = plan.add_colors(pts[m]);
    for (size_t m = 0, i = first; m < pts.size(); ++m)
      if (pts[m] > 0) primitives[i]["material"] = m, primitives[i++]["mode"] = kPoints;
  }
  BinWriter* blocks = s.add_node(level.name, level.screen_coverage, std::move(primitives), first_view);
  if (!blocks) return;
  BinWriter& bin = *blocks;
  auto per_material = [&](const std::vector<uint64_t>& counts, uint64_t bytes_each, const GlbStreamedLevel::MaterialBlock& block) {
    for (size_t m = 0; m < counts.size(); ++m)
      if (counts[m] > 0)
        bin.stream(bytes_each * counts[m], [&](const GlbStreamedLevel::Write& write) { block(static_cast<uint32_t>(m), write); });
  };
  if (level.triangles > 0) {
    bin.stream(12 * level.triangle_vertices, level.triangle_positions);
    if (level.normals) bin.stream(12 * level.triangle_vertices, level.triangle_normals);
    if (level.colors) bin.stream(4 * level.triangle_vertices, level.triangle_colors);
    per_material(tri, 12, level.triangle_indices);
  }
  if (level.edges > 0) {
    per_material(edg, 24, level.edge_positions);
    per_material(edg, 8, level.edge_thickness);
    if (level.colors) per_material(edg, 8, level.edge_colors);
  }
  if (level.points > 0) {
    per_material(pts, 12, level.point_positions);
    if (level.point_size) per_material(pts, 4, level.point_size);
    if (level.colors) per_material(pts, 4, level.point_colors);
  }
  if (bin.blocks() != plan.view_bytes().size()) fail(Status::internal, s.path + ": GLB data does not match its plan");
}

void GlbBuilder::finish() {
  State& s = *state_;
  if (s.nodes.empty()) fail(Status::internal, s.path + ": no level to write");
  const size_t levels = s.nodes.size();
  if (levels > 1) {
    Json ids = Json::array();
    Json coverage = Json::array();
    for (size_t i = 0; i < levels; ++i) {
      if (i > 0) ids.push_back(i);
      coverage.push_back(s.coverage[i]);
    }
    s.nodes[0]["extensions"]["MSFT_lod"]["ids"] = std::move(ids);
    s.nodes[0]["extras"]["MSFT_screencoverage"] = std::move(coverage);
  }

  Json gltf;
  gltf["asset"]["generator"] = s.generator;
  gltf["asset"]["version"] = "2.0";
  if (levels > 1) gltf["extensionsUsed"] = Json::array({"MSFT_lod"});
  gltf["scene"] = 0;
  gltf["scenes"] = Json::array({Json{{"nodes", Json::array({0})}}});
  gltf["nodes"] = std::move(s.nodes);
  if (!s.meshes.empty()) {
    gltf["meshes"] = std::move(s.meshes);
    if (s.materials.empty()) {
      Json material;
      material["pbrMetallicRoughness"]["metallicFactor"] = 0.0;  // a plain diffuse surface, not a metal
      material["doubleSided"] = true;
      gltf["materials"] = Json::array({std::move(material)});
    } else {
      gltf["materials"] = Json::array();
      for (const core::Material& m : s.materials) gltf["materials"].push_back(material_json(m));
    }
    gltf["accessors"] = std::move(s.plan.accessors());
    gltf["bufferViews"] = std::move(s.plan.views());
    gltf["buffers"] = Json::array({Json{{"byteLength", s.plan.bin_bytes()}}});
  }
  s.nodes = Json::array();
  s.meshes = Json::array();

  std::string json = gltf.dump();
  json.resize(align4(json.size()), ' ');
  const uint64_t bin_bytes = s.plan.bin_bytes();  // already a multiple of 4
  const uint64_t total = 12 + 8 + json.size() + (bin_bytes > 0 ? 8 + bin_bytes : 0);
  if (total > UINT32_MAX) fail(Status::io_error, s.path + ": the levels do not fit in one GLB file (4 GiB at most)");
  if (bin_bytes > 0) s.bin.commit();

  FileWriter out(s.path, 1 << 20, s.sync);
  write_u32(out, kMagic);
  write_u32(out, 2);
  write_u32(out, total);
  write_u32(out, json.size());
  write_u32(out, kChunkJson);
  out.write(json);
  if (bin_bytes > 0) {
    write_u32(out, bin_bytes);
    write_u32(out, kChunkBin);
    std::unique_ptr<FILE, int (*)(FILE*)> in(std::fopen(s.scratch.c_str(), "rb"), &std::fclose);
    if (!in) fail(Status::io_error, s.scratch + ": cannot reopen the GLB's binary data");
    std::vector<char> buffer(1 << 20);
    uint64_t copied = 0;
    for (size_t n; (n = std::fread(buffer.data(), 1, buffer.size(), in.get())) > 0; copied += n) out.write(buffer.data(), n);
    if (std::ferror(in.get()) || copied != bin_bytes)
      fail(Status::io_error, s.scratch + ": cannot read back the GLB's binary data");
  }
  out.commit();
  std::error_code ec;
  std::filesystem::remove(s.scratch, ec);
}

void write_glb(const std::string& path, std::span<const GlbLevel> levels, const std::string& generator, Sync sync) {
  if (levels.empty()) fail(Status::internal, path + ": no level to write");
  for (const GlbLevel& level : levels) check_level(path, level);
  GlbBuilder builder(path, path + ".bin.partial", generator, sync);  // a name that says "not a result" even once committed
  for (const GlbLevel& level : levels) builder.add(level);
  builder.finish();
}

}  // namespace lodstream::io

// Stand-in for the region sink of /work/REGIONS.md: a whole level cut by the octree rules (see
// stream/region_standin.h). Vertices are sorted by their depth-20 Morton code, so that a node's cells are
// the codes in [morton20(node), morton20(node) + 8^(20 - depth)), counted by binary search.
#include "stream/region_standin.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "core/status.h"
#include "io/file_writer.h"

namespace lodstream::stream::standin {

namespace {

uint64_t spread(uint32_t v) {  // bit i of v to bit 3i
  uint64_t x = v & 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

uint64_t point_code(const Cube& cube, const float* p) {
  constexpr double n = double{1 << kMaxDepth};
  uint32_t c[3];
  for (int k = 0; k < 3; ++k) {
    const double f = std::floor((static_cast<double>(p[k]) - cube.min[k]) / cube.side * n);
    c[k] = static_cast<uint32_t>(std::clamp(f, 0.0, n - 1));
  }
  return spread(c[0]) | spread(c[1]) << 1 | spread(c[2]) << 2;
}

uint64_t node_span(const Key& k) { return uint64_t{1} << (3 * (kMaxDepth - k.depth)); }

}  // namespace

Cube scene_cube(const double bbox_min[3], const double bbox_max[3]) {
  Cube c;
  double side = 0;
  for (int k = 0; k < 3; ++k) side = std::max(side, bbox_max[k] - bbox_min[k]);
  side = std::max(side * (1 + std::ldexp(1.0, -20)), 1e-30);
  for (int k = 0; k < 3; ++k) c.min[k] = (bbox_min[k] + bbox_max[k]) / 2 - side / 2;
  c.side = side;
  return c;
}

uint64_t morton20(const Key& k) {
  const unsigned s = kMaxDepth - k.depth;
  return spread(k.x << s) | spread(k.y << s) << 1 | spread(k.z << s) << 2;
}

void node_box(const Cube& cube, const Key& k, double min[3], double* side) {
  const double s = std::ldexp(cube.side, -static_cast<int>(k.depth));
  const uint32_t xyz[3] = {k.x, k.y, k.z};
  for (int i = 0; i < 3; ++i) min[i] = cube.min[i] + xyz[i] * s;
  *side = s;
}

std::vector<Region> cut_level(const Cube& cube, const core::LodMesh& mesh, const std::vector<Region>& coarser, uint64_t max_cells) {
  std::vector<uint64_t> codes(mesh.vertex_count());
  for (uint64_t v = 0; v < codes.size(); ++v) codes[v] = point_code(cube, &mesh.positions[3 * v]);
  std::sort(codes.begin(), codes.end());
  auto count = [&](const Key& k) {
    const uint64_t lo = morton20(k), hi = lo + node_span(k);
    return static_cast<uint64_t>(std::lower_bound(codes.begin(), codes.end(), hi) - std::lower_bound(codes.begin(), codes.end(), lo));
  };
  std::vector<Region> cut;
  // Depth first, children in Morton order (x bit lowest): the output is in region order when `coarser` is.
  auto split = [&](auto&& self, const Key& k) -> void {
    const uint64_t n = count(k);
    if (n <= max_cells || k.depth >= kMaxDepth) {
      cut.push_back({k, n});
      return;
    }
    for (uint32_t c = 0; c < 8; ++c)
      self(self, Key{static_cast<uint8_t>(k.depth + 1), 2 * k.x + (c & 1), 2 * k.y + (c >> 1 & 1), 2 * k.z + (c >> 2 & 1)});
  };
  if (coarser.empty()) split(split, Key{});
  for (const Region& r : coarser) split(split, r.key);
  return cut;
}

void split_level(const Cube& cube, const core::LodMesh& mesh, const std::vector<Region>& cut,
                 const std::function<void(const Region&, const core::LodMesh&)>& sink) {
  std::vector<uint64_t> starts(cut.size());
  for (size_t i = 0; i < cut.size(); ++i) starts[i] = morton20(cut[i].key);
  // The cut covers the cube, so a code's region is the last one starting at or before it.
  auto region_of = [&](uint32_t vertex) {
    const uint64_t code = point_code(cube, &mesh.positions[3 * uint64_t{vertex}]);
    return static_cast<uint32_t>(std::upper_bound(starts.begin(), starts.end(), code) - starts.begin() - 1);
  };
  // Owner of every primitive (the region of its smallest vertex id), then the primitives bucketed by owner
  // in level order: kinds[k] lists primitive indices of kind k (triangles, edges, points).
  const std::vector<uint32_t>* lists[3] = {&mesh.triangles, &mesh.edges, &mesh.points};
  const unsigned arity[3] = {3, 2, 1};
  std::vector<std::vector<uint64_t>> first(3), order(3);
  for (int k = 0; k < 3; ++k) {
    const uint64_t n = lists[k]->size() / arity[k];
    std::vector<uint32_t> owner(n);
    for (uint64_t i = 0; i < n; ++i) {
      const uint32_t* ids = &(*lists[k])[arity[k] * i];
      owner[i] = region_of(*std::min_element(ids, ids + arity[k]));
    }
    first[k].assign(cut.size() + 1, 0);
    for (uint32_t o : owner) ++first[k][o + 1];
    for (size_t r = 0; r < cut.size(); ++r) first[k][r + 1] += first[k][r];
    order[k].resize(n);
    std::vector<uint64_t> next(first[k].begin(), first[k].end() - 1);
    for (uint64_t i = 0; i < n; ++i) order[k][next[owner[i]]++] = i;
  }
  constexpr uint32_t kUnset = UINT32_MAX;
  std::vector<uint32_t> local(mesh.vertex_count(), kUnset);
  const bool normals = !mesh.normals.empty();
  std::vector<uint32_t> used;  // the level's ids of the vertices in `part`
  core::LodMesh part;
  for (size_t r = 0; r < cut.size(); ++r) {
    part = core::LodMesh();
    auto use = [&](uint32_t v) {
      if (local[v] == kUnset) {
        local[v] = static_cast<uint32_t>(part.vertex_count());
        used.push_back(v);
        part.positions.insert(part.positions.end(), &mesh.positions[3 * uint64_t{v}], &mesh.positions[3 * uint64_t{v} + 3]);
        if (normals) part.normals.insert(part.normals.end(), &mesh.normals[3 * uint64_t{v}], &mesh.normals[3 * uint64_t{v} + 3]);
      }
      return local[v];
    };
    std::vector<uint32_t>* outs[3] = {&part.triangles, &part.edges, &part.points};
    for (int k = 0; k < 3; ++k)
      for (uint64_t j = first[k][r]; j < first[k][r + 1]; ++j) {
        const uint64_t i = order[k][j];
        for (unsigned c = 0; c < arity[k]; ++c) outs[k]->push_back(use((*lists[k])[arity[k] * i + c]));
        if (k == 1) part.thickness.push_back(mesh.thickness[i]);
      }
    sink(cut[r], part);
    for (uint32_t v : used) local[v] = kUnset;
    used.clear();
  }
}

void save_mesh(const std::string& path, const core::LodMesh& mesh) {
  io::FileWriter out(path);
  const uint64_t sizes[6] = {mesh.positions.size(), mesh.normals.size(), mesh.triangles.size(),
                             mesh.edges.size(),     mesh.thickness.size(), mesh.points.size()};
  out.write(sizes, sizeof sizes);
  out.write(mesh.positions.data(), mesh.positions.size() * 4);
  out.write(mesh.normals.data(), mesh.normals.size() * 4);
  out.write(mesh.triangles.data(), mesh.triangles.size() * 4);
  out.write(mesh.edges.data(), mesh.edges.size() * 4);
  out.write(mesh.thickness.data(), mesh.thickness.size() * 4);
  out.write(mesh.points.data(), mesh.points.size() * 4);
  out.commit();
}

core::LodMesh load_mesh(const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> in(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!in) fail(Status::io_error, path + ": cannot read back a level");
  uint64_t sizes[6];
  if (std::fread(sizes, sizeof sizes, 1, in.get()) != 1) fail(Status::io_error, path + ": level file is truncated");
  core::LodMesh m;
  auto read = [&](auto& v, uint64_t n) {
    v.resize(n);
    if (n && std::fread(v.data(), 4, n, in.get()) != n) fail(Status::io_error, path + ": level file is truncated");
  };
  read(m.positions, sizes[0]);
  read(m.normals, sizes[1]);
  read(m.triangles, sizes[2]);
  read(m.edges, sizes[3]);
  read(m.thickness, sizes[4]);
  read(m.points, sizes[5]);
  return m;
}

}  // namespace lodstream::stream::standin

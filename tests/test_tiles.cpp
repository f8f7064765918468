// 3D Tiles output (stream/tiles.h, io/tileset_writer.h, core/thick_primitives.h) fed by the emit stage's
// region sink (stream/emit_regions.h): the union of a level's tiles is that level's mesh, primitive for
// primitive and bit for bit; tiles are byte-identical for any --threads, --memory and chunk size; the
// tileset's boxes hold their content and children and its errors never grow downwards; the error bound
// holds against report's Hausdorff.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include <nlohmann/json.hpp>

#include "core/octree_regions.h"
#include "core/polygon_triangulation.h"
#include "core/ray_scene.h"
#include "core/thick_primitives.h"
#include "io/lod_reader.h"
#include "io/tileset_writer.h"
#include "lodstream/lodstream.h"
#include "stream/tiles.h"
#include "core/status.h"
#include "test_util.h"

#ifdef LODSTREAM_HAVE_MESHOPT
#include <meshoptimizer.h>
#endif

namespace lodstream::test {
namespace {

using json = nlohmann::json;
using P3 = std::array<float, 3>;
// A primitive as its corner positions, bit patterns (so that -0 and 0 differ), sorted within nothing:
// the corner order is part of the primitive (winding).
using Prim = std::vector<uint32_t>;

uint32_t bits(float f) {
  uint32_t b;
  std::memcpy(&b, &f, 4);
  return b;
}

Prim prim(const core::LodMesh& m, const uint32_t* ids, int n) {
  Prim p;
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) p.push_back(bits(m.positions[3 * uint64_t{ids[i]} + k]));
  return p;
}

// Every primitive of `m` by kind (0 triangles, 1 edges, 2 points), as a multiset.
std::array<std::multiset<Prim>, 3> primitives(const core::LodMesh& m) {
  std::array<std::multiset<Prim>, 3> s;
  // A triangle from its smallest corner on: meshopt's index codec may rotate a triangle's corners (the
  // winding is kept).
  for (uint64_t t = 0; t < m.triangle_count(); ++t) {
    Prim p = prim(m, &m.triangles[3 * t], 3);
    const auto first = std::min({p.begin(), p.begin() + 3, p.begin() + 6}, [](auto a, auto b) {
      return std::lexicographical_compare(a, a + 3, b, b + 3);
    });
    std::rotate(p.begin(), first, p.end());
    s[0].insert(std::move(p));
  }
  for (uint64_t e = 0; e < m.edge_count(); ++e) s[1].insert(prim(m, &m.edges[2 * e], 2));
  for (uint32_t p : m.points) s[2].insert(prim(m, &p, 1));
  return s;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A tile GLB read back into a LodMesh (positions, triangles from indices, LINES and POINTS as
// unindexed vertices); `thickness` from _THICKNESS, `point_size` from _SIZE (left empty when a POINTS
// primitive has none). Enough for the files stream/tiles.cpp writes: float or
// KHR_mesh_quantization SHORT positions (dequantized through the node's translation and scale, in double,
// then rounded to float), uint16 or uint32 indices, views plain or EXT_meshopt_compression.
core::LodMesh read_tile(const std::string& path) {
  const std::string b = slurp(path);
  EXPECT_GE(b.size(), 20u) << path;
  uint32_t json_len;
  std::memcpy(&json_len, b.data() + 12, 4);
  const json g = json::parse(b.substr(20, json_len));
  const char* bin = b.data() + 20 + json_len + 8;
  std::vector<std::vector<char>> decoded;  // keeps meshopt-decoded views alive
  auto view = [&](int accessor, int* count, int* stride) -> const char* {
    const json& a = g["accessors"][accessor];
    *count = a["count"].get<int>();
    const json& v = g["bufferViews"][a["bufferView"].get<int>()];
    *stride = v.value("byteStride", 0);
    if (!v.contains("extensions")) return bin + v.value("byteOffset", size_t{0});
    const json& e = v["extensions"]["EXT_meshopt_compression"];
#ifdef LODSTREAM_HAVE_MESHOPT
    const size_t n = e["count"].get<size_t>(), es = e["byteStride"].get<size_t>();
    std::vector<char> out(n * es);
    const auto* src = reinterpret_cast<const unsigned char*>(bin + e.value("byteOffset", size_t{0}));
    const size_t len = e["byteLength"].get<size_t>();
    const int rc = e["mode"] == "TRIANGLES" ? meshopt_decodeIndexBuffer(out.data(), n, es, src, len)
                                            : meshopt_decodeVertexBuffer(out.data(), n, es, src, len);
    EXPECT_EQ(rc, 0) << path;
    *stride = static_cast<int>(es);
    decoded.push_back(std::move(out));
    return decoded.back().data();
#else
    ADD_FAILURE() << path << ": EXT_meshopt_compression needs meshoptimizer";
    (void)e;
    return nullptr;
#endif
  };
  double translation[3] = {0, 0, 0}, scale[3] = {1, 1, 1};
  const json& node = g["nodes"][0];
  for (int k = 0; k < 3; ++k) {
    if (node.contains("translation")) translation[k] = node["translation"][k].get<double>();
    if (node.contains("scale")) scale[k] = node["scale"][k].get<double>();
  }
  core::LodMesh m;
  for (const json& p : g["meshes"][0]["primitives"]) {
    const int mode = p["mode"].get<int>();
    int n, stride;
    const int pa = p["attributes"]["POSITION"].get<int>();
    const char* pos = view(pa, &n, &stride);
    const bool shorts = g["accessors"][pa]["componentType"] == 5122;
    if (stride == 0) stride = shorts ? 6 : 12;
    const uint32_t base = static_cast<uint32_t>(m.vertex_count());
    for (int i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        if (shorts) {
          int16_t q;
          std::memcpy(&q, pos + size_t(i) * stride + 2 * k, 2);
          m.positions.push_back(static_cast<float>(translation[k] + scale[k] * q));
        } else {
          float f;
          std::memcpy(&f, pos + size_t(i) * stride + 4 * k, 4);
          m.positions.push_back(static_cast<float>(translation[k] + scale[k] * f));
        }
      }
    if (mode == 4) {
      int ni, is;
      const int ia = p["indices"].get<int>();
      const char* idx = view(ia, &ni, &is);
      const bool u16 = g["accessors"][ia]["componentType"] == 5123;
      for (int i = 0; i < ni; ++i) {
        uint32_t v = 0;
        if (u16) {
          uint16_t w;
          std::memcpy(&w, idx + 2 * size_t(i), 2);
          v = w;
        } else {
          std::memcpy(&v, idx + 4 * size_t(i), 4);
        }
        m.triangles.push_back(base + v);
      }
    } else if (mode == 1) {
      int nt, ts;
      const char* t = view(p["attributes"]["_THICKNESS"].get<int>(), &nt, &ts);
      for (int i = 0; i < n; i += 2) {
        m.edges.push_back(base + i);
        m.edges.push_back(base + i + 1);
        float f;
        std::memcpy(&f, t + 4 * size_t(i), 4);
        m.thickness.push_back(f);
      }
    } else {
      for (int i = 0; i < n; ++i) m.points.push_back(base + i);
      if (p["attributes"].contains("_SIZE")) {
        int ns, ss;
        const char* sz = view(p["attributes"]["_SIZE"].get<int>(), &ns, &ss);
        EXPECT_EQ(ns, n) << path;
        for (int i = 0; i < ns; ++i) {
          float f;
          std::memcpy(&f, sz + 4 * size_t(i), 4);
          m.point_size.push_back(f);
        }
      }
    }
  }
  if (m.point_size.size() != m.points.size()) m.point_size.clear();
  return m;
}

// The position `x` snapped as the tiles snap it (io/glb_compact.h): to the nearest multiple of `quantum`.
float snapped(float x, double quantum) { return quantum > 0 ? io::snap_to_grid(x, quantum) : x; }

TEST(ThickPrimitives, EdgesBecomeCrossedQuadsAndPointsOctahedra) {
  core::LodMesh m;
  m.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 5, 5};
  m.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0};
  m.triangles = {0, 1, 2};
  m.edges = {1, 3, 0, 3};
  m.thickness = {0.5f, 0.0f};
  m.points = {3};
  double radius = 0;
  const core::LodMesh r = core::expand_thick(m, {0.1, 0.05}, &radius);
  EXPECT_EQ(r.triangle_count(), 1u + 2 * 4 + 8);
  EXPECT_EQ(r.vertex_count(), 4u + 2 * 8 + 6);
  EXPECT_TRUE(r.edges.empty() && r.points.empty() && r.thickness.empty());
  EXPECT_EQ(core::convention_violation(r), "");
  EXPECT_DOUBLE_EQ(radius, 0.25);
  // The original triangle is kept first, unchanged.
  EXPECT_EQ(std::vector<uint32_t>(r.triangles.begin(), r.triangles.begin() + 3), (std::vector<uint32_t>{0, 1, 2}));
  for (uint64_t v = 4; v < r.vertex_count(); ++v) {
    const double n = std::hypot(r.normals[3 * v], r.normals[3 * v + 1], r.normals[3 * v + 2]);
    EXPECT_NEAR(n, 1, 1e-6) << v;
  }
  // Every new triangle faces its normal (counter-clockwise seen from it) and has area.
  for (uint64_t t = 1; t < r.triangle_count(); ++t) {
    const uint32_t* id = &r.triangles[3 * t];
    double e1[3], e2[3], c[3], n[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) e1[k] = r.positions[3 * id[1] + k] - r.positions[3 * id[0] + k], e2[k] = r.positions[3 * id[2] + k] - r.positions[3 * id[0] + k];
    c[0] = e1[1] * e2[2] - e1[2] * e2[1], c[1] = e1[2] * e2[0] - e1[0] * e2[2], c[2] = e1[0] * e2[1] - e1[1] * e2[0];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) n[k] += r.normals[3 * id[i] + k];
    EXPECT_GT(c[0] * n[0] + c[1] * n[1] + c[2] * n[2], 0) << "triangle " << t;
  }
  // Width: the thick edge's quad corners lie 0.25 from its axis, the wire's 0.05 (half of one pixel, 0.1).
  auto distance_to_line = [&](uint64_t v, const float* a, const float* b) {
    double d[3], w[3], len = 0;
    for (int k = 0; k < 3; ++k) d[k] = b[k] - a[k], w[k] = r.positions[3 * v + k] - a[k], len += d[k] * d[k];
    const double t = (d[0] * w[0] + d[1] * w[1] + d[2] * w[2]) / len;
    return std::hypot(w[0] - t * d[0], w[1] - t * d[1], w[2] - t * d[2]);
  };
  for (uint64_t v = 4; v < 12; ++v) EXPECT_NEAR(distance_to_line(v, &m.positions[3], &m.positions[9]), 0.25, 1e-6);
  for (uint64_t v = 12; v < 20; ++v) EXPECT_NEAR(distance_to_line(v, &m.positions[0], &m.positions[9]), 0.05, 1e-6);
  EXPECT_THROW(core::expand_thick(m, {0.1, 0}, nullptr), Failure);
}

// A point with a size (the diameter of what collapsed into it) becomes an octahedron of radius size / 2,
// never below point_radius; without sizes every point takes point_radius.
TEST(ThickPrimitives, PointsAreOctahedraOfTheirSize) {
  core::LodMesh m;
  m.positions = {0, 0, 0, 4, 0, 0, 8, 0, 0};
  m.points = {0, 1, 2};
  m.point_size = {1.0f, 0.02f, 0.0f};
  double radius = 0;
  const core::LodMesh r = core::expand_thick(m, {0.1, 0.05}, &radius);
  ASSERT_EQ(r.vertex_count(), 3u + 3 * 6);
  EXPECT_EQ(core::convention_violation(r), "");
  EXPECT_DOUBLE_EQ(radius, 0.5);
  auto distance = [&](uint64_t v, uint32_t centre) {
    return std::hypot(r.positions[3 * v] - m.positions[3 * centre], r.positions[3 * v + 1] - m.positions[3 * centre + 1],
                      r.positions[3 * v + 2] - m.positions[3 * centre + 2]);
  };
  const double want[3] = {0.5, 0.05, 0.05};  // size / 2; the floor for 0.02 and for an unsized 0
  for (uint32_t p = 0; p < 3; ++p)
    for (uint64_t v = 3 + 6 * p; v < 3 + 6 * (p + 1); ++v) EXPECT_NEAR(distance(v, p), want[p], 1e-6) << "point " << p;
  m.point_size.clear();
  core::expand_thick(m, {0.1, 0.05}, &radius);
  EXPECT_DOUBLE_EQ(radius, 0.05);
}

// The side bound of 3D Tiles cuts (core/octree_regions.h SideBound): a node holding more than min_cells is
// split down to min_depth even when it holds fewer than max_cells; one holding fewer stays whole.
TEST(OctreeRegions, SideBoundSplitsNodesThatHoldMuch) {
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  const core::SceneCube cube = core::scene_cube(lo, hi);
  std::vector<uint64_t> codes;
  for (int i = 0; i < 10; ++i) {
    const double p[3] = {0.01 + 0.001 * i, 0.02, 0.03};  // ten cells near one corner
    codes.push_back(core::point_code(cube, p));
  }
  const double far[3] = {0.9, 0.9, 0.9};  // and one in the opposite corner
  codes.push_back(core::point_code(cube, far));
  std::sort(codes.begin(), codes.end());
  EXPECT_EQ(core::cut_regions(codes, {}, 100).size(), 1u);
  const std::vector<core::RegionKey> cut = core::cut_regions(codes, {}, 100, core::SideBound{3, 5});
  // The root and the corner's octants split down to depth 3; the far octant (one cell) stays at depth 1.
  EXPECT_EQ(cut.size(), 7u + 7u + 8u);
  for (const core::RegionKey& k : cut) {
    const uint64_t n = static_cast<uint64_t>(std::count_if(codes.begin(), codes.end(), [&](uint64_t c) {
      return c >= core::region_code(k) && c < core::region_code(k) + core::region_span(k);
    }));
    if (n > 5) {
      EXPECT_EQ(k.depth, 3u);
    }
  }
  EXPECT_NE(std::find(cut.begin(), cut.end(), core::RegionKey{1, 1, 1, 1}), cut.end());
  // Nested in a coarser cut, as without the bound.
  const std::vector<core::RegionKey> finer = core::cut_regions(codes, cut, 100, core::SideBound{4, 5});
  EXPECT_GT(finer.size(), cut.size());
}

TEST(TilesetWriter, BoxesAreInTheZUpFrame) {
  const double lo[3] = {1, 2, 3}, hi[3] = {3, 6, 11};
  const auto b = io::to_tileset_frame(lo, hi, 0);
  // glTF (x, y, z) -> tileset (x, -z, y): center (2, 4, 7) -> (2, -7, 4); half extents (1, 2, 4) -> (1, 4, 2).
  EXPECT_EQ(b, (std::array<double, 12>{2, -7, 4, 1, 0, 0, 0, 4, 0, 0, 0, 2}));
}

struct Tile {
  json node;
  int level = -1;
  std::string uri;
};

void collect(const json& node, std::vector<Tile>& out) {
  Tile t;
  t.node = node;
  if (node.contains("content")) t.uri = node["content"]["uri"];
  if (node.contains("extras")) t.level = node["extras"]["level"].get<int>();
  out.push_back(t);
  if (node.contains("children"))
    for (const json& c : node["children"]) collect(c, out);
}

// The box's axis-aligned extent in the tileset frame (lo, hi), for the axis-aligned boxes written.
void box_extent(const json& box, double lo[3], double hi[3]) {
  for (int k = 0; k < 3; ++k) {
    const double h = std::abs(box[3 + 3 * 0 + k].get<double>()) + std::abs(box[3 + 3 * 1 + k].get<double>()) + std::abs(box[3 + 3 * 2 + k].get<double>());
    lo[k] = box[k].get<double>() - h;
    hi[k] = box[k].get<double>() + h;
  }
}

// Checks the tree: errors non-increasing, boxes holding children's boxes and content positions (rotated
// Y-up to Z-up), REPLACE; returns the tiles.
std::vector<Tile> check_tree(const std::string& dir) {
  const json ts = json::parse(slurp(dir + "/tileset.json"));
  EXPECT_EQ(ts["asset"]["version"], "1.1");
  EXPECT_EQ(ts["root"]["refine"], "REPLACE");
  EXPECT_GE(ts["geometricError"].get<double>(), ts["root"]["geometricError"].get<double>());
  std::vector<Tile> tiles;
  collect(ts["root"], tiles);
  auto check = [&](auto&& self, const json& node) -> void {
    double lo[3], hi[3];
    box_extent(node["boundingVolume"]["box"], lo, hi);
    const double slack = 1e-9 * (hi[0] - lo[0] + hi[1] - lo[1] + hi[2] - lo[2]) + 1e-12;
    if (node.contains("content")) {
      const core::LodMesh m = read_tile(dir + "/" + node["content"]["uri"].get<std::string>());
      for (uint64_t v = 0; v < m.vertex_count(); ++v) {
        const double p[3] = {m.positions[3 * v], -double{m.positions[3 * v + 2]}, m.positions[3 * v + 1]};
        for (int k = 0; k < 3; ++k) ASSERT_TRUE(p[k] >= lo[k] - slack && p[k] <= hi[k] + slack) << node["content"]["uri"];
      }
    }
    if (!node.contains("children")) return;
    for (const json& c : node["children"]) {
      EXPECT_LE(c["geometricError"].get<double>(), node["geometricError"].get<double>());
      double clo[3], chi[3];
      box_extent(c["boundingVolume"]["box"], clo, chi);
      for (int k = 0; k < 3; ++k) EXPECT_TRUE(clo[k] >= lo[k] - slack && chi[k] <= hi[k] + slack);
      self(self, c);
    }
  };
  check(check, ts["root"]);
  return tiles;
}

Result run_simplify(const std::string& input, const std::string& out, SimplifyOptions::TileLines lines, const Options& o,
                    SimplifyReport* report, uint64_t tile_triangles = 3000) {
  SimplifyOptions so;
  so.output_dir = out;
  so.write_tiles = true;
  so.tile_triangles = tile_triangles;
  so.tile_lines = lines;
  Options opt = o;
  opt.check_disk_space = false;
  return simplify(input, so, opt, report);
}

std::map<std::string, std::string> files_under(const std::string& dir) {
  std::map<std::string, std::string> f;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file()) f[std::filesystem::relative(e.path(), dir).string()] = slurp(e.path().string());
  return f;
}

double s_cell_size(const SimplifyReport& r, size_t level) { return r.levels[level].cell_size; }

std::string sample_room() { return source_dir() + "/tests/data/sample-room.ply"; }

TEST(Tiles, UnionOfALevelsTilesIsTheLevel) {
  TempDir dir;
  SimplifyReport report;
  const Result r = run_simplify(sample_room(), dir.file("out"), SimplifyOptions::TileLines::lines, Options{}, &report);
  ASSERT_TRUE(r.ok()) << r.message;
  const std::vector<Tile> tiles = check_tree(dir.file("out/tiles"));
  EXPECT_GT(report.tiles.content_tiles, report.levels.size()) << "the small tile size splits some level";
  EXPECT_EQ(report.tiles.tiles, tiles.size());
  uint64_t points = 0, sizes_above_floor = 0;
  for (size_t l = 0; l < report.levels.size(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    core::LodMesh level = io::read_lod_mesh(dir.file("out/lod" + std::to_string(l) + ".ply"));
    // The tiles' positions are the level's snapped to the level's grid (the same step in every tile).
    double quantum = -1;
    for (const Tile& t : tiles)
      if (t.level == static_cast<int>(l) && !t.uri.empty()) {
        const double q = t.node["extras"]["quantum"].get<double>();
        if (quantum >= 0) {
          EXPECT_EQ(q, quantum);
        }
        quantum = q;
      }
    EXPECT_GT(quantum, 0);
    EXPECT_LE(quantum, s_cell_size(report, l) / 32);
    for (float& x : level.positions) x = snapped(x, quantum);
    std::array<std::multiset<Prim>, 3> got;
    std::multiset<std::pair<Prim, float>> thick, expected_thick, sized, expected_sized;
    uint64_t largest = 0;
    for (const Tile& t : tiles) {
      if (t.level != static_cast<int>(l) || t.uri.empty()) continue;
      const core::LodMesh m = read_tile(dir.file("out/tiles/" + t.uri));
      largest = std::max(largest, m.triangle_count());
      const auto s = primitives(m);
      for (int k = 0; k < 3; ++k) got[k].insert(s[k].begin(), s[k].end());
      for (uint64_t e = 0; e < m.edge_count(); ++e) thick.insert({prim(m, &m.edges[2 * e], 2), m.thickness[e]});
      // Every point keeps its size (_SIZE, as lods.glb has it) through quantization and meshopt compression.
      EXPECT_EQ(m.point_size.size(), m.point_count()) << t.uri;
      for (uint64_t i = 0; i < m.point_size.size(); ++i) sized.insert({prim(m, &m.points[i], 1), m.point_size[i]});
    }
    const auto want = primitives(level);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(got[k], want[k]) << "kind " << k;
    for (uint64_t e = 0; e < level.edge_count(); ++e) expected_thick.insert({prim(level, &level.edges[2 * e], 2), level.thickness[e]});
    EXPECT_EQ(thick, expected_thick);
    ASSERT_EQ(level.point_size.size(), level.point_count());
    for (uint64_t i = 0; i < level.point_count(); ++i) expected_sized.insert({prim(level, &level.points[i], 1), level.point_size[i]});
    EXPECT_EQ(sized, expected_sized);
    points += level.point_count();
    for (float z : level.point_size) sizes_above_floor += z > 0;
    // A region holds at most tile_triangles / 2 cells; a surface has about twice as many triangles as vertices.
    EXPECT_LE(largest, 2 * 3000u) << "tile triangles";
  }
  EXPECT_GT(points, 0u) << "the sample room's levels have points";
  EXPECT_GT(sizes_above_floor, 0u) << "some point has a size";
}

TEST(Tiles, BytesDoNotDependOnThreadsMemoryOrChunks) {
  TempDir dir;
  SimplifyReport a, b;
  Options o1;
  o1.threads = 1;
  Options o2;
  o2.threads = 3;
  o2.memory_bytes = 64ull << 20;
  o2.chunk_bytes = 4096;
  ASSERT_TRUE(run_simplify(sample_room(), dir.file("a"), SimplifyOptions::TileLines::triangles, o1, &a).ok());
  ASSERT_TRUE(run_simplify(sample_room(), dir.file("b"), SimplifyOptions::TileLines::triangles, o2, &b).ok());
  const auto fa = files_under(dir.file("a/tiles")), fb = files_under(dir.file("b/tiles"));
  EXPECT_GT(fa.size(), 3u);
  EXPECT_TRUE(fa == fb);
  // Thick output: triangles only, and as many tiles as with lines.
  check_tree(dir.file("a/tiles"));
  for (const auto& [name, bytes] : fa)
    if (name.ends_with(".glb")) {
      const core::LodMesh m = read_tile(dir.file("a/tiles/" + name));
      EXPECT_TRUE(m.edges.empty() && m.points.empty()) << name;
    }
}

// The geometric error written (sqrt(3)·c + margins) bounds the Hausdorff distance the report measures.
TEST(Tiles, GeometricErrorBoundsTheReportsHausdorff) {
  TempDir dir;
  SimplifyReport s;
  ASSERT_TRUE(run_simplify(sample_room(), dir.file("out"), SimplifyOptions::TileLines::lines, Options{}, &s, 200000).ok());
  ReportOptions ro;
  ro.output_dir = dir.file("report");
  ro.runs = {dir.file("out")};
  ro.views = 4;
  ro.resolution = 64;
  ro.samples = 50000;
  ro.html_views = 0;
  Options o;
  o.check_disk_space = false;
  Report rep;
  const Result r = report(ro, o, &rep);
  ASSERT_TRUE(r.ok()) << r.message;
  const std::vector<Tile> tiles = check_tree(dir.file("out/tiles"));
  ASSERT_EQ(rep.runs.size(), 1u);
  for (size_t l = 0; l < rep.runs[0].levels.size(); ++l) {
    double level_error = INFINITY;  // the smallest error written for a tile of this level
    for (const Tile& t : tiles)
      if (t.level == static_cast<int>(l) && !t.uri.empty()) level_error = std::min(level_error, t.node["geometricError"].get<double>());
    const double h = rep.runs[0].levels[l].hausdorff_max;
    std::cout << "level " << l << ": cell " << s.levels[l].cell_size << ", Hausdorff max " << h << ", tile error "
              << level_error << " (ratio " << h / level_error << ")\n";
    EXPECT_LE(h, level_error) << "level " << l;
  }
}

// The sample room as simplify reads it: its binary PLY's polygons (float x y z; uchar count, int indices)
// triangulated by core::triangulate_polygon, as ingest does (a fan would cover the outside of concave faces).
core::LodMesh sample_room_triangulated() {
  const std::string b = slurp(sample_room());
  const size_t body = b.find("end_header\n") + 11;
  const auto count = [&](const std::string& element) {
    const size_t at = b.find("element " + element + " ");
    return std::stoull(b.substr(at + 9 + element.size(), 20));
  };
  const uint64_t vertices = count("vertex"), faces = count("face");
  core::LodMesh m;
  m.positions.resize(3 * vertices);
  std::memcpy(m.positions.data(), b.data() + body, 12 * vertices);
  size_t at = body + 12 * vertices;
  std::vector<int32_t> ids;
  std::vector<double> xyz;
  std::vector<uint32_t> local;
  core::PolygonScratch scratch;
  for (uint64_t f = 0; f < faces; ++f) {
    const uint32_t n = static_cast<unsigned char>(b[at]);
    ids.resize(n);
    std::memcpy(ids.data(), b.data() + at + 1, 4 * size_t{n});
    at += 1 + 4 * size_t{n};
    if (n < 3) continue;
    xyz.resize(3 * n);
    for (uint32_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) xyz[3 * i + k] = m.positions[3 * size_t(ids[i]) + k];
    local.resize(3 * (n - 2));
    core::triangulate_polygon(xyz.data(), n, local.data(), &scratch);
    for (uint32_t c : local) m.triangles.push_back(static_cast<uint32_t>(ids[c]));
  }
  EXPECT_EQ(at, b.size());
  EXPECT_EQ(m.triangle_count(), 261865u);  // lodstream info: 261,865 triangles from 141,261 polygons
  return m;
}

// Each tile's geometricError bounds the distance between its content and the original, measured both ways
// with closest-point queries (Embree) on the sample room cut into many tiles, default encoding (snapped,
// meshopt) and thick edges: the corners, centroid and random points (16 a triangle in a tile's first 500
// triangles, 1 after) of each tile's triangles lie within the tile's error of the original; the corners,
// centroid and a random point of every fifth triangle of the original lie, from the level (all its tiles),
// within the largest error of the tiles whose content box grown by their error holds them (the image of a
// point lies in some tile, within that tile's error). Errors are positive (no content is the original's
// resolution) and never grow from parent to child (check_tree).
TEST(Tiles, EachTilesErrorBoundsItsMeasuredDistance) {
  TempDir dir;
  SimplifyReport s;
  ASSERT_TRUE(run_simplify(sample_room(), dir.file("out"), SimplifyOptions::TileLines::triangles, Options{}, &s).ok());
  const std::vector<Tile> tiles = check_tree(dir.file("out/tiles"));
  const core::LodMesh original = sample_room_triangulated();
  ASSERT_GT(original.triangle_count(), 0u);
  core::RayScene orig;
  orig.add_triangles(original.positions, original.triangles);
  orig.commit();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  // Random points on triangle t of m, plus its corners and centroid, appended to `out`.
  auto sample = [&](const core::LodMesh& m, uint64_t t, int n, std::vector<std::array<float, 3>>& out) {
    const float* c[3] = {&m.positions[3 * uint64_t{m.triangles[3 * t]}], &m.positions[3 * uint64_t{m.triangles[3 * t + 1]}],
                         &m.positions[3 * uint64_t{m.triangles[3 * t + 2]}]};
    for (int i = 0; i < n + 4; ++i) {
      double w[3];
      if (i < 3) w[0] = w[1] = w[2] = 0, w[i] = 1;
      else if (i == 3) w[0] = w[1] = w[2] = 1.0 / 3;
      else {
        double a = u(rng), b = u(rng);
        if (a + b > 1) a = 1 - a, b = 1 - b;
        w[0] = 1 - a - b, w[1] = a, w[2] = b;
      }
      std::array<float, 3> p;
      for (int k = 0; k < 3; ++k) p[k] = static_cast<float>(w[0] * c[0][k] + w[1] * c[1][k] + w[2] * c[2][k]);
      out.push_back(p);
    }
  };
  for (size_t l = 0; l < s.levels.size(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    struct Content {
      core::LodMesh mesh;
      double error, lo[3], hi[3];
    };
    std::vector<Content> contents;
    core::LodMesh level;
    double worst_ratio = 0;
    for (const Tile& t : tiles) {
      if (t.level != static_cast<int>(l)) continue;
      const double error = t.node["geometricError"].get<double>();
      EXPECT_GT(error, 0) << t.uri;
      if (t.uri.empty()) continue;
      Content c{read_tile(dir.file("out/tiles/" + t.uri)), error, {INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
      ASSERT_GT(c.mesh.triangle_count(), 0u) << t.uri;
      for (uint64_t v = 0; v < c.mesh.vertex_count(); ++v)
        for (int k = 0; k < 3; ++k) c.lo[k] = std::min<double>(c.lo[k], c.mesh.positions[3 * v + k]), c.hi[k] = std::max<double>(c.hi[k], c.mesh.positions[3 * v + k]);
      // Content to original.
      std::vector<std::array<float, 3>> pts;
      for (uint64_t f = 0; f < c.mesh.triangle_count(); ++f) sample(c.mesh, f, f < 500 ? 16 : 1, pts);
      double worst = 0;
      for (const auto& p : pts) worst = std::max<double>(worst, orig.closest_distance(p.data()));
      EXPECT_LE(worst, error) << t.uri;
      worst_ratio = std::max(worst_ratio, worst / error);
      const uint32_t base = static_cast<uint32_t>(level.vertex_count());
      level.positions.insert(level.positions.end(), c.mesh.positions.begin(), c.mesh.positions.end());
      for (uint32_t id : c.mesh.triangles) level.triangles.push_back(base + id);
      contents.push_back(std::move(c));
    }
    ASSERT_FALSE(contents.empty());
    // Original to the level, each point against the largest error of a tile that can hold its image.
    core::RayScene lod;
    lod.add_triangles(level.positions, level.triangles);
    lod.commit();
    std::vector<std::array<float, 3>> pts;
    for (uint64_t f = 0; f < original.triangle_count(); f += 5) sample(original, f, 1, pts);
    double worst_back = 0;
    for (const auto& p : pts) {
      double bound = -1;
      for (const Content& c : contents) {
        bool in = true;
        for (int k = 0; k < 3; ++k) in = in && p[k] >= c.lo[k] - c.error && p[k] <= c.hi[k] + c.error;
        if (in) bound = std::max(bound, c.error);
      }
      const double d = lod.closest_distance(p.data());
      ASSERT_GE(bound, 0) << "an original point near no tile of the level";
      EXPECT_LE(d, bound);
      worst_back = std::max(worst_back, d / bound);
    }
    std::cout << "level " << l << ": " << contents.size() << " tiles; largest measured distance / geometricError: tile to original "
              << worst_ratio << ", original to tiles " << worst_back << "\n";
  }
}

TEST(Tiles, TransformOptionAndUsageErrors) {
  TempDir dir;
  SimplifyOptions so;
  so.output_dir = dir.file("out");
  so.write_tiles = true;
  so.write_ply = so.write_glb = false;  // tiles alone are a valid output
  so.tiles_transform = {10, 50, 100};   // lon, lat, height: east-north-up on WGS84
  Options o;
  o.check_disk_space = false;
  SimplifyReport r;
  ASSERT_TRUE(simplify(sample_room(), so, o, &r).ok());
  const json ts = json::parse(slurp(dir.file("out/tiles/tileset.json")));
  const std::vector<double> m = ts["root"]["transform"].get<std::vector<double>>();
  ASSERT_EQ(m.size(), 16u);
  const std::vector<double> want = stream::enu_transform(10, 50, 100);
  for (int i = 0; i < 16; ++i) EXPECT_DOUBLE_EQ(m[i], want[i]);
  // Up (third column) is the ellipsoid normal at 50°N 10°E; the origin lies 100 m above the ellipsoid.
  EXPECT_NEAR(m[10], std::sin(50 * M_PI / 180), 1e-12);
  EXPECT_NEAR(std::hypot(m[12], m[13], m[14]), 6365731.5, 0.5);  // geocentric radius at 50°N, 100 m up
  EXPECT_FALSE(std::filesystem::exists(dir.file("out/lod0.ply")));
  // Z-up inputs: the root rotation takes content, turned Y-up to Z-up by the runtime ((x, y, z) -> (x, -z, y)),
  // back to (x, y, z); composed after a given transform.
  const std::vector<double> rot = stream::z_up_transform({});
  const double p[3] = {1, 2, 3}, turned[3] = {p[0], -p[2], p[1]};
  for (int row = 0; row < 3; ++row)
    EXPECT_DOUBLE_EQ(rot[row] * turned[0] + rot[4 + row] * turned[1] + rot[8 + row] * turned[2], p[row]);
  std::vector<double> shift = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 6, 7, 1};
  const std::vector<double> moved = stream::z_up_transform(shift);
  for (int i = 0; i < 12; ++i) EXPECT_DOUBLE_EQ(moved[i], rot[i]);
  EXPECT_EQ(std::vector<double>(moved.begin() + 12, moved.end()), (std::vector<double>{5, 6, 7, 1}));
  so.tiles_transform = {1, 2, 3, 4};
  EXPECT_EQ(simplify(sample_room(), so, o, &r).status, Status::usage);
  so.tiles_transform = {};
  so.tile_triangles = 1;
  EXPECT_EQ(simplify(sample_room(), so, o, &r).status, Status::usage);
}

}  // namespace
}  // namespace lodstream::test

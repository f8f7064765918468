// Emit region by region (stream/emit_regions.h, core/octree_regions.h): the octree cut follows
// core/octree_regions.h; the level files do not depend on how many batches the memory cap makes; and the union of
// a level's region parts is the level (same triangles, edges and points as one region holding it all).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/octree_regions.h"
#include "core/status.h"
#include "io/lod_reader.h"
#include "lodstream/lodstream.h"
#include "stream/emit_regions.h"
#include "stream/emit_stage.h"
#include "stream/scene_store.h"
#include "test_util.h"

namespace lodstream {
namespace {

TEST(OctreeRegions, KeysOrderAndBoxes) {
  const double lo[3] = {0, 0, 0}, hi[3] = {2, 1, 1};
  const core::SceneCube cube = core::scene_cube(lo, hi);
  EXPECT_GT(cube.side, 2.0);
  EXPECT_LT(cube.min[1], 0.0);  // centred on the box
  const double corner[3] = {2, 1, 1};
  const core::RegionKey deepest = core::point_node(cube, corner, 20);
  EXPECT_LT(deepest.x, 1u << 20);  // the far corner is inside the cube
  const core::RegionKey root{}, child{1, 1, 0, 0}, grandchild{2, 3, 1, 0};
  EXPECT_TRUE(core::region_before(root, child));
  EXPECT_TRUE(core::region_before(child, grandchild));  // a parent before its children
  EXPECT_EQ(core::region_parent(grandchild), child);
  EXPECT_EQ(core::region_code(core::RegionKey{1, 1, 0, 0}), uint64_t{1} << 57);
  EXPECT_EQ(core::region_code(core::RegionKey{1, 0, 1, 0}), uint64_t{2} << 57);
  EXPECT_EQ(core::region_code(core::RegionKey{1, 0, 0, 1}), uint64_t{4} << 57);
  double blo[3], bhi[3];
  core::region_box(cube, child, blo, bhi);
  EXPECT_DOUBLE_EQ(blo[0], cube.min[0] + cube.side / 2);
  EXPECT_DOUBLE_EQ(bhi[0], cube.min[0] + cube.side);
  EXPECT_DOUBLE_EQ(bhi[1], cube.min[1] + cube.side / 2);
}

TEST(OctreeRegions, CutSplitsFullNodesAndNestsInTheCoarserCut) {
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  const core::SceneCube cube = core::scene_cube(lo, hi);
  std::vector<uint64_t> fine, coarse;
  for (int i = 0; i < 1000; ++i) {
    const double p[3] = {std::fmod(i * 0.6180339, 1.0), std::fmod(i * 0.4142135, 1.0), std::fmod(i * 0.7320508, 1.0)};
    fine.push_back(core::point_code(cube, p));
    if (i % 10 == 0) coarse.push_back(core::point_code(cube, p));
  }
  const double lonely[3] = {0.999, 0.001, 0.999};  // in no coarse cell's neighbourhood
  fine.push_back(core::point_code(cube, lonely));
  std::sort(fine.begin(), fine.end());
  std::sort(coarse.begin(), coarse.end());
  const std::vector<core::RegionKey> c = core::cut_regions(coarse, {}, 30);
  const std::vector<core::RegionKey> f = core::cut_regions(fine, c, 30);
  for (const auto* cut : {&c, &f}) {
    const std::vector<uint64_t>& codes = cut == &c ? coarse : fine;
    std::vector<uint64_t> held(cut->size(), 0);
    for (uint64_t code : codes) {
      const uint32_t r = core::region_of_code(*cut, code);
      ASSERT_LT(r, cut->size());
      const core::RegionKey& k = (*cut)[r];
      ASSERT_GE(code, core::region_code(k));
      ASSERT_LT(code, core::region_code(k) + core::region_span(k));
      ++held[r];
    }
    for (size_t r = 0; r < cut->size(); ++r) {
      EXPECT_LE(held[r], 30u);
      if (r > 0) {
        EXPECT_TRUE(core::region_before((*cut)[r - 1], (*cut)[r]));
      }
    }
  }
  EXPECT_GT(f.size(), c.size());
  // The cut tiles the cube: the volumes of its regions add up to the cube's.
  uint64_t volume = 0;
  for (const core::RegionKey& k : c) volume += core::region_span(k);
  EXPECT_EQ(volume, uint64_t{1} << 60);
  // Every fine region is inside exactly one coarse region.
  for (const core::RegionKey& k : f) {
    int inside = 0;
    for (const core::RegionKey& p : c) {
      if (p.depth > k.depth) continue;
      const unsigned up = k.depth - p.depth;
      inside += (k.x >> up) == p.x && (k.y >> up) == p.y && (k.z >> up) == p.z;
    }
    EXPECT_EQ(inside, 1);
  }
  // The cut does not depend on anything but the codes and max_cells.
  EXPECT_EQ(core::cut_regions(fine, c, 30), f);
}

TEST(EmitRegions, TheLargeCityIsPlannedInBatchesAt1G) {
  // make-scene.sh 18 1 (192.5 M triangles, 136.6 M stored vertices) at --memory 1G: its finest level
  // (7.53 M cells) needed about 2.7 GiB whole; in batches of regions of at most 100,000 cells it needs its
  // map (23 bits a vertex, 375 MiB), 18 bytes a cell (129 MiB) and one region.
  const uint64_t vertices = 136'600'000, triangles = 192'500'000, budget = (1ull << 30) - (40ull << 20);
  const stream::EmitOptions quadric{Representative::quadric, 30, true, false};
  const stream::EmitLevelPlan plan = stream::plan_emit_level(0, 7'530'459, 100'000, vertices, triangles, budget, quadric);
  EXPECT_TRUE(plan.batched);
  EXPECT_GT(plan.batch_cells, 1'000'000u);
  EXPECT_LT(plan.batch_cells, 1'500'000u);  // 6 to 8 batches
  EXPECT_GT(plan.reps_range_cells, 3'750'000u);  // the quadrics in two passes
  // Its second level (1 M cells, say) whole.
  EXPECT_FALSE(stream::plan_emit_level(1, 1'000'000, 100'000, vertices, triangles, budget, quadric).batched);
  // At 512M not even one region fits beside the map and the tables: exit 64 with the figures.
  try {
    stream::plan_emit_level(0, 7'530'459, 100'000, vertices, triangles, (512ull << 20) - (40ull << 20), quadric);
    ADD_FAILURE() << "no failure";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::usage);
    EXPECT_NE(std::string(f.what()).find("level 0 (7530459 cells) region by region needs about"), std::string::npos) << f.what();
  }
}

// A bumpy n × n grid of quads as a binary PLY (2 n² triangles), with a few needle triangles that collapse.
// `colored`: every vertex with its own colour (uchar red, green, blue) and every face with one of four
// colours by quadrant (four materials), plus a row of thin strips across it that collapse to thick edges.
std::string bumpy_grid(const test::TempDir& tmp, int n, bool colored = false) {
  std::vector<float> v;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = i / static_cast<double>(n), y = j / static_cast<double>(n);
      v.insert(v.end(), {static_cast<float>(x), static_cast<float>(y),
                         static_cast<float>(0.05 * std::sin(9 * x) * std::cos(7 * y) + (x > 0.5 ? 0.02 : 0.0))});
    }
  const uint32_t grid_vertices = static_cast<uint32_t>(v.size() / 3);
  std::vector<std::array<uint32_t, 3>> triangles;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = static_cast<uint32_t>(j * (n + 1) + i), b = a + 1, c = a + static_cast<uint32_t>(n) + 1, d = c + 1;
      triangles.push_back({a, b, d}), triangles.push_back({a, d, c});
    }
  if (colored)
    for (int k = 0; k < 40; ++k) {  // strips 0.3 long and 0.002 wide, above the grid
      const float x = 0.025f * static_cast<float>(k), y = 0.3f + 0.01f * static_cast<float>(k % 7);
      const uint32_t a = static_cast<uint32_t>(v.size() / 3);
      v.insert(v.end(), {x, y, 0.2f, x + 0.3f, y, 0.2f, x + 0.3f, y + 0.002f, 0.2f, x, y + 0.002f, 0.2f});
      triangles.push_back({a, a + 1, a + 2}), triangles.push_back({a, a + 2, a + 3});
    }
  std::string body;
  auto u32 = [&](uint32_t x) { body.append(reinterpret_cast<const char*>(&x), 4); };
  for (size_t i = 0; i < v.size() / 3; ++i) {
    body.append(reinterpret_cast<const char*>(&v[3 * i]), 12);
    if (colored) body += {static_cast<char>(i * 7 % 251), static_cast<char>(i * 13 % 256), static_cast<char>(i < grid_vertices ? 40 : 250)};
  }
  for (const auto& t : triangles) {
    body += static_cast<char>(3);
    for (uint32_t id : t) u32(id);
    if (colored) {
      const float* p = &v[3 * uint64_t{t[0]}];
      const int quadrant = (p[0] > 0.5f ? 1 : 0) + (p[1] > 0.5f ? 2 : 0);
      body += {static_cast<char>(quadrant & 1 ? 200 : 10), static_cast<char>(quadrant & 2 ? 200 : 10), static_cast<char>(90)};
    }
  }
  const std::string colors = colored ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "";
  std::string head = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(v.size() / 3) +
                     "\nproperty float x\nproperty float y\nproperty float z\n" + colors + "element face " +
                     std::to_string(triangles.size()) + "\nproperty list uchar uint vertex_indices\n" + colors + "end_header\n";
  return tmp.write("grid.ply", head + body);
}

std::string read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Every output file (with `tiles`, the 3D Tiles too) of runs that emit the finest level whole and in
// batches, at 1 and 2 threads and tiny chunks: the same bytes.
void expect_same_bytes_in_one_batch_and_in_several(bool colored) {
  test::TempDir tmp;
  const std::string input = bumpy_grid(tmp, 400, colored);  // 320,000 triangles
  struct Run {
    uint64_t memory;
    unsigned threads;
    uint64_t chunk_bytes;
  };
  const Run runs[] = {{1ull << 30, 2, 0}, {64ull << 20, 1, 0}, {70ull << 20, 2, 4096}};
  std::vector<std::vector<std::string>> files;
  std::vector<uint64_t> triangles;
  for (size_t i = 0; i < std::size(runs); ++i) {
    Options o;
    o.memory_bytes = runs[i].memory;
    o.threads = runs[i].threads;
    o.chunk_bytes = runs[i].chunk_bytes;
    o.work_dir = tmp.file("work" + std::to_string(i));
    SimplifyOptions so;
    so.output_dir = tmp.file("out" + std::to_string(i));
    so.write_obj = true;
    so.tile_triangles = 4000;
    so.write_tiles = colored;
    SimplifyReport report;
    const Result r = simplify(input, so, o, &report);
    ASSERT_TRUE(r.ok()) << r.message;
    // Whether the finest level is emitted whole or in batches, by the stage's own plan.
    stream::StoreMeta meta;
    ASSERT_TRUE(stream::read_store_meta(o.work_dir + "/store", &meta));
    stream::EmitOptions eo{so.representative, so.crease_degrees, true, false};
    eo.colors = meta.colors, eo.materials = !meta.materials.empty();
    EXPECT_EQ(meta.colors, colored);
    EXPECT_EQ(meta.materials.size(), colored ? 5u : 0u);  // the white default and the four quadrants'
    const uint64_t stage = o.memory_bytes - std::min<uint64_t>(o.memory_bytes / 2, 40ull << 20);
    const stream::EmitLevelPlan plan = stream::plan_emit_level(0, report.levels[0].cells, so.tile_triangles / 2, meta.vertices,
                                                               meta.primitives(), stage, eo);
    if (i == 0) EXPECT_FALSE(plan.batched);
    else EXPECT_TRUE(plan.batched && plan.batch_cells < report.levels[0].cells) << plan.batch_cells << " of " << report.levels[0].cells;
    std::vector<std::string> bytes;
    for (size_t l = 0; l < report.levels.size(); ++l)
      for (const char* ext : {".ply", ".obj"}) bytes.push_back(read_bytes(so.output_dir + "/lod" + std::to_string(l) + ext));
    bytes.push_back(read_bytes(so.output_dir + "/lods.glb"));
    if (colored) {
      bytes.push_back(read_bytes(so.output_dir + "/lod0.mtl"));
      bytes.push_back(read_bytes(so.output_dir + "/tiles/tileset.json"));
      for (const auto& e : std::filesystem::recursive_directory_iterator(so.output_dir + "/tiles"))
        if (e.path().extension() == ".glb") bytes.push_back(e.path().lexically_relative(so.output_dir).string() + read_bytes(e.path()));
      std::sort(bytes.end() - static_cast<ptrdiff_t>(bytes.size() - 2 * report.levels.size() - 3), bytes.end());
      EXPECT_GT(report.levels[0].edges, 0u);
    }
    files.push_back(bytes);
    triangles.push_back(report.levels[0].triangles);
  }
  EXPECT_GT(triangles[0], 20000u);
  for (size_t i = 1; i < files.size(); ++i) {
    ASSERT_EQ(files[i].size(), files[0].size());
    for (size_t f = 0; f < files[0].size(); ++f) EXPECT_TRUE(files[i][f] == files[0][f]) << "run " << i << ", file " << f;
  }
}

TEST(EmitRegions, SameBytesInOneBatchAndInSeveral) { expect_same_bytes_in_one_batch_and_in_several(false); }

TEST(EmitRegions, SameBytesInOneBatchAndInSeveralWithColoursAndMaterials) {
  expect_same_bytes_in_one_batch_and_in_several(true);
}

// A level's triangles as position triples, each rotated to start at its least corner (winding kept), sorted.
std::vector<std::array<float, 9>> triangle_set(const core::LodMesh& m) {
  std::vector<std::array<float, 9>> out;
  for (uint64_t t = 0; t < m.triangle_count(); ++t) {
    std::array<std::array<float, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = m.positions[3 * uint64_t{m.triangles[3 * t + k]} + a];
    const int first = static_cast<int>(std::min_element(c.begin(), c.end()) - c.begin());
    std::array<float, 9> x;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) x[3 * k + a] = c[(first + k) % 3][a];
    out.push_back(x);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// One region per level against many: the same counts, vertices, and triangles (as positions).
void expect_union_is_the_level(const std::string& input, const std::string& what) {
  test::TempDir tmp;
  std::vector<SimplifyReport> reports(2);
  for (int i = 0; i < 2; ++i) {
    Options o;
    o.threads = 2;
    o.work_dir = tmp.file("work");  // shared: the second run reuses the stages up to cluster
    SimplifyOptions so;
    so.output_dir = tmp.file("out" + std::to_string(i));
    so.tile_triangles = i == 0 ? UINT64_MAX : 300;
    const Result r = simplify(input, so, o, &reports[i]);
    ASSERT_TRUE(r.ok()) << what << ": " << r.message;
  }
  ASSERT_EQ(reports[0].levels.size(), reports[1].levels.size()) << what;
  for (size_t l = 0; l < reports[0].levels.size(); ++l) {
    const LevelStats &a = reports[0].levels[l], &b = reports[1].levels[l];
    const std::string w = what + " level " + std::to_string(l);
    EXPECT_EQ(a.triangles, b.triangles) << w;
    EXPECT_EQ(a.edges, b.edges) << w;
    EXPECT_EQ(a.points, b.points) << w;
    EXPECT_EQ(a.vertices, b.vertices) << w;
    EXPECT_EQ(a.edges_on_triangles, b.edges_on_triangles) << w;
    EXPECT_EQ(a.points_covered, b.points_covered) << w;
    const std::string name = "/lod" + std::to_string(l) + ".ply";
    const core::LodMesh ma = io::read_lod_mesh(tmp.file("out0") + name), mb = io::read_lod_mesh(tmp.file("out1") + name);
    EXPECT_EQ(ma.triangle_count(), a.triangles) << w;
    EXPECT_TRUE(triangle_set(ma) == triangle_set(mb)) << w;
    std::vector<float> ta = ma.thickness, tb = mb.thickness;
    std::sort(ta.begin(), ta.end()), std::sort(tb.begin(), tb.end());
    EXPECT_EQ(ta, tb) << w;
  }
}

TEST(EmitRegions, UnionOfTheRegionPartsIsTheLevel) {
  expect_union_is_the_level(test::source_dir() + "/tests/data/sample-room.ply", "sample room");
}

TEST(EmitRegions, UnionOfTheRegionPartsIsTheLevelOnRealModels) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  for (const char* model : {"scans/stanford-bunny.obj", "buildings/duplex.obj", "furniture-cc0/peterbilt/peterbilt.obj"})
    expect_union_is_the_level(data + "/" + model, model);
}

}  // namespace
}  // namespace lodstream

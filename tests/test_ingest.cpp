// Pipeline-level tests of ingest: the scene store's bytes for every thread count, memory budget and
// chunk size; soup welding; degenerate and unused accounting; resuming; cancelling.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "lodstream/lodstream.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;

using test::read_dir;

SceneInfo run_info(const std::string& input, const std::string& work, unsigned threads, uint64_t memory,
                   uint64_t chunk) {
  Options o;
  o.threads = threads;
  o.memory_bytes = memory;
  o.chunk_bytes = chunk;
  o.work_dir = work;
  SceneInfo info;
  const Result r = lodstream::info(input, o, &info);
  EXPECT_TRUE(r.ok()) << r.message;
  return info;
}

// Every combination of {1, 2 threads} x {tiny, default chunks} x {minimum, large memory} gives the same
// store bytes and the same counts.
void expect_same_store_everywhere(const std::string& input, const std::vector<uint64_t>& chunk_sizes) {
  test::TempDir tmp;
  std::map<std::string, std::string> reference;
  SceneInfo ref_info;
  int n = 0;
  for (unsigned threads : {1u, 2u})
    for (uint64_t chunk : chunk_sizes)
      for (uint64_t memory : {min_memory_bytes, uint64_t{2} << 30}) {
        const std::string work = tmp.file(std::string("w").append(std::to_string(n++)));  // not "w" + ...: GCC 12's -Wrestrict false positive
        const SceneInfo info = run_info(input, work, threads, memory, chunk);
        auto files = read_dir(fs::path(work) / "store");
        files.erase("census.json");
        if (reference.empty()) {
          reference = files;
          ref_info = info;
          continue;
        }
        SCOPED_TRACE("threads " + std::to_string(threads) + " chunk " + std::to_string(chunk) + " memory " +
                     std::to_string(memory));
        EXPECT_EQ(info.triangles, ref_info.triangles);
        EXPECT_EQ(info.vertices, ref_info.vertices);
        EXPECT_EQ(info.vertices_welded, ref_info.vertices_welded);
        ASSERT_EQ(files.size(), reference.size());
        for (const auto& [name, bytes] : reference) EXPECT_TRUE(files[name] == bytes) << name << " differs";
      }
}

TEST(Ingest, SampleSceneStoreIsIdenticalForThreadsChunksAndMemory) {
  const std::string sample = test::source_dir() + "/tests/data/sample-room.ply";
  if (!fs::exists(sample)) GTEST_SKIP() << "sample scene not present";
  expect_same_store_everywhere(sample, {4096, 0});
}

TEST(Ingest, ObjStoreIsIdenticalForEveryChunkSize) {
  test::TempDir tmp;
  std::string obj = "# test\no first\n";
  for (int i = 0; i < 40; ++i) obj += "v " + std::to_string(i) + " " + std::to_string(i % 7) + " 0.5e1\n";
  for (int i = 1; i + 2 <= 40; ++i) obj += "f " + std::to_string(i) + " " + std::to_string(i + 1) + " -1\n";
  obj += "g second\nl 1 2 3\np 4 5\nf 1 1 2\n";
  const std::string path = tmp.write("scene.obj", obj);
  expect_same_store_everywhere(path, {1, 7, 64, 0});
}

TEST(Ingest, GlbStoreIsIdenticalForThreadsChunksAndMemory) {
  expect_same_store_everywhere(test::source_dir() + "/tests/data/gltf/bench.glb", {64, 0});
}

TEST(Ingest, StoreColumnsHoldExactlyTheInput) {
  test::TempDir tmp;
  // Two squares as quads (4 triangles), a degenerate triangle, a polyline of 3 vertices, a point, an
  // unused vertex, and two objects.
  const std::string path = tmp.write("s.obj",
                                     "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 5 5\n"
                                     "o a\nf 1 2 3 4\nf 1 1 2\n"
                                     "o b\nf 4 3 2 1\nl 1 2 3\np 4\n");
  const std::string work = tmp.file("w");
  const SceneInfo info = run_info(path, work, 2, 0, 0);
  EXPECT_EQ(info.vertices, 5u);
  EXPECT_EQ(info.vertices_welded, 5u);
  EXPECT_EQ(info.unused_vertices, 1u);
  EXPECT_EQ(info.polygons, 3u);
  EXPECT_EQ(info.triangles, 4u);
  EXPECT_EQ(info.degenerate, 1u);
  EXPECT_EQ(info.lines, 3u);  // f 1 1 2 is the segment 1-2
  EXPECT_EQ(info.face_segments, 1u);
  EXPECT_EQ(info.points, 1u);
  EXPECT_EQ(info.objects, 2u);
  EXPECT_EQ(info.bbox_max[0], 5.0);
  auto files = read_dir(fs::path(work) / "store");
  const std::vector<uint32_t> tri = {0, 1, 2, 0, 2, 3, 3, 2, 1, 3, 1, 0};
  ASSERT_EQ(files["triangles.u32"].size(), tri.size() * 4);
  EXPECT_EQ(std::memcmp(files["triangles.u32"].data(), tri.data(), tri.size() * 4), 0);
  // Object runs: triangles 0.. in object 1 ("a"), 2.. in object 2 ("b").
  const uint32_t runs[8] = {0, 0, 1, 0, 2, 0, 2, 0};
  ASSERT_EQ(files["triangle_objects.runs"].size(), sizeof runs);
  EXPECT_EQ(std::memcmp(files["triangle_objects.runs"].data(), runs, sizeof runs), 0);
  EXPECT_EQ(files.count("positions.f32"), 0u);  // OBJ text keeps double precision
  const std::vector<uint32_t> lines = {0, 1, 0, 1, 1, 2};
  ASSERT_EQ(files["lines.u32"].size(), 24u);
  EXPECT_EQ(std::memcmp(files["lines.u32"].data(), lines.data(), 24), 0);
  ASSERT_EQ(files["positions.f64"].size(), 5u * 24);
  double p[15];
  std::memcpy(p, files["positions.f64"].data(), sizeof p);
  EXPECT_EQ(p[6], 1.0);
  EXPECT_EQ(p[14], 5.0);
}

TEST(Ingest, WeldCountsDistinctPositionsWithSignedZeroAsOne) {
  test::TempDir tmp;
  const std::string path = tmp.write("d.obj", "v 0 0 0\nv -0 0 0\nv 1 0 0\nv 1 0 0\nv 0 1 0\nf 1 3 5\nf 2 4 5\n");
  const SceneInfo info = run_info(path, tmp.file("w"), 1, 0, 0);
  EXPECT_EQ(info.vertices, 5u);
  EXPECT_EQ(info.vertices_welded, 3u);
  EXPECT_EQ(info.triangles, 2u);
}

// A binary STL soup: a tetrahedron (4 facets, 12 corners, 4 distinct positions) plus a facet whose
// corners collapse onto two positions (degenerate after welding).
std::string tetra_stl() {
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const int f[5][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}, {1, 1, 2}};
  std::string s(80, ' ');
  const uint32_t n = 5;
  s.append(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : f) {
    const float normal[3] = {0, 0, 0};
    s.append(reinterpret_cast<const char*>(normal), 12);
    for (int k = 0; k < 3; ++k) s.append(reinterpret_cast<const char*>(v[t[k]]), 12);
    s.append(2, '\0');
  }
  return s;
}

TEST(Ingest, StlSoupIsWeldedByExactPositionInPositionOrder) {
  test::TempDir tmp;
  const std::string path = tmp.write("t.stl", tetra_stl());
  const std::string work = tmp.file("w");
  const SceneInfo info = run_info(path, work, 2, 0, 0);
  EXPECT_EQ(info.vertex_records, 15u);
  EXPECT_EQ(info.vertices, 4u);
  EXPECT_EQ(info.vertices_welded, 4u);
  EXPECT_EQ(info.polygons, 5u);
  EXPECT_EQ(info.triangles, 4u);
  EXPECT_EQ(info.degenerate, 1u);
  auto files = read_dir(fs::path(work) / "store");
  // Position order: (0,0,0) (0,0,1) (0,1,0) (1,0,0) -> input vertex 0,3,2,1 get ids 0,3,2,1 -> 0,1->3, ...
  const float expect_pos[12] = {0, 0, 0, 0, 0, 1, 0, 1, 0, 1, 0, 0};  // STL is single precision
  ASSERT_EQ(files["positions.f32"].size(), sizeof expect_pos);
  EXPECT_EQ(std::memcmp(files["positions.f32"].data(), expect_pos, sizeof expect_pos), 0);
  const uint32_t expect_tri[12] = {0, 2, 3, 0, 3, 1, 3, 2, 1, 0, 1, 2};
  ASSERT_EQ(files["triangles.u32"].size(), sizeof expect_tri);
  EXPECT_EQ(std::memcmp(files["triangles.u32"].data(), expect_tri, sizeof expect_tri), 0);
  expect_same_store_everywhere(path, {1, 50, 0});
}

// A binary STL grid of 2 n^2 facets sharing (n+1)^2 positions.
std::string grid_stl(int n) {
  std::string s(80, ' ');
  const uint32_t count = static_cast<uint32_t>(2 * n * n);
  s.append(reinterpret_cast<const char*>(&count), 4);
  auto corner = [&](int x, int y) {
    const float p[3] = {static_cast<float>(x) * 0.5f, static_cast<float>(y), static_cast<float>((x * 3 + y) % 5)};
    s.append(reinterpret_cast<const char*>(p), 12);
  };
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x)
      for (int t = 0; t < 2; ++t) {
        s.append(12, '\0');
        corner(x, y);
        if (t == 0) corner(x + 1, y), corner(x + 1, y + 1);
        else corner(x + 1, y + 1), corner(x, y + 1);
        s.append(2, '\0');
      }
  return s;
}

// At the minimum budget the weld's external sorts spill runs to disk; the store must not change.
TEST(Ingest, StlWeldSpillingToDiskGivesTheSameStore) {
  test::TempDir tmp;
  const int n = 245;  // 120,050 facets, 360,150 corners: more than the sort buffer at 64 MiB
  const std::string path = tmp.write("grid.stl", grid_stl(n));
  const SceneInfo info = run_info(path, tmp.file("w"), 2, min_memory_bytes, 0);
  EXPECT_EQ(info.vertices, static_cast<uint64_t>((n + 1) * (n + 1)));
  EXPECT_EQ(info.triangles, static_cast<uint64_t>(2 * n * n));
  EXPECT_EQ(info.degenerate, 0u);
  EXPECT_EQ(info.unused_vertices, 0u);
  expect_same_store_everywhere(path, {0});
}

TEST(Ingest, SecondRunReusesTheStore) {
  test::TempDir tmp;
  const std::string path = tmp.write("r.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const std::string work = tmp.file("w");
  const SceneInfo first = run_info(path, work, 1, 0, 0);
  ASSERT_FALSE(first.stages.empty());
  EXPECT_FALSE(first.stages[0].reused);
  const SceneInfo second = run_info(path, work, 1, 0, 0);
  EXPECT_TRUE(second.stages[0].reused);
  EXPECT_EQ(second.triangles, 1u);
  EXPECT_EQ(second.vertices_welded, 3u);
  // A changed input is ingested again.
  tmp.write("r.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n");
  fs::last_write_time(path, fs::last_write_time(path) + std::chrono::seconds(2));
  const SceneInfo third = run_info(path, work, 1, 0, 0);
  EXPECT_FALSE(third.stages[0].reused);
  EXPECT_EQ(third.triangles, 2u);
}

struct CancelAt {
  int calls = 0;
  int cancel_at = 0;
};
bool cancel_progress(void* user, const char*, double) {
  auto* c = static_cast<CancelAt*>(user);
  return ++c->calls < c->cancel_at;
}

TEST(Ingest, CancelEndsWithStatusCancelledAndLeavesNoPartialFile) {
  const std::string sample = test::source_dir() + "/tests/data/sample-room.ply";
  if (!fs::exists(sample)) GTEST_SKIP() << "sample scene not present";
  for (int at : {1, 2, 5, 20}) {
    test::TempDir tmp;
    CancelAt c;
    c.cancel_at = at;
    Options o;
    o.chunk_bytes = 16384;
    o.work_dir = tmp.file("w");
    o.progress = cancel_progress;
    o.progress_user = &c;
    SceneInfo info;
    const Result r = lodstream::info(sample, o, &info);
    EXPECT_EQ(r.status, Status::cancelled) << "at " << at << ": " << r.message;
    for (const auto& e : fs::recursive_directory_iterator(tmp.path())) {
      const std::string name = e.path().filename().string();
      EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
      EXPECT_NE(name, "store.json");
      EXPECT_EQ(name.find("scratch-"), std::string::npos) << name;
    }
  }
}

TEST(Ingest, MemoryBelowMinimumIsAUsageError) {
  test::TempDir tmp;
  const std::string path = tmp.write("m.obj", "v 0 0 0\n");
  Options o;
  o.memory_bytes = 1 << 20;
  SceneInfo info;
  EXPECT_EQ(lodstream::info(path, o, &info).status, Status::usage);
}

TEST(Ingest, TemporaryWorkDirectoryIsRemoved) {
  test::TempDir tmp;
  const std::string path = tmp.write("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const std::string tmpdir = tmp.file("tmp");
  fs::create_directories(tmpdir);
  setenv("TMPDIR", tmpdir.c_str(), 1);
  SceneInfo info;
  const Result r = lodstream::info(path, Options{}, &info);
  unsetenv("TMPDIR");
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_TRUE(fs::is_empty(tmpdir));
}

std::vector<uint32_t> stored_triangles(const std::string& work) {
  std::ifstream f(fs::path(work) / "store" / "triangles.u32", std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string bytes = ss.str();
  std::vector<uint32_t> t(bytes.size() / 4);
  std::memcpy(t.data(), bytes.data(), bytes.size());
  return t;
}

// The L-shaped slab (2,2) (1,2) (1,1) (0,1) (0,0) (2,0), area 3: the fan from corner 0 would cut across
// the notch; ear clipping gives these four triangles, all inside.
const std::vector<uint32_t> kLTriangles = {5, 0, 1, 5, 1, 2, 5, 2, 3, 3, 4, 5};
const double kL[6][2] = {{2, 2}, {1, 2}, {1, 1}, {0, 1}, {0, 0}, {2, 0}};

TEST(Ingest, ConcavePolygonIsTriangulatedInsideIt) {
  test::TempDir tmp;
  std::string obj;
  for (const auto& p : kL) obj += "v " + std::to_string(p[0]) + " 7 " + std::to_string(p[1]) + "\n";  // plane y = 7
  obj += "f 1 2 3 4 5 6\n";
  const std::string path = tmp.write("l.obj", obj);
  const std::string work = tmp.file("w");
  const SceneInfo info = run_info(path, work, 2, 0, 0);
  EXPECT_EQ(info.polygons, 1u);
  EXPECT_EQ(info.triangles, 4u);
  EXPECT_EQ(info.polygons_concave, 1u);
  EXPECT_EQ(info.polygons_fallback, 0u);
  const std::vector<uint32_t> t = stored_triangles(work);
  EXPECT_EQ(t, kLTriangles);
  double area = 0;
  for (size_t i = 0; i < t.size(); i += 3) {
    const double* a = kL[t[i]];
    const double* b = kL[t[i + 1]];
    const double* c = kL[t[i + 2]];
    area += std::fabs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2;
  }
  EXPECT_DOUBLE_EQ(area, 3.0);
}

TEST(Ingest, ObjAndPlyGiveTheSameTrianglesForTheSamePolygon) {
  test::TempDir tmp;
  std::string obj = "o slab\n";
  for (const auto& p : kL) obj += "v " + std::to_string(p[0]) + " " + std::to_string(p[1]) + " 0\n";
  obj += "f 1 2 3 4 5 6\nf 1 2 2\n";
  std::string header = "ply\nformat FORMAT 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n";
  std::string ascii = header, binary = header;
  ascii.replace(ascii.find("FORMAT"), 6, "ascii");
  binary.replace(binary.find("FORMAT"), 6, "binary_little_endian");
  for (const auto& p : kL) {
    ascii += std::to_string(p[0]) + " " + std::to_string(p[1]) + " 0\n";
    const float xyz[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), 0.0f};
    binary.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
  }
  ascii += "6 0 1 2 3 4 5\n3 0 1 1\n";
  const int32_t faces[] = {0, 1, 2, 3, 4, 5, 0, 1, 1};
  binary += char(6);
  binary.append(reinterpret_cast<const char*>(faces), 24);
  binary += char(3);
  binary.append(reinterpret_cast<const char*>(faces + 6), 12);
  int n = 0;
  for (const std::string& path : {tmp.write("l.obj", obj), tmp.write("l-ascii.ply", ascii), tmp.write("l-le.ply", binary)}) {
    SCOPED_TRACE(path);
    const std::string work = tmp.file(std::string("w").append(std::to_string(n++)));
    const SceneInfo info = run_info(path, work, 2, 0, 0);
    EXPECT_EQ(stored_triangles(work), kLTriangles);
    EXPECT_EQ(info.polygons, 2u);
    EXPECT_EQ(info.lines, 1u);  // (0, 1, 1) is the segment 0-1
    EXPECT_EQ(info.face_segments, 1u);
    EXPECT_EQ(info.degenerate, 1u);
    EXPECT_EQ(info.polygons_concave, 1u);
  }
}

TEST(Ingest, VertexNamedByAbsoluteAndRelativeIndexInOneFace) {
  // f 1 2 3 -4 names vertex 1 twice (the parse cannot tell: the encodings differ): its ring is the
  // triangle 1 2 3, as the counting rule says, and the store holds no triangle naming a vertex twice.
  test::TempDir tmp;
  const std::string path = tmp.write("mixed.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 -4\n");
  const std::string work = tmp.file("w");
  const SceneInfo info = run_info(path, work, 2, 0, 0);
  EXPECT_EQ(info.triangles, 1u);
  EXPECT_EQ(info.degenerate, 1u);
  EXPECT_EQ(stored_triangles(work), (std::vector<uint32_t>{0, 1, 2}));
}

TEST(Ingest, PlanarFacesAreTheSameForEveryChunkingThreadsAndMemory) {
  // Concave faces (L, U, notched) naming vertices of earlier chunks, later chunks (forward references)
  // and by relative indices, among convex quads, triangles and faces repeating a vertex.
  test::TempDir tmp;
  std::string obj;
  const double u[8][2] = {{3, 3}, {2, 3}, {2, 1}, {1, 1}, {1, 3}, {0, 3}, {0, 0}, {3, 0}};
  auto face = [&obj](std::initializer_list<int> corners) {
    obj.append("f");
    for (int c : corners) obj.append(" ").append(std::to_string(c));
    obj.append("\n");
  };
  for (int k = 0; k < 30; ++k) {
    const int base = 8 * k;
    for (const auto& p : u)
      obj.append("v ").append(std::to_string(p[0] + 5 * k)).append(" ").append(std::to_string(p[1])).append(" ")
          .append(std::to_string(k)).append("\n");
    if (k % 3 == 0) face({-8, -7, -6, -5, -4, -3, -2, -1});
    if (k % 3 == 1) face({base + 9, base + 10, base + 11, base + 12, 1, 1});  // forward references
    if (k > 0) {
      face({base - 7, base - 6, base - 5, base - 4, base - 3, base - 2, base - 1, base});
      face({base + 2, base + 3, base + 3});
    }
  }
  const std::string path = tmp.write("u.obj", obj);
  expect_same_store_everywhere(path, {1, 37, 200, 0});
  const SceneInfo info = run_info(path, tmp.file("check"), 2, 0, 1);
  EXPECT_GE(info.polygons_concave, 10u + 29u);  // every U, and whichever of the bent pentagons are concave
  EXPECT_EQ(info.face_segments, 29u);
}

}  // namespace
}  // namespace lodstream

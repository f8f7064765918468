// LOD file writers (io/ply_writer.h, io/obj_writer.h, io/glb_writer.h): a small hand-made level written in
// each format and read back (PLY and OBJ through the project's own readers, GLB by parsing its chunks here),
// deterministic bytes, failures that leave no file behind, and the Khronos glTF-Validator on a GLB holding
// every primitive kind (skipped when node or the npm package is absent: tools/install-deps.sh --test).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream::test {
namespace {

using core::LodMesh;
using nlohmann::json;

// Two triangles (1 3 2) and (0 1 2) on vertices 0..3, two edges (3 4) and (4 1) of different thickness
// sharing vertex 4, and a point on vertex 5. Coordinates that are not short decimals, to test round trips.
LodMesh small_level(bool with_normals) {
  LodMesh m;
  m.positions = {0.0f, 0.0f, 0.0f,                 // 0
                 1.0f, 0.0f, 0.0f,                 // 1
                 0.0f, 1.0f, -0.0f,                // 2
                 1.0f, 1.0f, 0.1f,                 // 3
                 2.0f, 0.3f, -0.5f,                // 4: edges only
                 -1e-7f, 3.14159274f, 1.5e10f};    // 5: point only
  if (with_normals)
    m.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0};
  m.triangles = {1, 3, 2, 0, 1, 2};
  m.edges = {3, 4, 4, 1};
  m.thickness = {0.25f, 1.0f / 3.0f};
  m.points = {5};
  m.point_size = {0.125f};
  return m;
}

std::vector<double> widened(const std::vector<float>& v) { return std::vector<double>(v.begin(), v.end()); }

template <class T>
std::vector<int64_t> as_i64(const std::vector<T>& v) {
  return std::vector<int64_t>(v.begin(), v.end());
}

// Several writers of one path at once (io::Writers::several, the weld units' shared bucket sizes): each
// writes its own temporary, so none fails at its rename (with one shared `<path>.partial`, a writer's
// rename took another's file, and the other failed with "cannot rename into place"), and the file is
// always one writer's whole contents; no temporary is left.
TEST(FileWriter, SeveralWritersOfOnePathAtOnce) {
  TempDir dir;
  const std::string path = dir.file("sizes.bin"), contents(100000, 'x');
  std::vector<std::thread> writers;
  std::atomic<int> failures{0};
  for (int t = 0; t < 4; ++t)
    writers.emplace_back([&] {
      for (int k = 0; k < 200; ++k) {
        try {
          io::write_file_atomic(path, contents, io::Sync::none, io::Writers::several);
        } catch (const Failure&) {
          ++failures;
        }
      }
    });
  for (auto& w : writers) w.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_EQ(io::read_small_file(path), contents);
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) files += e.is_regular_file();
  EXPECT_EQ(files, 1u) << "a temporary was left";
}

// ----------------------------------------------------------------------------------------------- PLY

TEST(WriterPly, ReadsBackThroughPlyReader) {
  TempDir dir;
  const LodMesh m = small_level(true);
  const std::string path = dir.file("level.ply");
  io::write_ply(path, m, {"lodstream test", "two\nlines\r"});
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));

  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.format, "ply-binary-le");
  EXPECT_EQ(r.positions, widened(m.positions));  // float in, float out: exact
  EXPECT_EQ(r.triangles, as_i64(m.triangles));
  EXPECT_EQ(r.lines, as_i64(m.edges));
  EXPECT_TRUE(r.points.empty());  // `element point` is ours: the reader walks and skips it
  EXPECT_EQ(r.polygons, 2u);

  // Header: comments on one line each, the schema in full.
  const std::string bytes = io::read_small_file(path);
  const size_t end = bytes.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end + 11);
  EXPECT_EQ(header,
            "ply\nformat binary_little_endian 1.0\n"
            "comment lodstream test\n"
            "comment two lines \n"
            "comment element point: one vertex index per point primitive, and its size (diameter, 0 = one pixel)\n"
            "element vertex 6\n"
            "property float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "element face 2\nproperty list uchar uint vertex_indices\n"
            "element edge 2\nproperty uint vertex1\nproperty uint vertex2\nproperty float thickness\n"
            "element point 1\nproperty uint vertex\nproperty float size\n"
            "end_header\n");
  ASSERT_EQ(bytes.size(), header.size() + 6 * 24 + 2 * 13 + 2 * 12 + 1 * 8);

  // Body, field by field.
  const char* p = bytes.data() + header.size();
  float nrm[3];
  std::memcpy(nrm, p + 3 * 24 + 12, 12);  // normal of vertex 3
  EXPECT_EQ(nrm[2], 1.0f);
  p += 6 * 24;
  EXPECT_EQ(p[0], 3);
  uint32_t tri[3];
  std::memcpy(tri, p + 1, 12);
  EXPECT_EQ(tri[0], 1u);
  EXPECT_EQ(tri[1], 3u);
  EXPECT_EQ(tri[2], 2u);
  p += 2 * 13;
  uint32_t edge[2];
  float thick;
  std::memcpy(edge, p + 12, 8);
  std::memcpy(&thick, p + 12 + 8, 4);
  EXPECT_EQ(edge[0], 4u);
  EXPECT_EQ(edge[1], 1u);
  EXPECT_EQ(thick, 1.0f / 3.0f);
  p += 2 * 12;
  uint32_t point;
  float size;
  std::memcpy(&point, p, 4);
  std::memcpy(&size, p + 4, 4);
  EXPECT_EQ(point, 5u);
  EXPECT_EQ(size, 0.125f);
}

TEST(WriterPly, WithoutNormalsAndEmpty) {
  TempDir dir;
  const LodMesh m = small_level(false);
  const std::string path = dir.file("level.ply");
  io::write_ply(path, m, {});
  const std::string bytes = io::read_small_file(path);
  EXPECT_EQ(bytes.find("property float nx"), std::string::npos);
  const ReadAll r = read_all(path, 16);  // tiny chunks: records cross chunk boundaries
  EXPECT_EQ(r.positions, widened(m.positions));
  EXPECT_EQ(r.triangles, as_i64(m.triangles));
  EXPECT_EQ(r.lines, as_i64(m.edges));

  // Nothing at all: every element is still declared, with count 0.
  const std::string empty = dir.file("empty.ply");
  io::write_ply(empty, LodMesh{}, {});
  const std::string e = io::read_small_file(empty);
  for (const char* line : {"element vertex 0\n", "element face 0\n", "element edge 0\n", "element point 0\n"})
    EXPECT_NE(e.find(line), std::string::npos) << line;
  EXPECT_EQ(e.substr(e.size() - 11), "end_header\n");
}

// ----------------------------------------------------------------------------------------------- OBJ

TEST(WriterObj, ReadsBackThroughObjReader) {
  TempDir dir;
  const LodMesh m = small_level(true);
  const std::string path = dir.file("level.obj");
  io::write_obj(path, m, {"lodstream test", "two\nlines"});
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));

  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.format, "obj");
  ASSERT_EQ(r.positions.size(), m.positions.size());
  for (size_t i = 0; i < m.positions.size(); ++i)  // the shortest decimal reads back as the same float
    EXPECT_EQ(static_cast<float>(r.positions[i]), m.positions[i]) << i;
  EXPECT_EQ(r.triangles, as_i64(m.triangles));
  EXPECT_EQ(r.lines, as_i64(m.edges));
  EXPECT_EQ(r.points, as_i64(m.points));
  EXPECT_EQ(r.skipped, 6u);  // the vn lines

  const std::string text = io::read_small_file(path);
  EXPECT_EQ(text.substr(0, 32), "# lodstream test\n# two lines\nv 0");
  EXPECT_NE(text.find("\nv 0 1 -0\n"), std::string::npos);
  EXPECT_NE(text.find("\nvn 0 0 1\n"), std::string::npos);
  EXPECT_NE(text.find("\nf 2//2 4//4 3//3\nf 1//1 2//2 3//3\nl 4 5\nl 5 2\np 6\n"), std::string::npos);
}

TEST(WriterObj, WithoutNormals) {
  TempDir dir;
  const LodMesh m = small_level(false);
  const std::string path = dir.file("level.obj");
  io::write_obj(path, m, {});
  const std::string text = io::read_small_file(path);
  EXPECT_EQ(text.find("vn"), std::string::npos);
  EXPECT_NE(text.find("\nf 2 4 3\nf 1 2 3\n"), std::string::npos);
  const ReadAll r = read_all(path, 8);
  EXPECT_EQ(r.triangles, as_i64(m.triangles));
  EXPECT_EQ(r.skipped, 0u);
}

// ----------------------------------------------------------------------------------------------- GLB

struct Glb {
  std::string bytes;
  json gltf;
  std::string bin;

  // The elements of accessor `a` as 4-byte values of type T.
  template <class T>
  std::vector<T> values(int a) const {
    const json& acc = gltf["accessors"][a];
    const json& view = gltf["bufferViews"][acc["bufferView"].get<int>()];
    const int components = acc["type"] == "VEC3" ? 3 : 1;
    std::vector<T> out(acc["count"].get<size_t>() * components);
    const size_t offset = view["byteOffset"].get<size_t>() + acc.value("byteOffset", size_t{0});
    EXPECT_LE(offset + out.size() * 4, bin.size());
    EXPECT_EQ(out.size() * 4, view["byteLength"].get<size_t>());
    if (offset + out.size() * 4 <= bin.size()) std::memcpy(out.data(), bin.data() + offset, out.size() * 4);
    return out;
  }
};

uint32_t u32_at(const std::string& s, size_t offset) {
  uint32_t v = 0;
  std::memcpy(&v, s.data() + offset, 4);
  return v;
}

// Parses and checks the container: header, JSON chunk (padded with spaces), BIN chunk (padded with zeros).
Glb read_glb(const std::string& path) {
  Glb g;
  g.bytes = io::read_small_file(path);
  const std::string& b = g.bytes;
  EXPECT_GE(b.size(), 20u);
  if (b.size() < 20) return g;
  EXPECT_EQ(b.substr(0, 4), "glTF");
  EXPECT_EQ(u32_at(b, 4), 2u);
  EXPECT_EQ(u32_at(b, 8), b.size());
  const uint32_t json_len = u32_at(b, 12);
  EXPECT_EQ(json_len % 4, 0u);
  EXPECT_EQ(b.substr(16, 4), "JSON");
  EXPECT_LE(20 + json_len, b.size());
  const std::string text = b.substr(20, json_len);
  g.gltf = json::parse(text);
  EXPECT_EQ(text.find_last_not_of(' ') + 1 + 3 >= text.size(), true);  // at most 3 spaces of padding
  const size_t bin_at = 20 + json_len;
  if (bin_at == b.size()) {
    EXPECT_FALSE(g.gltf.contains("buffers"));
    return g;
  }
  EXPECT_LE(bin_at + 8, b.size());
  const uint32_t bin_len = u32_at(b, bin_at);
  EXPECT_EQ(b.substr(bin_at + 4, 4), std::string("BIN\0", 4));
  EXPECT_EQ(bin_len % 4, 0u);
  EXPECT_EQ(bin_at + 8 + bin_len, b.size());
  g.bin = b.substr(bin_at + 8, bin_len);
  EXPECT_EQ(g.gltf["buffers"].size(), 1u);
  const uint64_t byte_length = g.gltf["buffers"][0]["byteLength"].get<uint64_t>();
  EXPECT_LE(byte_length, bin_len);
  EXPECT_LT(bin_len - byte_length, 4u);
  for (const json& view : g.gltf["bufferViews"]) {
    EXPECT_EQ(view["byteOffset"].get<uint64_t>() % 4, 0u);
    EXPECT_LE(view["byteOffset"].get<uint64_t>() + view["byteLength"].get<uint64_t>(), byte_length);
  }
  return g;
}

// The three-level chain used below: the full small level, its triangles only (no normals), and nothing.
struct Chain {
  LodMesh fine = small_level(true);
  LodMesh coarse;
  LodMesh empty;
  std::vector<io::GlbLevel> levels;
  Chain() {
    coarse.positions = fine.positions;
    coarse.triangles = {0, 1, 2};
    levels = {{&fine, "lod0", 0.5}, {&coarse, "lod1", 0.2}, {&empty, "lod2", 0.01}};
  }
};

TEST(WriterGlb, ContainerLodChainAndAccessors) {
  TempDir dir;
  Chain c;
  const std::string path = dir.file("scene.glb");
  io::write_glb(path, c.levels, "lodstream test");
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  const Glb g = read_glb(path);
  const json& j = g.gltf;

  EXPECT_EQ(j["asset"]["version"], "2.0");
  EXPECT_EQ(j["asset"]["generator"], "lodstream test");
  EXPECT_EQ(j["extensionsUsed"], json::array({"MSFT_lod"}));
  EXPECT_FALSE(j.contains("extensionsRequired"));
  EXPECT_EQ(j["scene"], 0);
  EXPECT_EQ(j["scenes"][0]["nodes"], json::array({0}));

  // MSFT_lod on node 0: the lower levels in order; one screen coverage per level, node 0 first.
  ASSERT_EQ(j["nodes"].size(), 3u);
  EXPECT_EQ(j["nodes"][0]["extensions"]["MSFT_lod"]["ids"], json::array({1, 2}));
  EXPECT_EQ(j["nodes"][0]["extras"]["MSFT_screencoverage"], json::array({0.5, 0.2, 0.01}));
  EXPECT_FALSE(j["nodes"][1].contains("extensions"));
  EXPECT_EQ(j["nodes"][0]["name"], "lod0");
  EXPECT_EQ(j["nodes"][0]["mesh"], 0);
  EXPECT_EQ(j["nodes"][1]["mesh"], 1);
  EXPECT_FALSE(j["nodes"][2].contains("mesh"));  // nothing to draw: a node without mesh
  ASSERT_EQ(j["meshes"].size(), 2u);
  ASSERT_EQ(j["materials"].size(), 1u);
  EXPECT_EQ(j["materials"][0]["doubleSided"], true);

  const json& prims = j["meshes"][0]["primitives"];
  ASSERT_EQ(prims.size(), 3u);
  for (const json& p : prims) EXPECT_EQ(p["material"], 0);

  // TRIANGLES: the 4 vertices the triangles use, with normals; indices into that array.
  const json& tri = prims[0];
  EXPECT_EQ(tri["mode"], 4);
  const int tri_pos = tri["attributes"]["POSITION"], tri_nrm = tri["attributes"]["NORMAL"];
  const int tri_idx = tri["indices"];
  EXPECT_EQ(j["accessors"][tri_pos]["count"], 4);
  EXPECT_EQ(j["accessors"][tri_nrm]["count"], 4);
  EXPECT_EQ(j["accessors"][tri_idx]["count"], 6);
  EXPECT_EQ(j["accessors"][tri_idx]["componentType"], 5125);
  EXPECT_EQ(j["accessors"][tri_pos]["min"], json::array({0.0, 0.0, 0.0}));
  EXPECT_EQ(j["accessors"][tri_pos]["max"], json::array({1.0, 1.0, static_cast<double>(0.1f)}));
  EXPECT_EQ(j["bufferViews"][j["accessors"][tri_pos]["bufferView"].get<int>()]["target"], 34962);
  EXPECT_EQ(j["bufferViews"][j["accessors"][tri_idx]["bufferView"].get<int>()]["target"], 34963);
  const auto pos = g.values<float>(tri_pos);
  const auto nrm = g.values<float>(tri_nrm);
  const auto idx = g.values<uint32_t>(tri_idx);
  ASSERT_EQ(idx.size(), 6u);
  for (size_t k = 0; k < 6; ++k) {
    ASSERT_LT(idx[k], 4u);
    for (int d = 0; d < 3; ++d) {
      EXPECT_EQ(pos[3 * idx[k] + d], c.fine.positions[3 * c.fine.triangles[k] + d]) << k;
      EXPECT_EQ(nrm[3 * idx[k] + d], c.fine.normals[3 * c.fine.triangles[k] + d]) << k;
    }
  }

  // LINES: two vertices per edge, each with its edge's thickness; no normals, no indices.
  const json& lines = prims[1];
  EXPECT_EQ(lines["mode"], 1);
  EXPECT_FALSE(lines.contains("indices"));
  EXPECT_FALSE(lines["attributes"].contains("NORMAL"));
  const int line_pos = lines["attributes"]["POSITION"], line_thick = lines["attributes"]["_THICKNESS"];
  EXPECT_EQ(j["accessors"][line_thick]["type"], "SCALAR");
  EXPECT_EQ(j["accessors"][line_thick]["componentType"], 5126);
  EXPECT_EQ(j["accessors"][line_pos]["count"], 4);
  EXPECT_EQ(j["accessors"][line_thick]["count"], 4);
  EXPECT_EQ(g.values<float>(line_thick), (std::vector<float>{0.25f, 0.25f, 1.0f / 3.0f, 1.0f / 3.0f}));
  const auto lp = g.values<float>(line_pos);
  for (size_t k = 0; k < 4; ++k)
    for (int d = 0; d < 3; ++d) EXPECT_EQ(lp[3 * k + d], c.fine.positions[3 * c.fine.edges[k] + d]);
  EXPECT_EQ(j["accessors"][line_pos]["min"], json::array({1.0, 0.0, -0.5}));
  EXPECT_EQ(j["accessors"][line_pos]["max"], json::array({2.0, 1.0, static_cast<double>(0.1f)}));

  // POINTS: one vertex per point, with its size.
  const json& pts = prims[2];
  EXPECT_EQ(pts["mode"], 0);
  const int pt_pos = pts["attributes"]["POSITION"], pt_size = pts["attributes"]["_SIZE"];
  EXPECT_EQ(j["accessors"][pt_pos]["count"], 1);
  EXPECT_EQ(j["accessors"][pt_size]["type"], "SCALAR");
  EXPECT_EQ(g.values<float>(pt_size), (std::vector<float>{0.125f}));
  EXPECT_EQ(g.values<float>(pt_pos), (std::vector<float>{-1e-7f, 3.14159274f, 1.5e10f}));
  EXPECT_EQ(j["accessors"][pt_pos]["min"], j["accessors"][pt_pos]["max"]);
  EXPECT_EQ(j["accessors"][pt_pos]["min"][2].get<double>(), static_cast<double>(1.5e10f));

  // The coarse level: triangles only, no normals in that mesh.
  const json& coarse = j["meshes"][1]["primitives"];
  ASSERT_EQ(coarse.size(), 1u);
  EXPECT_EQ(coarse[0]["mode"], 4);
  EXPECT_FALSE(coarse[0]["attributes"].contains("NORMAL"));
  EXPECT_EQ(j["accessors"][coarse[0]["attributes"]["POSITION"].get<int>()]["count"], 3);
}

TEST(WriterGlb, DeterministicAndSingleLevel) {
  TempDir dir;
  Chain c;
  io::write_glb(dir.file("a.glb"), c.levels, "g");
  io::write_glb(dir.file("b.glb"), c.levels, "g");
  EXPECT_EQ(io::read_small_file(dir.file("a.glb")), io::read_small_file(dir.file("b.glb")));

  // One level: no MSFT_lod at all.
  io::write_glb(dir.file("one.glb"), std::span(c.levels).first(1), "g");
  const Glb one = read_glb(dir.file("one.glb"));
  EXPECT_FALSE(one.gltf.contains("extensionsUsed"));
  EXPECT_FALSE(one.gltf["nodes"][0].contains("extensions"));
  EXPECT_EQ(one.gltf["nodes"].size(), 1u);

  // Nothing to draw anywhere: JSON chunk only, no buffer.
  io::write_glb(dir.file("empty.glb"), std::span(c.levels).last(1), "g");
  const Glb empty = read_glb(dir.file("empty.glb"));
  EXPECT_TRUE(empty.bin.empty());
  EXPECT_FALSE(empty.gltf.contains("meshes"));
  EXPECT_FALSE(empty.gltf.contains("accessors"));

  EXPECT_THROW(io::write_glb(dir.file("none.glb"), std::span<const io::GlbLevel>(), "g"), Failure);
}

TEST(WriterGlb, BuilderLevelByLevelGivesTheSameBytes) {
  // GlbBuilder as the simplify pipeline uses it: each level added from a mesh that is gone right after,
  // the BIN chunk gathered in a scratch file. Same bytes as write_glb with every level at once; the scratch
  // file is gone after finish(), and a builder dropped before finish() leaves neither it nor the GLB.
  TempDir dir;
  Chain c;
  io::write_glb(dir.file("whole.glb"), c.levels, "g");
  {
    io::GlbBuilder b(dir.file("built.glb"), dir.file("scratch"), "g");
    for (const io::GlbLevel& level : c.levels) {
      const LodMesh copy = *level.mesh;
      b.add({&copy, level.name, level.screen_coverage});
    }
    b.finish();
  }
  EXPECT_EQ(io::read_small_file(dir.file("built.glb")), io::read_small_file(dir.file("whole.glb")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("scratch")));
  {
    io::GlbBuilder b(dir.file("dropped.glb"), dir.file("scratch2"), "g");
    b.add(c.levels[0]);
    b.add(c.levels[1]);
  }
  for (const char* f : {"scratch2", "scratch2.partial", "dropped.glb", "dropped.glb.partial"})
    EXPECT_FALSE(std::filesystem::exists(dir.file(f))) << f;
  io::GlbBuilder none(dir.file("none.glb"), dir.file("scratch3"), "g");
  EXPECT_THROW(none.finish(), Failure);
}

// --------------------------------------------------------------------------------------------- errors

TEST(WriterErrors, MissingDirectoryThrowsIoErrorAndLeavesNothing) {
  TempDir dir;
  const LodMesh m = small_level(true);
  const io::GlbLevel level{&m, "lod0", 1.0};
  const std::filesystem::path missing = dir.path() / "no-such-dir";
  auto expect_io_error = [&](const char* name, auto&& write) {
    SCOPED_TRACE(name);
    const std::string path = (missing / name).string();
    try {
      write(path);
      ADD_FAILURE() << "no exception";
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::io_error) << f.what();
      EXPECT_NE(std::string(f.what()).find(name), std::string::npos) << f.what();
    }
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  };
  expect_io_error("x.ply", [&](const std::string& p) { io::write_ply(p, m, {}); });
  expect_io_error("x.obj", [&](const std::string& p) { io::write_obj(p, m, {}); });
  expect_io_error("x.glb", [&](const std::string& p) { io::write_glb(p, std::span(&level, 1), "g"); });
  EXPECT_FALSE(std::filesystem::exists(missing));
}

TEST(WriterErrors, BadMeshIsAnInternalError) {
  TempDir dir;
  LodMesh m = small_level(true);
  m.points = {6};  // one past the last vertex
  for (const char* name : {"bad.ply", "bad.obj", "bad.glb"}) {
    const std::string path = dir.file(name);
    const io::GlbLevel level{&m, "lod0", 1.0};
    try {
      if (std::string(name) == "bad.ply") io::write_ply(path, m, {});
      if (std::string(name) == "bad.obj") io::write_obj(path, m, {});
      if (std::string(name) == "bad.glb") io::write_glb(path, std::span(&level, 1), "g");
      ADD_FAILURE() << name << ": no exception";
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::internal) << f.what();
    }
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  }
}

// ------------------------------------------------------------------------------------ glTF-Validator

// Runs a shell command, returning its exit status and its output (stdout and stderr together).
int run(const std::string& command, std::string* output) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) output->append(buf, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(WriterGlbValidator, KhronosValidatorFindsNoErrorsOrWarnings) {
  std::string ignored;
  if (run("command -v node", &ignored) != 0) {
    std::cout << "skipped: node is not installed (glTF-Validator needs it)\n";
    GTEST_SKIP() << "skipped: node is not installed";
  }
  TempDir dir;
  Chain c;
  // The three-level chain (every primitive kind, a level without normals, an empty level), one level
  // alone, and a file with nothing to draw.
  io::write_glb(dir.file("chain.glb"), c.levels, "lodstream test");
  io::write_glb(dir.file("one.glb"), std::span(c.levels).first(1), "lodstream test");
  io::write_glb(dir.file("empty.glb"), std::span(c.levels).last(1), "lodstream test");

  const std::string script = source_dir() + "/tools/validate_gltf.js";
  for (const char* name : {"chain.glb", "one.glb", "empty.glb"}) {
    SCOPED_TRACE(name);
    std::string out;
    const int code = run("node '" + script + "' '" + dir.file(name) + "'", &out);
    if (code == 77) {  // tools/validate_gltf.js: the npm package is not installed
      std::cout << out;
      GTEST_SKIP() << out;
    }
    std::cout << "glTF-Validator report for " << name << ": " << out;
    ASSERT_TRUE(code == 0 || code == 1) << out;
    const json issues = json::parse(out, nullptr, false);
    ASSERT_FALSE(issues.is_discarded()) << out;
    EXPECT_EQ(code, 0) << out;
    EXPECT_EQ(issues["numErrors"], 0) << out;
    EXPECT_EQ(issues["numWarnings"], 0) << out;
  }
}

}  // namespace
}  // namespace lodstream::test

// The glTF reader (io/gltf_reader.cpp): exact small scenes built here, through the same chunk/parse/resolve
// sequence as the pipeline (tests/reader_harness.h) at every chunk size; bad input with its JSON pointer
// or byte offset; the real furniture scenes in tests/data converted with assimp; simplify end to end.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#ifdef LODSTREAM_HAVE_MESHOPT
#include <meshoptimizer.h>
#endif

#include "cli_harness.h"
#include "core/status.h"
#include "io/base64.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

using json = nlohmann::json;
using test::read_all;
using test::ReadAll;
using test::TempDir;

template <class T>
void put(std::string* s, T v) {
  s->append(reinterpret_cast<const char*>(&v), sizeof v);
}

// A GLB holding `doc` (buffer 0 = the BIN chunk `bin`, padded to 4 bytes).
std::string glb(json doc, std::string bin) {
  while (bin.size() % 4) bin.push_back('\0');
  if (!doc.contains("buffers")) doc["buffers"] = json::array({{{"byteLength", bin.size()}}});
  std::string text = doc.dump();
  while (text.size() % 4) text.push_back(' ');
  std::string s = "glTF";
  put<uint32_t>(&s, 2);
  put<uint32_t>(&s, static_cast<uint32_t>(12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size())));
  put<uint32_t>(&s, static_cast<uint32_t>(text.size()));
  put<uint32_t>(&s, 0x4E4F534A);
  s += text;
  if (!bin.empty()) {
    put<uint32_t>(&s, static_cast<uint32_t>(bin.size()));
    put<uint32_t>(&s, 0x004E4942);
    s += bin;
  }
  return s;
}

// A document with one mesh of one primitive over `bin`: POSITION accessor 0, indices accessor 1 if given.
json one_mesh(json primitive, json accessors, json views, json nodes = json::array({{{"mesh", 0}}})) {
  json doc = {{"asset", {{"version", "2.0"}}},
              {"scene", 0},
              {"scenes", json::array({{{"nodes", json::array()}}})},
              {"nodes", nodes},
              {"meshes", json::array({{{"primitives", json::array({primitive})}}})},
              {"accessors", accessors},
              {"bufferViews", views}};
  for (size_t i = 0; i < nodes.size(); ++i) {
    bool child = false;
    for (const auto& n : nodes)
      if (n.contains("children"))
        for (const auto& c : n["children"]) child = child || c.get<size_t>() == i;
    if (!child) doc["scenes"][0]["nodes"].push_back(i);
  }
  return doc;
}

std::string floats(std::initializer_list<float> v) {
  std::string s;
  for (float f : v) put(&s, f);
  return s;
}

// Reads with every chunk size from 1 to past the element count and checks they all agree; returns one.
ReadAll read_every_way(const std::string& path) {
  const ReadAll ref = read_all(path, 1);
  for (uint64_t target : {12, 24, 36, 100, 1000, 1 << 20}) test::expect_same(ref, read_all(path, target), "target " + std::to_string(target));
  test::expect_same(ref, test::read_parallel(path, 12, 3), "parallel");
  return ref;
}

std::string failure(const std::string& path, Status* status = nullptr) {
  try {
    read_all(path, 12);
  } catch (const Failure& f) {
    if (status) *status = f.status();
    return f.what();
  }
  return "(no failure)";
}

// Unit triangle (0,0,0) (1,0,0) (0,1,0), indexed, drawn by two nodes: TRS and matrix.
TEST(GltfReader, TwoNodesInstanceOneMeshWithTrsAndMatrix) {
  TempDir dir;
  std::string bin = floats({0, 0, 0, 1, 0, 0, 0, 1, 0});
  put<uint16_t>(&bin, 0), put<uint16_t>(&bin, 1), put<uint16_t>(&bin, 2);
  const json accessors = json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
                                      {{"bufferView", 1}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}});
  const json views = json::array({{{"buffer", 0}, {"byteLength", 36}}, {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 6}}});
  // Node 0: translate (10, 0, 0), rotate 90 degrees about Z, scale 2. Node 1 (child of 0): matrix moving +5 z.
  const double h = std::sqrt(0.5);
  const json nodes = json::array(
      {{{"name", "a"}, {"mesh", 0}, {"translation", {10, 0, 0}}, {"rotation", {0, 0, h, h}}, {"scale", {2, 2, 2}}, {"children", {1}}},
       {{"mesh", 0}, {"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1}}}});
  const std::string path = dir.write("two.glb", glb(one_mesh({{"attributes", {{"POSITION", 0}}}, {"indices", 1}}, accessors, views, nodes), bin));
  const ReadAll r = read_every_way(path);
  EXPECT_EQ(r.format, "glb");
  ASSERT_EQ(r.positions.size(), 18u);
  // Node 0: (x, y) -> rotate -> (-y, x), scale 2, + (10, 0, 0).
  const double expect0[9] = {10, 0, 0, 10, 2, 0, 8, 0, 0};
  // Node 1: its matrix first (+5 z, scaled by the parent to +10), then node 0's.
  const double expect1[9] = {10, 0, 10, 10, 2, 10, 8, 0, 10};
  for (int k = 0; k < 9; ++k) {
    EXPECT_NEAR(r.positions[k], expect0[k], 1e-12) << k;
    EXPECT_NEAR(r.positions[9 + k], expect1[k], 1e-12) << k;
  }
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"a", "node 1"}));
  EXPECT_EQ(r.polygons, 2u);
}

// Five vertices along x, not indexed, drawn in every mode.
TEST(GltfReader, EveryMode) {
  TempDir dir;
  const std::string bin = floats({0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0, 4, 0, 0});
  const json accessors = json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 5}, {"type", "VEC3"}}});
  const json views = json::array({{{"buffer", 0}, {"byteLength", 60}}});
  auto read_mode = [&](int mode, int count = 5) {
    json acc = accessors;
    acc[0]["count"] = count;
    const std::string path =
        dir.write("mode" + std::to_string(mode) + ".glb", glb(one_mesh({{"attributes", {{"POSITION", 0}}}, {"mode", mode}}, acc, views), bin));
    return read_every_way(path);
  };
  using V = std::vector<int64_t>;
  EXPECT_EQ(read_mode(0).points, (V{0, 1, 2, 3, 4}));
  EXPECT_EQ(read_mode(1, 4).lines, (V{0, 1, 2, 3}));
  EXPECT_EQ(read_mode(2).lines, (V{0, 1, 1, 2, 2, 3, 3, 4, 4, 0}));
  EXPECT_EQ(read_mode(3).lines, (V{0, 1, 1, 2, 2, 3, 3, 4}));
  EXPECT_EQ(read_mode(4, 3).triangles, (V{0, 1, 2}));
  EXPECT_EQ(read_mode(5).triangles, (V{0, 1, 2, 1, 3, 2, 2, 3, 4}));
  EXPECT_EQ(read_mode(6).triangles, (V{1, 2, 0, 2, 3, 0, 3, 4, 0}));
  const ReadAll points = read_mode(0);
  EXPECT_EQ(points.point_objects, (std::vector<uint32_t>(5, 0)));
}

// Indexed strip with a repeated index (a degenerate triangle the pipeline drops), uint8 indices.
TEST(GltfReader, IndexedStripKeepsDegenerateForThePipeline) {
  TempDir dir;
  std::string bin = floats({0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0});
  for (uint8_t i : {0, 1, 2, 2, 3}) bin.push_back(static_cast<char>(i));
  const json accessors = json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
                                      {{"bufferView", 1}, {"componentType", 5121}, {"count", 5}, {"type", "SCALAR"}}});
  const json views = json::array({{{"buffer", 0}, {"byteLength", 48}}, {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 5}}});
  const std::string path = dir.write("strip.glb", glb(one_mesh({{"attributes", {{"POSITION", 0}}}, {"indices", 1}, {"mode", 5}}, accessors, views), bin));
  const ReadAll r = read_every_way(path);
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 1, 2, 2, 2, 2, 3}));
}

// KHR_mesh_quantization: normalized int16 positions interleaved with padding (byteStride 12), and an
// unnormalized uint8 position accessor with byteStride 4.
TEST(GltfReader, QuantizedNormalizedPositionsWithStrides) {
  TempDir dir;
  std::string bin;
  for (int16_t v : {int16_t{32767}, int16_t{0}, int16_t{-32768}}) {
    put<int16_t>(&bin, v), put<int16_t>(&bin, static_cast<int16_t>(v / 2)), put<int16_t>(&bin, 16384);
    put<int16_t>(&bin, 7), put<int16_t>(&bin, 7), put<int16_t>(&bin, 7);  // padding the stride skips
  }
  for (uint8_t v : {1, 2, 3}) bin += std::string{static_cast<char>(v), 5, 9, 0};
  json doc = one_mesh({{"attributes", {{"POSITION", 0}}}, {"mode", 0}},
                      json::array({{{"bufferView", 0}, {"componentType", 5122}, {"normalized", true}, {"count", 3}, {"type", "VEC3"}},
                                   {{"bufferView", 1}, {"componentType", 5121}, {"count", 3}, {"type", "VEC3"}}}),
                      json::array({{{"buffer", 0}, {"byteLength", 36}, {"byteStride", 12}},
                                   {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 12}, {"byteStride", 4}}}));
  doc["meshes"][0]["primitives"].push_back({{"attributes", {{"POSITION", 1}}}, {"mode", 0}});
  doc["extensionsUsed"] = {"KHR_mesh_quantization"};
  doc["extensionsRequired"] = {"KHR_mesh_quantization"};
  const ReadAll r = read_every_way(dir.write("q.glb", glb(doc, bin)));
  ASSERT_EQ(r.positions.size(), 18u);
  const double expect[18] = {1, 16383 / 32767.0, 16384 / 32767.0, 0, 0, 16384 / 32767.0, -1, -16384 / 32767.0, 16384 / 32767.0,
                             1, 5, 9, 2, 5, 9, 3, 5, 9};
  for (int k = 0; k < 18; ++k) EXPECT_DOUBLE_EQ(r.positions[k], expect[k]) << k;
  EXPECT_EQ(r.points, (std::vector<int64_t>{0, 1, 2, 3, 4, 5}));
}

// A sparse accessor over a base view, and one over zeros (no bufferView).
TEST(GltfReader, SparseAccessors) {
  TempDir dir;
  std::string bin = floats({0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3});  // view 0: base
  put<uint16_t>(&bin, 1), put<uint16_t>(&bin, 3);                    // view 1: sparse indices
  bin += floats({10, 11, 12, 30, 31, 32});                            // view 2: sparse values
  const json sparse = {{"count", 2}, {"indices", {{"bufferView", 1}, {"componentType", 5123}}}, {"values", {{"bufferView", 2}}}};
  json doc = one_mesh({{"attributes", {{"POSITION", 0}}}, {"mode", 0}},
                      json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}, {"sparse", sparse}},
                                   {{"componentType", 5126}, {"count", 4}, {"type", "VEC3"}, {"sparse", sparse}}}),
                      json::array({{{"buffer", 0}, {"byteLength", 48}},
                                   {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 4}},
                                   {{"buffer", 0}, {"byteOffset", 52}, {"byteLength", 24}}}));
  doc["meshes"][0]["primitives"].push_back({{"attributes", {{"POSITION", 1}}}, {"mode", 0}});
  const ReadAll r = read_every_way(dir.write("sparse.glb", glb(doc, bin)));
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 10, 11, 12, 2, 2, 2, 30, 31, 32,  //
                                              0, 0, 0, 10, 11, 12, 0, 0, 0, 30, 31, 32}));
}

// .gltf with the buffer in a data URI and in a .bin beside it give the GLB's geometry.
TEST(GltfReader, GltfWithDataUriAndBinFile) {
  TempDir dir;
  std::string bin = floats({0, 0, 0, 1, 0, 0, 0, 1, 0});
  json doc = one_mesh({{"attributes", {{"POSITION", 0}}}},
                      json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}}}),
                      json::array({{{"buffer", 0}, {"byteLength", 36}}}));
  const std::string encoded = io::base64_encode(std::span(reinterpret_cast<const uint8_t*>(bin.data()), bin.size()));
  doc["buffers"] = json::array({{{"byteLength", 36}, {"uri", "data:application/octet-stream;base64," + encoded}}});
  const ReadAll a = read_every_way(dir.write("uri.gltf", doc.dump()));
  doc["buffers"][0]["uri"] = "my%20data.bin";
  dir.write("my data.bin", bin);
  const ReadAll b = read_every_way(dir.write("file.gltf", doc.dump()));
  EXPECT_EQ(a.format, "gltf");
  EXPECT_EQ(a.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 0, 1, 0}));
  EXPECT_EQ(a.triangles, (std::vector<int64_t>{0, 1, 2}));
  test::expect_same(a, b, "data URI vs .bin");
  std::filesystem::remove(dir.file("my data.bin"));
  Status status{};
  EXPECT_NE(failure(dir.file("file.gltf"), &status).find(": /buffers/0/uri: missing buffer file 'my data.bin'"), std::string::npos);
  EXPECT_EQ(status, Status::bad_data);
}

#ifdef LODSTREAM_HAVE_MESHOPT
// EXT_meshopt_compression: positions (ATTRIBUTES) and indices (TRIANGLES) encoded with meshoptimizer into
// buffer 0, the views pointing at a fallback buffer without data.
TEST(GltfReader, MeshoptCompressedViews) {
  TempDir dir;
  const float pos[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  const uint16_t idx[6] = {0, 1, 2, 2, 1, 3};
  std::vector<unsigned char> vb(meshopt_encodeVertexBufferBound(4, 12)), ib(meshopt_encodeIndexBufferBound(6, 4));
  vb.resize(meshopt_encodeVertexBuffer(vb.data(), vb.size(), pos, 4, 12));
  ib.resize(meshopt_encodeIndexBuffer(ib.data(), ib.size(), std::vector<unsigned>(idx, idx + 6).data(), 6));
  std::string bin(vb.begin(), vb.end());
  while (bin.size() % 4) bin.push_back('\0');
  const size_t ib_offset = bin.size();
  bin.append(ib.begin(), ib.end());
  json doc = one_mesh({{"attributes", {{"POSITION", 0}}}, {"indices", 1}},
                      json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
                                   {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}),
                      json::array({{{"buffer", 1}, {"byteLength", 48}, {"extensions", {{"EXT_meshopt_compression",
                                      {{"buffer", 0}, {"byteLength", vb.size()}, {"byteStride", 12}, {"count", 4}, {"mode", "ATTRIBUTES"}}}}}},
                                   {{"buffer", 1}, {"byteLength", 12}, {"extensions", {{"EXT_meshopt_compression",
                                      {{"buffer", 0}, {"byteOffset", ib_offset}, {"byteLength", ib.size()}, {"byteStride", 2}, {"count", 6}, {"mode", "TRIANGLES"}}}}}}}));
  doc["buffers"] = json::array({{{"byteLength", bin.size()}}, {{"byteLength", 60}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}}});
  doc["extensionsUsed"] = doc["extensionsRequired"] = {"EXT_meshopt_compression"};
  const ReadAll r = read_every_way(dir.write("meshopt.glb", glb(doc, bin)));
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0}));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 2, 1, 3}));
}
#endif

TEST(GltfReader, BadInputNamesPointerOrOffset) {
  TempDir dir;
  std::string bin = floats({0, 0, 0, 1, 0, 0, 0, 1, 0});
  put<uint16_t>(&bin, 0), put<uint16_t>(&bin, 1), put<uint16_t>(&bin, 9);
  const json accessors = json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
                                      {{"bufferView", 1}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}});
  const json views = json::array({{{"buffer", 0}, {"byteLength", 36}}, {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 6}}});
  const json prim = {{"attributes", {{"POSITION", 0}}}, {"indices", 1}};
  struct Case {
    std::string name, contents, expect;
    Status status = Status::bad_data;
  };
  std::vector<Case> cases;
  cases.push_back({"index", glb(one_mesh(prim, accessors, views), bin), ": /accessors/1: index 2 is 9, past the 3 vertices"});
  json big = accessors;
  big[0]["count"] = 1000;
  cases.push_back({"count", glb(one_mesh(prim, big, views), bin), ": /accessors/0: accessor: count 1000 past the end of bufferView 0"});
  json cyc = one_mesh(prim, accessors, views, json::array({{{"mesh", 0}, {"children", {1}}}, {{"children", {0}}}}));
  cyc.erase("scene");
  cyc["scene"] = 0;
  cyc["scenes"][0]["nodes"] = {0};
  cases.push_back({"cycle", glb(cyc, bin), ": /nodes/1/children/0: cycle: node 0 is an ancestor of node 1"});
  std::string lying = glb(one_mesh(prim, accessors, views), bin);
  lying[8] = static_cast<char>(lying[8] + 4);
  cases.push_back({"length", lying, ": byte 8: the GLB header says"});
  std::string truncated = glb(one_mesh(prim, accessors, views), bin);
  truncated.resize(truncated.size() - 10);
  cases.push_back({"truncated", truncated, ": byte 8: the GLB header says"});
  json lying_buffer = one_mesh(prim, accessors, views);
  lying_buffer["buffers"] = json::array({{{"byteLength", 4000}}});
  cases.push_back({"buffer", glb(lying_buffer, bin), ": /buffers/0/byteLength: says 4000 bytes but the data has 44"});
  json missing = one_mesh(prim, accessors, views);
  missing["buffers"] = json::array({{{"byteLength", 44}}, {{"byteLength", 8}}});
  missing["bufferViews"][1]["buffer"] = 1;
  cases.push_back({"missing", glb(missing, bin), ": /buffers/1: no uri, and it is not the GLB's BIN chunk (missing buffer)"});
  json draco = one_mesh(prim, accessors, views);
  draco["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  cases.push_back({"draco", glb(draco, bin), ": /extensionsRequired: unsupported glTF extension(s): KHR_draco_mesh_compression", Status::usage});
  std::string bad_json = glb(one_mesh(prim, accessors, views), bin);
  bad_json[20] = '[';
  cases.push_back({"json", bad_json, ": byte 32: bad JSON: syntax error"});
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir.write(c.name + ".glb", c.contents);
    Status status{};
    const std::string message = failure(path, &status);
    EXPECT_EQ(message.rfind(path + c.expect, 0), 0u) << message;
    EXPECT_EQ(status, c.status);
  }
}

// Real scenes: the furniture-cc0 bench (tests/data/LICENSE-gltf.md) converted with assimp export.
TEST(GltfReader, RealBenchAgreesWithItsObj) {
  const std::string data = test::source_dir() + "/tests/data/gltf";
  const ReadAll glb_read = read_all(data + "/bench.glb", 1 << 16);
  const ReadAll gltf_read = read_all(data + "/bench.gltf", 1 << 16);
  test::expect_same(glb_read, read_all(data + "/bench.glb", 1000), "chunk sizes");
  EXPECT_EQ(glb_read.positions, gltf_read.positions);
  EXPECT_EQ(glb_read.triangles, gltf_read.triangles);
  EXPECT_EQ(glb_read.triangles.size() / 3, 2516u);
  LODSTREAM_REQUIRE_SHARED_DATA(shared);
  const ReadAll obj = read_all(shared + "/furniture-cc0/bench/bench.obj", 1 << 16);
  EXPECT_EQ(obj.triangles.size(), glb_read.triangles.size());
  // assimp triangulates the OBJ's quads and polygons itself, with other diagonals than ours for some, so the
  // triangles are compared by what does not depend on the diagonal: the positions they use and their
  // total area (the same to 1e-6 when the polygons are planar; it was 291 of 2,516 triangles here).
  auto used_positions = [](const ReadAll& r) {
    std::set<std::tuple<float, float, float>> s;
    for (int64_t v : r.triangles)
      s.emplace(static_cast<float>(r.positions[3 * v]), static_cast<float>(r.positions[3 * v + 1]), static_cast<float>(r.positions[3 * v + 2]));
    return s;
  };
  auto area = [](const ReadAll& r) {
    double sum = 0;
    for (size_t t = 0; t < r.triangles.size(); t += 3) {
      const double* a = &r.positions[3 * r.triangles[t]];
      const double* b = &r.positions[3 * r.triangles[t + 1]];
      const double* c = &r.positions[3 * r.triangles[t + 2]];
      const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
      const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
      sum += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    }
    return sum;
  };
  // assimp parses numbers with its own fast_atof, which can be an ulp off the correctly rounded float.
  const auto pa = used_positions(obj), pb = used_positions(glb_read);
  ASSERT_EQ(pa.size(), pb.size());
  size_t far = 0;
  for (auto ia = pa.begin(), ib = pb.begin(); ia != pa.end(); ++ia, ++ib) {
    const auto [ax, ay, az] = *ia;
    const auto [bx, by, bz] = *ib;
    far += std::abs(ax - bx) > 1e-4f || std::abs(ay - by) > 1e-4f || std::abs(az - bz) > 1e-4f;
  }
  EXPECT_EQ(far, 0u) << "positions more than 1e-4 apart (the bench spans 170 units)";
  EXPECT_NEAR(area(glb_read) / area(obj), 1.0, 1e-6) << area(glb_read) << " vs " << area(obj);
}

TEST(GltfCli, SimplifyAGlbEndToEnd) {
  TempDir tmp;
  const std::string in = test::source_dir() + "/tests/data/gltf/bench.glb";
  const test::CliRun r = test::run_cli({"simplify", in, "-o", tmp.file("out"), "--work", tmp.file("work"), "--levels", "2",
                                        "--progress", "none"}, tmp);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(tmp.file("out/manifest.json"))) << r.out;
  const test::CliRun info = test::run_cli({"info", in, "--json", "--work", tmp.file("work2")}, tmp);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const json j = json::parse(info.out);
  EXPECT_EQ(j.dump().find("\"glb\"") != std::string::npos, true) << info.out;
}

}  // namespace
}  // namespace lodstream

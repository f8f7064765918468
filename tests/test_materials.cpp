// Materials through the pipeline (issue 16.2): OBJ usemtl/MTL in, the kept-material rule of the emit stage
// (stream/emit_stage.h), and the writers' material outputs read back: PLY material_index and its comment
// table, OBJ usemtl with its MTL file, GLB one primitive per material with the glTF material table.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/primitive_color.h"
#include "core/ray_scene.h"
#include "core/status.h"
#include "core/view_cast.h"
#include "io/base64.h"
#include "io/lod_reader.h"
#include "io/ply_writer.h"
#include "io/png_writer.h"
#include "io/texture_mean.h"
#include "lodstream/lodstream.h"
#include "cli_harness.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

using Json = nlohmann::json;

struct Level {
  uint32_t vertices = 0;
  std::vector<uint32_t> triangles, triangle_materials, edge_materials, point_materials;
  std::vector<std::string> material_comments;
};

// Reads a level PLY as io/ply_writer.h writes it with materials (normals on, no colours).
Level read_ply(const std::string& path) {
  const std::string bytes = test::read_file(path);
  const size_t end = bytes.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end);
  Level l;
  uint64_t faces = 0, edges = 0, points = 0;
  std::istringstream in(header);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("comment material ", 0) == 0) l.material_comments.push_back(line.substr(17));
    if (line.rfind("element vertex ", 0) == 0) l.vertices = static_cast<uint32_t>(std::stoul(line.substr(15)));
    if (line.rfind("element face ", 0) == 0) faces = std::stoull(line.substr(13));
    if (line.rfind("element edge ", 0) == 0) edges = std::stoull(line.substr(13));
    if (line.rfind("element point ", 0) == 0) points = std::stoull(line.substr(14));
  }
  EXPECT_NE(header.find("element face " + std::to_string(faces) + "\nproperty list uchar uint vertex_indices\nproperty uint material_index\n"), std::string::npos);
  const char* p = bytes.data() + end + 11 + uint64_t{l.vertices} * 24;
  auto u32 = [&] {
    uint32_t v;
    std::memcpy(&v, p, 4);
    p += 4;
    return v;
  };
  for (uint64_t f = 0; f < faces; ++f) {
    EXPECT_EQ(*p, 3);
    ++p;
    for (int k = 0; k < 3; ++k) l.triangles.push_back(u32());
    l.triangle_materials.push_back(u32());
  }
  for (uint64_t e = 0; e < edges; ++e) p += 12, l.edge_materials.push_back(u32());
  for (uint64_t i = 0; i < points; ++i) p += 8, l.point_materials.push_back(u32());  // vertex, size, material
  EXPECT_EQ(p, bytes.data() + bytes.size());
  return l;
}

// A GLB's JSON chunk, and its BIN chunk's bytes.
struct GlbFile {
  Json json;
  std::string bin;
};
GlbFile read_glb(const std::string& path) {
  const std::string bytes = test::read_file(path);
  uint32_t n;
  std::memcpy(&n, bytes.data() + 12, 4);
  return {Json::parse(bytes.substr(20, n)), bytes.substr(20 + n + 8)};
}

Json glb_json(const std::string& path) { return read_glb(path).json; }

Result run(const std::string& input, const std::string& out, std::vector<double> sizes, bool obj = true) {
  SimplifyOptions so;
  so.output_dir = out;
  so.representative = Representative::center;
  so.cell_sizes = std::move(sizes);
  so.write_obj = obj;
  Options o;
  o.threads = 1;
  SimplifyReport report;
  return simplify(input, so, o, &report);
}

const char* kMtl = "newmtl red\nKd 1 0 0\nnewmtl blue glass\nKd 0 0 1\nd 0.5\n";

TEST(Materials, FineLevelKeepsEveryTrianglesMaterialInEveryFormat) {
  // Two unit quads side by side, red then blue; at cell size 0.1 nothing merges.
  test::TempDir tmp;
  tmp.write("a.mtl", kMtl);
  const std::string input = tmp.write("a.obj",
                                      "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n"
                                      "usemtl red\nf 1 2 3 4\nusemtl blue glass\nf 2 5 6 3\n");
  const Result r = run(input, tmp.file("out"), {0.1});
  ASSERT_TRUE(r.ok()) << r.message;
  const Level l = read_ply(tmp.file("out/lod0.ply"));
  EXPECT_EQ(l.triangle_materials, (std::vector<uint32_t>{1, 1, 2, 2}));
  ASSERT_EQ(l.material_comments.size(), 3u);
  EXPECT_EQ(l.material_comments[1], "1 1 0 0 1 0 1 OPAQUE 1 red");
  EXPECT_EQ(l.material_comments[2], "2 0 0 1 0.5 0 1 BLEND 1 blue glass");
  const std::string obj = test::read_file(tmp.file("out/lod0.obj"));
  EXPECT_NE(obj.find("mtllib lod0.mtl\n"), std::string::npos);
  const size_t red = obj.find("usemtl m1_red\nf "), blue = obj.find("usemtl m2_blue_glass\nf ");
  EXPECT_TRUE(red != std::string::npos && blue != std::string::npos && red < blue) << obj;
  const std::string mtl = test::read_file(tmp.file("out/lod0.mtl"));
  EXPECT_NE(mtl.find("newmtl m2_blue_glass\nKd 0 0 1\nd 0.5\n"), std::string::npos) << mtl;
  const Json g = glb_json(tmp.file("out/lods.glb"));
  ASSERT_EQ(g["materials"].size(), 3u);
  EXPECT_EQ(g["materials"][2]["name"], "blue glass");
  EXPECT_EQ(g["materials"][2]["alphaMode"], "BLEND");
  EXPECT_EQ(g["materials"][2]["pbrMetallicRoughness"]["baseColorFactor"], Json::array({0.0, 0.0, 1.0, 0.5}));
  const Json& prims = g["meshes"][0]["primitives"];
  ASSERT_EQ(prims.size(), 2u);
  EXPECT_EQ(prims[0]["material"], 1);
  EXPECT_EQ(prims[1]["material"], 2);
  EXPECT_EQ(g["accessors"][prims[0]["indices"].get<int>()]["count"], 6);
  // The MTL file the OBJ names reads back (through the OBJ reader) to the same colours.
  const Result again = run(tmp.file("out/lod0.obj"), tmp.file("again"), {0.1}, false);
  ASSERT_TRUE(again.ok()) << again.message;
  const Json g2 = glb_json(tmp.file("again/lods.glb"));
  EXPECT_EQ(g2["materials"][2]["pbrMetallicRoughness"]["baseColorFactor"], Json::array({0.0, 0.0, 1.0, 0.5}));
}

TEST(Materials, CollapsedPointsKeepTheirMaterialAndSizeInPlyAndGlb) {
  // A red square of side 0.5 (two triangles) and a blue unit square fanned from its centre, far apart: at
  // cell size 2 each collapses to one point, sized over its distinct corners (core/mesh.h): red 2·r with r
  // = 0.25·sqrt(2), blue 2·(4·0.5·sqrt(2))/5 (the centre is a corner at distance 0).
  test::TempDir tmp;
  tmp.write("a.mtl", kMtl);
  const std::string input = tmp.write("a.obj",
                                      "mtllib a.mtl\nv 0 0 0\nv 0.5 0 0\nv 0.5 0.5 0\nv 0 0.5 0\n"
                                      "v 4 4 0\nv 5 4 0\nv 5 5 0\nv 4 5 0\nv 4.5 4.5 0\n"
                                      "usemtl red\nf 1 2 3\nf 1 3 4\n"
                                      "usemtl blue glass\nf 9 5 6\nf 9 6 7\nf 9 7 8\nf 9 8 5\n");
  const Result r = run(input, tmp.file("out"), {2}, false);
  ASSERT_TRUE(r.ok()) << r.message;
  const std::map<uint32_t, double> want{{1, 0.5 * std::sqrt(2.0)}, {2, 0.8 * std::sqrt(2.0)}};
  const core::LodMesh l = io::read_lod_mesh(tmp.file("out/lod0.ply"));
  ASSERT_EQ(l.point_count(), 2u);
  ASSERT_EQ(l.point_size.size(), 2u);
  ASSERT_EQ(l.point_materials.size(), 2u);
  for (size_t i = 0; i < 2; ++i) EXPECT_NEAR(l.point_size[i], want.at(l.point_materials[i]), 1e-6) << i;
  // GLB: one POINTS primitive per material, each with its own _SIZE accessor holding its point's size.
  const GlbFile glb = read_glb(tmp.file("out/lods.glb"));
  const Json& g = glb.json;
  const char* bin = glb.bin.data();
  const Json& prims = g["meshes"][0]["primitives"];
  ASSERT_EQ(prims.size(), 2u);
  for (const Json& p : prims) {
    EXPECT_EQ(p["mode"], 0);
    ASSERT_TRUE(p["attributes"].contains("_SIZE"));
    const Json& acc = g["accessors"][p["attributes"]["_SIZE"].get<int>()];
    ASSERT_EQ(acc["count"], 1);
    const Json& view = g["bufferViews"][acc["bufferView"].get<int>()];
    float size;
    std::memcpy(&size, bin + view["byteOffset"].get<size_t>() + acc.value("byteOffset", size_t{0}), 4);
    EXPECT_NEAR(size, want.at(p["material"].get<uint32_t>()), 1e-6);
  }
}

TEST(Materials, KeptPrimitiveTakesTheMaterialOfTheFirstInputPrimitiveInStoreOrder) {
  // The same triangle twice, blue first, then red in the other winding: one output triangle, blue. A thin
  // strip (red, then blue) collapses to one edge, red: the material of its first collapsing triangle.
  test::TempDir tmp;
  tmp.write("a.mtl", kMtl);
  const std::string input = tmp.write("b.obj",
                                      "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                      "v 10 0 0\nv 14 0 0\nv 14 0.25 0\nv 10 0.25 0\n"
                                      "usemtl blue glass\nf 1 2 3\nusemtl red\nf 1 3 2\nf 4 5 6\nusemtl blue glass\nf 4 6 7\n");
  const Result r = run(input, tmp.file("out"), {0.5});
  ASSERT_TRUE(r.ok()) << r.message;
  const Level l = read_ply(tmp.file("out/lod0.ply"));
  EXPECT_EQ(l.triangle_materials, (std::vector<uint32_t>{1}));  // ids: 0 default, 1 blue glass, 2 red
  // The strip: at cell size 0.5 its ends fall in two cells each... use a level where it is one edge.
  const Result c = run(input, tmp.file("coarse"), {2});
  ASSERT_TRUE(c.ok()) << c.message;
  const Level lc = read_ply(tmp.file("coarse/lod0.ply"));
  EXPECT_EQ(lc.edge_materials, (std::vector<uint32_t>{2}));
}

TEST(Materials, GltfMaterialsAreReadPerPrimitive) {
  // bench.gltf (tests/data/gltf): mesh 0 has primitives with materials 2 and 1, mesh 1 one with material 3.
  const std::string path = test::source_dir() + "/tests/data/gltf/bench.gltf";
  const test::ReadAll r = test::read_all(path, 1 << 20);
  ASSERT_EQ(r.materials.size(), 4u);  // every primitive names one: no default material appended
  EXPECT_EQ(r.materials[1].name, "darkGrey");
  EXPECT_EQ(r.materials[1].base_color[0], 0.3f);
  EXPECT_EQ(r.materials[1].metallic, 0.0f);
  EXPECT_EQ(r.materials[1].roughness, 0.99292892f);
  EXPECT_FALSE(r.materials[1].double_sided);  // the glTF default
  EXPECT_EQ(r.materials[2].name, "green");
  EXPECT_EQ(std::set<uint32_t>(r.triangle_materials.begin(), r.triangle_materials.end()), (std::set<uint32_t>{1, 2, 3}));
  ASSERT_EQ(r.triangle_materials.size(), r.triangles.size() / 3);
  test::expect_same(r, test::read_all(path, 4096), "small chunks");
}

// Two red vertices and a cyan one at the ends of a thin triangle strip, then a blue one: the PLY ascii and
// binary forms give the same colours (floats scaled by 255, integers clamped, no alpha = 255).
TEST(Colors, PlyVertexColoursAsciiAndBinary) {
  test::TempDir tmp;
  const std::string ascii = tmp.write("a.ply",
                                      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                      "property float z\nproperty uchar red\nproperty float green\nproperty int blue\n"
                                      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                      "0 0 0 255 0 300\n1 0 0 10 0.5 -4\n0 1 0 0 1 7\n3 0 1 2\n");
  const test::ReadAll a = test::read_all(ascii, 1 << 20);
  EXPECT_EQ(a.colors, (std::vector<uint8_t>{255, 0, 255, 255, 10, 128, 0, 255, 0, 255, 7, 255}));
  std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nproperty uchar red\nproperty float green\nproperty int blue\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const float xyz[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const uint8_t red[3] = {255, 10, 0};
  const float green[3] = {0, 0.5f, 1};
  const int32_t blue[3] = {300, -4, 7};
  for (int v = 0; v < 3; ++v) {
    bin.append(reinterpret_cast<const char*>(xyz[v]), 12);
    bin.append(reinterpret_cast<const char*>(&red[v]), 1);
    bin.append(reinterpret_cast<const char*>(&green[v]), 4);
    bin.append(reinterpret_cast<const char*>(&blue[v]), 4);
  }
  const uint8_t n = 3;
  const int32_t face[3] = {0, 1, 2};
  bin.append(reinterpret_cast<const char*>(&n), 1);
  bin.append(reinterpret_cast<const char*>(face), 12);
  const std::string binary = tmp.write("b.ply", bin);
  EXPECT_EQ(test::read_all(binary, 1 << 20).colors, a.colors);
  EXPECT_EQ(test::read_all(binary, 1).colors, a.colors);
}

// A glTF with one triangle per primitive: COLOR_0 as normalized unsigned byte VEC4, as float VEC3 (clamped,
// opaque), as normalized unsigned short VEC4, and a primitive without COLOR_0 (white).
std::string gltf_with_colors() {
  std::vector<uint8_t> bin;
  auto put = [&](const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    bin.insert(bin.end(), b, b + n);
  };
  const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  put(xyz, sizeof xyz);  // 0: positions, 36 bytes
  const uint8_t u8[12] = {255, 0, 0, 255, 0, 128, 0, 64, 1, 2, 3, 4};
  put(u8, sizeof u8);  // 36: 12 bytes
  const float f[9] = {0.5f, 2.0f, -1.0f, 0, 0, 1, 1, 1, 1};
  put(f, sizeof f);  // 48: 36 bytes
  const uint16_t u16[12] = {65535, 0, 32768, 65535, 0, 0, 0, 0, 257, 514, 771, 65535};
  put(u16, sizeof u16);  // 84: 24 bytes
  Json j;
  j["asset"] = {{"version", "2.0"}};
  j["buffers"] = Json::array({{{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + io::base64_encode(bin)}}});
  j["bufferViews"] = Json::array({{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}},
                                  {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 12}},
                                  {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 36}},
                                  {{"buffer", 0}, {"byteOffset", 84}, {"byteLength", 24}}});
  j["accessors"] = Json::array({{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"},
                                 {"min", {0, 0, 0}}, {"max", {1, 1, 0}}},
                                {{"bufferView", 1}, {"componentType", 5121}, {"normalized", true}, {"count", 3}, {"type", "VEC4"}},
                                {{"bufferView", 2}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
                                {{"bufferView", 3}, {"componentType", 5123}, {"normalized", true}, {"count", 3}, {"type", "VEC4"}}});
  Json prims = Json::array();
  for (int c : {1, 2, 3, -1}) {
    Json a = {{"POSITION", 0}};
    if (c >= 0) a["COLOR_0"] = c;
    prims.push_back({{"attributes", a}});
  }
  j["meshes"] = Json::array({{{"primitives", prims}}});
  j["nodes"] = Json::array({{{"mesh", 0}}});
  j["scenes"] = Json::array({{{"nodes", {0}}}});
  j["scene"] = 0;
  return j.dump();
}

TEST(Colors, GltfColor0InEveryAllowedForm) {
  test::TempDir tmp;
  const std::string path = tmp.write("c.gltf", gltf_with_colors());
  const test::ReadAll r = test::read_all(path, 1 << 20);
  EXPECT_EQ(r.colors, (std::vector<uint8_t>{255, 0, 0, 255, 0, 128, 0, 64, 1, 2, 3, 4,          // ubyte VEC4
                                            128, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 255,  // float VEC3
                                            255, 0, 128, 255, 0, 0, 0, 0, 1, 2, 3, 255,          // ushort VEC4
                                            255, 255, 255, 255, 255, 255, 255, 255, 255, 255, 255, 255}));
  test::expect_same(r, test::read_all(path, 1), "one-element chunks");
  Json bad = Json::parse(gltf_with_colors());
  bad["accessors"][1]["normalized"] = false;
  try {
    test::read_all(tmp.write("bad.gltf", bad.dump()), 1 << 20);
    ADD_FAILURE() << "a COLOR_0 of bytes not normalized was accepted";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::bad_data);
    EXPECT_NE(std::string(f.what()).find("/accessors/1"), std::string::npos) << f.what();
  }
}

TEST(Colors, PlyFaceColoursBecomeMaterialsInOrderOfFirstAppearance) {
  // Faces red, green (a quad: two triangles), red, and a two-index face in blue (a segment); an edge
  // element's segment takes material 0, the white default.
  const char* body = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n";
  test::TempDir tmp;
  const std::string ascii = tmp.write("a.ply", std::string("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                                           "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                                                           "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                                                           "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n") +
                                                   body + "3 0 1 2 255 0 0\n4 0 1 3 2 0 255 0\n3 1 3 2 255 0 0\n2 0 3 0 0 255\n0 3\n");
  const test::ReadAll a = test::read_all(ascii, 1 << 20);
  ASSERT_EQ(a.materials.size(), 4u);
  EXPECT_EQ(a.materials[0].name, "default");
  EXPECT_EQ(a.materials[1].name, "rgba_ff0000ff");
  EXPECT_EQ(a.materials[2].name, "rgba_00ff00ff");
  EXPECT_EQ(a.materials[3].name, "rgba_0000ffff");
  EXPECT_EQ(a.materials[2].base_color[1], 1.0f);
  EXPECT_EQ(a.triangle_materials, (std::vector<uint32_t>{1, 2, 2, 1}));
  EXPECT_EQ(a.line_materials, (std::vector<uint32_t>{3, 0}));
  test::expect_same(a, test::read_all(ascii, 1), "one-record chunks");
  // The same in binary, with float colours and an alpha.
  std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 2\nproperty float red\nproperty list uchar int vertex_indices\n"
                    "property float green\nproperty float blue\nproperty uchar alpha\nend_header\n";
  const float xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  bin.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
  auto face = [&](std::vector<int32_t> v, float r, float g, float b, uint8_t alpha) {
    bin.append(reinterpret_cast<const char*>(&r), 4);
    const uint8_t n = static_cast<uint8_t>(v.size());
    bin.append(reinterpret_cast<const char*>(&n), 1);
    bin.append(reinterpret_cast<const char*>(v.data()), 4 * v.size());
    bin.append(reinterpret_cast<const char*>(&g), 4);
    bin.append(reinterpret_cast<const char*>(&b), 4);
    bin.append(reinterpret_cast<const char*>(&alpha), 1);
  };
  face({0, 1, 2}, 1, 0.5f, 0, 128);
  face({1, 3, 2}, 1, 0.5f, 0, 128);
  const std::string binary = tmp.write("b.ply", bin);
  const test::ReadAll b = test::read_all(binary, 1);
  ASSERT_EQ(b.materials.size(), 2u);
  EXPECT_EQ(b.materials[1].name, "rgba_ff800080");
  EXPECT_EQ(b.materials[1].alpha, core::Material::Alpha::blend);
  EXPECT_EQ(b.triangle_materials, (std::vector<uint32_t>{1, 1}));
}

TEST(Materials, BaseColourTexturesBecomeTheirMeanColour) {
  // PNG: a red and a half-transparent blue texel; sRGB 255 is linear 1, 0 is 0, so the mean is
  // (0.5, 0, 0.5) and alpha (1 + 128/255) / 2.
  const std::vector<uint8_t> texels{255, 0, 0, 255, 0, 0, 255, 128};
  const std::vector<uint8_t> png = io::encode_png(texels, 2, 1, 4);
  float rgba[4];
  std::string error;
  ASSERT_TRUE(io::texture_mean_color(png, rgba, &error)) << error;
  EXPECT_NEAR(rgba[0], 0.5, 1e-6);
  EXPECT_NEAR(rgba[1], 0.0, 1e-6);
  EXPECT_NEAR(rgba[2], 0.5, 1e-6);
  EXPECT_NEAR(rgba[3], (1 + 128 / 255.0) / 2, 1e-6);
  // JPEG (tests/data/textures/orange-8x8.jpg, sRGB 255 128 0 at quality 100): linear (1, 0.2159, 0).
  const std::string jpeg_path = test::source_dir() + "/tests/data/textures/orange-8x8.jpg";
  const std::string jpeg = test::read_file(jpeg_path);
  ASSERT_TRUE(io::texture_file_mean_color(jpeg_path, rgba, &error)) << error;
  EXPECT_NEAR(rgba[0], 1.0, 0.01);
  EXPECT_NEAR(rgba[1], 0.2159, 0.01);
  EXPECT_NEAR(rgba[2], 0.0, 0.01);
  EXPECT_EQ(rgba[3], 1.0f);
  EXPECT_FALSE(io::texture_mean_color(std::vector<uint8_t>{1, 2, 3, 4}, rgba, &error));
  std::vector<uint8_t> broken = png;
  broken.resize(broken.size() / 2);
  EXPECT_FALSE(io::texture_mean_color(broken, rgba, &error));

  // glTF: material 0's texture is a PNG data URI, material 1's a JPEG in a bufferView, material 2's a file
  // that does not exist (factor alone).
  test::TempDir tmp;
  Json j = Json::parse(gltf_with_colors());
  std::vector<uint8_t> bin;
  ASSERT_TRUE(io::base64_decode(j["buffers"][0]["uri"].get<std::string>().substr(37), &bin));
  const uint64_t at = bin.size();
  bin.insert(bin.end(), jpeg.begin(), jpeg.end());
  j["buffers"][0] = {{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + io::base64_encode(bin)}};
  j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", jpeg.size()}});
  j["images"] = Json::array({{{"uri", "data:image/png;base64," + io::base64_encode(png)}},
                             {{"bufferView", 4}, {"mimeType", "image/jpeg"}},
                             {{"uri", "missing.png"}}});
  j["textures"] = Json::array({{{"source", 0}}, {{"source", 1}}, {{"source", 2}}});
  j["materials"] = Json::array();
  for (int t = 0; t < 3; ++t)
    j["materials"].push_back({{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 1, 1, 1}}, {"baseColorTexture", {{"index", t}}}}}});
  for (int p = 0; p < 3; ++p) j["meshes"][0]["primitives"][p]["material"] = p;
  const test::ReadAll r = test::read_all(tmp.write("t.gltf", j.dump()), 1 << 20);
  ASSERT_EQ(r.materials.size(), 4u);  // and the default, for the fourth primitive
  EXPECT_NEAR(r.materials[0].base_color[0], 0.25, 1e-6);
  EXPECT_NEAR(r.materials[0].base_color[3], (1 + 128 / 255.0) / 2, 1e-6);
  EXPECT_NEAR(r.materials[1].base_color[0], 0.5, 0.01);
  EXPECT_NEAR(r.materials[1].base_color[1], 0.2159, 0.01);
  EXPECT_EQ(r.materials[2].base_color[0], 0.5f);
  EXPECT_EQ(r.materials[2].base_color[1], 1.0f);

  // MTL: map_Kd with an option before the file name multiplies Kd; a missing file counts as white.
  std::filesystem::create_directories(tmp.path() / "tex");
  {
    std::ofstream f(tmp.path() / "tex" / "a.png", std::ios::binary);
    f.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  }
  tmp.write("m.mtl", "newmtl a\nmap_Kd -s 1 1 1 tex/a.png\nKd 0.5 0.5 0.5\nnewmtl b\nKd 0.5 0.5 0.5\nmap_Kd none.jpg\n");
  const test::ReadAll o = test::read_all(
      tmp.write("m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\n"), 1 << 20);
  ASSERT_EQ(o.materials.size(), 3u);
  EXPECT_EQ(o.materials[1].name, "a");
  EXPECT_NEAR(o.materials[1].base_color[0], 0.25, 1e-6);
  EXPECT_NEAR(o.materials[1].base_color[1], 0.0, 1e-6);
  EXPECT_EQ(o.materials[1].base_color[3], 1.0f);  // d gives the opacity, not the texture
  EXPECT_EQ(o.materials[2].base_color[0], 0.5f);
}

TEST(Materials, KicadBoardKeepsItsVrmlColoursThroughSimplify) {
  // tests/data/gltf/kicad-board.glb (tools/make_kicad_board.py): 6 KiCad components instanced 26 times on
  // a board, one primitive per VRML material, the VRML diffuse colours as base colours.
  const std::string path = test::source_dir() + "/tests/data/gltf/kicad-board.glb";
  const test::ReadAll r = test::read_all(path, 1 << 20);
  EXPECT_EQ(r.triangles.size() / 3, 12432u);
  ASSERT_EQ(r.materials.size(), 9u);
  EXPECT_EQ(r.materials[3].name, "RES-SMD-01");
  EXPECT_EQ(r.materials[3].base_color[0], 0.082f);
  EXPECT_EQ(std::set<uint32_t>(r.triangle_materials.begin(), r.triangle_materials.end()).size(), 9u);
  test::expect_same(r, test::read_all(path, 4096), "small chunks");
  // The finest level (cells of 0.05 mm, below the models' detail) keeps every material; the coarsest
  // (5 mm: the board and a few blobs) keeps the board's green on most of its triangles.
  test::TempDir tmp;
  const Result res = run(path, tmp.file("out"), {0.05, 5}, false);
  ASSERT_TRUE(res.ok()) << res.message;
  const Level fine = read_ply(tmp.file("out/lod0.ply"));
  EXPECT_EQ(std::set<uint32_t>(fine.triangle_materials.begin(), fine.triangle_materials.end()).size(), 9u);
  const Level coarse = read_ply(tmp.file("out/lod1.ply"));
  ASSERT_FALSE(coarse.triangle_materials.empty());
  const size_t green = static_cast<size_t>(std::count(coarse.triangle_materials.begin(), coarse.triangle_materials.end(), 0u));
  EXPECT_GT(green, 0u);
  const Json g = glb_json(tmp.file("out/lods.glb"));
  ASSERT_EQ(g["materials"].size(), 9u);
  EXPECT_EQ(g["materials"][0]["name"], "FR4");
}

// The vertices of an OBJ level written with colours (`v x y z r g b`): x, y and the colour as 0..255.
struct ObjVertex {
  double x, y;
  std::array<int, 3> second;
};
std::vector<ObjVertex> obj_vertices(const std::string& path) {
  std::vector<ObjVertex> out;
  std::istringstream in(test::read_file(path));
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("v ", 0) != 0) continue;
    std::istringstream v(line.substr(2));
    double x, y, z, r, g, b;
    v >> x >> y >> z >> r >> g >> b;
    out.push_back({x, y, {static_cast<int>(std::lround(r * 255)), static_cast<int>(std::lround(g * 255)),
                          static_cast<int>(std::lround(b * 255))}});
  }
  return out;
}

TEST(Colors, CellColourIsWeightedAsTheRepresentative) {
  // A red triangle far from a thin one whose close vertices b0 = (5,0,0) blue and b1 = (5.01,0,0) cyan
  // share a cell at cell size 0.5 (the third, (5,1,0) blue, has a cell of its own). The merged cell's
  // colour follows its representative: center, the colour of the center vertex (the one at the
  // representative's position); mean, the grade-weighted mean with the position's weights, so with
  // t = (x - 5) / 0.01 the weight of b1, green = 255 t; quadric, the plain mean, green 127.5 -> 128.
  test::TempDir tmp;
  const std::string input = tmp.write("c.ply",
                                      "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                                      "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                                      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                                      "0 0 0 255 0 0\n1 0 0 255 0 0\n0 1 0 255 0 0\n"
                                      "5 0 0 0 0 255\n5.01 0 0 0 255 255\n5 1 0 0 0 255\n3 0 1 2\n3 3 4 5\n");
  for (Representative rep : {Representative::center, Representative::mean, Representative::quadric}) {
    SCOPED_TRACE(static_cast<int>(rep));
    SimplifyOptions so;
    so.output_dir = tmp.file("out" + std::to_string(static_cast<int>(rep)));
    so.representative = rep;
    so.cell_sizes = {0.5};
    so.write_obj = true;
    Options o;
    o.threads = 1;
    SimplifyReport report;
    const Result r = simplify(input, so, o, &report);
    ASSERT_TRUE(r.ok()) << r.message;
    const auto v = obj_vertices(so.output_dir + "/lod0.obj");
    ASSERT_EQ(v.size(), 5u);  // the red triangle's three vertices and the edge's two ends (in region order)
    std::vector<ObjVertex> far;
    for (const ObjVertex& x : v)
      if (x.x < 2) EXPECT_EQ(x.second, (std::array<int, 3>{255, 0, 0}));
      else far.push_back(x);
    ASSERT_EQ(far.size(), 2u);
    // The edge's two ends: the lone vertex (5,1,0), its cell's center, and the merged cell's (y 0).
    const ObjVertex& merged = far[0].y < 0.5 ? far[0] : far[1];
    const ObjVertex& lone = &merged == &far[0] ? far[1] : far[0];
    EXPECT_EQ(lone.second, (std::array<int, 3>{0, 0, 255}));
    if (rep == Representative::center) {
      EXPECT_TRUE(merged.x == 5.0 || std::abs(merged.x - 5.01) < 1e-6) << merged.x;
      EXPECT_EQ(merged.second, (std::array<int, 3>{0, merged.x == 5.0 ? 0 : 255, 255}));
    } else if (rep == Representative::mean) {
      const double t = (merged.x - 5) / 0.01;
      EXPECT_NEAR(merged.second[1], 255 * t, 0.5 + 255 * 1e-4) << merged.x;
      EXPECT_EQ(merged.second[2], 255);
    } else {
      EXPECT_EQ(merged.second, (std::array<int, 3>{0, 128, 255}));
    }
  }
}

TEST(Colors, LevelPlyReadsBackWithItsColoursAndMaterials) {
  // What the report reads: a level PLY as io/ply_writer.cpp writes it, colours and materials included.
  core::LodMesh m;
  m.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 2, 2};
  m.triangles = {0, 1, 2};
  m.edges = {1, 3};
  m.thickness = {0.25f};
  m.points = {3};
  m.colors = {255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 10, 20, 30, 40};
  m.materials.resize(3);
  m.materials[1].name = "red paint";
  m.materials[1].base_color[1] = 0.5f;
  m.materials[2].alpha = core::Material::Alpha::blend;
  m.materials[2].base_color[3] = 0.25f;
  m.triangle_materials = {2}, m.edge_materials = {1}, m.point_materials = {0};
  m.point_size = {0.5f};
  test::TempDir tmp;
  io::write_ply(tmp.file("l.ply"), m, {"test"});
  const core::LodMesh r = io::read_lod_mesh(tmp.file("l.ply"));
  EXPECT_EQ(r.point_size, m.point_size);
  EXPECT_EQ(r.colors, m.colors);
  EXPECT_EQ(r.materials, m.materials);
  EXPECT_EQ(r.triangle_materials, m.triangle_materials);
  EXPECT_EQ(r.edge_materials, m.edge_materials);
  EXPECT_EQ(r.point_materials, m.point_materials);
  EXPECT_EQ(core::convention_violation(r), "");
  // One colour per primitive: the material's base colour times the mean of the vertex colours.
  const uint8_t* v[3] = {&m.colors[0], &m.colors[4], &m.colors[8]};
  uint8_t rgb[3];
  core::primitive_rgb(v, 3, &m.materials[1], rgb);
  EXPECT_EQ(rgb[0], 85);   // (255 + 0 + 0) / 3
  EXPECT_EQ(rgb[1], 43);   // 255 / 3 * 0.5 = 42.5, rounded up
  EXPECT_EQ(rgb[2], 85);
  core::primitive_rgb(nullptr, 3, nullptr, rgb);
  EXPECT_EQ(rgb[0], 255);
}

TEST(Colors, RenderedPixelsTakeTheColourOfThePrimitiveHit) {
  // A unit square of two triangles, red and blue, seen from above: the report's ViewImage::color.
  core::RayScene scene;
  const std::vector<float> xyz = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
  const std::vector<uint32_t> tris = {0, 1, 2, 0, 2, 3};
  scene.add_triangles(xyz, tris);
  scene.set_colors({255, 0, 0, 0, 0, 255});
  scene.commit();
  const double eye[3] = {0, 0, 5}, target[3] = {0, 0, 0};
  const core::Camera cam = core::look_at(eye, target, 30, 64);
  core::ViewImage v;
  const core::RayScene* scenes[] = {&scene};
  core::cast_view(scenes, cam, &v);
  ASSERT_EQ(v.color.size(), 3u * 64 * 64);
  std::set<std::array<uint8_t, 3>> seen;
  for (uint64_t p = 0; p < 64 * 64; ++p) {
    const std::array<uint8_t, 3> c{v.color[3 * p], v.color[3 * p + 1], v.color[3 * p + 2]};
    if (v.covered(p)) seen.insert(c);
    else EXPECT_EQ(c, (std::array<uint8_t, 3>{255, 255, 255}));
  }
  EXPECT_EQ(seen, (std::set<std::array<uint8_t, 3>>{{255, 0, 0}, {0, 0, 255}}));
  // A scene without colours leaves the image without them.
  core::RayScene plain;
  plain.add_triangles(xyz, tris);
  plain.commit();
  const core::RayScene* plain_scenes[] = {&plain};
  core::cast_view(plain_scenes, cam, &v);
  EXPECT_TRUE(v.color.empty());
}

TEST(Materials, InputsWithoutMaterialsWriteNoMaterialFields) {
  test::TempDir tmp;
  const std::string input = tmp.write("p.obj", "mtllib none.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  ASSERT_TRUE(run(input, tmp.file("out"), {0.1}).ok());
  const std::string ply = test::read_file(tmp.file("out/lod0.ply"));
  EXPECT_EQ(ply.find("material"), std::string::npos);
  EXPECT_EQ(test::read_file(tmp.file("out/lod0.obj")).find("mtllib"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(tmp.file("out/lod0.mtl")));
  const Json g = glb_json(tmp.file("out/lods.glb"));
  EXPECT_EQ(g["materials"].size(), 1u);
}

}  // namespace
}  // namespace lodstream

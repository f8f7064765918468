// Materials through the pipeline (issue 16.2): OBJ usemtl/MTL in, the kept-material rule of the emit stage
// (stream/emit_stage.h), and the writers' material outputs read back: PLY material_index and its comment
// table, OBJ usemtl with its MTL file, GLB one primitive per material with the glTF material table.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

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
  for (uint64_t i = 0; i < points; ++i) p += 4, l.point_materials.push_back(u32());
  EXPECT_EQ(p, bytes.data() + bytes.size());
  return l;
}

Json glb_json(const std::string& path) {
  const std::string bytes = test::read_file(path);
  uint32_t n;
  std::memcpy(&n, bytes.data() + 12, 4);
  return Json::parse(bytes.substr(20, n));
}

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

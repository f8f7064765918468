// Whole-file LOD reader (io/lod_reader.h): exact round trips through the project's PLY and OBJ writers,
// hand-made ascii and big-endian PLY files with other elements, other properties and polygons, OBJ with
// every corner form, and every error path with its status and location.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/lod_reader.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"
#include "test_util.h"

namespace lodstream::test {
namespace {

using core::LodMesh;

// Bit patterns, so that -0.0, denormals and NaN payloads would all be told apart.
std::vector<uint32_t> bits(const std::vector<float>& v) {
  std::vector<uint32_t> b(v.size());
  std::transform(v.begin(), v.end(), b.begin(), [](float f) { return std::bit_cast<uint32_t>(f); });
  return b;
}

// Two triangles on vertices 0..3, two edges of different thickness sharing vertex 4, two points (5, 0).
// Coordinates that short decimals do not hold, a denormal and a negative zero.
LodMesh small_level() {
  LodMesh m;
  m.positions = {0.0f,   0.0f,        0.0f,     //
                 1.0f,   1e-40f,      0.0f,     //
                 0.0f,   1.0f,        -0.0f,    //
                 1.0f,   1.0f,        0.1f,     //
                 2.0f,   0.3f,        -0.5f,    //
                 -1e-7f, 3.14159274f, 1.5e10f};
  m.triangles = {1, 3, 2, 0, 1, 2};
  m.edges = {3, 4, 4, 1};
  m.thickness = {0.25f, 1.0f / 3.0f};
  m.points = {5, 0};
  m.point_size = {0.75f, 0.0f};
  return m;
}

void expect_same(const LodMesh& want, const LodMesh& got, bool thickness = true) {
  EXPECT_EQ(bits(want.positions), bits(got.positions));
  EXPECT_TRUE(got.normals.empty());
  EXPECT_EQ(want.triangles, got.triangles);
  EXPECT_EQ(want.edges, got.edges);
  if (thickness) EXPECT_EQ(bits(want.thickness), bits(got.thickness));
  else EXPECT_EQ(std::vector<float>(want.edge_count(), 0.0f), got.thickness);
  EXPECT_EQ(want.points, got.points);
  if (thickness) EXPECT_EQ(bits(want.point_size), bits(got.point_size));
  else EXPECT_TRUE(got.point_size.empty());  // OBJ's p has no size
  EXPECT_EQ("", core::convention_violation(got));
}

// Expects read_lod_mesh(path) to fail with `status` and a message holding the path and every fragment.
void expect_failure(const std::string& path, Status status, const std::vector<std::string>& fragments) {
  try {
    (void)io::read_lod_mesh(path);
    ADD_FAILURE() << path << ": no failure";
  } catch (const Failure& f) {
    EXPECT_EQ(status_name(status), std::string(status_name(f.status()))) << f.what();
    const std::string m = f.what();
    EXPECT_NE(m.find(path), std::string::npos) << m;
    for (const std::string& s : fragments) EXPECT_NE(m.find(s), std::string::npos) << "'" << s << "' not in: " << m;
  }
}

// Binary PLY bytes in either byte order.
struct Bytes {
  bool big_endian = false;
  std::string s;
  template <class T>
  Bytes& put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof v);
    if (big_endian) std::reverse(b, b + sizeof v);
    s.append(b, sizeof v);
    return *this;
  }
};

// ------------------------------------------------------------------------------------ round trips

TEST(LodReader, PlyWriterRoundTripIsExact) {
  TempDir dir;
  const LodMesh m = small_level();
  const std::string path = dir.file("lod.ply");
  io::write_ply(path, m, {"a comment", "another"});
  io::LodFileStats st;
  expect_same(m, io::read_lod_mesh(path, &st));
  EXPECT_EQ("ply-binary-le", st.format);
  EXPECT_EQ(2u, st.faces);
  EXPECT_EQ(0u, st.degenerate_triangles + st.degenerate_edges + st.skipped);

  // With normals (x y z nx ny nz): the normals are skipped, the rest is the same.
  LodMesh with_normals = m;
  with_normals.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0};
  io::write_ply(path, with_normals, {});
  expect_same(m, io::read_lod_mesh(path));

  // An empty level: every element present with count 0.
  io::write_ply(path, LodMesh{}, {});
  expect_same(LodMesh{}, io::read_lod_mesh(path));
}

TEST(LodReader, ObjWriterRoundTripIsExact) {
  TempDir dir;
  const LodMesh m = small_level();
  const std::string path = dir.file("lod.obj");
  io::write_obj(path, m, {"made by test_lod_reader"});
  io::LodFileStats st;
  expect_same(m, io::read_lod_mesh(path, &st), /*thickness=*/false);  // OBJ has no thickness
  EXPECT_EQ("obj", st.format);
  LodMesh with_normals = m;
  with_normals.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0};
  io::write_obj(path, with_normals, {});  // f a//a b//b c//c and vn lines
  expect_same(m, io::read_lod_mesh(path, &st), false);
  EXPECT_EQ(6u, st.skipped);  // the vn lines
}

// ------------------------------------------------------------------------------------ PLY variants

TEST(LodReader, AsciiPlyWithOtherElementsPropertiesAndPolygons) {
  TempDir dir;
  const std::string path = dir.write("a.ply",
                                     "ply\r\n"
                                     "format ascii 1.0\r\n"
                                     "comment faces first, vertices later, things to skip in between\r\n"
                                     "element face 3\r\n"
                                     "property uchar flags\r\n"
                                     "property list uint8 int32 vertex_index\r\n"
                                     "property list uchar float uv\r\n"
                                     "element material 2\r\n"
                                     "property list int uchar name\r\n"
                                     "element vertex 5\r\n"
                                     "property double x\r\n"
                                     "property uchar red\r\n"
                                     "property float32 y\r\n"
                                     "property short z\r\n"
                                     "property list uchar int tags\r\n"
                                     "element edge 2\r\n"
                                     "property int vertex2\r\n"
                                     "property int vertex1\r\n"
                                     "element point 1\r\n"
                                     "property ushort vertex\r\n"
                                     "end_header\r\n"
                                     "7 4 0 1 2 3 2 0.5 0.5\r\n"   // a quad: (0 1 2) (0 2 3)
                                     "0 5 4 3 2 1 0 0\r\n"         // a pentagon: (4 3 2) (4 2 1) (4 1 0)
                                     "\r\n"                        // blank lines are allowed
                                     "1 3 0 1 1 0\r\n"             // (0 1 1) is degenerate: dropped
                                     "3 65 66 67\r\n"
                                     "0\r\n"
                                     "0.5 255 1.5 -3 0\r\n"
                                     "1e3 0 -2.25 7 2 1 2\r\n"
                                     "  0.1 1 0.2 0 0\r\n"
                                     "-0 2 3.4028235e38 -32768 0\r\n"
                                     "1 3 1 1 0\r\n"
                                     "4 3\r\n"
                                     "2 2\r\n"                     // an edge on one vertex: dropped
                                     "4\r\n"
                                     "\r\n");
  io::LodFileStats st;
  const LodMesh m = io::read_lod_mesh(path, &st);
  EXPECT_EQ("ply-ascii", st.format);
  EXPECT_EQ(bits({0.5f, 1.5f, -3, 1e3f, -2.25f, 7, 0.1f, 0.2f, 0, -0.0f, 3.4028235e38f, -32768, 1, 1, 1}),
            bits(m.positions));
  EXPECT_EQ((std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 4, 3, 2, 4, 2, 1, 4, 1, 0}), m.triangles);
  EXPECT_EQ((std::vector<uint32_t>{3, 4}), m.edges);  // vertex1 = 3, vertex2 = 4
  EXPECT_EQ((std::vector<float>{0}), m.thickness);
  EXPECT_EQ((std::vector<uint32_t>{4}), m.points);
  EXPECT_EQ(3u, st.faces);
  EXPECT_EQ(1u, st.degenerate_triangles);
  EXPECT_EQ(1u, st.degenerate_edges);
  EXPECT_EQ(2u, st.skipped);
  EXPECT_EQ("", core::convention_violation(m));
}

TEST(LodReader, BigEndianPlyWithOtherElementsPropertiesAndPolygons) {
  TempDir dir;
  Bytes b{true, {}};
  // vertex: int8 x, double y, uint16 z, list uchar float extra, float nx
  b.put<int8_t>(-1).put<double>(0.1).put<uint16_t>(65535).put<uint8_t>(2).put<float>(7).put<float>(8).put<float>(0);
  b.put<int8_t>(2).put<double>(-2.5).put<uint16_t>(1).put<uint8_t>(0).put<float>(1);
  b.put<int8_t>(3).put<double>(1e-300).put<uint16_t>(2).put<uint8_t>(1).put<float>(9).put<float>(1);
  b.put<int8_t>(4).put<double>(4).put<uint16_t>(3).put<uint8_t>(0).put<float>(1);
  // junk: fixed-size records of an element nobody knows
  b.put<double>(1).put<int16_t>(2).put<double>(3).put<int16_t>(4);
  // face: list ushort uint vertex_indices, int material
  b.put<uint16_t>(4).put<uint32_t>(3).put<uint32_t>(2).put<uint32_t>(1).put<uint32_t>(0).put<int32_t>(-7);
  b.put<uint16_t>(3).put<uint32_t>(0).put<uint32_t>(1).put<uint32_t>(3).put<int32_t>(1);
  b.put<uint16_t>(2).put<uint32_t>(1).put<uint32_t>(2).put<int32_t>(1);  // two indices: an edge
  // edge: uchar vertex1, short vertex2, double thickness, list int int weights
  b.put<uint8_t>(0).put<int16_t>(3).put<double>(0.125).put<int32_t>(1).put<int32_t>(5);
  b.put<uint8_t>(2).put<int16_t>(3).put<double>(2).put<int32_t>(0);
  // point: uint vertex
  b.put<uint32_t>(3).put<uint32_t>(0);
  const std::string header =
      "ply\nformat binary_big_endian 1.0\n"
      "element vertex 4\nproperty int8 x\nproperty double y\nproperty uint16 z\n"
      "property list uchar float extra\nproperty float nx\n"
      "element junk 2\nproperty float64 a\nproperty short b\n"
      "element face 3\nproperty list ushort uint vertex_indices\nproperty int material\n"
      "element edge 2\nproperty uchar vertex1\nproperty short vertex2\nproperty double thickness\n"
      "property list int int weights\n"
      "element point 2\nproperty uint vertex\n"
      "end_header\n";
  const std::string path = dir.write("be.ply", header + b.s);
  io::LodFileStats st;
  const LodMesh m = io::read_lod_mesh(path, &st);
  EXPECT_EQ("ply-binary-be", st.format);
  EXPECT_EQ(bits({-1, 0.1f, 65535, 2, -2.5f, 1, 3, static_cast<float>(1e-300), 2, 4, 4, 3}), bits(m.positions));
  EXPECT_EQ((std::vector<uint32_t>{3, 2, 1, 3, 1, 0, 0, 1, 3}), m.triangles);
  EXPECT_EQ((std::vector<uint32_t>{1, 2, 0, 3, 2, 3}), m.edges);
  EXPECT_EQ((std::vector<float>{0, 0.125f, 2}), m.thickness);
  EXPECT_EQ((std::vector<uint32_t>{3, 0}), m.points);
  EXPECT_EQ(3u, st.faces);
  EXPECT_EQ(2u, st.skipped);
  EXPECT_EQ("", core::convention_violation(m));
}

// ------------------------------------------------------------------------------------------- OBJ

TEST(LodReader, ObjWithEveryCornerFormPolylinesPointsAndRelativeIndices) {
  TempDir dir;
  const std::string path = dir.write("m.OBJ",
                                     "# a comment\n"
                                     "mtllib m.mtl\n"
                                     "o first\n"
                                     "v 0 0 0\n"
                                     "v 1 0 0 1.0\n"            // w ignored
                                     "v 1 1 0 0.5 0.5 0.5\r\n"  // colour ignored, CRLF
                                     "v +0 1 \\\n 0\n"          // continued on the next line
                                     "vt 0 0\nvn 0 0 1\n"
                                     "usemtl red\n"
                                     "f 1 2 3 4\n"                   // quad: (0 1 2) (0 2 3)
                                     "f 1/1 2/1 3/1\n"
                                     "f 1//1 -3//1 -2//1 # comment\n"  // (0 1 2)
                                     "f -4/1/1 2/1/1 4/1/1\n"        // (0 1 3)
                                     "f 1 1 2\n"                     // degenerate: dropped
                                     "f 3 4\n"                       // two corners: an edge
                                     "l 1 2 3 3 5\n"                 // forward reference to vertex 5
                                     "p 4 -1\n"
                                     "g group\ns off\n"
                                     "v 2 2 2\n"
                                     "p 5\n");
  io::LodFileStats st;
  const LodMesh m = io::read_lod_mesh(path, &st);
  EXPECT_EQ("obj", st.format);
  EXPECT_EQ((std::vector<float>{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 2, 2, 2}), m.positions);
  EXPECT_EQ((std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 1, 2, 0, 1, 3}), m.triangles);
  EXPECT_EQ((std::vector<uint32_t>{2, 3, 0, 1, 1, 2, 2, 4}), m.edges);
  EXPECT_EQ((std::vector<float>{0, 0, 0, 0}), m.thickness);
  EXPECT_EQ((std::vector<uint32_t>{3, 3, 4}), m.points);
  EXPECT_EQ(6u, st.faces);
  EXPECT_EQ(1u, st.degenerate_triangles);
  EXPECT_EQ(1u, st.degenerate_edges);  // l ... 3 3 ...
  EXPECT_EQ(7u, st.skipped);           // mtllib o vt vn usemtl g s
  EXPECT_EQ("", core::convention_violation(m));
}

// ------------------------------------------------------------------------------------------ errors

TEST(LodReaderErrors, MissingUnreadableOrUnknown) {
  TempDir dir;
  expect_failure(dir.file("absent.ply"), Status::no_input, {"cannot open"});
  expect_failure(dir.path().string(), Status::no_input, {"cannot open", "directory"});
  expect_failure(dir.write("lod.stl", "solid x\nendsolid x\n"), Status::usage, {"unsupported LOD format"});
  expect_failure(dir.write("lod.glb", "glTF"), Status::usage, {"unsupported LOD format"});
  expect_failure(dir.write("lod.ply", "PLY\n"), Status::bad_data, {"byte 0", "not a PLY file"});
  expect_failure(dir.write("empty.ply", ""), Status::bad_data, {"byte 0", "empty file"});
}

TEST(LodReader, BinaryElementWithoutPropertiesTakesNoBytes) {
  // Found by review: an empty element without properties once divided by its zero record size.
  TempDir dir;
  const std::string ply = std::string("ply\nformat binary_little_endian 1.0\nelement empty 0\nelement vertex 1\n") +
                          "property float x\nproperty float y\nproperty float z\nend_header\n" + std::string(12, '\0');
  const core::LodMesh m = io::read_lod_mesh(dir.write("e.ply", ply));
  EXPECT_EQ(m.vertex_count(), 1u);
  EXPECT_EQ(m.positions, std::vector<float>(3, 0.0f));
}

TEST(LodReaderErrors, TruncatedBinaryBody) {
  TempDir dir;
  const std::string full = [&] {
    io::write_ply(dir.file("full.ply"), small_level(), {});
    return io::read_small_file(dir.file("full.ply"));
  }();
  const size_t header = full.find("end_header\n") + 11;
  // Vertices 6 x 12, faces 2 x 13, edges 2 x 12, points 2 x 8 bytes.
  const size_t faces = header + 72, last_face = faces + 13, edges = faces + 26, points = edges + 24;
  ASSERT_EQ(points + 16, full.size());
  // The last point loses its last byte: found while reading, at the record's first byte.
  expect_failure(dir.write("t1.ply", full.substr(0, full.size() - 1)), Status::bad_data,
                 {"byte " + std::to_string(points + 8), "truncated", "inside record 2 of 2 of element 'point'"});
  // Cut inside the second face (its list is longer than what is left): the header counts no longer fit
  // the bytes, caught before anything is read.
  expect_failure(dir.write("t2.ply", full.substr(0, last_face + 5)), Status::bad_data,
                 {":", "element 'edge' declares 2 records", "truncated or the count is wrong"});
  // The counts fit their minimum sizes but a face list runs past the end of the file.
  std::string lying = full;
  lying[last_face] = 100;  // the second face claims 100 indices
  expect_failure(dir.write("t3.ply", lying), Status::bad_data,
                 {"byte " + std::to_string(last_face), "inside record 2 of 2 of element 'face'"});
  // Bytes after the last element.
  expect_failure(dir.write("t4.ply", full + "x"), Status::bad_data, {"byte " + std::to_string(full.size()), "after the last element"});
}

TEST(LodReaderErrors, IndexOutOfRange) {
  TempDir dir;
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\n";
  const std::string verts = "0 0 0\n1 0 0\n0 1 0\n";
  const std::string faces = "element face 2\nproperty list uchar int vertex_indices\n";
  expect_failure(dir.write("f.ply", head + faces + "end_header\n" + verts + "3 0 1 2\n4 0 1 2 3\n"), Status::bad_data,
                 {":14:", "vertex index 3 out of range in record 2 of 2 of element 'face': the file has 3 vertices"});
  expect_failure(dir.write("fneg.ply", head + faces + "end_header\n" + verts + "3 0 -1 2\n3 0 1 2\n"), Status::bad_data,
                 {":13:", "vertex index -1 out of range in record 1 of 2 of element 'face'"});
  expect_failure(dir.write("e.ply", head + "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                                    "property float thickness\nend_header\n" + verts + "0 7 0.5\n"),
                 Status::bad_data, {":15:", "vertex index 7 out of range in record 1 of 1 of element 'edge'"});
  expect_failure(dir.write("p.ply", head + "element point 1\nproperty uint vertex\nend_header\n" + verts + "3\n"),
                 Status::bad_data, {":13:", "vertex index 3 out of range in record 1 of 1 of element 'point'"});
  // Binary: at the record's first byte.
  LodMesh m = small_level();
  io::write_ply(dir.file("b.ply"), m, {});
  std::string b = io::read_small_file(dir.file("b.ply"));
  const size_t faces_at = b.find("end_header\n") + 11 + 72;
  const uint32_t bad = 6;
  std::memcpy(&b[faces_at + 13 + 1 + 4], &bad, 4);
  expect_failure(dir.write("b2.ply", b), Status::bad_data,
                 {"byte " + std::to_string(faces_at + 13), "vertex index 6 out of range in record 2 of 2 of element 'face'"});
  // OBJ: relative before the first vertex, zero, past the last vertex (first such line in file order).
  expect_failure(dir.write("r.obj", "v 0 0 0\nv 1 0 0\nf 1 2 -3\n"), Status::bad_data,
                 {":3:", "relative vertex index -3 reaches before the first vertex"});
  expect_failure(dir.write("z.obj", "v 0 0 0\nl 0 1\n"), Status::bad_data, {":2:", "vertex index 0"});
  expect_failure(dir.write("past.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\np 9\nf 1 2 5\n"), Status::bad_data,
                 {":5:", "vertex index 9 is past the last vertex (the file has 3 vertices)"});
}

TEST(LodReaderErrors, BadHeader) {
  TempDir dir;
  expect_failure(dir.write("fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n"), Status::bad_data,
                 {":2:", "unknown PLY format"});
  expect_failure(dir.write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"),
                 Status::bad_data, {":5:", "no end_header"});
  expect_failure(dir.write("novertex.ply", "ply\nformat ascii 1.0\nelement face 0\n"
                                           "property list uchar int vertex_indices\nend_header\n"),
                 Status::bad_data, {":5:", "no element 'vertex'"});
  expect_failure(dir.write("noz.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                                      "end_header\n"),
                 Status::bad_data, {":3:", "no property 'z'"});
  expect_failure(dir.write("type.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty real x\nend_header\n"),
                 Status::bad_data, {":4:", "unknown property type 'real'"});
  expect_failure(dir.write("findex.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                                         "property float y\nproperty float z\nelement face 0\n"
                                         "property list uchar float vertex_indices\nend_header\n"),
                 Status::bad_data, {":7:", "integer type"});
  expect_failure(dir.write("bin.ply", std::string("ply\nformat binary_little_endian 1.0\nelement vertex 1\n\x01\x02\n")),
                 Status::bad_data, {":4:", "binary data in the PLY header"});
  // A count the file cannot hold fails before anything is allocated.
  expect_failure(dir.write("huge.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n"
                                       "property float x\nproperty float y\nproperty float z\nend_header\n" +
                                           std::string(24, '\0')),
                 Status::bad_data, {":3:", "4000000000 records", "truncated or the count is wrong"});
}

TEST(LodReaderErrors, BadValues) {
  TempDir dir;
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                           "property float z\nend_header\n";
  expect_failure(dir.write("word.ply", head + "0 0 0\n1 abc 0\n"), Status::bad_data,
                 {":9:", "bad value for property 'y' (float) in record 2 of 2 of element 'vertex': 'abc'"});
  expect_failure(dir.write("few.ply", head + "0 0 0\n10 20\n"), Status::bad_data, {":9:", "too few values"});
  expect_failure(dir.write("extra.ply", head + "0 0 0 9\n1 2 3\n"), Status::bad_data, {":8:", "extra values"});
  // Too short for the count by the header's own measure (2 records of 3 values need 11 bytes), or only by
  // reading: both name the vertex element.
  expect_failure(dir.write("short.ply", head + "0 0 0\n"), Status::bad_data, {":3:", "element 'vertex' declares 2"});
  expect_failure(dir.write("short2.ply", head + "0.000 0.000 0\n"), Status::bad_data,
                 {":9:", "truncated: the file ends before record 2 of 2 of element 'vertex'"});
  expect_failure(dir.write("nan.ply", head + "0 0 0\nnan 0 0\n"), Status::bad_data, {":9:", "not finite"});
  expect_failure(dir.write("after.ply", head + "0 0 0\n1 2 3\n\n4\n"), Status::bad_data, {":11:", "after the last element"});
  // A double that a float cannot hold.
  expect_failure(dir.write("big.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\n"
                                      "property double z\nend_header\n0 1e300 0\n"),
                 Status::bad_data, {":8:", "not finite as a float"});
  // A negative thickness; a byte value out of range for its type.
  expect_failure(dir.write("neg.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                                      "property float z\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n"
                                      "property float thickness\nend_header\n0 0 0\n1 1 1\n0 1 -0.5\n"),
                 Status::bad_data, {":14:", "thickness -0.5 is negative"});
  expect_failure(dir.write("range.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty uchar x\nproperty uchar y\n"
                                        "property uchar z\nend_header\n1 256 0\n"),
                 Status::bad_data, {":8:", "value out of range for property 'y' (uchar)"});
  // Binary: a non-finite coordinate at its record's byte.
  Bytes b;
  b.put<float>(0).put<float>(0).put<float>(0).put<float>(1).put<float>(std::numeric_limits<float>::infinity()).put<float>(0);
  const std::string bh = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                         "property float z\nend_header\n";
  expect_failure(dir.write("inf.ply", bh + b.s), Status::bad_data, {"byte " + std::to_string(bh.size() + 12), "not finite"});
  // OBJ.
  expect_failure(dir.write("v.obj", "v 0 0 0\nv 1 x 0\n"), Status::bad_data, {":2:", "bad vertex coordinate 'x'"});
  expect_failure(dir.write("v2.obj", "v 0 0\n"), Status::bad_data, {":1:", "vertex has 2 coordinates, needs 3"});
  expect_failure(dir.write("inf.obj", "v 0 0 1e39\n"), Status::bad_data, {":1:", "not finite"});
  expect_failure(dir.write("f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 a\n"), Status::bad_data,
                 {":5:", "bad vertex reference 'a' in 'f' statement"});
  expect_failure(dir.write("f1.obj", "v 0 0 0\nf 1\n"), Status::bad_data, {":2:", "face with 1 corner"});
  expect_failure(dir.write("l1.obj", "v 0 0 0\nl 1\n"), Status::bad_data, {":2:", "line with 1 vertex"});
  expect_failure(dir.write("p0.obj", "v 0 0 0\np\n"), Status::bad_data, {":2:", "point statement without vertices"});
  expect_failure(dir.write("nul.obj", std::string("v 0 0 0\nvt 0 \0 1\n", 17)), Status::bad_data,
                 {":2:", "binary data in a text file (byte 0x00)"});
  expect_failure(dir.write("nul2.obj", std::string("v 0 0 0\n# \x01\n", 12)), Status::bad_data,
                 {":2:", "binary data in a text file (byte 0x01)"});
}

}  // namespace
}  // namespace lodstream::test

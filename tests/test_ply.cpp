// PLY reader tests: generated ascii and binary files with every type, extra properties, other elements,
// polygons and edges; identical results for every chunk size; malformed files; the shared KiCad sample.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/status.h"
#include "io/reader.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream::test {
namespace {

// ------------------------------------------------------------------------------------ PLY writer

enum class Fmt { ascii, le, be };

const char* fmt_name(Fmt f) {
  switch (f) {
    case Fmt::ascii: return "ascii";
    case Fmt::le: return "binary_little_endian";
    case Fmt::be: return "binary_big_endian";
  }
  return "";
}

struct Prop {
  std::string type;        // scalar type, or the list's item type
  std::string name;
  std::string count_type;  // empty: scalar
};

// One record: per property, its values (one for a scalar, the items for a list).
using Record = std::vector<std::vector<double>>;

struct Elem {
  std::string name;
  std::vector<Prop> props;
  std::vector<Record> records;
};

size_t type_size(const std::string& t) {
  if (t == "char" || t == "int8" || t == "uchar" || t == "uint8") return 1;
  if (t == "short" || t == "int16" || t == "ushort" || t == "uint16") return 2;
  if (t == "double" || t == "float64") return 8;
  return 4;
}

bool is_float(const std::string& t) { return t == "float" || t == "float32" || t == "double" || t == "float64"; }

void put(std::string* out, const std::string& t, double v, bool be) {
  char b[8];
  const size_t n = type_size(t);
  if (t == "float" || t == "float32") {
    const float f = static_cast<float>(v);
    std::memcpy(b, &f, 4);
  } else if (t == "double" || t == "float64") {
    std::memcpy(b, &v, 8);
  } else {
    const int64_t i = static_cast<int64_t>(v);
    std::memcpy(b, &i, n);  // little-endian host: the low bytes
  }
  if (be) std::reverse(b, b + n);
  out->append(b, n);
}

std::string number(const std::string& t, double v) {
  if (!is_float(t)) return std::to_string(static_cast<int64_t>(v));
  if (std::isnan(v)) return "nan";
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

std::string header(Fmt f, const std::vector<Elem>& elems, const std::string& eol = "\n") {
  std::string h = "ply" + eol + "format " + fmt_name(f) + " 1.0" + eol + "comment made by test_ply" + eol;
  for (const Elem& e : elems) {
    h += "element " + e.name + " " + std::to_string(e.records.size()) + eol;
    for (const Prop& p : e.props) {
      if (p.count_type.empty()) h += "property " + p.type + " " + p.name + eol;
      else h += "property list " + p.count_type + " " + p.type + " " + p.name + eol;
    }
  }
  return h + "end_header" + eol;
}

std::string body(Fmt f, const std::vector<Elem>& elems, const std::string& eol = "\n") {
  std::string d;
  for (const Elem& e : elems) {
    for (const Record& r : e.records) {
      std::string line;
      for (size_t k = 0; k < e.props.size(); ++k) {
        const Prop& p = e.props[k];
        if (f == Fmt::ascii) {
          auto word = [&line](const std::string& w) {
            if (!line.empty()) line.push_back(' ');
            line.append(w);
          };
          if (!p.count_type.empty()) word(std::to_string(r[k].size()));
          for (double v : r[k]) word(number(p.type, v));
        } else {
          if (!p.count_type.empty()) put(&d, p.count_type, static_cast<double>(r[k].size()), f == Fmt::be);
          for (double v : r[k]) put(&d, p.type, v, f == Fmt::be);
        }
      }
      if (f == Fmt::ascii) d += line + eol;
    }
  }
  return d;
}

std::string ply(Fmt f, const std::vector<Elem>& elems, const std::string& eol = "\n") {
  return header(f, elems, eol) + body(f, elems, eol);
}

// ------------------------------------------------------------------------------------ models

const std::vector<std::vector<double>> kPositions = {{0, 0, 0},      {1, 0, 0},  {1, 1, 0},     {0, 1, 0},
                                                     {0.5, 1.5, 0.25}, {-2, 3, 4.5}, {1024, -0.0009765625, 7}};

// 7 vertices with properties before, between and after x y z (one a per-vertex list); an unknown element
// between vertex and face; triangle, quad and pentagon faces with properties around the index list; an
// edge element; an unknown element at the end.
std::vector<Elem> rich_model(const std::string& coord, const std::string& count, const std::string& index) {
  Elem v{"vertex",
         {{"uchar", "red", ""},
          {coord, "x", ""},
          {"float", "nx", ""},
          {coord, "y", ""},
          {"short", "extras", "uchar"},
          {coord, "z", ""},
          {"double", "w", ""}},
         {}};
  for (size_t i = 0; i < kPositions.size(); ++i) {
    const auto& p = kPositions[i];
    std::vector<double> extras(i % 3, -7.0);
    v.records.push_back({{double(i * 30)}, {p[0]}, {0.5}, {p[1]}, extras, {p[2]}, {2.25}});
  }
  Elem material{"material", {{"float", "shine", ""}, {"int", "ids", "uchar"}}, {{{1.5}, {1, 2}}, {{2.5}, {}}}};
  Elem face{"face", {{"int", "flag", ""}, {index, "vertex_indices", count}, {"float", "q", ""}}, {}};
  face.records.push_back({{1}, {0, 1, 2}, {0.5}});
  face.records.push_back({{2}, {0, 1, 2, 3}, {0.5}});
  face.records.push_back({{3}, {1, 2, 3, 4, 5}, {0.5}});
  face.records.push_back({{4}, {6, 5, 4}, {0.5}});
  Elem edge{"edge", {{index, "vertex1", ""}, {index, "vertex2", ""}, {"uchar", "red", ""}}, {}};
  edge.records.push_back({{0}, {6}, {255}});
  edge.records.push_back({{3}, {4}, {0}});
  Elem tail{"tristrips", {{"int", "vertex_indices", "int"}}, {{{0, 1, 2, 3}}}};
  return {v, material, face, edge, tail};
}

struct Expected {
  std::vector<double> positions;
  std::vector<int64_t> triangles, lines;
  uint64_t polygons = 0, skipped = 0;
};

Expected rich_expected() {
  Expected e;
  for (const auto& p : kPositions) e.positions.insert(e.positions.end(), p.begin(), p.end());
  e.triangles = {0, 1, 2, 0, 1, 2, 0, 2, 3, 1, 2, 3, 1, 3, 4, 1, 4, 5, 6, 5, 4};
  e.lines = {0, 6, 3, 4};
  e.polygons = 4;
  e.skipped = 3;  // two materials, one tristrip
  return e;
}

void expect_result(const ReadAll& r, const Expected& e, const std::string& what) {
  EXPECT_EQ(r.positions, e.positions) << what;
  EXPECT_EQ(r.triangles, e.triangles) << what;
  EXPECT_EQ(r.lines, e.lines) << what;
  EXPECT_EQ(r.polygons, e.polygons) << what;
  EXPECT_EQ(r.skipped, e.skipped) << what;
  EXPECT_EQ(r.triangle_objects, std::vector<uint32_t>(e.triangles.size() / 3, 0)) << what;
  EXPECT_EQ(r.line_objects, std::vector<uint32_t>(e.lines.size() / 2, 0)) << what;
  EXPECT_TRUE(r.points.empty()) << what;
  EXPECT_FALSE(r.soup) << what;
}

bool same(const ReadAll& a, const ReadAll& b) {
  return a.positions == b.positions && a.triangles == b.triangles && a.lines == b.lines && a.points == b.points &&
         a.triangle_objects == b.triangle_objects && a.line_objects == b.line_objects && a.polygons == b.polygons &&
         a.skipped == b.skipped && a.format == b.format;
}

// Every chunk size from 1 to the file size gives the same result.
void expect_every_target_same(const std::string& path, const ReadAll& reference) {
  const uint64_t size = std::filesystem::file_size(path);
  for (uint64_t t = 1; t <= size + 1; ++t) {
    const ReadAll r = read_all(path, t);
    ASSERT_TRUE(same(r, reference)) << path << " differs at target_bytes " << t;
  }
}

// The Failure read_all raises, which must be bad_data and name the path and `where`.
std::string expect_bad_data(const std::string& path, const std::string& where, const std::string& words,
                            uint64_t target = 1 << 20) {
  try {
    read_all(path, target);
  } catch (const Failure& f) {
    const std::string m = f.what();
    EXPECT_EQ(f.status(), Status::bad_data) << m;
    EXPECT_NE(m.find(path), std::string::npos) << m;
    EXPECT_NE(m.find(where), std::string::npos) << "expected '" << where << "' in: " << m;
    EXPECT_NE(m.find(words), std::string::npos) << "expected '" << words << "' in: " << m;
    return m;
  }
  ADD_FAILURE() << path << ": no error (expected " << words << ")";
  return {};
}

// ------------------------------------------------------------------------------------ tests

TEST(PlyReader, RichModelEveryFormat) {
  TempDir dir;
  const Expected want = rich_expected();
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* coord : {"float", "double"}) {
      const std::string path = dir.write(std::string("rich-") + fmt_name(f) + "-" + coord + ".ply",
                                         ply(f, rich_model(coord, "uchar", "int")));
      const ReadAll r = read_all(path, 1 << 20);
      EXPECT_EQ(r.format, f == Fmt::ascii ? "ply-ascii" : f == Fmt::le ? "ply-binary-le" : "ply-binary-be");
      expect_result(r, want, path);
      expect_every_target_same(path, r);
    }
  }
}

TEST(PlyReader, EveryCountAndIndexType) {
  TempDir dir;
  const Expected want = rich_expected();
  int n = 0;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* count : {"uchar", "uint8", "char", "ushort", "short", "int", "uint"}) {
      for (const char* index : {"char", "int8", "uchar", "short", "ushort", "int", "int32", "uint", "uint32"}) {
        const std::string path = dir.write("t" + std::to_string(n++) + ".ply", ply(f, rich_model("float", count, index)));
        const std::string what = std::string(fmt_name(f)) + " list " + count + " " + index;
        const ReadAll r = read_all(path, 1 << 20);
        expect_result(r, want, what);
        for (uint64_t t : {1, 2, 5, 13, 64, 200})
          ASSERT_TRUE(same(read_all(path, t), r)) << what << " target " << t;
      }
    }
  }
}

TEST(PlyReader, TypeAliasesAndCoordinateTypes) {
  TempDir dir;
  // Coordinates of integer types, mixed types, and the sized type names.
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    Elem v{"vertex", {{"int16", "z", ""}, {"float64", "y", ""}, {"int32", "x", ""}, {"uint8", "flags", ""}}, {}};
    v.records.push_back({{3}, {-2.5}, {-7}, {1}});
    v.records.push_back({{-3}, {1e10}, {40000}, {2}});
    v.records.push_back({{0}, {0.125}, {0}, {3}});
    Elem face{"face", {{"uint16", "vertex_index", "uint8"}}, {{{{2, 1, 0}}}}};
    const std::string path = dir.write(std::string("types-") + fmt_name(f) + ".ply", ply(f, {v, face}));
    const ReadAll r = read_all(path, 1 << 20);
    EXPECT_EQ(r.positions, (std::vector<double>{-7, -2.5, 3, 40000, 1e10, -3, 0, 0.125, 0}));
    EXPECT_EQ(r.triangles, (std::vector<int64_t>{2, 1, 0}));
    expect_every_target_same(path, r);
  }
}

TEST(PlyReader, PlainTrianglesFastPath) {
  // The common layout (float x y z, list uchar int|uint) in both byte orders, with a quad among triangles
  // and element counts large enough for many chunks.
  TempDir dir;
  for (Fmt f : {Fmt::le, Fmt::be, Fmt::ascii}) {
    for (const char* index : {"int", "uint"}) {
      Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
      Elem face{"face", {{index, "vertex_indices", "uchar"}}, {}};
      Expected e;
      const int n = 40;
      for (int i = 0; i < n; ++i) {
        const double x = i * 0.5, y = -i, z = i * 0.25 + 1;
        v.records.push_back({{x}, {y}, {z}});
        e.positions.insert(e.positions.end(), {x, y, z});
      }
      for (int i = 0; i + 3 < n; ++i) {
        if (i % 7 == 3) {
          face.records.push_back({{double(i), double(i + 1), double(i + 2), double(i + 3)}});
          e.triangles.insert(e.triangles.end(), {i, i + 1, i + 2, i, i + 2, i + 3});
        } else {
          face.records.push_back({{double(i + 2), double(i), double(i + 1)}});
          e.triangles.insert(e.triangles.end(), {i + 2, i, i + 1});
        }
        ++e.polygons;
      }
      const std::string path = dir.write(std::string("plain-") + fmt_name(f) + index + ".ply", ply(f, {v, face}));
      const ReadAll r = read_all(path, 1 << 20);
      expect_result(r, e, path);
      expect_every_target_same(path, r);
    }
  }
}

TEST(PlyReader, FacesRepeatingAVertex) {
  // As in OBJ (io::add_face): (a, b, b) is the segment a-b, (a, b, b, c) the triangle (a, b, c), (d, d, d)
  // nothing; the quad of distinct vertices is the fan placeholder of a planar face. Every format and the
  // fast path (list uchar int|uint).
  TempDir dir;
  for (Fmt f : {Fmt::le, Fmt::be, Fmt::ascii}) {
    for (const char* index : {"int", "uint", "ushort"}) {
      Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
      for (const auto& p : {std::vector<double>{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}})
        v.records.push_back({{p[0]}, {p[1]}, {p[2]}});
      Elem face{"face", {{index, "vertex_indices", "uchar"}}, {}};
      face.records = {{{0, 1, 1}}, {{0, 1, 1, 2}}, {{3, 3, 3}}, {{0, 1, 2, 3}}, {{2, 3, 0}}};
      const std::string path = dir.write(std::string("repeat-") + fmt_name(f) + index + ".ply", ply(f, {v, face}));
      SCOPED_TRACE(path);
      const ReadAll r = read_all(path, 1 << 20);
      EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 0, 1, 2, 0, 2, 3, 2, 3, 0}));
      EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 1}));
      EXPECT_EQ(r.polygons, 5u);
      EXPECT_EQ(r.degenerate, 3u);
      EXPECT_EQ(r.face_segments, 1u);
      EXPECT_EQ(r.planar_faces, 1u);
      expect_every_target_same(path, r);
    }
  }
}

TEST(PlyReader, FacesBeforeVerticesAndEmptyElements) {
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le}) {
    Elem face{"face", {{"int", "vertex_indices", "uchar"}}, {{{{0, 1, 2}}}}};
    Elem empty{"material", {{"float", "a", ""}}, {}};
    Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
    for (int i = 0; i < 3; ++i) v.records.push_back({{double(i)}, {0}, {1}});
    const std::string path = dir.write(std::string("order-") + fmt_name(f) + ".ply", ply(f, {face, empty, v}));
    const ReadAll r = read_all(path, 1 << 20);
    EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 1, 1, 0, 1, 2, 0, 1}));
    EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
    expect_every_target_same(path, r);
  }
  // No faces at all, and no records at all.
  const std::string pts = dir.write("points.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                                  "property float y\nproperty float z\nend_header\n1 2 3\n");
  EXPECT_EQ(read_all(pts, 1).positions, (std::vector<double>{1, 2, 3}));
  const std::string none = dir.write("none.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 0\n"
                                                 "property float x\nproperty float y\nproperty float z\n"
                                                 "element face 0\nproperty list uchar int vertex_indices\nend_header\n");
  const ReadAll r = read_all(none, 1);
  EXPECT_TRUE(r.positions.empty());
  EXPECT_TRUE(r.triangles.empty());
}

TEST(PlyReader, AsciiCrlfWhitespaceAndBlankLines) {
  TempDir dir;
  const std::string text =
      "ply\r\nformat ascii 1.0\r\ncomment crlf\r\nobj_info x\r\nelement vertex 3\r\nproperty float x\r\n"
      "property float y\r\nproperty float z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\n"
      "end_header\r\n  0\t0  0  \r\n\r\n1 0 +0\r\n   \r\n0 1e0 -0.5\r\n3 0 1 2\r\n\r\n  \n";
  const std::string path = dir.write("crlf.ply", text);
  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 0, 1, -0.5}));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
  expect_every_target_same(path, r);
  // A binary file whose header uses CRLF line ends.
  Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {{{1}, {2}, {3}}}};
  const std::string bin = dir.write("crlf-bin.ply", ply(Fmt::le, {v}, "\r\n"));
  EXPECT_EQ(read_all(bin, 1).positions, (std::vector<double>{1, 2, 3}));
}

TEST(PlyReader, LargeFilesLongRecordsAndLongHeader) {
  // Files larger than the splitter's read-ahead window, records longer than it (a face of 3000 vertices,
  // an ascii line of 20 KB), and a header longer than the first 64 KB mapped.
  TempDir dir;
  std::string comments;
  for (int i = 0; i < 2000; ++i) comments += "comment " + std::string(50, 'a' + i % 26) + "\n";
  for (Fmt f : {Fmt::le, Fmt::be, Fmt::ascii}) {
    for (const char* count : {"uchar", "uint"}) {
      const int n = 6000;
      Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
      for (int i = 0; i < n; ++i) v.records.push_back({{double(i)}, {double(i % 7)}, {-1}});
      Elem face{"face", {{"int", "vertex_indices", count}}, {}};
      uint64_t triangles = 0;
      for (int i = 0; i + 5 < n; i += 3) {
        const int m = 3 + i % 4;  // triangles to hexagons
        std::vector<double> idx;
        for (int j = 0; j < m; ++j) idx.push_back(i + j);
        face.records.push_back({idx});
        triangles += m - 2;
      }
      if (std::string(count) == "uint") {
        std::vector<double> big;
        for (int j = 0; j < 3000; ++j) big.push_back(j);
        face.records.push_back({big});
        triangles += 2998;
      }
      std::string text = ply(f, {v, face});
      text.insert(text.find("element vertex"), comments);
      const std::string path = dir.write(std::string("large-") + fmt_name(f) + count + ".ply", text);
      ASSERT_GT(text.size(), 150000u);
      const ReadAll r = read_all(path, 1 << 20);
      EXPECT_EQ(r.vertex_count(), uint64_t(n));
      EXPECT_EQ(r.triangles.size(), 3 * triangles);
      EXPECT_EQ(r.polygons, face.records.size());
      EXPECT_EQ(r.positions[3 * 4321], 4321.0);
      for (uint64_t t : {1, 100, 4095, 4096, 9999, 65537}) {
        const ReadAll c = read_all(path, t);
        ASSERT_TRUE(same(c, r)) << path << " target " << t;
      }
    }
  }
}

TEST(PlyReader, ParseIsThreadSafe) {
  // Cut every chunk first, parse them on several threads at once, resolve in order: same result.
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    const std::string path = dir.write(std::string("mt-") + fmt_name(f) + ".ply", ply(f, rich_model("float", "uchar", "int")));
    const ReadAll want = read_all(path, 1 << 20);
    expect_same(want, read_parallel(path, 3, 4), fmt_name(f));
  }
}

// ------------------------------------------------------------------------------------ malformed

std::vector<Elem> small_model(const std::string& count = "uchar", const std::string& index = "int") {
  Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
  for (int i = 0; i < 4; ++i) v.records.push_back({{double(i)}, {1}, {2}});
  Elem face{"face", {{index, "vertex_indices", count}}, {{{{0, 1, 2}}}, {{{0, 2, 3}}}, {{{1, 2, 3}}}}};
  return {v, face};
}

constexpr const char* kHeadXyz = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                 "property float z\n";

TEST(PlyMalformed, TruncatedVertexData) {
  TempDir dir;
  // Fixed-size vertex records: the header's count cannot fit, caught before any data is read.
  std::string b = ply(Fmt::le, small_model());
  const size_t header_size = header(Fmt::le, small_model()).size();
  b.resize(header_size + 30);
  expect_bad_data(dir.write("tv.ply", b), ":4:", "truncated");
  // Vertex records with a list (variable size): found by the splitter, reported at the record's byte.
  Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}, {"int", "l", "uchar"}}, {}};
  for (int i = 0; i < 3; ++i) v.records.push_back({{1}, {2}, {3}, {1, 2}});
  std::string vb = ply(Fmt::le, {v});
  const size_t hs = header(Fmt::le, {v}).size();
  vb.resize(vb.size() - 3);
  const std::string p2 = dir.write("tv2.ply", vb);
  for (uint64_t t : {1, 7, 21, 1000})
    expect_bad_data(p2, "byte " + std::to_string(hs + 2 * 21), "inside record 3 of 3 of element 'vertex'", t);
  // Ascii: the file ends early.
  const std::string a = dir.write("tv3.ply", std::string(kHeadXyz).replace(std::string(kHeadXyz).find("vertex 1"), 8, "vertex 3") +
                                                 "end_header\n1.5 2.5 3.5\n4.5 5.5 6.5\n");
  for (uint64_t t : {1, 5, 1000}) expect_bad_data(a, ":10:", "ends before record 3 of 3 of element 'vertex'", t);
}

TEST(PlyMalformed, TruncatedFaceList) {
  TempDir dir;
  std::string b = ply(Fmt::le, small_model());
  const size_t hs = header(Fmt::le, small_model()).size();
  b.resize(b.size() - 2);  // the last face loses part of its last index
  const std::string path = dir.write("tf.ply", b);
  const std::string last_face = std::to_string(hs + 4 * 12 + 2 * 13);
  for (uint64_t t = 1; t <= b.size(); ++t) expect_bad_data(path, "byte " + last_face, "truncated", t);
  // The file ends exactly between two faces.
  b.resize(b.size() - 11);
  expect_bad_data(dir.write("tf2.ply", b), "byte " + last_face, "ends before record 3 of 3 of element 'face'");
  // Big-endian, generic layout (ushort count).
  std::string be = ply(Fmt::be, small_model("ushort", "uint"));
  be.resize(be.size() - 1);
  expect_bad_data(dir.write("tf3.ply", be), "byte ", "inside record 3 of 3 of element 'face'", 5);
  // An element after the faces that is cut short must be caught too.
  auto m = small_model();
  m.push_back(Elem{"material", {{"double", "a", ""}}, {{{1.0}}, {{2.0}}}});
  std::string t = ply(Fmt::le, m);
  t.resize(t.size() - 4);
  expect_bad_data(dir.write("tf4.ply", t), "byte " + std::to_string(t.size() - 4), "element 'material'", 3);
}

TEST(PlyMalformed, HugeCountFailsFast) {
  TempDir dir;
  std::string body_bytes(1000, '\0');
  for (const char* fmt : {"binary_little_endian", "ascii"}) {
    for (const char* elem : {"vertex", "face"}) {
      std::string h = std::string("ply\nformat ") + fmt + " 1.0\nelement vertex " +
                      (std::string(elem) == "vertex" ? "3000000000" : "3") +
                      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                      (std::string(elem) == "face" ? "3000000000" : "1") +
                      "\nproperty list uchar int vertex_indices\nend_header\n";
      std::string data = std::string(fmt) == "ascii" ? std::string(500, '1') : body_bytes;
      const std::string path = dir.write(std::string("huge-") + fmt + elem + ".ply", h + data);
      const auto t0 = std::chrono::steady_clock::now();
      expect_bad_data(path, std::string(elem) == "vertex" ? ":3:" : ":7:", "3000000000 records");
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      EXPECT_LT(s, 0.5) << "must fail before reading the data";
    }
  }
  // A list count of 4 billion in a face record: a truncation, not an allocation.
  std::string b = header(Fmt::le, small_model("uint", "int"));
  Elem v = small_model()[0];
  b += body(Fmt::le, {v});
  const uint64_t face_at = b.size();
  b += std::string("\xff\xff\xff\xff", 4) + std::string(40, '\0');
  expect_bad_data(dir.write("hugelist.ply", b), "byte " + std::to_string(face_at), "truncated");
}

TEST(PlyMalformed, IndexOutOfRange) {
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* index : {"int", "uint", "ushort"}) {
      auto m = small_model("uchar", index);
      m[1].records[1][0] = {0, 4, 3};
      const std::string path = dir.write(std::string("oor-") + fmt_name(f) + index + ".ply", ply(f, m));
      const std::string where =
          f == Fmt::ascii ? ":16:" : "byte " + std::to_string(header(f, m).size() + 48 + 1 + 3 * type_size(index));
      for (uint64_t t : {1, 20, 1000}) expect_bad_data(path, where, "vertex index 4 out of range: the file has 4 vertices", t);
    }
  }
  // Edges are checked too.
  Elem e{"edge", {{"int", "vertex1", ""}, {"int", "vertex2", ""}}, {{{0}, {9}}}};
  auto m = small_model();
  m.push_back(e);
  expect_bad_data(dir.write("edge.ply", ply(Fmt::le, m)), "byte ", "edge vertex index 9 out of range");
}

TEST(PlyMalformed, NegativeIndex) {
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* index : {"int", "char", "short"}) {
      auto m = small_model("uchar", index);
      m[1].records[2][0] = {1, -1, 3};
      const std::string path = dir.write(std::string("neg-") + fmt_name(f) + index + ".ply", ply(f, m));
      const std::string where =
          f == Fmt::ascii ? ":17:" : "byte " + std::to_string(header(f, m).size() + 48 + 2 * (1 + 3 * type_size(index)));
      expect_bad_data(path, where, "vertex index -1 out of range");
    }
  }
  // A negative list count (signed count type).
  auto m = small_model("char", "int");
  std::string b = ply(Fmt::le, m);
  const size_t at = header(Fmt::le, m).size() + 48 + 13;
  b[at] = static_cast<char>(-3);
  expect_bad_data(dir.write("negcount.ply", b), "byte " + std::to_string(at), "negative list count", 1);
  auto m2 = small_model("short", "int");
  std::string b2 = ply(Fmt::le, m2);
  const size_t at2 = header(Fmt::le, m2).size() + 48 + 14;
  b2[at2 + 1] = static_cast<char>(0xff);
  for (uint64_t t : {1, 14, 100}) expect_bad_data(dir.write("negcount2.ply", b2), "byte " + std::to_string(at2), "negative list count", t);
}

TEST(PlyMalformed, NanCoordinate) {
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* coord : {"float", "double"}) {
      auto m = small_model();
      m[0].props[1].type = coord;
      m[0].records[2][1] = {std::numeric_limits<double>::quiet_NaN()};
      const std::string path = dir.write(std::string("nan-") + fmt_name(f) + coord + ".ply", ply(f, m));
      const size_t rs = 8 + type_size(coord);
      const std::string where = f == Fmt::ascii ? ":13:" : "byte " + std::to_string(header(f, m).size() + 2 * rs);
      expect_bad_data(path, where, "vertex coordinate is not finite");
    }
  }
  const std::string inf = dir.write("inf.ply", std::string(kHeadXyz) + "end_header\n1 inf 2\n");
  expect_bad_data(inf, ":8:", "not finite");
  const std::string big = dir.write("big.ply", std::string(kHeadXyz) + "end_header\n1 1e39 2\n");  // overflows float
  expect_bad_data(big, ":8:", "not finite");
}

TEST(PlyMalformed, HeaderErrors) {
  TempDir dir;
  const std::string tail = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  struct Case {
    std::string text, where, words;
  };
  const std::vector<Case> cases = {
      {std::string(kHeadXyz) + "1 2 3\n", ":7:", "unknown PLY header line '1 2 3'"},
      {std::string(kHeadXyz), ":7:", "no end_header"},
      {"ply\nformat binary_middle_endian 1.0\n" + tail + "end_header\n", ":2:", "unknown PLY format"},
      {"ply\nformat ascii 2.0\n" + tail + "end_header\n", ":2:", "version"},
      {"ply\nformat ascii\n" + tail + "end_header\n", ":2:", "version"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty flaot x\nproperty float y\nproperty float z\nend_header\n1 2 3\n",
       ":4:", "unknown property type 'flaot'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar x\nend_header\n", ":4:", "property"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n", ":4:", "count type"},
      {"ply\nformat ascii 1.0\nelement vertex -1\n", ":3:", "bad element count"},
      {"ply\nformat ascii 1.0\nelement vertex\n", ":3:", "bad element line"},
      {"ply\nformat ascii 1.0\nproperty float x\n", ":3:", "property before any element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n", ":3:",
       "no property 'z'"},
      {"ply\nformat ascii 1.0\n" + tail + "element face 1\nproperty int foo\nend_header\n1 2 3\n1\n", ":7:",
       "vertex_indices"},
      {"ply\nformat ascii 1.0\n" + tail + "frobnicate 3\nend_header\n", ":7:", "unknown PLY header line"},
      {"ply\n" + tail + "end_header\n", ":2:", "element before the format line"},
      {"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n", ":5:",
       "no element 'vertex'"},
      {"ply\nformat ascii 1.0\n" + tail + "property float x\nend_header\n", ":7:", "second property named 'x'"},
      {"ply\nformat ascii 1.0 extra\n" + tail + "end_header\n", ":2:", "unexpected 'extra'"},
      {"ply\nformat ascii 1.0\n" + tail + "end_header\n1 2 3\n4 5 6\n", ":9:", "data after the last element"},
      {"ply\nformat ascii 1.0\n" + tail + "end_header\n1.5 2.5\n", ":8:", "too few values"},
      {"ply\nformat ascii 1.0\n" + tail + "end_header\n1 2 3 4\n", ":8:", "extra values"},
      {"ply\nformat ascii 1.0\n" + tail + "end_header\n1 2 x\n", ":8:", "bad value for property 'z'"},
  };
  int n = 0;
  for (const Case& c : cases) {
    const std::string path = dir.write("h" + std::to_string(n++) + ".ply", c.text);
    SCOPED_TRACE(c.text);
    expect_bad_data(path, c.where, c.words);
  }
  // Missing end_header over binary data.
  Elem v{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {{{1.5}, {2}, {3}}}};
  std::string h = header(Fmt::le, {v});
  h.resize(h.find("end_header"));
  expect_bad_data(dir.write("noend.ply", h + body(Fmt::le, {v})), ":8:", "end_header");
  std::string big_body;
  for (int i = 0; i < 20000; ++i) big_body += body(Fmt::le, {v});
  expect_bad_data(dir.write("noend-big.ply", h + big_body), ":8:", "end_header");
  // A ply file that does not start with 'ply' is refused by format detection.
  try {
    read_all(dir.write("x.ply", "plx\nformat ascii 1.0\n"), 1);
    ADD_FAILURE() << "no error";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::bad_data);
  }
}

TEST(PlyMalformed, AsciiHeaderOverBinaryData) {
  TempDir dir;
  const auto m = small_model();
  std::string h = header(Fmt::le, m);
  h.replace(h.find("binary_little_endian"), 20, "ascii");
  const std::string path = dir.write("lie.ply", h + body(Fmt::le, m));
  expect_bad_data(path, "byte ", "format ascii");
  // Binary bytes deep in an otherwise ascii file.
  std::string text = "ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\n"
                     "end_header\n";
  for (int i = 0; i < 999; ++i) text += "1 2 3\n";
  text += std::string("1 \x01\x02 3\n", 8);
  expect_bad_data(dir.write("lie2.ply", text), ":1007:", "binary data in an ascii PLY file");
}

TEST(PlyMalformed, FaceWithFewerThanTwoIndices) {
  TempDir dir;
  for (Fmt f : {Fmt::ascii, Fmt::le, Fmt::be}) {
    for (const char* count : {"uchar", "int"}) {
      auto m = small_model(count, "int");
      const size_t cs = type_size(count);
      const std::string where =
          f == Fmt::ascii ? ":16:" : "byte " + std::to_string(header(f, m).size() + 48 + cs + 12);
      m[1].records[1][0] = {};
      expect_bad_data(dir.write(std::string("zero-") + fmt_name(f) + count + ".ply", ply(f, m)), where,
                      "face with 0 vertices");
    }
  }
}

TEST(PlyMalformed, TrailingData) {
  TempDir dir;
  const std::string b = ply(Fmt::le, small_model());
  expect_bad_data(dir.write("trail.ply", b + "xyz"), "byte " + std::to_string(b.size()), "3 bytes after the last element");
  // Trailing whitespace after ascii data is fine.
  const std::string a = dir.write("trail-ok.ply", ply(Fmt::ascii, small_model()) + "\n  \n\t");
  EXPECT_EQ(read_all(a, 1).triangles.size(), 9u);
}

TEST(PlyMalformed, FirstErrorInFileOrder) {
  // A bad index early and a truncation at the end: the index is reported, whatever the chunk size.
  TempDir dir;
  auto m = small_model();
  m[1].records[0][0] = {0, 1, 77};
  std::string b = ply(Fmt::le, m);
  b.resize(b.size() - 1);
  const std::string path = dir.write("order.ply", b);
  for (uint64_t t = 1; t <= b.size(); ++t) expect_bad_data(path, "byte ", "vertex index 77", t);
}

// ------------------------------------------------------------------------------------ real data

// Triangle count of a binary little-endian PLY, walking its records directly.
uint64_t count_triangles_directly(const std::string& path, uint64_t* vertices) {
  std::ifstream in(path, std::ios::binary);
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t end_header = data.find("end_header\n");
  EXPECT_NE(end_header, std::string::npos);
  std::istringstream h(data.substr(0, end_header));
  struct P {
    bool list;
    size_t count_size, size;
    std::string name;
  };
  struct E {
    std::string name;
    uint64_t count;
    std::vector<P> props;
  };
  std::vector<E> elems;
  std::string line;
  while (std::getline(h, line)) {
    std::istringstream ls(line);
    std::string kw;
    ls >> kw;
    if (kw == "format") {
      std::string f;
      ls >> f;
      EXPECT_EQ(f, "binary_little_endian");
    } else if (kw == "element") {
      E e;
      ls >> e.name >> e.count;
      elems.push_back(e);
    } else if (kw == "property") {
      std::string t, t2, name;
      ls >> t;
      if (t == "list") {
        ls >> t >> t2 >> name;
        elems.back().props.push_back({true, type_size(t), type_size(t2), name});
      } else {
        ls >> name;
        elems.back().props.push_back({false, 0, type_size(t), name});
      }
    }
  }
  size_t at = end_header + 11;
  uint64_t triangles = 0;
  for (const E& e : elems) {
    if (e.name == "vertex") *vertices = e.count;
    for (uint64_t r = 0; r < e.count; ++r) {
      for (const P& p : e.props) {
        if (!p.list) {
          at += p.size;
          continue;
        }
        uint64_t n = 0;
        std::memcpy(&n, data.data() + at, p.count_size);
        at += p.count_size + n * p.size;
        if (e.name == "face" && (p.name == "vertex_indices" || p.name == "vertex_index")) triangles += n - 2;
      }
    }
  }
  EXPECT_EQ(at, data.size()) << path;
  return triangles;
}

TEST(PlySharedData, KicadSampleTriangleCounts) {
  LODSTREAM_REQUIRE_SHARED_DATA(shared);
  const std::filesystem::path dir = std::filesystem::path(shared) / "kicad-sample";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << "skipped: " << dir << " is absent";
  int files = 0;
  uint64_t total = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".ply") continue;
    const std::string path = entry.path().string();
    uint64_t vertices = 0;
    const uint64_t want = count_triangles_directly(path, &vertices);
    const ReadAll r = read_all(path, 1 << 16);
    EXPECT_EQ(r.format, "ply-binary-le") << path;
    EXPECT_EQ(r.triangles.size() / 3, want) << path;
    EXPECT_EQ(r.vertex_count(), vertices) << path;
    const ReadAll small = read_all(path, 4099);
    EXPECT_TRUE(same(small, r)) << path;
    total += want;
    ++files;
  }
  EXPECT_GT(files, 0);
  std::printf("[          ] %d KiCad PLY files, %llu triangles\n", files, static_cast<unsigned long long>(total));
}

}  // namespace
}  // namespace lodstream::test

namespace lodstream {
namespace {

// A two-index face is an edge, kept as a line segment like OBJ's two-corner faces; float x/y/z make the
// store single precision, double does not.
TEST(PlyReader, TwoIndexFaceIsALineSegmentAndPrecisionIsReported) {
  test::TempDir dir;
  for (const char* type : {"float", "double"}) {
    const std::string path = dir.write(std::string("e-") + type + ".ply",
                                       std::string("ply\nformat ascii 1.0\nelement vertex 3\nproperty ") + type +
                                           " x\nproperty " + type + " y\nproperty " + type +
                                           " z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                                           "0 0 0\n1 0 0\n0 1 0\n2 0 2\n3 0 1 2\n");
    const test::ReadAll r = test::read_all(path, 1);
    EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 2}));
    EXPECT_EQ(r.line_objects, (std::vector<uint32_t>{0}));
    EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
    EXPECT_EQ(r.polygons, 1u);
    io::MappedFile file(path);
    auto reader = io::open_reader(file);
    reader->open();
    EXPECT_EQ(reader->single_precision(), std::string(type) == "float");
  }
}


// The same for binary faces whose only property is `list uchar int` (the fast path), which used to
// refuse two-index faces ("face with 2 vertices (a face needs at least 2)").
TEST(PlyReader, BinaryTwoIndexFaceIsALineSegment) {
  test::TempDir dir;
  for (const char* item : {"int", "uint"}) {
    std::string data = std::string("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                                   "property float y\nproperty float z\nelement face 3\nproperty list uchar ") +
                       item + " vertex_indices\nend_header\n";
    const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    data.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
    auto face = [&](std::vector<int32_t> idx) {
      data += static_cast<char>(idx.size());
      data.append(reinterpret_cast<const char*>(idx.data()), 4 * idx.size());
    };
    face({0, 2});
    face({0, 1, 2});
    face({1, 2});
    const std::string path = dir.write(std::string("edge-") + item + ".ply", data);
    for (uint64_t chunk : {uint64_t(1), uint64_t(1) << 20}) {
      const test::ReadAll r = test::read_all(path, chunk);
      EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 2, 1, 2}));
      EXPECT_EQ(r.line_objects, (std::vector<uint32_t>{0, 0}));
      EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
      EXPECT_EQ(r.polygons, 1u);
    }
  }
}

}  // namespace
}  // namespace lodstream

// The STL reader (io/stl_reader.cpp), binary and ASCII, through the same chunk/parse/resolve sequence as
// the pipeline (tests/reader_harness.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "core/status.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

using test::read_all;
using test::ReadAll;
using test::TempDir;
using Facet = std::array<float, 9>;

void put_u32(std::string* s, uint32_t v) {
  for (int i = 0; i < 4; ++i) s->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void put_f32(std::string* s, float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  put_u32(s, u);
}

// A binary STL: `header` padded to 80 bytes, the count (the real one unless given), 50-byte records.
std::string binary_stl(const std::vector<Facet>& facets, std::string header = "lodstream test",
                       int64_t count = -1) {
  header.resize(80, '\0');
  std::string s = header;
  put_u32(&s, static_cast<uint32_t>(count < 0 ? static_cast<int64_t>(facets.size()) : count));
  for (const Facet& f : facets) {
    put_f32(&s, 0.f);
    put_f32(&s, 0.f);
    put_f32(&s, 1.f);
    for (float c : f) put_f32(&s, c);
    s.push_back('\x07');  // attribute bytes: ignored
    s.push_back('\x00');
  }
  return s;
}

std::vector<double> corners_of(const std::vector<Facet>& facets) {
  std::vector<double> v;
  for (const Facet& f : facets) v.insert(v.end(), f.begin(), f.end());
  return v;
}

// Reads with every target_bytes from 1 to past the file size and checks every result equals the first.
ReadAll read_every_way(const std::string& path) {
  const uint64_t size = std::filesystem::file_size(path);
  const ReadAll ref = read_all(path, 1);
  for (uint64_t target = 2; target <= size + 1; ++target) {
    const ReadAll r = read_all(path, target);
    SCOPED_TRACE("target_bytes " + std::to_string(target));
    EXPECT_EQ(r.format, ref.format);
    EXPECT_EQ(r.positions, ref.positions);
    EXPECT_EQ(r.triangle_objects, ref.triangle_objects);
    EXPECT_EQ(r.object_names, ref.object_names);
    EXPECT_EQ(r.polygons, ref.polygons);
    EXPECT_TRUE(r.triangles.empty() && r.lines.empty() && r.points.empty());
    if (::testing::Test::HasFailure()) break;
  }
  const ReadAll whole = read_all(path, size + 100);
  EXPECT_LE(whole.chunks, 1u) << "one chunk when the target exceeds the file";
  return ref;
}

// Expects Failure(bad_data) for every target_bytes (the same message each time); returns the message.
std::string failure_message(const std::string& path, bool every_target = true) {
  const uint64_t size = std::filesystem::file_size(path);
  std::string first;
  for (uint64_t target = every_target ? 1 : size + 1; target <= size + 1; ++target) {
    std::string msg;
    try {
      read_all(path, target);
      ADD_FAILURE() << path << " read without error at target_bytes " << target;
      return {};
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::bad_data) << f.what();
      msg = f.what();
    }
    if (first.empty()) first = msg;
    EXPECT_EQ(msg, first) << "target_bytes " << target;
    if (msg != first) break;
  }
  EXPECT_NE(first.find(path), std::string::npos) << first;
  return first;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// ------------------------------------------------------------------------------------------------------
// Binary

const std::vector<Facet> kFacets = {
    Facet{0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f},
    Facet{1.5f, -2.25f, 3.f, 1e-7f, 1e30f, -0.f, 7.f, 8.f, 9.f},
    Facet{0.1f, 0.2f, 0.3f, -1.f, -2.f, -3.f, 4.f, 5.f, 6.f},
};

TEST(StlBinary, ReadsCornersObjectsAndPolygons) {
  TempDir dir;
  const std::string path = dir.write("a.stl", binary_stl(kFacets));
  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.format, "stl-binary");
  EXPECT_TRUE(r.soup);
  EXPECT_EQ(r.positions, corners_of(kFacets));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 0, 0}));
  EXPECT_EQ(r.object_names, std::vector<std::string>{""});
  EXPECT_EQ(r.polygons, 3u);
  EXPECT_TRUE(r.triangles.empty() && r.lines.empty() && r.points.empty());
  EXPECT_EQ(r.chunks, 1u);
}

TEST(StlBinary, HeaderStartingWithSolidIsStillBinary) {
  TempDir dir;
  const std::string path = dir.write("solidhead.stl", binary_stl(kFacets, "solid exported by a CAD tool\nfacet"));
  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.format, "stl-binary");
  EXPECT_EQ(r.positions, corners_of(kFacets));
  EXPECT_EQ(r.polygons, 3u);
  // Without the .stl extension the "solid" start routes to the size check too.
  const std::string bare = dir.write("solidhead.bin", binary_stl(kFacets, "solid x"));
  EXPECT_EQ(read_all(bare, 1 << 20).format, "stl-binary");
}

TEST(StlBinary, EmptyFileWithZeroFacets) {
  TempDir dir;
  const ReadAll r = read_all(dir.write("zero.stl", binary_stl({})), 1);
  EXPECT_EQ(r.polygons, 0u);
  EXPECT_TRUE(r.positions.empty());
  EXPECT_EQ(r.object_names, std::vector<std::string>{""});
}

TEST(StlBinary, SameResultForEveryTargetBytes) {
  std::vector<Facet> facets;
  for (int i = 0; i < 9; ++i)
    facets.push_back(Facet{float(i), float(i) + 0.5f, -float(i), 1.f, 2.f, 3.f, float(i * i), 0.25f, 1e-3f});
  TempDir dir;
  const std::string path = dir.write("nine.stl", binary_stl(facets));
  const ReadAll r = read_every_way(path);
  EXPECT_EQ(r.positions, corners_of(facets));
  EXPECT_EQ(r.polygons, 9u);
  EXPECT_EQ(read_all(path, 1).chunks, 9u);    // one record per chunk at the minimum
  EXPECT_EQ(read_all(path, 149).chunks, 5u);  // two records (100 bytes) per chunk
}

TEST(StlMalformed, BinaryCountLargerThanFile) {
  TempDir dir;
  const std::string path = dir.write("big.stl", binary_stl(kFacets, "x", 1000));
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, "byte 80")) << msg;
  EXPECT_TRUE(contains(msg, "1000 triangles (50084 bytes) but the file has 234 bytes")) << msg;
}

TEST(StlMalformed, BinaryCountSmallerThanFile) {
  TempDir dir;
  const std::string path = dir.write("small.stl", binary_stl(kFacets, "x", 1));
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, "byte 80")) << msg;
  EXPECT_TRUE(contains(msg, "1 triangles (134 bytes) but the file has 234 bytes")) << msg;
}

TEST(StlMalformed, FileShorterThanHeader) {
  TempDir dir;
  const std::string path = dir.write("fifty.stl", std::string(50, '\x01'));
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, "byte 50")) << msg;
  EXPECT_TRUE(contains(msg, "truncated")) << msg;
}

TEST(StlMalformed, BinaryNonFiniteCoordinate) {
  TempDir dir;
  std::vector<Facet> facets = kFacets;
  facets[1][4] = std::numeric_limits<float>::quiet_NaN();
  facets[2][0] = std::numeric_limits<float>::infinity();
  const std::string path = dir.write("nan.stl", binary_stl(facets));
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, "byte 134")) << msg;  // 84 + 50 * 1: the second record
  EXPECT_TRUE(contains(msg, "non-finite")) << msg;

  facets = kFacets;
  facets[2][8] = -std::numeric_limits<float>::infinity();
  const std::string inf = failure_message(dir.write("inf.stl", binary_stl(facets)));
  EXPECT_TRUE(contains(inf, "byte 184")) << inf;
}

// ------------------------------------------------------------------------------------------------------
// ASCII

const char* const kMultiSolid =
    "solid alpha\n"
    "  facet normal 0 0 1\n"
    "    outer loop\n"
    "      vertex 0 0 0\n"
    "      vertex 1 0 0\n"
    "      vertex 0 1 0\n"
    "    endloop\n"
    "  endfacet\n"
    "  facet normal 0 0 -1\n"
    "    outer loop\n"
    "      vertex 1.5 -2.25 3e2\n"
    "      vertex +4 5E-1 -6\n"
    "      vertex 7 8 9\n"
    "    endloop\n"
    "  endfacet\n"
    "endsolid alpha\n"
    "\n"
    "solid the beta part\n"
    "  facet normal 1 0 0\n"
    "    outer loop\n"
    "      vertex 10 11 12\n"
    "      vertex 13 14 15\n"
    "      vertex 16 17 18\n"
    "    endloop\n"
    "  endfacet\n"
    "endsolid the beta part\n"
    "solid alpha\n"
    "  facet normal 0 1 0\n"
    "    outer loop\n"
    "      vertex -1 -2 -3\n"
    "      vertex -4 -5 -6\n"
    "      vertex -7 -8 -9\n"
    "    endloop\n"
    "  endfacet\n"
    "endsolid\n"
    "solid\n"
    "endsolid\n";

TEST(StlAscii, MultiSolidNamesCornersAndObjects) {
  TempDir dir;
  const std::string path = dir.write("multi.stl", kMultiSolid);
  const ReadAll r = read_every_way(path);
  EXPECT_EQ(r.format, "stl-ascii");
  EXPECT_TRUE(r.soup);
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 0, 1, 0,                  //
                                              1.5, -2.25, 300, 4, 0.5, -6, 7, 8, 9,        //
                                              10, 11, 12, 13, 14, 15, 16, 17, 18,          //
                                              -1, -2, -3, -4, -5, -6, -7, -8, -9}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 0, 1, 0}));
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"alpha", "the beta part", ""}));
  EXPECT_EQ(r.polygons, 4u);
}

TEST(StlAscii, CrlfTabsUppercaseKeywordsAndMissingEndsolid) {
  // The first "solid" stays lower case: format detection (io/reader.cpp) looks for it exactly.
  const std::string text =
      "solid Part One\r\n"
      "\r\n"
      "\tFACET NORMAL 0 0 1\r\n"
      "\t\tOuter Loop\r\n"
      "   VERTEX\t1 2 3\r\n"
      "   Vertex 4 5 6 \r\n"
      "   vErTeX 7 8 9\r\n"
      "\t\tENDLOOP\r\n"
      "\tENDFACET\r\n"
      "ENDSOLID Part One\r\n"
      "SOLID two\r\n"
      " facet normal 0 0 0\r\n"
      "  outer loop\r\n"
      "   vertex 0.5 0.25 0.125\r\n"
      "   vertex 1 1 1\r\n"
      "   vertex -1 -1 -1\r\n"
      "  endloop\r\n"
      " endfacet";  // no endsolid, no final line break
  TempDir dir;
  const std::string path = dir.write("crlf.stl", text);
  const ReadAll r = read_every_way(path);
  EXPECT_EQ(r.format, "stl-ascii");
  EXPECT_EQ(r.positions, (std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8, 9, 0.5, 0.25, 0.125, 1, 1, 1, -1, -1, -1}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"Part One", "two"}));
  EXPECT_EQ(r.polygons, 2u);
}

TEST(StlAscii, EmptySolid) {
  TempDir dir;
  const ReadAll r = read_every_way(dir.write("empty.stl", "solid nothing\nendsolid nothing\n"));
  EXPECT_EQ(r.polygons, 0u);
  EXPECT_TRUE(r.positions.empty());
  EXPECT_EQ(r.object_names, std::vector<std::string>{"nothing"});
}

std::string one_facet(const std::string& loop_body) {
  return "solid s\n facet normal 0 0 1\n  outer loop\n" + loop_body + "  endloop\n endfacet\nendsolid s\n";
}

// A good facet first, so that errors on later lines cross chunk boundaries for small targets.
const std::string kGoodFacet = " facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
                               "   vertex 0 1 0\n  endloop\n endfacet\n";

TEST(StlMalformed, AsciiFacetWithTwoVertices) {
  TempDir dir;
  const std::string path = dir.write(
      "two.stl", "solid s\n" + kGoodFacet + kGoodFacet +
                     " facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n  endloop\n endfacet\n"
                     "endsolid s\n");
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, path + ":20:")) << msg;  // the endloop line
  EXPECT_TRUE(contains(msg, "2 vertices")) << msg;
}

TEST(StlMalformed, AsciiFacetWithFourVertices) {
  TempDir dir;
  const std::string path =
      dir.write("four.stl", "solid s\n" + kGoodFacet +
                                " facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
                                "   vertex 0 1 0\n   vertex 1 1 0\n  endloop\n endfacet\nendsolid s\n");
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, path + ":14:")) << msg;  // the fourth vertex
  EXPECT_TRUE(contains(msg, "more than 3 vertices")) << msg;
}

TEST(StlMalformed, AsciiTruncatedInsideFacet) {
  TempDir dir;
  const std::string path = dir.write(
      "trunc.stl", "solid s\n" + kGoodFacet + " facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0");
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, path + ":9:")) << msg;  // where the unfinished facet starts
  EXPECT_TRUE(contains(msg, "ends inside")) << msg;

  const std::string cut = dir.write("cut.stl", "solid s\n" + kGoodFacet + " facet normal 0 0 1\n  outer loop\n");
  EXPECT_TRUE(contains(failure_message(cut), cut + ":9:"));
  // Cut inside a keyword: that last line is the error.
  const std::string mid = dir.write("mid.stl", "solid s\n" + kGoodFacet + " facet normal 0 0 1\n  outer loop\n   vert");
  EXPECT_TRUE(contains(failure_message(mid), mid + ":11:"));
}

TEST(StlMalformed, AsciiGarbageLine) {
  TempDir dir;
  const std::string path = dir.write("garbage.stl", "solid s\n" + kGoodFacet + "hello world\n" + kGoodFacet);
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, path + ":9:")) << msg;
  EXPECT_TRUE(contains(msg, "'hello'")) << msg;

  const std::string bad_number = dir.write("num.stl", one_facet("   vertex 0 0 0\n   vertex 1 x 0\n   vertex 0 1 0\n"));
  EXPECT_TRUE(contains(failure_message(bad_number), bad_number + ":5:"));
  const std::string short_vertex = dir.write("short.stl", one_facet("   vertex 0 0 0\n   vertex 1 0\n   vertex 0 1 0\n"));
  EXPECT_TRUE(contains(failure_message(short_vertex), short_vertex + ":5:"));
  const std::string extra = dir.write("extra.stl", one_facet("   vertex 0 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n"));
  EXPECT_TRUE(contains(failure_message(extra), extra + ":4:"));
  const std::string nan = dir.write("nan.stl", one_facet("   vertex 0 0 0\n   vertex 1 0 0\n   vertex nan 1 0\n"));
  const std::string nan_msg = failure_message(nan);
  EXPECT_TRUE(contains(nan_msg, nan + ":6:") && contains(nan_msg, "non-finite")) << nan_msg;
  const std::string outside = dir.write("outside.stl", "solid s\n" + kGoodFacet + "endsolid s\n" + kGoodFacet);
  EXPECT_TRUE(contains(failure_message(outside), outside + ":10:"));
  const std::string no_loop = dir.write("noloop.stl", "solid s\n facet normal 0 0 1\n   vertex 0 0 0\n");
  EXPECT_TRUE(contains(failure_message(no_loop), no_loop + ":3:"));
}

TEST(StlMalformed, AsciiBinaryBytes) {
  TempDir dir;
  std::string text = "solid s\n" + kGoodFacet + " facet normal 0 0 1\n";
  text += std::string("\x01\x02\x00\xff\n", 5);
  text += "endsolid\n";
  const std::string path = dir.write("bin.stl", text);
  const std::string msg = failure_message(path);
  EXPECT_TRUE(contains(msg, path + ":10:")) << msg;
  EXPECT_TRUE(contains(msg, "binary")) << msg;

  // A binary STL whose header starts with "solid" but whose size disagrees with its count is read as
  // ASCII (like every STL reader does) and fails on its first line, naming the binary count too.
  const std::string wrong = dir.write("wrongsize.stl", binary_stl(kFacets, "solid part", 7));
  const std::string wrong_msg = failure_message(wrong);
  EXPECT_TRUE(contains(wrong_msg, wrong + ":1:")) << wrong_msg;
  EXPECT_TRUE(contains(wrong_msg, "7 triangles (434 bytes) but the file has 234 bytes")) << wrong_msg;
}

// ------------------------------------------------------------------------------------------------------
// Shared data: every mechanical/*.stl, facet count checked against a count made here.

TEST(StlSharedData, MechanicalFiles) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  const std::filesystem::path mech = std::filesystem::path(data) / "mechanical";
  if (!std::filesystem::is_directory(mech)) GTEST_SKIP() << "skipped: " << mech << " is absent";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(mech)) {
    if (entry.path().extension() != ".stl") continue;
    const std::string path = entry.path().string();
    SCOPED_TRACE(path);
    std::ifstream in(path, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    uint64_t expected = 0;
    bool binary = false;
    std::vector<double> corners;
    if (bytes.size() >= 84) {
      uint32_t count;
      std::memcpy(&count, bytes.data() + 80, 4);
      binary = 84 + 50 * uint64_t(count) == bytes.size();
      if (binary) {
        expected = count;
        for (uint64_t i = 0; i < count; ++i) {
          for (int k = 0; k < 9; ++k) {
            float f;
            std::memcpy(&f, bytes.data() + 84 + 50 * i + 12 + 4 * k, 4);
            corners.push_back(f);
          }
        }
      }
    }
    if (!binary) {
      std::string lower = bytes;
      for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      for (size_t at = lower.find("endfacet"); at != std::string::npos; at = lower.find("endfacet", at + 8))
        ++expected;
    }
    for (uint64_t target : {uint64_t(4096), uint64_t(1) << 20}) {
      const ReadAll r = read_all(path, target);
      EXPECT_EQ(r.format, binary ? "stl-binary" : "stl-ascii");
      EXPECT_EQ(r.polygons, expected);
      EXPECT_EQ(r.positions.size(), 9 * expected);
      EXPECT_EQ(r.triangle_objects.size(), expected);
      if (binary) {
        EXPECT_EQ(r.positions, corners);
      }
    }
    ++files;
  }
  EXPECT_GT(files, 0);
  std::printf("read %d STL files from %s\n", files, mech.c_str());
}

}  // namespace
}  // namespace lodstream

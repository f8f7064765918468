// Ingest by byte ranges (stream/ingest_range.h): for every format and N ranges, the store joined from the
// ranges' segments holds the bytes of a one-machine ingest of the whole file, and malformed input fails
// with the message and status one machine gives.
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/status.h"
#include "lodstream/lodstream.h"
#include "stream/ingest.h"
#include "stream/ingest_range.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/work_dir.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;

using test::read_dir;

// What an ingest gave: the store's files, or the failure.
struct Outcome {
  std::map<std::string, std::string> store;
  int status = 0;
  std::string message;
};

Outcome whole(const std::string& input, const std::string& work_path) {
  Outcome o;
  Options options;
  options.work_dir = work_path;
  try {
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    stream::WorkDir work(work_path);
    bool reused = false;
    stream::ingest(input, work.subdir("store"), plan, work, progress, &reused);
    o.store = read_dir(fs::path(work_path) / "store");
  } catch (const Failure& f) {
    o.status = static_cast<int>(f.status());
    o.message = f.what();
  }
  return o;
}

// N range tasks (in reverse order, as a scheduler may run them), then the join.
Outcome ranged(const std::string& input, const std::string& work_path, unsigned n, unsigned threads = 2) {
  Outcome o;
  Options options;
  options.work_dir = work_path;
  options.threads = threads;
  try {
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    stream::WorkDir work(work_path);
    for (unsigned i = n; i-- > 0;) stream::ingest_range(input, work, i, n, plan, progress);
    const std::string dir = stream::ingest_ranges_dir(work);
    for (unsigned i = 0; i < n; ++i) EXPECT_TRUE(fs::exists(stream::segment_path(dir, i, n))) << i;
    bool reused = false;
    stream::ingest(input, work.subdir("store"), plan, work, progress, &reused, dir);
    // The join took the segments (it removes them once the store is complete).
    for (unsigned i = 0; i < n; ++i) EXPECT_FALSE(fs::exists(stream::segment_path(dir, i, n))) << i;
    o.store = read_dir(fs::path(work_path) / "store");
  } catch (const Failure& f) {
    o.status = static_cast<int>(f.status());
    o.message = f.what();
  }
  return o;
}

void expect_same_for_every_n(const std::string& input, bool expect_failure = false) {
  test::TempDir tmp;
  const Outcome ref = whole(input, tmp.file("whole"));
  if (expect_failure) EXPECT_EQ(ref.status, static_cast<int>(Status::bad_data)) << input << ": " << ref.message;
  else ASSERT_EQ(ref.status, 0) << ref.message;
  for (unsigned n : {1u, 2u, 3u, 7u}) {
    const Outcome got = ranged(input, tmp.file(fmt::format("n{}", n)), n);
    EXPECT_EQ(got.status, ref.status) << input << " N=" << n << ": " << got.message;
    EXPECT_EQ(got.message, ref.message) << input << " N=" << n;
    ASSERT_EQ(got.store.size(), ref.store.size()) << input << " N=" << n;
    for (const auto& [name, bytes] : ref.store) {
      ASSERT_TRUE(got.store.count(name)) << name;
      EXPECT_TRUE(got.store.at(name) == bytes) << input << " N=" << n << ": " << name << " differs";
    }
  }
}

// An OBJ with objects, groups, materials (a library beside it), absolute and negative relative indices
// reaching back across many lines, quads and a concave pentagon (triangulated in their plane), lines,
// points and comments: a few hundred lines, so that 7 ranges cut it everywhere.
std::string make_obj(const test::TempDir& tmp) {
  tmp.write("ranges.mtl", "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\nd 0.5\n");
  std::string s = "# ranges test\nmtllib ranges.mtl\n";
  int v = 0;
  for (int block = 0; block < 24; ++block) {
    if (block % 5 == 1) s += fmt::format("o part{}\n", block % 3);
    if (block % 4 == 2) s += fmt::format("usemtl {}\n", block % 8 == 2 ? "red" : "blue");
    if (block % 7 == 3) s += "g grouped\n";
    for (int k = 0; k < 6; ++k, ++v) s += fmt::format("v {} {} {}\n", block * 1.5 + k * 0.25, (k % 3) * 0.75, block % 2 ? 0.125 * k : -0.5);
    s += "f -6 -5 -4\n";
    s += fmt::format("f {} {} {} {}\n", v - 5, v - 4, v - 2, v - 3);  // absolute, a quad
    s += "f -3 -2 -1 -6 -5\n";                                          // relative, a pentagon
    if (block > 2) s += "f -13 -7 -1\n";                                // back across blocks
    if (block % 3 == 0) s += "l -6 -5 -4 -3\n";
    if (block % 3 == 1) s += fmt::format("p {} -1\n", v);
    if (block % 6 == 5) s += "vn 0 0 1\n# a comment\n\n";
  }
  return tmp.write("ranges.obj", s);
}

// PLY with vertex colours (uchar rgb) and faces of 3 and 4 corners (variable-size binary records).
std::string make_ply(const test::TempDir& tmp, bool binary) {
  const int nv = 150, nf = 140;
  std::string s = fmt::format("ply\nformat {} 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
                              "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face {}\n"
                              "property list uchar int vertex_indices\nend_header\n",
                              binary ? "binary_little_endian" : "ascii", nv, nf);
  auto put = [&](const auto& value) { s.append(reinterpret_cast<const char*>(&value), sizeof value); };
  for (int i = 0; i < nv; ++i) {
    const float x = static_cast<float>(i % 10) * 0.5f, y = static_cast<float>(i / 10) * 0.5f, z = static_cast<float>(i % 7) * 0.125f;
    const uint8_t rgb[3] = {static_cast<uint8_t>(i * 7), static_cast<uint8_t>(255 - i), static_cast<uint8_t>(i * 13)};
    if (binary) {
      put(x), put(y), put(z);
      s.append(reinterpret_cast<const char*>(rgb), 3);
    } else {
      s += fmt::format("{} {} {} {} {} {}\n", x, y, z, rgb[0], rgb[1], rgb[2]);
    }
  }
  for (int f = 0; f < nf; ++f) {
    const int a = f % 135, corners = f % 3 == 0 ? 4 : 3;
    const int ids[4] = {a, a + 1, a + 11, a + 10};
    if (binary) {
      s.push_back(static_cast<char>(corners));
      for (int c = 0; c < corners; ++c) put(static_cast<int32_t>(ids[c]));
    } else {
      s += std::to_string(corners);
      for (int c = 0; c < corners; ++c) s += " " + std::to_string(ids[c]);
      s += "\n";
    }
  }
  return tmp.write(binary ? "ranges-le.ply" : "ranges-ascii.ply", s);
}

// STL whose facets share corners (the weld joins them) in two solids (ascii).
std::string make_stl(const test::TempDir& tmp, bool binary) {
  const int n = 120;
  auto corner = [](int i, int k) {
    const int c = i + (k == 2 ? 11 : k);
    return std::array<float, 3>{static_cast<float>(c % 10), static_cast<float>(c / 10), static_cast<float>(c % 4) * 0.5f};
  };
  std::string s;
  if (binary) {
    s.assign(80, ' ');
    const uint32_t count = n;
    s.append(reinterpret_cast<const char*>(&count), 4);
    for (int i = 0; i < n; ++i) {
      const float normal[3] = {0, 0, 1};
      s.append(reinterpret_cast<const char*>(normal), 12);
      for (int k = 0; k < 3; ++k) s.append(reinterpret_cast<const char*>(corner(i, k).data()), 12);
      s.append(2, '\0');
    }
  } else {
    for (int solid = 0; solid < 2; ++solid) {
      s += fmt::format("solid part{}\n", solid);
      for (int i = solid * n / 2; i < (solid + 1) * n / 2; ++i) {
        s += "  facet normal 0 0 1\n    outer loop\n";
        for (int k = 0; k < 3; ++k) {
          const auto c = corner(i, k);
          s += fmt::format("      vertex {} {} {}\n", c[0], c[1], c[2]);
        }
        s += "    endloop\n  endfacet\n";
      }
      s += fmt::format("endsolid part{}\n", solid);
    }
  }
  return tmp.write(binary ? "ranges-bin.stl" : "ranges-ascii.stl", s);
}

TEST(IngestRanges, ObjWithNegativeIndicesMaterialsAndLines) {
  test::TempDir tmp;
  expect_same_for_every_n(make_obj(tmp));
}

TEST(IngestRanges, BinaryPlyWithColors) {
  test::TempDir tmp;
  expect_same_for_every_n(make_ply(tmp, true));
}

TEST(IngestRanges, AsciiPlyWithColors) {
  test::TempDir tmp;
  expect_same_for_every_n(make_ply(tmp, false));
}

TEST(IngestRanges, BinaryStl) {
  test::TempDir tmp;
  expect_same_for_every_n(make_stl(tmp, true));
}

TEST(IngestRanges, AsciiStl) {
  test::TempDir tmp;
  expect_same_for_every_n(make_stl(tmp, false));
}

TEST(IngestRanges, SampleRoom) {
  expect_same_for_every_n(test::source_dir() + "/tests/data/sample-room.ply");
}

// Malformed input, one case a format made here (the error in the middle of the file, so that a range
// other than the first meets it), then every file of the malformed corpus: the same message and status.
TEST(IngestRanges, MalformedInMidFile) {
  test::TempDir tmp;
  {
    std::string obj;
    for (int i = 0; i < 60; ++i) obj += fmt::format("v {} 0 0\nv 0 {} 1\nv 1 1 {}\nf -3 -2 -1\n", i, i, i);
    obj.insert(obj.find("f -3", obj.size() / 2), "f 1 2 x\n");
    expect_same_for_every_n(tmp.write("bad.obj", obj), true);
    std::string past = obj;
    past.replace(past.find("f 1 2 x"), 7, "f 1 2 9999");
    expect_same_for_every_n(tmp.write("past.obj", past), true);
  }
  {
    std::string ply = fs::path(make_ply(tmp, false)).string();
    std::ifstream f(ply);
    std::stringstream ss;
    ss << f.rdbuf();
    std::string s = ss.str();
    s.replace(s.find("\n3 ", s.size() * 3 / 4) + 1, 1, "3 x");
    expect_same_for_every_n(tmp.write("bad-ascii.ply", s), true);
  }
  {
    std::ifstream f(make_ply(tmp, true), std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    std::string s = ss.str();
    const int32_t far = 100000;
    std::memcpy(&s[s.size() - 200], &far, 4);  // some face's index, or a list count gone wrong
    expect_same_for_every_n(tmp.write("bad-le.ply", s), true);
    expect_same_for_every_n(tmp.write("cut-le.ply", s.substr(0, s.size() - 7)), true);
  }
  {
    std::ifstream f(make_stl(tmp, false));
    std::stringstream ss;
    ss << f.rdbuf();
    std::string s = ss.str();
    s.replace(s.find("vertex", s.size() * 2 / 3), 6, "vortex");
    expect_same_for_every_n(tmp.write("bad-ascii.stl", s), true);
  }
  {
    std::ifstream f(make_stl(tmp, true), std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    expect_same_for_every_n(tmp.write("cut-bin.stl", ss.str().substr(0, ss.str().size() - 20)), true);
  }
}

TEST(IngestRanges, MalformedCorpus) {
  const fs::path dir = fs::path(test::source_dir()) / "tests/data/malformed";
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().filename() == "EXPECTED.tsv") continue;
    test::TempDir tmp;
    const Outcome ref = whole(e.path().string(), tmp.file("whole"));
    for (unsigned n : {2u, 3u}) {
      const Outcome got = ranged(e.path().string(), tmp.file(fmt::format("n{}", n)), n, 1);
      EXPECT_EQ(got.status, ref.status) << e.path() << " N=" << n << ": " << got.message;
      EXPECT_EQ(got.message, ref.message) << e.path() << " N=" << n;
      EXPECT_TRUE(got.store == ref.store) << e.path() << " N=" << n;
    }
    ++files;
  }
  EXPECT_GT(files, 20);
}

// The join refuses an incomplete set, naming the missing ranges, with Status::no_input.
TEST(IngestRanges, JoinNamesMissingRanges) {
  test::TempDir tmp;
  const std::string input = make_obj(tmp);
  Options options;
  options.work_dir = tmp.file("work");
  const stream::MemoryPlan plan = stream::plan_memory(options);
  stream::Progress progress(options);
  stream::WorkDir work(options.work_dir);
  for (unsigned i : {0u, 2u, 4u}) stream::ingest_range(input, work, i, 5, plan, progress);
  bool reused = false;
  try {
    stream::ingest(input, work.subdir("store"), plan, work, progress, &reused, stream::ingest_ranges_dir(work));
    FAIL() << "joined an incomplete set";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::no_input);
    EXPECT_NE(std::string(f.what()).find("range 1, 3 missing"), std::string::npos) << f.what();
  }
}

}  // namespace
}  // namespace lodstream

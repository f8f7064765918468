// OBJ reader: exact results on small hand-written files, independence from the chunk size, errors.
#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "core/status.h"
#include "io/reader.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream::test {
namespace {

constexpr uint64_t kOneChunk = uint64_t(1) << 40;

void expect_same(const ReadAll& a, const ReadAll& b, uint64_t target) {
  expect_same(a, b, "target_bytes " + std::to_string(target));
}

// Reads `contents` in one chunk and checks that every chunk size from 1 byte up gives the same result.
ReadAll read_obj(const std::string& contents, const std::string& name = "model.obj") {
  TempDir dir;
  const std::string path = dir.write(name, contents);
  ReadAll whole = read_all(path, kOneChunk);
  EXPECT_EQ(whole.format, "obj");
  EXPECT_EQ(whole.chunks, 1u);
  for (uint64_t target = 1; target <= contents.size(); ++target) {
    const ReadAll r = read_all(path, target);
    if (target == 1 && contents.find('\n') + 1 < contents.size()) {
      EXPECT_GT(r.chunks, 1u);
    }
    expect_same(whole, r, target);
    if (testing::Test::HasFailure()) break;
  }
  return whole;
}

// Expects the file to fail with bad_data at `line` (path:line: ...) and a message containing `what`,
// whatever the chunk size.
void expect_bad(const std::string& contents, uint64_t line, const std::string& what) {
  TempDir dir;
  const std::string path = dir.write("bad.obj", contents);
  const std::string where = path + ":" + std::to_string(line) + ": ";
  for (uint64_t target : {kOneChunk, uint64_t(1), uint64_t(2), uint64_t(3), uint64_t(5), uint64_t(8), uint64_t(13),
                          uint64_t(21), uint64_t(34), uint64_t(contents.size() / 2 + 1)}) {
    SCOPED_TRACE("target_bytes " + std::to_string(target));
    try {
      read_all(path, target);
      ADD_FAILURE() << "no error for:\n" << contents;
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::bad_data);
      const std::string message = f.what();
      EXPECT_NE(message.find(where), std::string::npos) << message << "\nexpected location " << where;
      EXPECT_NE(message.find(what), std::string::npos) << message << "\nexpected text " << what;
    }
    if (testing::Test::HasFailure()) break;
  }
}

const std::vector<std::string> kDefault{""};

TEST(ObjReader, TriangleAndQuad) {
  const ReadAll r = read_obj(
      "# a comment\n"
      "v 0 0 0\n"
      "v 1 0 0\n"
      "v 1 1 0\n"
      "v 0 1 0\n"
      "f 1 2 3\n"
      "f 1 2 3 4\n");
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 0, 0}));
  EXPECT_EQ(r.object_names, kDefault);
  EXPECT_EQ(r.polygons, 2u);
  EXPECT_EQ(r.skipped, 0u);
  EXPECT_TRUE(r.lines.empty());
  EXPECT_TRUE(r.points.empty());
}

TEST(ObjReader, FacesRepeatingAVertex) {
  // (a, b, b) is the segment a-b; a repeated corner in a larger face is dropped from its ring; (a, a, a) is
  // nothing; a ring that touches itself (1 2 3 1 4 5) keeps its fan, the fan triangles naming a vertex
  // twice becoming segments. sum (n - 2) = 1 + 3 + 1 + 4 + 2 = 11 = 5 triangles + 6 degenerate.
  const ReadAll r = read_obj(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\n"
      "f 1 2 2\n"
      "f 1 2 2 3 1\n"
      "f 4 4 4\n"
      "f 1 2 3 1 4 5\n"
      "f 1 2 3 4\n");
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 0, 1, 2, 0, 3, 4, 0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 1, 0, 2, 0, 3}));
  EXPECT_EQ(r.line_objects.size(), 3u);
  EXPECT_EQ(r.polygons, 5u);
  EXPECT_EQ(r.degenerate, 1u + 2u + 1u + 2u);
  EXPECT_EQ(r.face_segments, 3u);
  EXPECT_EQ(r.planar_faces, 1u);  // only the quad of distinct vertices waits for its plane
}

TEST(ObjReader, VertexSyntax) {
  const ReadAll r = read_obj(
      "v 1.5 -2.25 3e2\n"                  // exponent
      "v +1 +2.5E-1 -4e+1 1.0\n"           // leading '+', w
      "\tv\t0.5\t\t1\t2  \n"               // tabs, leading and trailing blanks
      "v 1 2 3 0.1 0.2 0.3\r\n"            // colours, CRLF
      "   v 7 8 9 # trailing comment\n"    // leading blanks, comment
      "\n"
      "   \n"
      "v .5 5. -0 1 2 3 4 5 6 7\n"         // extra values
      "v 1e-400 2 3\n"                     // underflow is zero
      "v 1 2 3#comment right after\n");
  EXPECT_EQ(r.positions, (std::vector<double>{1.5, -2.25, 300, 1, 0.25, -40, 0.5, 1, 2, 1, 2, 3, 7, 8, 9, 0.5, 5, -0.0,
                                              0, 2, 3, 1, 2, 3}));
  EXPECT_EQ(r.vertex_count(), 8u);
  EXPECT_EQ(r.skipped, 0u);
  EXPECT_TRUE(r.triangles.empty());
}

TEST(ObjReader, FaceForms) {
  const ReadAll r = read_obj(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 2\n"
      "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
      "f 1/1 2/2 3/3\n"
      "f 1//1 3//1 4//1\n"
      "f 2/1/1 3/2/1 4/3/1 5/3/1 1/1/1\n"  // pentagon
      "f\t+1  2\t\t5   # comment\n"
      "f 3 4 5\r\n");
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2,                             //
                                               0, 2, 3,                             //
                                               1, 2, 3, 1, 3, 4, 1, 4, 0,           //
                                               0, 1, 4,                             //
                                               2, 3, 4}));
  EXPECT_EQ(r.triangle_objects, std::vector<uint32_t>(7, 0));
  EXPECT_EQ(r.polygons, 5u);
  EXPECT_EQ(r.skipped, 4u);
}

TEST(ObjReader, LinesAndPoints) {
  const ReadAll r = read_obj(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "l 1 2\n"
      "l 1/1 2/2 3/3 4/4\n"
      "p 4\n"
      "p 1 2 -1\n"
      "f 1 2 3\n");
  EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 1, 0, 1, 1, 2, 2, 3}));
  EXPECT_EQ(r.line_objects, std::vector<uint32_t>(4, 0));
  EXPECT_EQ(r.points, (std::vector<int64_t>{3, 0, 1, 3}));
  EXPECT_EQ(r.point_objects, std::vector<uint32_t>(4, 0));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
  EXPECT_EQ(r.polygons, 1u);
  EXPECT_EQ(r.skipped, 0u);
}

// Blender writes loose edges as two-corner faces (real files in ../shared/data do): they are kept as
// line segments, not refused and not counted as polygons.
TEST(ObjReader, TwoCornerFaceIsALineSegment) {
  const ReadAll r = read_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\no e\nf 1 2\nf 3/1 -1/1 2/1\nf 2//1 3//1\n");
  EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 1, 1, 2}));
  EXPECT_EQ(r.line_objects, (std::vector<uint32_t>{1, 1}));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{2, 2, 1}));
  EXPECT_EQ(r.polygons, 1u);
}

TEST(ObjReader, RelativeIndices) {
  const ReadAll r = read_obj(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\n"
      "f -3 -2 -1\n"
      "v 0 1 0\n"
      "f -4 -2/1 -1//3\n"
      "f 1 -3 -1\n"
      "l -1 -4\n"
      "v 5 5 5\n"
      "p -1 -5\n");
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 0, 2, 3, 0, 1, 3}));
  EXPECT_EQ(r.lines, (std::vector<int64_t>{3, 0}));
  EXPECT_EQ(r.points, (std::vector<int64_t>{4, 0}));
}

TEST(ObjReader, ForwardReferences) {
  const ReadAll r = read_obj(
      "f 1 2 3\n"
      "l 4 1\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\n"
      "f -1 4 -3\n"
      "v 0 1 0\n");
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 2, 3, 0}));
  EXPECT_EQ(r.lines, (std::vector<int64_t>{3, 0}));
  EXPECT_EQ(r.vertex_count(), 4u);
}

TEST(ObjReader, Objects) {
  const ReadAll r = read_obj(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "f 1 2 3\n"                     // before any o/g: object 0, ""
      "o wall\n"
      "f 1 2 3\n"
      "g  roof  part # the roof\n"    // full rest of the line, trimmed, comment removed
      "f 1 2 3 4\n"
      "l 1 2\n"
      "o wall\n"                      // same name, same id
      "p 1\n"
      "g\n"                           // no name: the default object
      "f 2 3 4\n"
      "g\troof  part\r\n"
      "p 2\n"
      "o door\n"
      "o\tlast one\t\n"
      "f 1 3 4\n");
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"", "wall", "roof  part", "door", "last one"}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 1, 2, 2, 0, 4}));
  EXPECT_EQ(r.line_objects, (std::vector<uint32_t>{2}));
  EXPECT_EQ(r.point_objects, (std::vector<uint32_t>{1, 2}));
  EXPECT_EQ(r.polygons, 5u);
  EXPECT_EQ(r.skipped, 0u);
}

TEST(ObjReader, ObjectCarriesAcrossChunks) {
  std::string text = "o first\n";
  for (int i = 0; i < 20; ++i) text += "v " + std::to_string(i) + " 0 0\n";
  text += "f 1 2 3\nf 4 5 6\ng second\nf 7 8 9\no first\nf 1 2 3\n";
  const ReadAll r = read_obj(text);
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"", "first", "second"}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{1, 1, 2, 1}));
}

TEST(ObjReader, SkippedStatements) {
  const ReadAll r = read_obj(
      "mtllib a.mtl b.mtl\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\n"
      "vt 0 0\nvn 0 0 1\nvp 0.5\n"
      "s 1\ns off\nusemtl brick\n"
      "cstype bspline\ndeg 3\nbmat u 1 2\nstep 1\ncurv 0 1 1 2\ncurv2 1 2\nsurf 0 1 0 1 1 2\nparm u 0 1\n"
      "trim 0 1 1\nhole 0 1 1\nscrv 0 1 1\nsp 1\nend\ncon 1 0 1 1\nmg 1 0.5\nbevel on\nc_interp off\n"
      "d_interp off\nlod 1\nmaplib a.map\nusemap off\nshadow_obj s.obj\ntrace_obj t.obj\nctech cparm 1\n"
      "stech cparm 1\n"
      "Ka 1 1 1\n"          // unknown keywords: tolerated
      "vx 1 2 3\n"
      "v1 1 2 3\n"
      "\xc3\xa9t\xc3\xa9 utf8\n"
      "f 1 2 3\n");
  EXPECT_EQ(r.skipped, 30u + 4u);  // 29 keywords (mtllib and usemtl are read), "s" twice, 4 unknown
  EXPECT_EQ(r.vertex_count(), 3u);
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
}

TEST(ObjReader, MaterialsFromUsemtlAndMtllib) {
  // Materials get ids in order of first use after material 0 (what comes before any usemtl); their
  // properties come from the libraries, whether mtllib comes before or after the usemtl; a name no
  // library defines keeps the defaults; a missing library is skipped.
  TempDir tmp;
  tmp.write("a.mtl", "# comment\nnewmtl red\nKd 1 0 0\nPm 0.25\nPr 0.5\nnewmtl glass pane\nKd 0.5\nd 0.25\n");
  tmp.write("b.mtl", "newmtl late\nKd 0 1 0\nTr 0.75\nnewmtl red\nKd 0 0 1\n");  // second red ignored
  std::string text = "mtllib a.mtl missing.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\n"
                     "usemtl red\nf 1 2 3 4\nl 1 3\nusemtl glass pane  # a comment\np 2\nf 2 3 4\n"
                     "usemtl late\nf 1 3 4\nusemtl nowhere\nf 1 2 4\nusemtl red\nf 4 3 2\nmtllib b.mtl\n";
  const std::string path = tmp.write("m.obj", text);
  const ReadAll r = read_all(path, 1 << 20);
  EXPECT_EQ(r.triangle_materials, (std::vector<uint32_t>{0, 1, 1, 2, 3, 4, 1}));
  EXPECT_EQ(r.line_materials, (std::vector<uint32_t>{1}));
  EXPECT_EQ(r.point_materials, (std::vector<uint32_t>{2}));
  ASSERT_EQ(r.materials.size(), 5u);
  EXPECT_EQ(r.materials[0].name, "");
  EXPECT_EQ(r.materials[0].base_color[0], 1.0f);
  EXPECT_EQ(r.materials[1].name, "red");
  EXPECT_EQ(std::vector<float>(r.materials[1].base_color, r.materials[1].base_color + 4), (std::vector<float>{1, 0, 0, 1}));
  EXPECT_EQ(r.materials[1].metallic, 0.25f);
  EXPECT_EQ(r.materials[1].roughness, 0.5f);
  EXPECT_EQ(r.materials[2].name, "glass pane");
  EXPECT_EQ(std::vector<float>(r.materials[2].base_color, r.materials[2].base_color + 4), (std::vector<float>{0.5f, 0.5f, 0.5f, 0.25f}));
  EXPECT_EQ(r.materials[2].alpha, core::Material::Alpha::blend);
  EXPECT_EQ(r.materials[3].name, "late");
  EXPECT_EQ(r.materials[3].base_color[1], 1.0f);
  EXPECT_EQ(r.materials[3].base_color[3], 0.25f);
  EXPECT_EQ(r.materials[4].name, "nowhere");
  EXPECT_EQ(r.materials[4].base_color[2], 1.0f);
  EXPECT_EQ(r.skipped, 0u);
  for (uint64_t bytes : {1, 7, 40}) expect_same(r, read_all(path, bytes), "chunk " + std::to_string(bytes));
  expect_same(r, read_parallel(path, 16, 3), "parallel");
  // No usemtl: no materials at all (mtllib alone changes nothing).
  EXPECT_TRUE(read_all(tmp.write("n.obj", "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n"), 1 << 20).materials.empty());
}

TEST(ObjReader, LineContinuation) {
  const ReadAll r = read_obj(
      "v 0 0 \\\n0\n"
      "v 1 \\\r\n 0 0\n"
      "v 1 1 0\nv 0 1 0\n"
      "f 1 2 \\\n 3 \\\n 4\n"
      "l 1 \\\n2\n"
      "p \\\n 3\n"
      "vt 0.5 \\\n 0.5\n"        // a continued skipped statement is one statement
      "# a comment ending with a backslash does not continue \\\n"
      "o name\\\n continued # c\n"
      "f 1 2 3\\\n\n"
      "p 4 \\");
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}));
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2, 0, 2, 3, 0, 1, 2}));
  EXPECT_EQ(r.lines, (std::vector<int64_t>{0, 1}));
  EXPECT_EQ(r.points, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(r.skipped, 1u);
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"", "name  continued"}));
  EXPECT_EQ(r.triangle_objects, (std::vector<uint32_t>{0, 0, 1}));
}

TEST(ObjReader, EmptyAndCommentOnly) {
  const ReadAll r = read_obj("# nothing here\n\n   \n# still nothing");
  EXPECT_TRUE(r.positions.empty());
  EXPECT_EQ(r.object_names, kDefault);
  EXPECT_EQ(r.polygons, 0u);
}

TEST(ObjReader, NoFinalNewline) {
  const ReadAll r = read_obj("v 1 2 3\nv 4 5 6\nv 7 8 9\nf 1 2 3");
  EXPECT_EQ(r.triangles, (std::vector<int64_t>{0, 1, 2}));
  EXPECT_EQ(r.positions.back(), 9);
}

// A mixed file with every feature: identical results for every chunk size (read_obj checks it).
TEST(ObjReader, EveryChunkSizeGivesTheSameResult) {
  std::string text = "# mixed\r\nmtllib m.mtl\r\n";
  for (int block = 0; block < 4; ++block) {
    const std::string b = std::to_string(block);
    text += (block % 2 ? "o obj" : "g group ") + b + "\r\n";
    for (int i = 0; i < 6; ++i) {
      text += "v " + std::to_string(i * 0.5 + block) + " \t" + std::to_string(-i) + "e-1 +" + std::to_string(block) + "\r\n";
      text += "vn 0 0 1\n";
    }
    text += "f -6//1 -5//1 -4//1 -3//1\n";
    text += "f " + std::to_string(block * 6 + 1) + "/1 -1/2 " + std::to_string(block * 6 + 3) + "/3 # c\n";
    text += "l -1 -2 -3\np -6\nusemtl x\n";
    text += "f 1 2 \\\n 3\n";
  }
  text += "f 1 2 24\no obj1\np 24\n";
  const ReadAll r = read_obj(text);
  EXPECT_EQ(r.vertex_count(), 24u);
  EXPECT_EQ(r.polygons, 13u);
  EXPECT_EQ(r.triangles.size(), 3u * (4 * 4 + 1));
  EXPECT_EQ(r.lines.size(), 2u * 2 * 4);
  EXPECT_EQ(r.points.size(), 5u);
  EXPECT_EQ(r.object_names, (std::vector<std::string>{"", "group 0", "obj1", "group 2", "obj3"}));
  EXPECT_EQ(r.skipped, 4u * 6);  // vn (mtllib and usemtl are read)
  EXPECT_EQ(r.point_objects.back(), 2u);
}

// parse() runs on many threads at once: parse the chunks concurrently, resolve in order.
TEST(ObjReader, ParallelParseMatchesSerial) {
  std::string text;
  for (int i = 0; i < 300; ++i) {
    text += "v " + std::to_string(i) + " 1 2\n";
    if (i % 7 == 6) text += "o part" + std::to_string(i % 3) + "\n";
    if (i >= 2) text += "f -1 -2 " + std::to_string(i - 1) + "\n";
  }
  TempDir dir;
  const std::string path = dir.write("par.obj", text);
  const ReadAll serial = read_all(path, kOneChunk);

  const ReadAll r = read_parallel(path, 97, 4);
  EXPECT_GT(r.chunks, 20u);
  expect_same(serial, r, 97);
}

// Randomly damaged files: whatever the outcome (a result or an error), it must not depend on the chunk
// size.
TEST(ObjReader, DamagedFilesGiveTheSameOutcomeForEveryChunkSize) {
  const std::string base =
      "v 0 0 0\nv 1 0 0\r\nv 1 1 0 # c\nv 0 1 0\no a\nf 1 2 3\nf -4 -3/1 -2//1 -1/1/1\nl 1 2 \\\n 3\n"
      "g b c\np -1 2\nvt 0 0\nf 1 2 5\nv 2 2 2\n";
  const std::string alphabet = std::string(" \t\r\n\\/#-+0123456789.evfplog") + std::string(1, '\0');
  auto outcome = [](const std::string& path, uint64_t target) {
    try {
      const ReadAll r = read_all(path, target);
      std::string s;
      for (double d : r.positions) s += std::to_string(d) + ",";
      s += "|";
      for (auto* refs : {&r.triangles, &r.lines, &r.points}) {
        for (int64_t i : *refs) s += std::to_string(i) + ",";
        s += "|";
      }
      for (auto* ids : {&r.triangle_objects, &r.line_objects, &r.point_objects}) {
        for (uint32_t i : *ids) s += std::to_string(i) + ",";
        s += "|";
      }
      for (const auto& n : r.object_names) s += n + ",";
      return s + "|" + std::to_string(r.polygons) + "|" + std::to_string(r.skipped);
    } catch (const Failure& f) {
      return std::string("error ") + std::to_string(static_cast<int>(f.status())) + " " + f.what();
    }
  };
  TempDir dir;
  uint32_t seed = 12345;
  auto rnd = [&seed](uint32_t n) {
    seed = seed * 1664525u + 1013904223u;
    return (seed >> 8) % n;
  };
  int errors = 0;
  for (int round = 0; round < 150; ++round) {
    std::string text = base;
    for (int edits = 1 + rnd(3); edits > 0; --edits) {
      const size_t at = rnd(static_cast<uint32_t>(text.size()));
      const char c = alphabet[rnd(static_cast<uint32_t>(alphabet.size()))];
      switch (rnd(3)) {
        case 0: text[at] = c; break;
        case 1: text.insert(text.begin() + static_cast<std::ptrdiff_t>(at), c); break;
        default: text.erase(at, 1); break;
      }
    }
    const std::string path = dir.write("damaged" + std::to_string(round) + ".obj", text);
    const std::string expected = outcome(path, kOneChunk);
    errors += expected.rfind("error", 0) == 0;
    for (uint64_t target : {1, 2, 3, 7, 16, 40}) {
      ASSERT_EQ(outcome(path, target), expected) << "target_bytes " << target << ", file:\n" << text;
    }
  }
  EXPECT_GT(errors, 10);
  EXPECT_LT(errors, 140);
}

TEST(ObjReader, DetectedWithoutExtension) {
  TempDir dir;
  const std::string path = dir.write("model.txt", "# exported\nv 1 2 3\nv 4 5 6\nv 7 8 9\nf 1 2 3\n");
  EXPECT_EQ(read_all(path, 5).format, "obj");
}

// ---- malformed input -------------------------------------------------------------------------------

TEST(ObjMalformed, IndexZero) {
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 0 1 2\n", 5, "index 0");
  expect_bad("v 0 0 0\nv 1 0 0\nl 1 0/1\n", 3, "index 0");
}

TEST(ObjMalformed, IndexPastTheEnd) {
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 2 4\nf 1 2 3\n", 5, "vertex index 4 is past the last vertex (the file has 3");
  // The first occurrence in file order, even when a later one is larger or earlier chunks reference
  // vertices defined later.
  expect_bad("f 1 2 3\nv 0 0 0\nf 4 1 2\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 9\np 7\n", 7, "vertex index 9");
  expect_bad("p 4\nv 0 0 0\nv 1 0 0\nl 1 2\np 3\nv 1 0 0\nv 1 0 0\np 4 6\n", 8, "vertex index 6");
}

TEST(ObjMalformed, RelativeIndexBeforeTheStart) {
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf -1 -2 -3\nf -1 -2 -4\n", 5, "relative vertex index -4 reaches before the first vertex");
  expect_bad("v 0 0 0\nv 1 0 0\np -3\n", 3, "-3");
  // A relative error comes before a later syntax error in the same chunk.
  expect_bad("v 0 0 0\nv 1 0 0\nl 1 -5\nv 1 2\n", 3, "-5");
  expect_bad("v 0 0 0\nf -1 -1 -99999999999999999\n", 2, "reaches before the first vertex");
}

TEST(ObjMalformed, NotFinite) {
  expect_bad("v 0 0 0\nv nan 0 0\n", 2, "vertex coordinate is not finite");
  expect_bad("v 0 0 0\nv 1 -inf 0\n", 2, "not finite");
  expect_bad("v 0 0 0\nv 1 2 infinity\n", 2, "not finite");
  expect_bad("v 0 0 0\nv 1 2 1e999\n", 2, "not finite");
}

TEST(ObjMalformed, TooFewCorners) {
  expect_bad("v 0 0 0\nf 1\n", 2, "face with 1 corner");
  expect_bad("v 0 0 0\n  f  # nothing\n", 2, "face with 0 corners");
  expect_bad("v 0 0 0\nl 1\n", 2, "line with 1 vertex");
  expect_bad("v 0 0 0\np\n", 2, "point statement without vertices");
}

TEST(ObjMalformed, GarbageBytes) {
  expect_bad(std::string("v 0 0 0\nv 1 0 0\n\x01\x02\xff\x7f garbage\nv 1 1 0\n"), 3, "binary data");
  expect_bad(std::string("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\0\n", 33), 4, "binary data in a text file (byte 0x00)");
  expect_bad(std::string("v 0 0 0\nvn 0 0\x1b 1\n", 18), 2, "binary data");
  expect_bad(std::string("v 0 0 0\n# comment \x04\n", 20), 2, "binary data");
  expect_bad(std::string("v 0 0 0\no name\x10\n", 16), 2, "binary data");
  expect_bad(std::string("\0\0\0\0v 1 2 3\n", 12), 1, "binary data");
}

TEST(ObjMalformed, BadNumbers) {
  expect_bad("v 0 0 0\nv 1 2\nv 1 2 3\n", 2, "vertex has 2 coordinates, needs 3");
  expect_bad("v 0 0 0\nv 1 2 # comment 3\n", 2, "vertex has 2 coordinates");
  expect_bad("v 0 0 0\nv\n", 2, "vertex has 0 coordinates");
  expect_bad("v 0 0 0\nv 1 2 3x\n", 2, "bad vertex coordinate '3x'");
  expect_bad("v 0 0 0\nv 1 +-2 3\n", 2, "bad vertex coordinate");
  expect_bad("v 0 0 0\nv 1 , 3\n", 2, "bad vertex coordinate");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 x 3\n", 4, "bad vertex reference 'x' in 'f' statement");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2.5 3\n", 4, "bad vertex reference '2.5'");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1/ 2 3\n", 4, "bad vertex reference '1/'");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1/a 2 3\n", 4, "bad vertex reference");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1//x 2 3\n", 4, "bad vertex reference");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1/2/3/4 2 3\n", 4, "bad vertex reference");
  expect_bad("v 0 0 0\nv 1 0 0\nl 1 2,\n", 3, "bad vertex reference '2,' in 'l' statement");
  expect_bad("v 0 0 0\np 1234567890123456789012\n", 2, "bad vertex reference");
}

TEST(ObjMalformed, LineNumbersCountContinuationsAndCrlf) {
  expect_bad("v 0 0 0\r\nv 1 \\\r\n 0 0\r\n\r\nf 1\r\n", 5, "face with 1 corner");
  expect_bad("v 0 0 0\r\nv 1 \\\r\n 0 0\r\n\r\nf \\\n 2\r\n", 5, "face with 1 corner");
}

TEST(ObjMalformed, FirstErrorInFileOrder) {
  // A bad line in an early chunk wins over an index past the end found at finish().
  expect_bad("v 0 0 0\nf 1 2 9\nv 1 0 0\nv 1 2\nv 1 1 0\n", 4, "vertex has 2");
  expect_bad("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 2 3\nv 1 2 x\nf 0 1 2\n", 6, "bad vertex coordinate 'x'");
}

// A number from_chars reports out of range is read again whole: a long mantissa with a large negative
// exponent underflows to 0 (it used to be cut at 511 bytes, which read 1000...0 as infinity).
TEST(ObjReader, LongOutOfRangeNumbers) {
  const std::string zeros(600, '0');
  const ReadAll r = read_obj("v 1" + zeros + "e-1000 0 0\nv 0 1" + zeros + "e-700 0\nv 0 0 1\nf 1 2 3\n");
  EXPECT_EQ(r.positions, (std::vector<double>{0, 0, 0, 0, 1e-100, 0, 0, 0, 1}));
  expect_bad("v 0." + zeros + "1e1000 0 0\n", 1, "not finite");
}

}  // namespace
}  // namespace lodstream::test

// `lodstream report` end to end, through the CLI as a user runs it: exact figures where geometry makes
// them exact (a LOD identical to its original, a LOD moved by a known offset), the same figures for any
// thread count or memory budget, every file written, runs side by side, the documented exit codes, and
// report.html rendered by headless Chromium (tools/check_html.py).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "test_util.h"

namespace lodstream::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const std::string kRoom = std::string(LODSTREAM_SOURCE_DIR) + "/tests/data/sample-room.ply";
// Small settings keep each report well under a second on the sample room.
const std::vector<std::string> kQuick = {"--views", "4", "--resolution", "64", "--samples", "5000", "--progress", "none"};

std::vector<std::string> cat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// A flat n×n grid of squares in the plane z = `z`, side 1, as OBJ.
std::string grid_obj(int n, double z) {
  std::string s;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) s += "v " + std::to_string(double(i) / n) + " " + std::to_string(double(j) / n) + " " + std::to_string(z) + "\n";
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i + 1, b = a + 1, c = a + n + 2, d = a + n + 1;
      s += "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c) + " " + std::to_string(d) + "\n";
    }
  return s;
}

// report.json without what may differ between runs (times, memory, the directory of the files).
json figures(const std::string& path) {
  json j = json::parse(read_file(path));
  j.erase("stages"), j.erase("seconds"), j.erase("peak_rss_bytes"), j.erase("performance"), j.erase("work_dir");
  for (auto& run : j["runs"]) {
    run.erase("name");
    for (auto& level : run["levels"]) level.erase("seconds"), level.erase("file");
  }
  return j;
}

class ReportRoom : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    tmp_ = new TempDir();
    const CliRun s = run_cli({"simplify", kRoom, "-o", tmp_->file("room"), "--progress", "none"}, *tmp_);
    ASSERT_EQ(s.exit_code, 0) << s.err;
    const CliRun r = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("base")}, kQuick), *tmp_);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete tmp_; }
  static TempDir* tmp_;
};
TempDir* ReportRoom::tmp_ = nullptr;

TEST_F(ReportRoom, WritesEveryFileWithTheManifestsLevels) {
  const json manifest = json::parse(read_file(tmp_->file("room/manifest.json")));
  const json report = json::parse(read_file(tmp_->file("base/report.json")));
  ASSERT_EQ(report["runs"].size(), 1u);
  const json& levels = report["runs"][0]["levels"];
  ASSERT_EQ(levels.size(), manifest["levels"].size());
  EXPECT_EQ(report["runs"][0]["original"]["triangles"], manifest["input"]["triangles"]);
  for (size_t l = 0; l < levels.size(); ++l) {
    const json& v = levels[l];
    EXPECT_EQ(v["triangles"], manifest["levels"][l]["triangles"]);
    EXPECT_EQ(v["edges"], manifest["levels"][l]["edges"]);
    EXPECT_EQ(v["points"], manifest["levels"][l]["points"]);
    EXPECT_DOUBLE_EQ(v["switch_distance"].get<double>(), manifest["levels"][l]["switch_distance"].get<double>());
    // 4 views of 64×64 pixels; 5000 face samples per direction (the figures' denominators).
    EXPECT_LE(v["silhouette"]["covered_pixels"].get<uint64_t>(), 4u * 64 * 64);
    EXPECT_GT(v["silhouette"]["covered_pixels"].get<uint64_t>(), 0u);
    EXPECT_GE(v["hausdorff"]["lod_to_original"]["count"].get<uint64_t>(), 10000u);
    for (const char* k : {"max", "mean", "rms"}) EXPECT_GE(v["hausdorff"][k].get<double>(), 0) << k;
    EXPECT_LE(v["hausdorff"]["mean"].get<double>(), v["hausdorff"]["max"].get<double>());
    EXPECT_LE(v["silhouette"]["p95_px"].get<double>(), v["silhouette"]["max_px"].get<double>());
    EXPECT_LE(v["normal_degrees"]["max"].get<double>(), 180.0);
    EXPECT_TRUE(fs::exists(tmp_->file("base/lod" + std::to_string(l) + ".csv")));
    // One CSV row per view, plus the header.
    const std::string csv = read_file(tmp_->file("base/lod" + std::to_string(l) + ".csv"));
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 5);
  }
  // Coarser levels are further off.
  EXPECT_GT(levels[4]["hausdorff"]["mean"].get<double>(), levels[0]["hausdorff"]["mean"].get<double>());
  EXPECT_TRUE(fs::exists(tmp_->file("base/report.html")));
  for (const auto& e : fs::directory_iterator(tmp_->file("base")))
    EXPECT_NE(e.path().extension(), ".partial") << e.path();
}

TEST_F(ReportRoom, SameFiguresForOneAndTwoThreadsAndAnyMemory) {
  const CliRun a = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("t1"), "--threads", "1", "--memory", "256M"}, kQuick), *tmp_);
  ASSERT_EQ(a.exit_code, 0) << a.err;
  const CliRun b = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("t2"), "--threads", "2", "--memory", "4G"}, kQuick), *tmp_);
  ASSERT_EQ(b.exit_code, 0) << b.err;
  EXPECT_EQ(figures(tmp_->file("t1/report.json")), figures(tmp_->file("base/report.json")));
  EXPECT_EQ(figures(tmp_->file("t2/report.json")), figures(tmp_->file("base/report.json")));
  for (int l = 0; l < 5; ++l) {
    const std::string name = "/lod" + std::to_string(l) + ".csv";
    EXPECT_EQ(read_file(tmp_->file("t1") + name), read_file(tmp_->file("base") + name));
    EXPECT_EQ(read_file(tmp_->file("t2") + name), read_file(tmp_->file("base") + name));
  }
  EXPECT_EQ(read_file(tmp_->file("t1/report.html")), read_file(tmp_->file("base/report.html")));
}

// The original traced in several chunks (at --memory 64M, the least, the room's 262 K triangles now fit one
// chunk, so --chunk-bytes 6M cuts them; --chunk-bytes 2M cuts it and the finest level finer still) gives
// report.json, every CSV and report.html byte for byte as in one chunk, timings aside.
TEST_F(ReportRoom, SameBytesInOneChunkAndInSeveral) {
  const CliRun one = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("one"), "--memory", "4G"}, kQuick), *tmp_);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const CliRun some = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("some"), "--memory", "64M", "--chunk-bytes", "6M"}, kQuick), *tmp_);
  ASSERT_EQ(some.exit_code, 0) << some.err;
  const CliRun many = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("many"), "--chunk-bytes", "2M"}, kQuick), *tmp_);
  ASSERT_EQ(many.exit_code, 0) << many.err;
  const json j1 = json::parse(read_file(tmp_->file("one/report.json")));
  EXPECT_EQ(j1["performance"]["original_chunks"], 1);
  // The cap holds in several chunks as a parent sees it (wait4's ru_maxrss, /usr/bin/time -v's figure):
  // the chunks are sized from what the measure stage holds beside them and Embree's measured bytes.
  EXPECT_LE(some.max_rss_bytes, 64ull << 20);
  EXPECT_GE(json::parse(read_file(tmp_->file("some/report.json")))["performance"]["original_chunks"].get<int>(), 2);
  const json many_perf = json::parse(read_file(tmp_->file("many/report.json")))["performance"];
  EXPECT_GE(many_perf["original_chunks"].get<int>(), 8);
  EXPECT_GE(many_perf["level_chunks"].get<int>(), 2);  // the finest level (84 K triangles) is cut too
  for (const char* dir : {"some", "many"}) {
    EXPECT_EQ(figures(tmp_->file(std::string(dir) + "/report.json")), figures(tmp_->file("one/report.json"))) << dir;
    for (int l = 0; l < 5; ++l) {
      const std::string name = "/lod" + std::to_string(l) + ".csv";
      EXPECT_EQ(read_file(tmp_->file(dir) + name), read_file(tmp_->file("one") + name)) << dir << name;
    }
    EXPECT_EQ(read_file(tmp_->file(dir) + "/report.html"), read_file(tmp_->file("one/report.html"))) << dir;
  }
}

// report.json says where the measure stage's time went, part by part, and what Embree took a triangle.
TEST_F(ReportRoom, PerformanceListsTheMeasureStagesParts) {
  const json p = json::parse(read_file(tmp_->file("base/report.json")))["performance"];
  std::vector<std::string> names;
  for (const json& phase : p["phases"]) {
    names.push_back(phase["name"]);
    EXPECT_GE(phase["seconds"].get<double>(), 0) << phase;
    EXPECT_GE(phase["cpu_seconds"].get<double>(), 0) << phase;
  }
  EXPECT_EQ(names, (std::vector<std::string>{"chunk_read", "chunk_build", "wire_build", "queries_on_original",
                                             "rays_on_original", "level_read", "level_build", "queries_on_level",
                                             "rays_on_level", "compare"}));
  EXPECT_GT(p["phases"][1]["cpu_seconds"].get<double>() + p["phases"][4]["cpu_seconds"].get<double>(), 0);
  // The room's one chunk (262 K triangles) measured Embree's bytes a triangle: 82-94 on every scene so far.
  EXPECT_GT(p["chunk_triangle_bytes"].get<double>(), 40);
  EXPECT_LT(p["chunk_triangle_bytes"].get<double>(), 200);
}

TEST_F(ReportRoom, AnotherSeedMovesTheViews) {
  const CliRun r = run_cli(cat({"report", tmp_->file("room"), "-o", tmp_->file("seed2"), "--seed", "2"}, kQuick), *tmp_);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(read_file(tmp_->file("seed2/lod0.csv")), read_file(tmp_->file("base/lod0.csv")));
}

TEST_F(ReportRoom, RunsGivenTogetherSitSideBySide) {
  const CliRun s = run_cli({"simplify", kRoom, "-o", tmp_->file("uniform"), "--clustering", "uniform", "--progress", "none"}, *tmp_);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  const CliRun r = run_cli(cat({"report", tmp_->file("room"), tmp_->file("uniform"), "-o", tmp_->file("both")}, kQuick), *tmp_);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(read_file(tmp_->file("both/report.json")));
  ASSERT_EQ(j["runs"].size(), 2u);
  EXPECT_EQ(j["runs"][0]["levels"][0]["csv"], "run0-lod0.csv");
  EXPECT_EQ(j["runs"][1]["levels"][0]["csv"], "run1-lod0.csv");
  EXPECT_TRUE(fs::exists(tmp_->file("both/run1-lod4.csv")));
  // The first run's figures are those of the report made for it alone.
  json alone = figures(tmp_->file("base/report.json"))["runs"][0];
  json together = figures(tmp_->file("both/report.json"))["runs"][0];
  for (auto& l : together["levels"]) l.erase("csv");
  for (auto& l : alone["levels"]) l.erase("csv");
  EXPECT_EQ(together, alone);
  const std::string html = read_file(tmp_->file("both/report.html"));
  EXPECT_NE(html.find(tmp_->file("uniform")), std::string::npos);
  // One plot polyline per run in each of the two plots.
  size_t lines = 0;
  for (size_t at = html.find("<polyline"); at != std::string::npos; at = html.find("<polyline", at + 1)) ++lines;
  EXPECT_EQ(lines, 4u);
}

TEST_F(ReportRoom, HtmlRendersInHeadlessChromium) {
  const std::string script = std::string(LODSTREAM_SOURCE_DIR) + "/tools/check_html.py";
  const std::string cmd = "python3 " + script + " " + tmp_->file("base/report.html") + " > " + tmp_->file("check.json") + " 2> " + tmp_->file("check.err");
  const int rc = std::system(cmd.c_str());
  const int code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  if (code == 77) GTEST_SKIP() << "skipped: " << read_file(tmp_->file("check.err"));
  ASSERT_EQ(code, 0) << read_file(tmp_->file("check.json")) << read_file(tmp_->file("check.err"));
  const json j = json::parse(read_file(tmp_->file("check.json")));
  // 5 levels × 3 views × (original, level, heat map).
  EXPECT_EQ(j["status"], "ok 45/45");
  EXPECT_FALSE(j["screenshot"]["flat"].get<bool>());
}

TEST(ReportExact, ALevelIdenticalToItsOriginalIsOffByNothing) {
  TempDir tmp;
  const std::string obj = tmp.write("grid.obj", grid_obj(8, 0));
  const CliRun r = run_cli(cat({"report", "--original", obj, "--lod", obj, "--switch-distances", "2", "-o", tmp.file("r")}, kQuick), tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json v = json::parse(read_file(tmp.file("r/report.json")))["runs"][0]["levels"][0];
  EXPECT_EQ(v["silhouette"]["mismatched_pixels"], 0);
  EXPECT_GT(v["silhouette"]["covered_pixels"].get<uint64_t>(), 0u);
  EXPECT_EQ(v["depth_px"]["max"], 0.0);
  EXPECT_EQ(v["normal_degrees"]["max"], 0.0);
  EXPECT_LT(v["hausdorff"]["max"].get<double>(), 1e-6);
  EXPECT_DOUBLE_EQ(v["switch_distance"].get<double>(), 2.0);
}

TEST(ReportExact, ALevelMovedByAnOffsetIsThatFarOff) {
  // The LOD is the grid lifted by 0.01 along its normal: every sample of either is exactly 0.01 from the
  // other (to float precision), so max = mean = rms = 0.01 both ways.
  TempDir tmp;
  const std::string original = tmp.write("grid.obj", grid_obj(8, 0));
  const std::string lifted = tmp.write("lifted.obj", grid_obj(8, 0.01));
  const CliRun r = run_cli(cat({"report", "--original", original, "--lod", lifted, "-o", tmp.file("r")}, kQuick), tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json v = json::parse(read_file(tmp.file("r/report.json")))["runs"][0]["levels"][0];
  for (const char* dir : {"lod_to_original", "original_to_lod"})
    for (const char* k : {"max", "mean", "rms", "p95"}) EXPECT_NEAR(v["hausdorff"][dir][k].get<double>(), 0.01, 1e-6) << dir << " " << k;
  // No distance given: the level is shown from where its Hausdorff max spans 5 pixels of 64.
  const double pixel = v["pixel_size"].get<double>();
  EXPECT_NEAR(v["hausdorff"]["max_px"].get<double>(), 5.0, 1e-4);
  EXPECT_NEAR(pixel, 0.01 / 5, 1e-8);
  EXPECT_NEAR(v["hausdorff"]["max_percent_diagonal"].get<double>(), 100 * 0.01 / std::sqrt(2.0), 1e-4);
}

// A point is drawn at the size of what it replaces: a unit cube (4 to 7 pixels across at distance 14 in
// 64 pixels) collapsed to one point at its centre is mostly covered by a point of size 1.2, and mostly
// missed by the same point without a size (drawn one pixel wide, as before point sizes).
TEST(ReportExact, APointIsDrawnAtItsSize) {
  TempDir tmp;
  std::string cube;
  for (int i = 0; i < 8; ++i)
    cube += std::string("v ") + (i & 1 ? "0.5" : "-0.5") + (i & 2 ? " 0.5" : " -0.5") + (i & 4 ? " 0.5\n" : " -0.5\n");
  cube += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
  const std::string original = tmp.write("cube.obj", cube);
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string sized = tmp.write("sized.ply", head + "element point 1\nproperty uint vertex\nproperty float size\nend_header\n0 0 0\n0 1.2\n");
  const std::string unsized = tmp.write("unsized.ply", head + "element point 1\nproperty uint vertex\nend_header\n0 0 0\n0\n");
  auto mismatched = [&](const std::string& lod, const std::string& out) {
    const CliRun r = run_cli(cat({"report", "--original", original, "--lod", lod, "--switch-distances", "14", "-o", tmp.file(out)}, kQuick), tmp);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    const json s = json::parse(read_file(tmp.file(out + "/report.json")))["runs"][0]["levels"][0]["silhouette"];
    return std::pair(s["mismatched_pixels"].get<uint64_t>(), s["covered_pixels"].get<uint64_t>());
  };
  // covered: pixels covered by the original or the level (the unsized point lies inside the cube's).
  const auto [with_size, covered_either] = mismatched(sized, "sized");
  const auto [without, covered] = mismatched(unsized, "unsized");
  EXPECT_GE(covered, 4u * 16u);  // 4 views, at least 4 x 4 pixels each
  EXPECT_GT(without, covered * 3 / 4);
  EXPECT_LT(with_size, covered / 3);
  EXPECT_GE(covered_either, covered);
}

// A larger real scene (a building of ../shared/data, given as --lod files of its simplify output, so that
// the distances come from the Hausdorff pass over the chunks too): the same bytes in one chunk and in many.
TEST(ReportChunks, ABuildingInOneChunkAndInManyGivesTheSameBytes) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  TempDir tmp;
  const std::string building = data + "/buildings/ISSUE_021_Mini_Project.obj";
  const CliRun s = run_cli({"simplify", building, "-o", tmp.file("lods"), "--progress", "none"}, tmp);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  std::vector<std::string> lods = {"report", "--original", building};
  for (int l = 0; l < 3; ++l) lods.insert(lods.end(), {"--lod", tmp.file("lods/lod" + std::to_string(l) + ".ply")});
  const CliRun one = run_cli(cat(cat(lods, {"-o", tmp.file("one"), "--memory", "4G"}), kQuick), tmp);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const CliRun many = run_cli(cat(cat(lods, {"-o", tmp.file("many"), "--memory", "64M", "--chunk-bytes", "3M"}), kQuick), tmp);
  ASSERT_EQ(many.exit_code, 0) << many.err;
  EXPECT_EQ(json::parse(read_file(tmp.file("one/report.json")))["performance"]["original_chunks"], 1);
  EXPECT_GE(json::parse(read_file(tmp.file("many/report.json")))["performance"]["original_chunks"].get<int>(), 4);
  EXPECT_EQ(figures(tmp.file("many/report.json")), figures(tmp.file("one/report.json")));
  for (int l = 0; l < 3; ++l) {
    const std::string name = "/lod" + std::to_string(l) + ".csv";
    EXPECT_EQ(read_file(tmp.file("many") + name), read_file(tmp.file("one") + name)) << name;
  }
  EXPECT_EQ(read_file(tmp.file("many/report.html")), read_file(tmp.file("one/report.html")));
}

TEST(ReportErrors, DocumentedExitCodesAndNoReportLeftBehind) {
  TempDir tmp;
  const std::string obj = tmp.write("grid.obj", grid_obj(2, 0));
  const std::string bad = tmp.write("bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\nnot-a-number\n");
  fs::create_directories(tmp.file("empty"));
  struct Case {
    std::vector<std::string> args;
    int code;
  };
  const std::vector<Case> cases = {
      {{"report", tmp.file("missing"), "-o", tmp.file("o1")}, 66},
      {{"report", tmp.file("empty"), "-o", tmp.file("o2")}, 66},
      {{"report", "--lod", obj, "-o", tmp.file("o3")}, 64},
      {{"report", tmp.file("empty"), tmp.file("empty")}, 64},
      {{"report", "--original", obj, "--lod", obj, "--views", "0", "-o", tmp.file("o5")}, 64},
      {{"report", "--original", obj, "--lod", obj, "--switch-distances", "1,2", "-o", tmp.file("o6")}, 64},
      {{"report", "--original", obj, "--lod", tmp.file("nope.ply"), "-o", tmp.file("o7")}, 66},
      {{"report", "--original", obj, "--lod", bad, "-o", tmp.file("o8")}, 65},
      {{"report", "--original", tmp.file("nope.obj"), "--lod", obj, "-o", tmp.file("o9")}, 66},
  };
  for (size_t i = 0; i < cases.size(); ++i) {
    const CliRun r = run_cli(cases[i].args, tmp);
    EXPECT_EQ(r.exit_code, cases[i].code) << "case " << i << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "case " << i << ": one line expected: " << r.err;
    EXPECT_FALSE(fs::exists(tmp.file(std::string("o").append(std::to_string(i + 1)).append("/report.json")))) << "case " << i;
  }
}

}  // namespace
}  // namespace lodstream::test

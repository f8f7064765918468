// The lodstream CLI as a user runs it: exit codes, JSON output, the memory cap, SIGINT.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/mount.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;

using test::CliRun;
using test::run_cli;

// An OBJ grid of n x n quads, about 60 bytes per quad.
std::string grid_obj(const test::TempDir& tmp, int n) {
  const std::string path = tmp.file("grid.obj");
  std::ofstream f(path);
  f << "o grid\n";
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) f << "v " << x * 0.25 << ' ' << y * 0.5 << ' ' << ((x * 7 + y * 3) % 11) * 0.1 << '\n';
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const int a = y * (n + 1) + x + 1;
      f << "f " << a << ' ' << a + 1 << ' ' << a + n + 2 << ' ' << a + n + 1 << '\n';
    }
  return path;
}

TEST(Cli, InfoJsonHasTheDocumentedKeys) {
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 1 0\nf 1 2 3\nl 1 2\np 3\n");
  const CliRun r = run_cli({"info", obj, "--json"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  for (const char* key : {"vertices", "triangles", "lines", "points", "objects", "degenerate", "bbox", "seconds", "peak_rss_bytes"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["vertices"], 4);
  EXPECT_EQ(j["vertices_welded"], 3);
  EXPECT_EQ(j["unused_vertices"], 1);
  EXPECT_EQ(j["triangles"], 1);
  EXPECT_EQ(j["lines"], 1);
  EXPECT_EQ(j["points"], 1);
  EXPECT_EQ(j["bbox"]["max"][1], 1.0);
  EXPECT_TRUE(r.err.empty()) << r.err;  // quiet when stderr is not a terminal
}

TEST(Cli, UsageErrorsExit64) {
  test::TempDir tmp;
  const std::string obj = tmp.write("t.obj", "v 0 0 0\n");
  EXPECT_EQ(run_cli({}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"frobnicate"}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"info"}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"info", obj, "--memory", "lots"}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"info", obj, "--memory", "1M"}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"info", obj, "--threads", "-3"}, tmp).exit_code, 64);
  EXPECT_EQ(run_cli({"info", obj, "--progress", "loud"}, tmp).exit_code, 64);
  const CliRun r = run_cli({"info", tmp.write("scene.xyz", "1 2 3\n")}, tmp);
  EXPECT_EQ(r.exit_code, 64);
  EXPECT_NE(r.err.find("unrecognised format"), std::string::npos) << r.err;
}

// The CLI runs with the allocator's large blocks in transparent huge pages (use_huge_pages in
// tools/lodstream_cli.cpp): it sets glibc.malloc.hugetlb=1 and executes itself again, keeping the user's
// other tunables, and leaves a user's own glibc.malloc.hugetlb alone (=0: the opt-out). Whether a block
// may take huge pages is checked where the kernel's THP mode is "madvise" (the default), the one mode in
// which the tunable decides it.
TEST(Cli, RunsWithHugePagesUnlessTheUserSaysOtherwise) {
  test::TempDir tmp;
  const bool madvise = test::read_file("/sys/kernel/mm/transparent_hugepage/enabled").find("[madvise]") != std::string::npos;
  const char* saved = std::getenv("GLIBC_TUNABLES");
  const std::string kept = saved ? saved : "";
  auto run = [&](const char* tunables) {
    if (tunables) ::setenv("GLIBC_TUNABLES", tunables, 1);
    else ::unsetenv("GLIBC_TUNABLES");
    ::setenv("LODSTREAM_TEST_HUGE_PAGES", "1", 1);
    const CliRun r = run_cli({}, tmp);
    ::unsetenv("LODSTREAM_TEST_HUGE_PAGES");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.out;
  };
  const std::string none = run(nullptr), other = run("glibc.malloc.mmap_threshold=1048576"), off = run("glibc.malloc.hugetlb=0");
  if (saved) ::setenv("GLIBC_TUNABLES", kept.c_str(), 1);
  else ::unsetenv("GLIBC_TUNABLES");
  EXPECT_EQ(none.rfind("tunables=glibc.malloc.hugetlb=1 ", 0), 0u) << none;
  EXPECT_EQ(other.rfind("tunables=glibc.malloc.mmap_threshold=1048576:glibc.malloc.hugetlb=1 ", 0), 0u) << other;
  EXPECT_EQ(off.rfind("tunables=glibc.malloc.hugetlb=0 ", 0), 0u) << off;
  if (madvise) {
    EXPECT_NE(none.find("thp_eligible=1"), std::string::npos) << none;
    EXPECT_NE(other.find("thp_eligible=1"), std::string::npos) << other;
    EXPECT_NE(off.find("thp_eligible=0"), std::string::npos) << off;
  } else {
    std::printf("notice: the kernel's THP mode is not madvise: only the tunables are checked\n");
  }
}

TEST(Cli, ProgressJsonIsOneObjectPerLine) {
  test::TempDir tmp;
  const CliRun r = run_cli({"info", grid_obj(tmp, 100), "--progress", "json", "--chunk-bytes", "4K"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::istringstream lines(r.err);
  std::string line;
  int n = 0;
  double last_ingest = -1;
  while (std::getline(lines, line)) {
    const auto j = nlohmann::json::parse(line);
    ASSERT_TRUE(j.contains("stage") && j.contains("fraction")) << line;
    if (j["stage"] == "ingest") {
      EXPECT_GE(j["fraction"].get<double>(), last_ingest);
      last_ingest = j["fraction"].get<double>();
    }
    ++n;
  }
  EXPECT_GT(n, 3);
  EXPECT_EQ(last_ingest, 1.0);
}

// --memory caps VmHWM (mapped pages included) for an input several times larger than the cap.
TEST(Cli, PeakMemoryStaysUnderTheCap) {
  test::TempDir tmp;
  const std::string obj = grid_obj(tmp, 1200);  // ~1.44 M quads, ~100 MB of OBJ
  ASSERT_GT(fs::file_size(obj), 64u << 20);
  const CliRun r = run_cli({"info", obj, "--json", "--memory", "64M"}, tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["triangles"], 2 * 1200 * 1200);
  EXPECT_LE(j["peak_rss_bytes"].get<uint64_t>(), uint64_t{64} << 20);
  for (const auto& s : j["stages"]) EXPECT_LE(s["peak_rss_bytes"].get<uint64_t>(), uint64_t{64} << 20) << s["name"];
}

TEST(Cli, SigintExits130AndLeavesNoPartialFile) {
  test::TempDir tmp;
  const std::string obj = grid_obj(tmp, 1200);
  const std::string work = tmp.file("work");
  const CliRun r = run_cli({"info", obj, "--work", work, "--chunk-bytes", "64K", "--threads", "1"}, tmp, 150);
  ASSERT_EQ(r.exit_code, 130) << r.err;
  EXPECT_NE(r.err.find("cancelled"), std::string::npos) << r.err;
  for (const auto& e : fs::recursive_directory_iterator(work)) {
    const std::string name = e.path().filename().string();
    EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
    EXPECT_NE(name, "store.json");
  }
}

// A full disk while writing the store (past the free-space check): exit 74, one line naming the file,
// nothing left under a final name and no partial file. Needs a 2 MiB tmpfs, so it runs only where
// mounting is allowed (root).
TEST(Cli, DiskFullExits74AndLeavesNothingBehind) {
  test::TempDir tmp;
  const std::string mnt = tmp.file("tiny");
  fs::create_directories(mnt);
  if (geteuid() != 0 || mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=2m") != 0)
    GTEST_SKIP() << "skipped: cannot mount a small tmpfs here (needs root)";
  const std::string sample = test::source_dir() + "/tests/data/sample-room.ply";
  const CliRun r = run_cli({"info", sample, "--work", mnt + "/w", "--no-space-check"}, tmp);
  std::vector<std::string> left;
  for (const auto& e : fs::recursive_directory_iterator(mnt))
    if (e.is_regular_file()) left.push_back(e.path().filename().string());
  umount(mnt.c_str());
  EXPECT_EQ(r.exit_code, 74) << r.err;
  EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_TRUE(left.empty()) << "left behind: " << left.front();
}

}  // namespace
}  // namespace lodstream

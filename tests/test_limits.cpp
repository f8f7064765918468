// The resource contracts as an operator checks them from outside the process: peak memory as a parent
// sees it (wait4's ru_maxrss, the same figure /usr/bin/time -v prints), and disk space (the work
// directory's size, the free-space check before a run, a disk that fills mid-run).
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sched.h>
#include <spawn.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

struct MeasuredRun {
  int exit_code = -1;
  uint64_t max_rss_bytes = 0;  // the child's ru_maxrss, as its parent sees it
  std::string err;
};

// Runs `lodstream args...` as a child (posix_spawn) and reaps it with wait4, which reports the child's
// peak resident set: what /usr/bin/time -v and any supervisor see.
MeasuredRun run_measured(std::vector<std::string> args, const test::TempDir& tmp) {
  args.insert(args.begin(), LODSTREAM_CLI);
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string out = tmp.file("stdout"), err = tmp.file("stderr");
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid;
  EXPECT_EQ(posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&fa);
  int status = 0;
  rusage ru{};
  EXPECT_EQ(wait4(pid, &status, 0, &ru), pid);
  MeasuredRun r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.max_rss_bytes = static_cast<uint64_t>(ru.ru_maxrss) << 10;  // Linux: KiB
  r.err = test::read_file(err);
  return r;
}

Json read_json(const std::string& path) { return Json::parse(test::read_file(path)); }

// The figures a parent sees against the job's own: ru_maxrss within the cap, the JSON's peak equal to it
// (both are the kernel's high-water mark; the JSON's is read just before the file is written, and the
// little the process does after that can raise the mark by a few pages at most), and every sampled stage
// peak at most the run's.
void expect_memory_figures(const MeasuredRun& r, const Json& j, uint64_t cap) {
  constexpr uint64_t kSlack = 64 << 10;
  EXPECT_LE(r.max_rss_bytes, cap);
  const uint64_t peak = j.at("peak_rss_bytes").get<uint64_t>();
  EXPECT_LE(peak, r.max_rss_bytes);
  EXPECT_LE(r.max_rss_bytes - std::min(peak, r.max_rss_bytes), kSlack) << "JSON " << peak << ", parent " << r.max_rss_bytes;
  for (const Json& st : j.at("stages")) {
    EXPECT_GT(st.at("peak_rss_bytes").get<uint64_t>(), 0u) << st;
    EXPECT_LE(st.at("peak_rss_bytes").get<uint64_t>(), peak) << st;
  }
}

TEST(Limits, SimplifyAndReportPeaksAreWhatTheParentSees) {
  test::TempDir tmp;
  const std::string lods = tmp.file("lods"), rep = tmp.file("report");
  const MeasuredRun s = run_measured({"simplify", sample_room(), "-o", lods, "--memory", "64M", "--progress", "none"}, tmp);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  expect_memory_figures(s, read_json(lods + "/manifest.json"), 64ull << 20);

  const MeasuredRun r = run_measured({"report", lods, "-o", rep, "--memory", "128M", "--views", "4", "--resolution", "64",
                                      "--samples", "2000", "--html-views", "1", "--progress", "none"},
                                     tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  expect_memory_figures(r, read_json(rep + "/report.json"), 128ull << 20);
}

}  // namespace
}  // namespace lodstream

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

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

Json read_json(const std::string& path) { return Json::parse(test::read_file(path)); }

// The figures a parent sees against the job's own: ru_maxrss within the cap, the JSON's peak equal to it
// (both are the kernel's high-water mark; the JSON's is read just before the file is written, and the
// little the process does after that can raise the mark by a few pages at most; the kernel keeps RSS in
// per-CPU counters that are folded in batches, so either figure may also be a few dozen pages off the
// other: seen 68 KiB above the parent's), and every sampled stage peak at most the run's.
void expect_memory_figures(const test::CliRun& r, const Json& j, uint64_t cap) {
  constexpr uint64_t kSlack = 256 << 10;
  EXPECT_LE(r.max_rss_bytes, cap);
  const uint64_t peak = j.at("peak_rss_bytes").get<uint64_t>();
  EXPECT_LE(peak, r.max_rss_bytes + kSlack);
  EXPECT_LE(r.max_rss_bytes - std::min(peak, r.max_rss_bytes), kSlack) << "JSON " << peak << ", parent " << r.max_rss_bytes;
  for (const Json& st : j.at("stages")) {
    EXPECT_GT(st.at("peak_rss_bytes").get<uint64_t>(), 0u) << st;
    EXPECT_LE(st.at("peak_rss_bytes").get<uint64_t>(), peak) << st;
  }
}

TEST(Limits, SimplifyAndReportPeaksAreWhatTheParentSees) {
  test::TempDir tmp;
  const std::string lods = tmp.file("lods"), rep = tmp.file("report");
  const test::CliRun s = test::run_cli({"simplify", sample_room(), "-o", lods, "--memory", "64M", "--progress", "none"}, tmp);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  expect_memory_figures(s, read_json(lods + "/manifest.json"), 64ull << 20);

  const test::CliRun r = test::run_cli({"report", lods, "-o", rep, "--memory", "128M", "--views", "4", "--resolution", "64",
                                      "--samples", "2000", "--html-views", "1", "--progress", "none"},
                                     tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  expect_memory_figures(r, read_json(rep + "/report.json"), 128ull << 20);
}

// Bytes of the regular files under `dir`, and their paths relative to it.
std::map<std::string, uint64_t> files_under(const std::string& dir) {
  std::map<std::string, uint64_t> files;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_regular_file()) files[fs::relative(it->path(), dir).string()] = it->file_size();
  return files;
}

uint64_t total_bytes(const std::map<std::string, uint64_t>& files) {
  uint64_t n = 0;
  for (const auto& [name, bytes] : files) n += bytes;
  return n;
}

bool write_text(const char* path, const std::string& text) {
  const int fd = open(path, O_WRONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  close(fd);
  return ok;
}

// Mounts of this test process's own, invisible to the rest of the machine and gone with the process: a
// mount namespace (as root), or a user namespace mapping this user to root inside it (unprivileged, where
// the kernel allows it). The CLI children inherit it. Needs a single-threaded process, so a gtest binary
// that ran other tests first (TBB threads) falls back to mounting in the host's namespace when root.
// Returns "" when done, else why not.
std::string private_mounts() {
  static const std::string why = [] {
    if (unshare(CLONE_NEWNS) != 0) {
      const uid_t uid = getuid();
      const gid_t gid = getgid();
      if (unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0) return std::string("unshare: ") + std::strerror(errno);
      if (!write_text("/proc/self/setgroups", "deny") || !write_text("/proc/self/uid_map", fmt::format("0 {} 1", uid)) ||
          !write_text("/proc/self/gid_map", fmt::format("0 {} 1", gid)))
        return std::string("cannot map the user namespace: ") + std::strerror(errno);
    }
    // Mounts below stay in this namespace rather than propagate to the host's.
    if (mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0)
      return std::string("cannot make mounts private: ") + std::strerror(errno);
    return std::string();
  }();
  return why;
}

// A tmpfs of a given size: a disk that fills up. Unmounted with the object.
class SmallDisk {
 public:
  explicit SmallDisk(std::string dir) : dir_(std::move(dir)) { fs::create_directories(dir_); }
  ~SmallDisk() {
    if (mounted_) umount2(dir_.c_str(), MNT_DETACH);
  }
  // Returns "" when mounted, else why not.
  std::string mount_size(uint64_t bytes) {
    const std::string why = private_mounts();
    if (!why.empty() && geteuid() != 0) return why;
    if (mount("tmpfs", dir_.c_str(), "tmpfs", 0, fmt::format("size={}", bytes).c_str()) != 0)
      return std::string("mount tmpfs: ") + std::strerror(errno);
    mounted_ = true;
    return std::string();
  }
  bool resize(uint64_t bytes) {
    return mount("tmpfs", dir_.c_str(), "tmpfs", MS_REMOUNT, fmt::format("size={}", bytes).c_str()) == 0;
  }
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
  bool mounted_ = false;
};

#define LODSTREAM_MOUNT_OR_SKIP(disk, bytes)                                                              \
  if (const std::string why = (disk).mount_size(bytes); !why.empty())                                    \
  GTEST_SKIP() << "skipped: cannot mount a small tmpfs here (" << why << ")"

std::vector<std::string> simplify_args(const std::string& out, const std::string& work) {
  return {"simplify", sample_room(), "-o", out, "--work", work, "--progress", "none"};
}

TEST(Limits, WorkDirectorySizeIsReported) {
  test::TempDir tmp;
  const std::string out = tmp.file("out"), work = tmp.file("work");
  const test::CliRun r = test::run_cli(simplify_args(out, work), tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json w = read_json(out + "/manifest.json").at("work_dir");
  const uint64_t bytes = total_bytes(files_under(work));
  EXPECT_EQ(w.at("bytes").get<uint64_t>(), bytes);
  EXPECT_EQ(w.at("input_bytes").get<uint64_t>(), fs::file_size(sample_room()));
  EXPECT_DOUBLE_EQ(w.at("ratio").get<double>(), static_cast<double>(bytes) / static_cast<double>(fs::file_size(sample_room())));
  uint64_t sum = 0;
  for (const auto& [name, n] : w.at("entries").items()) {
    const std::string path = work + "/" + name;
    EXPECT_EQ(n.get<uint64_t>(), fs::is_directory(path) ? total_bytes(files_under(path)) : fs::file_size(path)) << name;
    sum += n.get<uint64_t>();
  }
  EXPECT_EQ(sum, bytes);
  EXPECT_TRUE(w.at("entries").contains("store"));

  const test::CliRun info = test::run_cli({"info", sample_room(), "--work", work, "--json"}, tmp);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const Json iw = Json::parse(info.out).at("work_dir");
  EXPECT_EQ(iw.at("bytes").get<uint64_t>(), total_bytes(files_under(work)));
  EXPECT_GT(iw.at("entries").at("store").get<uint64_t>(), 0u);
}

TEST(Limits, ARunThatCannotFitStopsBeforeWritingAnything) {
  test::TempDir tmp;
  SmallDisk disk(tmp.file("disk"));
  LODSTREAM_MOUNT_OR_SKIP(disk, 1 << 20);
  for (const std::string cmd : {"simplify", "info"}) {
    const std::vector<std::string> args =
        cmd == "simplify" ? simplify_args(disk.dir() + "/out", disk.dir() + "/work")
                          : std::vector<std::string>{"info", sample_room(), "--work", disk.dir() + "/work"};
    const test::CliRun r = test::run_cli(args, tmp);
    EXPECT_EQ(r.exit_code, 74) << cmd << ": " << r.err;
    EXPECT_NE(r.err.find("not enough free disk space"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("MB free"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_TRUE(files_under(disk.dir()).empty()) << cmd << " wrote " << files_under(disk.dir()).begin()->first;
  }
}

// The disk fills at several points of a run (the store, the weight index, the cluster maps, the
// outputs): each run exits 74 with one line, leaves no partial file and no file under a final name that
// differs from a complete run's; a rerun on the same work directory, with room again, reuses every stage
// the failed run finished and writes the same bytes.
TEST(Limits, ADiskThatFillsMidRunExits74AndTheRerunResumes) {
  test::TempDir tmp;
  const std::string ref_out = tmp.file("ref-out"), ref_work = tmp.file("ref-work");
  const test::CliRun ref = test::run_cli(simplify_args(ref_out, ref_work), tmp);
  ASSERT_EQ(ref.exit_code, 0) << ref.err;
  std::map<std::string, std::string> expected;
  for (const auto& [name, bytes] : files_under(ref_out))
    if (name != "manifest.json") expected[name] = test::read_file(ref_out + "/" + name);
  const uint64_t total = total_bytes(files_under(ref_work)) + total_bytes(files_under(ref_out));

  for (const double fraction : {0.1, 0.22, 0.45, 0.75, 0.95}) {
    SCOPED_TRACE(fraction);
    SmallDisk disk(tmp.file(fmt::format("disk-{}", fraction)));
    LODSTREAM_MOUNT_OR_SKIP(disk, static_cast<uint64_t>(fraction * static_cast<double>(total)) / 4096 * 4096);
    const std::string out = disk.dir() + "/out", work = disk.dir() + "/work";
    std::vector<std::string> args = simplify_args(out, work);
    args.push_back("--no-space-check");
    const test::CliRun r = test::run_cli(args, tmp);
    EXPECT_EQ(r.exit_code, 74) << r.err;
    EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    for (const auto& [name, bytes] : files_under(disk.dir()))
      EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
    for (const auto& [name, bytes] : files_under(out)) {
      EXPECT_NE(name, "manifest.json");
      if (expected.count(name)) {
        EXPECT_TRUE(test::read_file(out + "/" + name) == expected[name]) << name << " differs";
      }
    }
    const std::map<std::string, bool> done{{"ingest", fs::exists(work + "/store/store.json")},
                                           {"grade", fs::exists(work + "/grade.json")},
                                           {"cluster", fs::exists(work + "/cluster.json")}};
    std::printf("disk of %.0f%% of a run's bytes: %s; stages done:%s%s%s\n", 100 * fraction, r.err.substr(0, r.err.find('\n')).c_str(),
                done.at("ingest") ? " ingest" : "", done.at("grade") ? " grade" : "", done.at("cluster") ? " cluster" : "");

    ASSERT_TRUE(disk.resize(4 * total + (1 << 20)));
    const test::CliRun again = test::run_cli(args, tmp);
    ASSERT_EQ(again.exit_code, 0) << again.err;
    for (const auto& [name, bytes] : expected)
      EXPECT_TRUE(test::read_file(out + "/" + name) == bytes) << name << " differs after the rerun";
    for (const Json& st : read_json(out + "/manifest.json").at("stages")) {
      const auto it = done.find(st.at("name").get<std::string>());
      if (it != done.end() && it->second) {
        EXPECT_TRUE(st.at("reused").get<bool>()) << st;
      }
    }
    for (const auto& [name, bytes] : files_under(disk.dir()))
      EXPECT_EQ(name.find("scratch-"), std::string::npos) << name << " left behind";
  }
}

}  // namespace
}  // namespace lodstream

// Malformed input through the CLI: every file of tests/data/malformed/ (listed with its expected exit
// code and a substring of the message in EXPECTED.tsv) must end with exactly one line on stderr,
// "lodstream: " + the file path + a location, the right exit code, nothing on stdout, within a second, and
// leave no store.json or *.partial file in the work directory. Plus the cases that need no file: a missing
// file and a directory (66), an unrecognised format (64).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "test_util.h"

extern char** environ;

namespace lodstream::test {
namespace {

namespace fs = std::filesystem;

std::string corpus_dir() { return source_dir() + "/tests/data/malformed"; }

struct Row {
  std::string file;
  int exit_code = 0;
  std::string substring;
};

void PrintTo(const Row& r, std::ostream* os) { *os << r.file; }

// EXPECTED.tsv: FILE <tab> EXIT CODE <tab> MESSAGE SUBSTRING; '#' lines and blank lines are comments.
std::vector<Row> load_rows() {
  std::vector<Row> rows;
  std::ifstream in(corpus_dir() + "/EXPECTED.tsv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    Row r;
    std::string code;
    std::getline(fields, r.file, '\t');
    std::getline(fields, code, '\t');
    std::getline(fields, r.substring);
    r.exit_code = std::atoi(code.c_str());
    rows.push_back(r);
  }
  return rows;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct CliRun {
  int exit_code = -1;  // the exit status, or -signal
  std::string out, err;
  double seconds = 0;
  std::string work;
};

// `lodstream info FILE --progress none --work DIR/work`, stdout and stderr to files. A run that has not
// ended after 20 s is killed (and fails the time check).
CliRun run_info(const std::string& file, const TempDir& dir) {
  CliRun r;
  r.work = dir.file("work");
  const std::string out_path = dir.file("stdout"), err_path = dir.file("stderr");
  std::vector<std::string> args = {LODSTREAM_CLI, "info", file, "--progress", "none", "--work", r.work};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    ADD_FAILURE() << "cannot run " << argv[0] << ": " << std::strerror(rc);
    return r;
  }
  int status = 0;
  for (;;) {
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (std::chrono::steady_clock::now() - t0 > std::chrono::seconds(20)) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? -WTERMSIG(status) : -1;
  r.out = read_file(out_path);
  r.err = read_file(err_path);
  return r;
}

// The checks every failing run must pass.
void check_failure(const CliRun& r, const std::string& file, int exit_code, const std::string& substring) {
  EXPECT_EQ(r.exit_code, exit_code) << "stderr: " << r.err;
  EXPECT_EQ(r.out, "") << "stdout must be empty";
  ASSERT_FALSE(r.err.empty());
  EXPECT_EQ(r.err.back(), '\n') << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr must be one line: " << r.err;
  EXPECT_EQ(r.err.rfind("lodstream: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find(file), std::string::npos) << "the message must name " << file << ": " << r.err;
  EXPECT_NE(r.err.find(substring), std::string::npos) << "the message must contain '" << substring << "': " << r.err;
  EXPECT_LT(r.seconds, 1.0) << "took " << r.seconds << " s";
  std::error_code ec;
  if (fs::exists(r.work, ec)) {
    for (const auto& entry : fs::recursive_directory_iterator(r.work, ec)) {
      const std::string name = entry.path().filename().string();
      EXPECT_NE(name, "store.json") << "left behind: " << entry.path();
      EXPECT_FALSE(name.size() >= 8 && name.compare(name.size() - 8, 8, ".partial") == 0)
          << "left behind: " << entry.path();
    }
  }
}

class MalformedFile : public ::testing::TestWithParam<Row> {};

TEST_P(MalformedFile, FailsWithOneLineNamingTheLocation) {
  const Row& row = GetParam();
  const std::string file = corpus_dir() + "/" + row.file;
  ASSERT_TRUE(fs::is_regular_file(file)) << file << " is listed in EXPECTED.tsv but missing";
  TempDir dir;
  check_failure(run_info(file, dir), file, row.exit_code, row.substring);
}

std::string row_name(const ::testing::TestParamInfo<Row>& info) {
  std::string name = info.param.file;
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return name;
}

INSTANTIATE_TEST_SUITE_P(Malformed, MalformedFile, ::testing::ValuesIn(load_rows()), row_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(MalformedFile);

TEST(MalformedCorpus, EveryFileHasARowAndEveryRowAFile) {
  const std::vector<Row> rows = load_rows();
  ASSERT_FALSE(rows.empty()) << corpus_dir() << "/EXPECTED.tsv is missing or empty";
  std::set<std::string> listed;
  for (const Row& r : rows) {
    EXPECT_TRUE(listed.insert(r.file).second) << r.file << " is listed twice";
    EXPECT_TRUE(fs::is_regular_file(corpus_dir() + "/" + r.file)) << r.file << " is listed but missing";
    EXPECT_TRUE(r.exit_code == 64 || r.exit_code == 65 || r.exit_code == 66) << r.file << ": exit " << r.exit_code;
    EXPECT_FALSE(r.substring.empty()) << r.file << " has no expected message substring";
  }
  for (const auto& entry : fs::directory_iterator(corpus_dir())) {
    const std::string name = entry.path().filename().string();
    if (name == "EXPECTED.tsv") continue;
    EXPECT_TRUE(listed.count(name)) << name << " is in the corpus but not in EXPECTED.tsv";
  }
}

TEST(MalformedCli, MissingFileIsNoInput) {
  TempDir dir;
  const std::string file = dir.file("does-not-exist.obj");
  check_failure(run_info(file, dir), file, 66, "cannot open");
}

TEST(MalformedCli, DirectoryIsNoInput) {
  TempDir dir;
  const std::string file = dir.file("a-directory.ply");
  fs::create_directories(file);
  check_failure(run_info(file, dir), file, 66, "is a directory");
}

TEST(MalformedCli, UnrecognisedFormatIsUsage) {
  TempDir dir;
  const std::string file = dir.write("points.xyz", "1 2 3\n4 5 6\n");
  check_failure(run_info(file, dir), file, 64, "unrecognised format");
}

}  // namespace
}  // namespace lodstream::test

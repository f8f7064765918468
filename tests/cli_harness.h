// Runs the lodstream CLI (the LODSTREAM_CLI compile definition) as a user would: a child process with
// stdout and stderr captured to files, optionally interrupted with SIGINT.
#pragma once

#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "test_util.h"

extern char** environ;

namespace lodstream::test {

// A whole file as bytes ("" when it cannot be read).
inline std::string read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

struct CliRun {
  int exit_code = -1;  // 128 + signal when killed by one
  std::string out, err;
  uint64_t max_rss_bytes = 0;  // the child's ru_maxrss (wait4), as /usr/bin/time -v and any parent see it
};

// Runs `lodstream args...`; with sigint_after_ms >= 0, sends SIGINT after that many milliseconds.
inline CliRun run_cli(std::vector<std::string> args, const TempDir& tmp, int sigint_after_ms = -1) {
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
  if (sigint_after_ms >= 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(sigint_after_ms));
    kill(pid, SIGINT);
  }
  int status = 0;
  rusage ru{};
  EXPECT_EQ(wait4(pid, &status, 0, &ru), pid);
  CliRun r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.max_rss_bytes = static_cast<uint64_t>(ru.ru_maxrss) << 10;  // Linux: KiB
  r.out = read_file(out);
  r.err = read_file(err);
  return r;
}

}  // namespace lodstream::test

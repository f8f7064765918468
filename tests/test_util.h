// Shared test helpers: temporary files and directories, the path of ../shared/data.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <string_view>

namespace lodstream::test {

// A fresh directory under the build's temp area, removed with the object.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    const char* base = std::getenv("TMPDIR");
    path_ = std::filesystem::path(base ? base : "/tmp") /
            ("lodstream-test-" + std::to_string(getpid()) + "-" + std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string file(std::string_view name) const { return (path_ / name).string(); }
  std::string write(std::string_view name, std::string_view contents) const {
    const std::string p = file(name);
    std::ofstream(p, std::ios::binary).write(contents.data(), static_cast<std::streamsize>(contents.size()));
    return p;
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// ../shared/data beside the repository, or empty when absent (a user's machine). LODSTREAM_SHARED_DATA
// overrides. Tests that need it call GTEST_SKIP() with a notice when this is empty.
inline std::string shared_data_dir() {
  const char* env = std::getenv("LODSTREAM_SHARED_DATA");
  const std::filesystem::path p =
      env && *env ? std::filesystem::path(env) : std::filesystem::path(LODSTREAM_SOURCE_DIR) / ".." / "shared" / "data";
  return std::filesystem::is_directory(p) ? std::filesystem::canonical(p).string() : std::string();
}

inline std::string source_dir() { return LODSTREAM_SOURCE_DIR; }

// Every file of `dir` (not its subdirectories' files), name to bytes: two directories compare as maps.
inline std::map<std::string, std::string> read_dir(const std::filesystem::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    std::ifstream f(e.path(), std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    files[e.path().filename().string()] = ss.str();
  }
  return files;
}

}  // namespace lodstream::test

#define LODSTREAM_REQUIRE_SHARED_DATA(dir)                                                          \
  const std::string dir = ::lodstream::test::shared_data_dir();                                     \
  if (dir.empty()) GTEST_SKIP() << "skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)"

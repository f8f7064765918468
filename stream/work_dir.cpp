#include "stream/work_dir.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "core/status.h"

namespace lodstream::stream {

namespace fs = std::filesystem;

namespace {
void make_dirs(const std::string& path) {
  std::error_code ec;
  fs::create_directories(path, ec);
  if (ec) fail(Status::io_error, path + ": cannot create work directory: " + ec.message());
  if (!fs::is_directory(path, ec)) fail(Status::io_error, path + ": work directory is not a directory");
  if (access(path.c_str(), W_OK) != 0)
    fail(Status::io_error, path + ": work directory is not writable: " + std::strerror(errno));
}

// Scratch files are named scratch-STEM-PID-N (WorkDir::scratch). A process removes its own when done, so
// one whose PID is no longer running was left by a killed run and is never read again; a live process's
// (another job on the same work directory) is left alone.
void remove_stale_scratch(const std::string& dir) {
  std::error_code ec;
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("scratch-", 0) != 0) continue;
    const size_t last = name.rfind('-');
    const size_t before = last == std::string::npos || last == 0 ? std::string::npos : name.rfind('-', last - 1);
    if (before == std::string::npos) continue;
    char* end = nullptr;
    const long pid = std::strtol(name.c_str() + before + 1, &end, 10);
    if (end != name.c_str() + last || pid <= 0) continue;
    if (pid == getpid() || (::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH)) {
      std::error_code rm;
      fs::remove(it->path(), rm);
    }
  }
}
}  // namespace

WorkDir::WorkDir(const std::string& path) {
  if (!path.empty()) {
    path_ = path;
    make_dirs(path_);
    remove_stale_scratch(path_);
    return;
  }
  const char* base = std::getenv("TMPDIR");
  std::string tmpl = std::string(base && *base ? base : "/tmp") + "/lodstream-XXXXXX";
  if (!mkdtemp(tmpl.data()))
    fail(Status::io_error, tmpl + ": cannot create temporary work directory: " + std::strerror(errno));
  path_ = tmpl;
  temporary_ = true;
}

WorkDir::~WorkDir() {
  if (temporary_) {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
}

std::string WorkDir::subdir(std::string_view name) const {
  const std::string p = file(name);
  make_dirs(p);
  return p;
}

std::string WorkDir::scratch(std::string_view stem) const {
  return file(std::string("scratch-") + std::string(stem) + "-" + std::to_string(getpid()) + "-" +
              std::to_string(scratch_counter_++));
}

void make_output_dir(const std::string& path) {
  std::error_code ec;
  std::filesystem::create_directories(path, ec);
  if (ec || !std::filesystem::is_directory(path))
    fail(Status::io_error, path + ": cannot create the output directory" + (ec ? ": " + ec.message() : ""));
}

void remove_summary(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
  if (ec) fail(Status::io_error, path + ": cannot remove the previous run's file: " + ec.message());
}

}  // namespace lodstream::stream

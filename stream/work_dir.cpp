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
// Scratch files are named scratch-<stem>-<pid>-<n> (WorkDir::scratch). Removes those of process `pid`,
// or with pid 0 those of processes that no longer run (a run killed mid-stage leaves its own behind).
void remove_scratch(const std::string& dir, pid_t pid) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("scratch-", 0) != 0) continue;
    const size_t last = name.rfind('-');
    const size_t before = last == std::string::npos || last == 0 ? std::string::npos : name.rfind('-', last - 1);
    if (before == std::string::npos) continue;
    char* digits_end = nullptr;
    const pid_t owner = static_cast<pid_t>(std::strtol(name.c_str() + before + 1, &digits_end, 10));
    if (digits_end != name.c_str() + last || owner <= 0) continue;
    const bool stale = pid ? owner == pid : owner == getpid() || (kill(owner, 0) != 0 && errno == ESRCH);
    std::error_code e2;
    if (stale) fs::remove(it->path(), e2);
  }
}
}  // namespace

WorkDir::WorkDir(const std::string& path) {
  if (!path.empty()) {
    path_ = path;
    make_dirs(path_);
    remove_scratch(path_, 0);
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
  std::error_code ec;
  if (temporary_) fs::remove_all(path_, ec);
  // A job that failed (a full disk, say) leaves no scratch behind to fill the disk of the rerun.
  else remove_scratch(path_, getpid());
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

void link_file(const std::string& from, const std::string& to) {
  std::error_code ec;
  std::filesystem::remove(to, ec);
  std::filesystem::create_hard_link(from, to, ec);
  if (ec) std::filesystem::copy_file(from, to, std::filesystem::copy_options::overwrite_existing, ec);
  if (ec) fail(Status::io_error, to + ": cannot write: " + ec.message());
}

}  // namespace lodstream::stream

// The job's work directory: the scene store and every intermediate file live here, so a stage can be
// rerun, resumed or inspected on its own. A temporary work directory is removed with the object; a kept
// one loses its scratch files (scratch()) with the object, and those of dead processes when opened.
#pragma once

#include <atomic>
#include <string>
#include <string_view>

namespace lodstream::stream {

class WorkDir {
 public:
  // Uses `path`, creating it if needed; an empty path makes a fresh temporary directory. Scratch files
  // left by a process that no longer runs (one killed with `kill -9`) are removed.
  // Throws Failure(io_error) if it cannot be created or written.
  explicit WorkDir(const std::string& path);
  WorkDir(const WorkDir&) = delete;
  WorkDir& operator=(const WorkDir&) = delete;
  ~WorkDir();

  const std::string& path() const { return path_; }
  std::string file(std::string_view name) const { return path_ + "/" + std::string(name); }
  // A subdirectory, created if needed.
  std::string subdir(std::string_view name) const;
  // A fresh name for a scratch file inside the directory (not created): scratch-STEM-PID-N.
  std::string scratch(std::string_view stem) const;

 private:
  std::string path_;
  bool temporary_ = false;
  mutable std::atomic<uint64_t> scratch_counter_{0};
};

// Creates a job's output directory (and its parents) if missing. Throws Failure(io_error) naming it when
// it cannot be created or is not a directory.
void make_output_dir(const std::string& path);

// Removes an output directory's summary file (manifest.json, report.json), which a job writes last so
// that its presence means the directory is complete, before the job writes any other file there: an
// older run's summary would otherwise vouch for a mix of its files and a killed run's. Throws
// Failure(io_error) naming it when it exists and cannot be removed.
void remove_summary(const std::string& path);

// Links (or, across file systems, copies) `from` to `to`, replacing it: a stage's file that another
// stage's file already holds. Throws Failure(io_error) naming `to`.
void link_file(const std::string& from, const std::string& to);

}  // namespace lodstream::stream

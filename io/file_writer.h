// Buffered sequential file output that never leaves a partial file under its final name: bytes go to
// `<path>.partial`, and commit() flushes and renames it into place. Every failure (disk full included)
// throws Failure(io_error) naming the file.
//
// Durability: a committed file survives the process being killed either way (the page cache holds it).
// Sync::durable also has commit() wait until the data (fdatasync) and then the rename (fsync of the
// directory) are on the disk, so that a finished job's outputs survive a power loss too; the user's
// output files use it. Work-directory files use Sync::none: a killed run resumes from them, but syncing
// gigabytes of scratch would cost more than redoing the job after the rare power loss.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace lodstream::io {

enum class Sync { none, durable };
// Who may write a path at once. one: this writer only (its temporary is `<path>.partial`). several: other
// processes or threads may write the same path with the same contents at the same time (weld units that
// each leave the bucket sizes they counted for the others): each writes its own temporary,
// `<path>.partial-<pid>-<thread>`, so that no writer's rename takes another's file; the last rename wins.
enum class Writers { one, several };

class FileWriter {
 public:
  FileWriter() = default;
  explicit FileWriter(const std::string& path, size_t buffer_bytes = 1 << 20, Sync sync = Sync::none,
                      Writers writers = Writers::one) {
    open(path, buffer_bytes, sync, writers);
  }
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;
  ~FileWriter();  // discards the partial file if commit() was not called

  void open(const std::string& path, size_t buffer_bytes = 1 << 20, Sync sync = Sync::none, Writers writers = Writers::one);
  void write(const void* data, size_t bytes);
  void write(std::string_view s) { write(s.data(), s.size()); }
  template <class T>
  void write_array(std::span<const T> values) {
    write(values.data(), values.size_bytes());
  }
  const std::string& path() const { return path_; }
  void commit();
  void discard();

 private:
  void flush();
  void write_through(const char* p, size_t bytes);
  std::string path_, partial_;  // the final name, and the temporary the bytes go to until commit()
  int fd_ = -1;
  std::vector<char> buffer_;
  size_t used_ = 0;
  Sync sync_ = Sync::none;
};

// Writes a whole small file atomically (temporary + rename).
void write_file_atomic(const std::string& path, std::string_view contents, Sync sync = Sync::none,
                       Writers writers = Writers::one);

// Reads a whole small file; throws Failure(io_error) on failure.
std::string read_small_file(const std::string& path);

}  // namespace lodstream::io

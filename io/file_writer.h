// Buffered sequential file output that never leaves a partial file under its final name: bytes go to
// `<path>.partial`, and commit() flushes, syncs the data to the file and renames it into place.
// Every failure (disk full included) throws Failure(io_error) naming the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace lodstream::io {

class FileWriter {
 public:
  FileWriter() = default;
  explicit FileWriter(const std::string& path, size_t buffer_bytes = 1 << 20) { open(path, buffer_bytes); }
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;
  ~FileWriter();  // discards the partial file if commit() was not called

  void open(const std::string& path, size_t buffer_bytes = 1 << 20);
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
  std::string path_;
  int fd_ = -1;
  std::vector<char> buffer_;
  size_t used_ = 0;
};

// Writes a whole small file atomically (temporary + rename).
void write_file_atomic(const std::string& path, std::string_view contents);

// Reads a whole small file; throws Failure(io_error) on failure.
std::string read_small_file(const std::string& path);

}  // namespace lodstream::io

// Read-only input file mapped in windows. Only the windows in use are mapped, so the resident pages of
// the input stay bounded by what the caller holds, whatever the file size.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace lodstream::io {

// A mapped byte range [begin, end) of a file. Move-only; unmaps on destruction.
class Window {
 public:
  Window() = default;
  Window(Window&& other) noexcept { *this = std::move(other); }
  Window& operator=(Window&& other) noexcept;
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;
  ~Window() { reset(); }

  const char* data() const { return data_; }  // the byte at file offset begin()
  uint64_t begin() const { return begin_; }
  uint64_t end() const { return end_; }
  uint64_t size() const { return end_ - begin_; }
  std::string_view view() const { return {data_, static_cast<size_t>(size())}; }
  void reset();

 private:
  friend class MappedFile;
  void* base_ = nullptr;      // page-aligned mapping
  size_t mapped_bytes_ = 0;
  const char* data_ = nullptr;
  uint64_t begin_ = 0, end_ = 0;
};

class MappedFile {
 public:
  // Opens `path` for reading. Throws Failure(no_input) if it is missing, unreadable or not a regular file.
  explicit MappedFile(const std::string& path);
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  ~MappedFile();

  const std::string& path() const { return path_; }
  uint64_t size() const { return size_; }
  int64_t mtime_ns() const { return mtime_ns_; }
  // How a window will be read. `sequential`: front to back once (a chunk of a column): the kernel is asked
  // to read the whole window ahead and to drop its pages early. `random`: at scattered offsets, and often
  // a whole column mapped again and again to drop its touched pages from the resident set: no advice, so
  // mapping costs nothing. Asking to read a whole column ahead at every remap made the kernel walk (and,
  // where the page cache cannot hold the store, read) gigabytes per remap on a 1 B-triangle scene.
  enum class Access { sequential, random };
  // Maps [begin, min(end, size())). An empty range gives an empty window. Thread-safe.
  Window map(uint64_t begin, uint64_t end, Access access = Access::sequential) const;
  // Copies bytes [begin, begin + bytes) into `out` (pread): for a pass that reads a file front to back in
  // small blocks on several threads, where a window mapped and unmapped a block costs page faults and,
  // at each unmap, a flush of every thread's TLB. Throws Failure(io_error) past the end. Thread-safe.
  void read(uint64_t begin, uint64_t bytes, void* out) const;

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
  int64_t mtime_ns_ = 0;
};

}  // namespace lodstream::io

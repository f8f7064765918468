// A file read and written at offsets (pread, pwrite): what several processes fill in place, each its own
// byte ranges of a file sized beforehand (stream/grade_shares.h's merge units, the weld map's units).
// Every failure throws Failure(io_error) naming the file.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <string>

#include "core/status.h"

namespace lodstream::io {

// Reads exactly `bytes` at `offset` of the open file `fd` (pread, retried where it stops short or is
// interrupted); Failure(io_error) naming `path` where it cannot.
inline void pread_all(int fd, void* data, size_t bytes, uint64_t offset, const std::string& path) {
  char* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd, p, std::min<size_t>(bytes, 1 << 30), static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      fail(Status::io_error, path + ": cannot read at byte " + std::to_string(offset) +
                                 (n < 0 ? std::string(": ") + std::strerror(errno) : std::string(": file shrank")));
    p += n, bytes -= static_cast<size_t>(n), offset += static_cast<uint64_t>(n);
  }
}

class OffsetFile {
 public:
  // `flags` as open(2)'s (O_RDONLY; O_WRONLY, with O_CREAT | O_TRUNC for a new file).
  OffsetFile(const std::string& path, int flags) : path_(path), fd_(::open(path.c_str(), flags | O_CLOEXEC, 0644)) {
    if (fd_ < 0) fail(Status::io_error, path_ + ": cannot open: " + std::strerror(errno));
  }
  OffsetFile(const OffsetFile&) = delete;
  OffsetFile& operator=(const OffsetFile&) = delete;
  ~OffsetFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  const std::string& path() const { return path_; }
  void read(void* data, size_t bytes, uint64_t offset) const { pread_all(fd_, data, bytes, offset, path_); }
  void write(const void* data, size_t bytes, uint64_t offset) const {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pwrite(fd_, p, std::min<size_t>(bytes, 1 << 30), static_cast<off_t>(offset));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail(Status::io_error, path_ + ": cannot write: " + std::strerror(n < 0 ? errno : ENOSPC));
      p += n, bytes -= static_cast<size_t>(n), offset += static_cast<uint64_t>(n);
    }
  }
  // Sets the file's size (new bytes read as zeros).
  void resize(uint64_t bytes) const {
    if (::ftruncate(fd_, static_cast<off_t>(bytes)) != 0) fail(Status::io_error, path_ + ": cannot size: " + std::strerror(errno));
  }
  // Record i of a file of fixed-size records.
  template <class Rec>
  Rec record(uint64_t i) const {
    Rec r;
    read(&r, sizeof r, i * sizeof r);
    return r;
  }
  // The first of the file's first `n` records (of type Rec) for which below(record) is false, where it is
  // true for a prefix of them and false after (a binary search: about log2(n) reads).
  template <class Rec, class Below>
  uint64_t partition_point(uint64_t n, Below&& below) const {
    uint64_t lo = 0, hi = n;
    while (lo < hi) {
      const uint64_t mid = lo + (hi - lo) / 2;
      if (below(record<Rec>(mid))) lo = mid + 1;
      else hi = mid;
    }
    return lo;
  }
  // Closes the file, reporting a write error the close reveals (a file system that writes back late).
  void close() {
    const int r = ::close(fd_);
    fd_ = -1;
    if (r != 0) fail(Status::io_error, path_ + ": cannot write: " + std::strerror(errno));
  }

 private:
  std::string path_;
  int fd_;
};

}  // namespace lodstream::io

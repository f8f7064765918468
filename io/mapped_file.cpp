#include "io/mapped_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "core/status.h"
#include "io/offset_file.h"

namespace lodstream::io {

Window& Window::operator=(Window&& other) noexcept {
  if (this != &other) {
    reset();
    base_ = other.base_;
    mapped_bytes_ = other.mapped_bytes_;
    data_ = other.data_;
    begin_ = other.begin_;
    end_ = other.end_;
    other.base_ = nullptr;
    other.mapped_bytes_ = 0;
    other.data_ = nullptr;
    other.begin_ = other.end_ = 0;
  }
  return *this;
}

void Window::reset() {
  if (base_) munmap(base_, mapped_bytes_);
  base_ = nullptr;
  mapped_bytes_ = 0;
  data_ = nullptr;
  begin_ = end_ = 0;
}

MappedFile::MappedFile(const std::string& path) : path_(path) {
  struct stat st {};
  if (stat(path.c_str(), &st) != 0) fail(Status::no_input, path + ": cannot open: " + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) fail(Status::no_input, path + ": cannot open: is a directory");
  if (!S_ISREG(st.st_mode)) fail(Status::no_input, path + ": cannot open: not a regular file");
  fd_ = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail(Status::no_input, path + ": cannot open: " + std::strerror(errno));
  size_ = static_cast<uint64_t>(st.st_size);
  mtime_ns_ = static_cast<int64_t>(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
}

MappedFile::~MappedFile() {
  if (fd_ >= 0) close(fd_);
}

Window MappedFile::map(uint64_t begin, uint64_t end, Access access) const {
  Window w;
  if (end > size_) end = size_;
  if (begin >= end) {
    w.begin_ = w.end_ = begin < size_ ? begin : size_;
    w.data_ = "";
    return w;
  }
  static const uint64_t page = static_cast<uint64_t>(sysconf(_SC_PAGESIZE));
  const uint64_t aligned = begin / page * page;
  const size_t bytes = static_cast<size_t>(end - aligned);
  void* p = mmap(nullptr, bytes, PROT_READ, MAP_PRIVATE, fd_, static_cast<off_t>(aligned));
  if (p == MAP_FAILED) fail(Status::no_input, path_ + ": cannot map: " + std::strerror(errno));
  if (access == Access::sequential) {
    // Advice values are not flags: give each on its own.
    madvise(p, bytes, MADV_SEQUENTIAL);
    madvise(p, bytes, MADV_WILLNEED);
  }
  w.base_ = p;
  w.mapped_bytes_ = bytes;
  w.data_ = static_cast<const char*>(p) + (begin - aligned);
  w.begin_ = begin;
  w.end_ = end;
  return w;
}

void MappedFile::read(uint64_t begin, uint64_t bytes, void* out) const {
  if (begin > size_ || bytes > size_ - begin)
    fail(Status::io_error, path_ + ": cannot read " + std::to_string(bytes) + " bytes at byte " + std::to_string(begin));
  pread_all(fd_, out, static_cast<size_t>(bytes), begin, path_);
}

}  // namespace lodstream::io

#include "io/file_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <algorithm>
#include <cstring>
#include <functional>
#include <string>
#include <thread>

#include "core/status.h"

namespace lodstream::io {

namespace {
[[noreturn]] void io_fail(const std::string& path, const char* what, int err) {
  fail(Status::io_error, path + ": cannot " + what + ": " + std::strerror(err));
}
// Makes a rename in the directory of `path` durable. The file itself is already in place, so a failure is
// reported (the caller asked for durability) but nothing is removed.
void sync_directory_of(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) io_fail(dir, "open the directory to sync", errno);
  int r;
  while ((r = ::fsync(fd)) != 0 && errno == EINTR) {
  }
  const int e = errno;
  ::close(fd);
  // Some file systems cannot sync a directory (EINVAL): the rename is then as durable as they make it.
  if (r != 0 && e != EINVAL) io_fail(dir, "sync the directory", e);
}
}  // namespace

FileWriter::~FileWriter() { discard(); }

void FileWriter::open(const std::string& path, size_t buffer_bytes, Sync sync, Writers writers) {
  discard();
  path_ = path;
  sync_ = sync;
  partial_ = writers == Writers::one
                 ? path + ".partial"
                 : path + ".partial-" + std::to_string(::getpid()) + "-" + std::to_string(std::hash<std::thread::id>{}(std::this_thread::get_id()));
  fd_ = ::open(partial_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) io_fail(partial_, "create", errno);
  buffer_.resize(buffer_bytes < 4096 ? 4096 : buffer_bytes);
  used_ = 0;
}

void FileWriter::write_through(const char* p, size_t bytes) {
  size_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::write(fd_, p + done, bytes - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      io_fail(partial_, "write", errno);
    }
    if (n == 0) io_fail(partial_, "write", ENOSPC);
    done += static_cast<size_t>(n);
  }
}

void FileWriter::flush() {
  write_through(buffer_.data(), used_);
  used_ = 0;
}

void FileWriter::write(const void* data, size_t bytes) {
  const char* p = static_cast<const char*>(data);
  if (bytes >= buffer_.size()) {
    // Large spans go straight to the kernel: copying them through the buffer first costs a memcpy.
    flush();
    write_through(p, bytes);
    return;
  }
  while (bytes > 0) {
    if (used_ == buffer_.size()) flush();
    const size_t n = std::min(bytes, buffer_.size() - used_);
    std::memcpy(buffer_.data() + used_, p, n);
    used_ += n;
    p += n;
    bytes -= n;
  }
}

void FileWriter::commit() {
  if (fd_ < 0) return;
  flush();
  const std::string& partial = partial_;
  if (sync_ == Sync::durable) {
    int r;
    while ((r = ::fdatasync(fd_)) != 0 && errno == EINTR) {
    }
    if (r != 0) {
      const int e = errno;
      ::close(fd_);
      fd_ = -1;
      ::unlink(partial.c_str());
      io_fail(partial, "sync", e);
    }
  }
  if (::close(fd_) != 0) {
    const int e = errno;
    fd_ = -1;
    ::unlink(partial.c_str());
    io_fail(partial, "close", e);
  }
  fd_ = -1;
  if (std::rename(partial.c_str(), path_.c_str()) != 0) {
    const int e = errno;
    ::unlink(partial.c_str());
    io_fail(path_, "rename into place", e);
  }
  if (sync_ == Sync::durable) sync_directory_of(path_);
}

void FileWriter::discard() {
  if (fd_ < 0) return;
  ::close(fd_);
  fd_ = -1;
  ::unlink(partial_.c_str());
}

void write_file_atomic(const std::string& path, std::string_view contents, Sync sync, Writers writers) {
  FileWriter w(path, contents.size() + 1, sync, writers);
  w.write(contents);
  w.commit();
}

std::string read_small_file(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) io_fail(path, "read", errno);
  std::string s;
  char buf[65536];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
  const bool bad = std::ferror(f);
  std::fclose(f);
  if (bad) io_fail(path, "read", EIO);
  return s;
}

}  // namespace lodstream::io

// Reading a sharded run's binary files: see task_file.h.
#include "stream/task_file.h"

#include <cerrno>
#include <cstring>

#include "core/status.h"

namespace lodstream::stream {

TaskFileReader::TaskFileReader(const std::string& path, const char (&magic)[8], std::string what)
    : path_(path), what_(std::move(what)) {
  f_ = std::fopen(path.c_str(), "rb");
  if (!f_) fail(Status::io_error, path + ": cannot open " + what_ + ": " + std::strerror(errno));
  char got[8];
  read(got, sizeof got);
  if (std::memcmp(got, magic, sizeof got) != 0) fail(Status::io_error, path + ": not " + what_ + " of this version");
}

TaskFileReader::~TaskFileReader() {
  if (f_) std::fclose(f_);
}

void TaskFileReader::read(void* data, size_t bytes) {
  if (bytes && std::fread(data, 1, bytes, f_) != bytes) fail(Status::io_error, path_ + ": " + what_ + " is cut short");
}

}  // namespace lodstream::stream

// The binary files the processes of a sharded run hand one another through the work directory (a task's
// parts, a report task's views and shares, a range ingest's segments, the wide levels' units of pass A):
// written in order with put / put_array / put_string, read back in the same order with a TaskFileReader.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "io/file_writer.h"

namespace lodstream::stream {

// A task's binary file, written in order: a value's bytes, an array or a string as its count then its
// elements.
template <class T>
void put(io::FileWriter& out, const T& v) {
  out.write(&v, sizeof(T));
}
template <class T>
void put_array(io::FileWriter& out, const std::vector<T>& v) {
  put(out, uint64_t{v.size()});
  if (!v.empty()) out.write(v.data(), v.size() * sizeof(T));
}
inline void put_string(io::FileWriter& out, const std::string& s) {
  put(out, uint64_t{s.size()});
  out.write(s);
}

// A task's binary file, read from its start: opened, its 8-byte magic checked, then read in order.
// Failure(io_error) naming the file and `what` it holds ("a task's parts") when it is missing, of
// another version or cut short.
class TaskFileReader {
 public:
  TaskFileReader(const TaskFileReader&) = delete;
  TaskFileReader& operator=(const TaskFileReader&) = delete;

 protected:
  TaskFileReader(const std::string& path, const char (&magic)[8], std::string what);
  ~TaskFileReader();
  void read(void* data, size_t bytes);
  std::string path_, what_;
  std::FILE* f_ = nullptr;
};

}  // namespace lodstream::stream

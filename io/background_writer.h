// Sequential file output whose writes into the kernel run on a thread of their own, so that a producer
// that is itself serial (the weight index's k-way merge) does not also wait for the page-cache copies:
// on this kind of machine those cost about as much as producing the bytes. Same contract as FileWriter,
// which it wraps: nothing under the final name before commit(), every failure a Failure(io_error).
//
// Two buffers: the caller fills one while the thread writes the other; a full buffer waits only for the
// previous one. A failure in the thread is rethrown by the caller's next write or commit.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <exception>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "io/file_writer.h"

namespace lodstream::io {

class BackgroundWriter {
 public:
  explicit BackgroundWriter(const std::string& path, size_t buffer_bytes = 8 << 20);
  BackgroundWriter(const BackgroundWriter&) = delete;
  BackgroundWriter& operator=(const BackgroundWriter&) = delete;
  ~BackgroundWriter();  // stops the thread; discards the partial file if commit() was not called

  void write(const void* data, size_t bytes);
  void commit();

 private:
  void hand_off();  // gives the filled buffer to the thread (after the previous one is written)
  void wait_idle(std::unique_lock<std::mutex>& lock);
  void run();

  FileWriter file_;
  std::vector<char> fill_, busy_;  // the caller's buffer, the thread's
  size_t used_ = 0;
  std::mutex mutex_;
  std::condition_variable cv_;
  size_t pending_ = 0;  // bytes of busy_ to write; 0 when the thread is idle
  bool stop_ = false;
  std::exception_ptr error_;
  std::thread thread_;
};

}  // namespace lodstream::io

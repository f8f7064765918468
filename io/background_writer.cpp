#include "io/background_writer.h"

#include <algorithm>
#include <cstring>

namespace lodstream::io {

BackgroundWriter::BackgroundWriter(const std::string& path, size_t buffer_bytes)
    // The wrapped writer's own buffer is small: the thread hands it whole buffers, which FileWriter passes
    // straight to the kernel.
    : file_(path, 64 << 10), fill_(std::max<size_t>(buffer_bytes, 4096)), busy_(fill_.size()) {
  thread_ = std::thread([this] { run(); });
}

BackgroundWriter::~BackgroundWriter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  // file_'s destructor discards the partial file unless commit() renamed it into place.
}

void BackgroundWriter::run() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    cv_.wait(lock, [this] { return pending_ > 0 || stop_; });
    if (pending_ == 0) return;  // stopped with nothing left to write
    const size_t bytes = pending_;
    lock.unlock();
    std::exception_ptr error;
    try {
      file_.write(busy_.data(), bytes);
    } catch (...) {
      error = std::current_exception();
    }
    lock.lock();
    if (error && !error_) error_ = error;
    pending_ = 0;
    cv_.notify_all();
  }
}

void BackgroundWriter::wait_idle(std::unique_lock<std::mutex>& lock) {
  cv_.wait(lock, [this] { return pending_ == 0; });
  if (error_) std::rethrow_exception(error_);
}

void BackgroundWriter::hand_off() {
  std::unique_lock<std::mutex> lock(mutex_);
  wait_idle(lock);
  if (used_ == 0) return;
  fill_.swap(busy_);
  pending_ = used_;
  used_ = 0;
  cv_.notify_all();
}

void BackgroundWriter::write(const void* data, size_t bytes) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    if (used_ == fill_.size()) hand_off();
    const size_t n = std::min(bytes, fill_.size() - used_);
    std::memcpy(fill_.data() + used_, p, n);
    used_ += n;
    p += n;
    bytes -= n;
  }
}

void BackgroundWriter::commit() {
  hand_off();
  {
    std::unique_lock<std::mutex> lock(mutex_);
    wait_idle(lock);
  }
  file_.commit();
}

}  // namespace lodstream::io

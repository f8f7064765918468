// Progress reporting and cancellation for every stage: wraps the user's ProgressFn. check() throws
// Failure(cancelled) as soon as the callback has returned false once; the pipelines call it per chunk.
#pragma once

#include <atomic>
#include <string>

#include "core/status.h"
#include "lodstream/lodstream.h"

namespace lodstream::stream {

class Progress {
 public:
  explicit Progress(const Options& options) : fn_(options.progress), user_(options.progress_user) {}
  // Thread-safe. Reports and throws Failure(cancelled) if the job is (or was) cancelled.
  void report(const char* stage, double fraction) {
    if (fn_ && !cancelled_.load(std::memory_order_relaxed) && !fn_(user_, stage, fraction))
      cancelled_.store(true, std::memory_order_relaxed);
    check();
  }
  void check() const {
    if (cancelled_.load(std::memory_order_relaxed)) fail(Status::cancelled, "cancelled");
  }

 private:
  ProgressFn fn_;
  void* user_;
  std::atomic<bool> cancelled_{false};
};

}  // namespace lodstream::stream

// Wall and process CPU time of a call, for the benchmarks in tools/ (the CPU from stream/job.h).
#pragma once

#include <chrono>

#include "stream/job.h"

namespace lodstream::bench {

struct Timing {
  double wall = 0, cpu = 0;
};

template <class F>
Timing timed(F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  const double c0 = stream::process_cpu_seconds();
  f();
  return {std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), stream::process_cpu_seconds() - c0};
}

}  // namespace lodstream::bench

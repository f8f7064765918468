// What every public entry point shares: stages timed and measured one by one, exceptions turned into a
// Result at the API boundary.
#pragma once

#include <algorithm>
#include <chrono>
#include <new>
#include <string>
#include <type_traits>
#include <vector>

#include <sys/resource.h>

#include <nlohmann/json.hpp>

#include "core/status.h"
#include "lodstream/lodstream.h"
#include "stream/memory.h"

namespace lodstream::stream {

// User plus system CPU seconds of the whole process so far (all threads).
inline double process_cpu_seconds() {
  rusage u{};
  if (getrusage(RUSAGE_SELF, &u) != 0) return 0;
  auto s = [](const timeval& t) { return double(t.tv_sec) + double(t.tv_usec) * 1e-6; };
  return s(u.ru_utime) + s(u.ru_stime);
}

// A stage as manifest.json, report.json and the grid report list it.
inline nlohmann::ordered_json stage_json(const StageStats& s) {
  return {{"name", s.name}, {"seconds", s.seconds}, {"cpu_seconds", s.cpu_seconds}, {"peak_rss_bytes", s.peak_rss_bytes},
          {"reused", s.reused}};
}

// Runs `body(StageStats&)` as the named stage and appends its time and peak memory to `stages`. The
// stage's peak is sampled (StagePeak): the process's VmHWM is never reset, so that outside tools see the
// whole run's peak.
template <class Body>
auto run_stage(std::vector<StageStats>* stages, const char* name, Body&& body) {
  release_free_memory();
  StagePeak peak;
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = process_cpu_seconds();
  StageStats st;
  st.name = name;
  auto finish = [&] {
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    st.cpu_seconds = process_cpu_seconds() - cpu0;
    // The kernel's resident counters are per-CPU and read approximately (a few pages either way), so a
    // sample can exceed the high-water mark read later; the true resident set never does.
    st.peak_rss_bytes = std::min(peak.bytes(), peak_rss_bytes());
    stages->push_back(st);
  };
  if constexpr (std::is_void_v<decltype(body(st))>) {
    body(st);
    finish();
  } else {
    auto r = body(st);
    finish();
    return r;
  }
}

template <class Job>
Result guarded(Job&& job) {
  try {
    job();
    return {};
  } catch (const Failure& f) {
    return {f.status(), f.what()};
  } catch (const std::bad_alloc&) {
    return {Status::internal, "out of memory (raise --memory or free memory)"};
  } catch (const std::exception& e) {
    return {Status::internal, std::string("internal error: ") + e.what()};
  } catch (...) {
    return {Status::internal, "internal error"};
  }
}

}  // namespace lodstream::stream

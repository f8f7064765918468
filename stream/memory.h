// Resident-memory accounting and the memory plan that every stage sizes its buffers from.
#pragma once

#include <cstdint>

#include "lodstream/lodstream.h"

namespace lodstream::stream {

uint64_t physical_memory_bytes();
// The process's peak resident set so far (VmHWM): what outside tools see (/usr/bin/time -v, a parent's
// getrusage ru_maxrss, cgroups). Never reset: a job's peak is the whole process's.
uint64_t peak_rss_bytes();
// The resident set now (/proc/self/statm), mapped file pages included; 0 if unknown.
uint64_t resident_bytes();

// Gives the heap's free pages back to the system (glibc malloc_trim). Freed memory otherwise stays in the
// resident set: the allocator keeps most of a stage's freed tables, and the next stage's larger blocks come
// from fresh pages beside them (measured on the 193 M-triangle city at --memory 1G: the emit stage peaked
// 150 MiB higher after the cluster stage than in a process that ran emit alone). Called between stages
// and between emit's passes; changes no output byte.
void release_free_memory();

// How often StagePeak samples the resident set.
inline constexpr unsigned kRssSampleMilliseconds = 5;

// The highest resident set while a stage runs, measured without touching VmHWM: while any StagePeak is
// alive, one process-wide sampler thread reads the resident set every kRssSampleMilliseconds and raises
// the peak of every live StagePeak. A sampled figure: a spike shorter than the interval can be missed
// (VmHWM, the run's figure, has it). Concurrent stages (several jobs in one process) see the same
// process-wide resident set.
class StagePeak {
 public:
  StagePeak();   // samples now, and starts the sampler thread if it is not running
  ~StagePeak();  // stops the sampler thread when no other StagePeak is alive
  StagePeak(const StagePeak&) = delete;
  StagePeak& operator=(const StagePeak&) = delete;
  // The highest resident set sampled since construction, a sample taken now included.
  uint64_t bytes();

 private:
  friend struct RssSampler;
  uint64_t peak_ = 0;  // guarded by the sampler's mutex
};

// How a job spends its memory budget. Derived from Options only, never from the input, and nothing in it
// may change an output byte: it sizes buffers, it does not choose algorithms.
struct MemoryPlan {
  uint64_t budget = 0;       // the cap on VmHWM
  unsigned threads = 1;
  unsigned tokens = 2;       // chunks in flight in a pipeline
  uint64_t chunk_bytes = 0;  // input bytes per parse chunk
  uint64_t sort_bytes = 0;   // in-memory buffer of an external sort that runs beside a pipeline
  uint64_t stage_bytes = 0;  // working memory of a stage that runs alone
};

// Throws Failure(usage) for a budget below min_memory_bytes.
MemoryPlan plan_memory(const Options& options);

}  // namespace lodstream::stream

// Resident-memory accounting and the memory plan that every stage sizes its buffers from.
#pragma once

#include <cstdint>

#include "lodstream/lodstream.h"

namespace lodstream::stream {

uint64_t physical_memory_bytes();
uint64_t peak_rss_bytes();     // VmHWM
// Resets VmHWM to the current RSS (Linux: "5" into /proc/self/clear_refs), so that a stage's peak can be
// measured on its own. Returns false where the kernel does not allow it.
bool reset_peak_rss();

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

#include "stream/memory.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>

#include "core/status.h"

namespace lodstream::stream {

namespace {

uint64_t status_field_kib(const char* field) {
  FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  uint64_t kib = 0;
  const size_t n = std::strlen(field);
  while (std::fgets(line, sizeof line, f)) {
    if (std::strncmp(line, field, n) == 0 && line[n] == ':') {
      kib = std::strtoull(line + n + 1, nullptr, 10);
      break;
    }
  }
  std::fclose(f);
  return kib;
}

}  // namespace

uint64_t physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? static_cast<uint64_t>(pages) * static_cast<uint64_t>(page) : (4ull << 30);
}

uint64_t peak_rss_bytes() { return status_field_kib("VmHWM") << 10; }

bool reset_peak_rss() {
  const int fd = open("/proc/self/clear_refs", O_WRONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = write(fd, "5", 1) == 1;
  close(fd);
  return ok;
}

MemoryPlan plan_memory(const Options& options) {
  MemoryPlan plan;
  plan.budget = options.memory_bytes ? options.memory_bytes : physical_memory_bytes() / 2;
  if (plan.budget < min_memory_bytes)
    fail(Status::usage, "--memory " + std::to_string(plan.budget) + " is below the minimum of " +
                            std::to_string(min_memory_bytes >> 20) + " MiB");
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  plan.threads = options.threads ? options.threads : hw;
  plan.tokens = 4 * plan.threads;
  // The process itself (code and libraries ~28 MiB resident, TBB, the store writers' ~3 MiB of buffers)
  // needs up to 40 MiB; the rest is split between the chunks in flight and one external-sort buffer. A
  // parsed chunk can be up to ~8x its input bytes (short text records become 8-byte references and
  // doubles), and its prepared form up to 4x more, so a chunk slot costs 13x its input. Chunks of about 1 MiB
  // keep a chunk's parsed output in cache between the stages that touch it; larger ones measured slower
  // (city scene, binary PLY: 0.55 s at 1 MiB, 0.61 s at 4 MiB, 0.81 s at 16 MiB).
  const uint64_t usable = plan.budget - std::min<uint64_t>(plan.budget / 2, 40ull << 20);
  const uint64_t per_slot = usable / 2 / plan.tokens / 13;
  plan.chunk_bytes = options.chunk_bytes ? options.chunk_bytes
                                         : std::clamp<uint64_t>(per_slot, 64ull << 10, 1ull << 20);
  plan.sort_bytes = std::max<uint64_t>(usable / 2, 4ull << 20);
  plan.stage_bytes = std::max<uint64_t>(usable, 8ull << 20);
  return plan;
}

}  // namespace lodstream::stream

#include "stream/memory.h"

#include <fcntl.h>
#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

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

void release_free_memory() { malloc_trim(0); }

uint64_t resident_bytes() {
  // statm is "size resident shared ..." in pages; one short read, cheaper than parsing status.
  const int fd = open("/proc/self/statm", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  char buf[128];
  const ssize_t n = read(fd, buf, sizeof buf - 1);
  close(fd);
  if (n <= 0) return 0;
  buf[n] = 0;
  char* p = nullptr;
  std::strtoull(buf, &p, 10);
  static const uint64_t page = static_cast<uint64_t>(sysconf(_SC_PAGESIZE));
  return std::strtoull(p, nullptr, 10) * page;
}

// The process-wide sampler behind StagePeak. `lifecycle` serialises starting and stopping the thread (a
// stop joins it, and the thread needs `m` to finish its tick, so the join cannot happen under `m`).
struct RssSampler {
  std::mutex lifecycle;
  std::mutex m;
  std::condition_variable wake;
  std::vector<StagePeak*> live;  // guarded by m
  bool stop = false;             // guarded by m
  std::thread thread;            // guarded by lifecycle

  static RssSampler& get() {
    // Never destroyed: a StagePeak in a static object's destructor must still find it.
    static RssSampler* s = new RssSampler;
    return *s;
  }

  void run() {
    std::unique_lock lock(m);
    while (!stop) {
      const uint64_t rss = resident_bytes();
      for (StagePeak* p : live) p->peak_ = std::max(p->peak_, rss);
      wake.wait_for(lock, std::chrono::milliseconds(kRssSampleMilliseconds), [&] { return stop; });
    }
  }

  void add(StagePeak* p) {
    std::lock_guard life(lifecycle);
    {
      std::lock_guard lock(m);
      p->peak_ = resident_bytes();
      live.push_back(p);
    }
    if (!thread.joinable()) {
      try {
        thread = std::thread([this] { run(); });
      } catch (const std::system_error&) {
        // No thread to spare: the stage's peak is then its resident set at start and end.
      }
    }
  }

  void remove(StagePeak* p) {
    std::lock_guard life(lifecycle);
    {
      std::lock_guard lock(m);
      live.erase(std::find(live.begin(), live.end(), p));
      if (!live.empty() || !thread.joinable()) return;
      stop = true;
    }
    wake.notify_all();
    thread.join();
    std::lock_guard lock(m);
    stop = false;
  }
};

StagePeak::StagePeak() { RssSampler::get().add(this); }

StagePeak::~StagePeak() { RssSampler::get().remove(this); }

uint64_t StagePeak::bytes() {
  RssSampler& s = RssSampler::get();
  const uint64_t now = resident_bytes();
  std::lock_guard lock(s.m);
  peak_ = std::max(peak_, now);
  return peak_;
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

// Ingest by byte ranges (stream/ingest_range.h), measured: a one-machine ingest of FILE, then for each
// N the N range tasks one after another (as N machines would run them at once) and the join, with each
// task's wall and CPU time, the bytes it parsed, its splitter's skip over the chunks before its range,
// and a byte comparison of the joined store with the one-machine store.
//
// usage: bench_ingest_ranges [--threads T] [--memory SIZE_BYTES] --work DIR FILE N...
// DIR gets DIR/whole and DIR/nN (removed at the end). Prints one line per task and per join.

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/status.h"
#include "lodstream/lodstream.h"
#include "stream/ingest.h"
#include "stream/ingest_range.h"
#include "stream/job.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace {

namespace fs = std::filesystem;
using namespace lodstream;

struct Clock {
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  double cpu0 = stream::process_cpu_seconds();
  double wall() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }
  double cpu() const { return stream::process_cpu_seconds() - cpu0; }
};

bool same_file(const fs::path& a, const fs::path& b) {
  std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
  std::vector<char> ba(1 << 20), bb(1 << 20);
  for (;;) {
    fa.read(ba.data(), static_cast<std::streamsize>(ba.size()));
    fb.read(bb.data(), static_cast<std::streamsize>(bb.size()));
    if (fa.gcount() != fb.gcount() || std::memcmp(ba.data(), bb.data(), static_cast<size_t>(fa.gcount())) != 0) return false;
    if (!fa) return !fb;
  }
}

bool same_store(const fs::path& a, const fs::path& b) {
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(a)) {
    ++files;
    if (!fs::exists(b / e.path().filename()) || !same_file(e.path(), b / e.path().filename())) {
      std::printf("  store file %s differs\n", e.path().filename().c_str());
      return false;
    }
  }
  return files == static_cast<size_t>(std::distance(fs::directory_iterator(b), fs::directory_iterator()));
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  std::string work_root, input;
  std::vector<unsigned> counts;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--threads" && i + 1 < argc) options.threads = static_cast<unsigned>(std::atoi(argv[++i]));
    else if (a == "--memory" && i + 1 < argc) options.memory_bytes = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--work" && i + 1 < argc) work_root = argv[++i];
    else if (input.empty()) input = a;
    else counts.push_back(static_cast<unsigned>(std::atoi(a.c_str())));
  }
  if (work_root.empty() || input.empty() || counts.empty()) {
    std::fprintf(stderr, "usage: bench_ingest_ranges [--threads T] [--memory BYTES] --work DIR FILE N...\n");
    return 64;
  }
  try {
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    const uint64_t size = fs::file_size(input);
    std::printf("%s: %llu bytes, %u threads, chunk %llu bytes (one machine)\n", input.c_str(), static_cast<unsigned long long>(size),
                plan.threads, static_cast<unsigned long long>(plan.chunk_bytes));
    const std::string whole_dir = work_root + "/whole";
    {
      stream::WorkDir work(whole_dir);
      bool reused = false;
      const Clock c;
      stream::ingest(input, work.subdir("store"), plan, work, progress, &reused);
      std::printf("one machine: ingest %.2f s wall, %.2f s CPU, read %llu bytes\n", c.wall(), c.cpu(),
                  static_cast<unsigned long long>(size));
    }
    for (unsigned n : counts) {
      const std::string dir = work_root + fmt::format("/n{}", n);
      stream::WorkDir work(dir);
      double max_wall = 0, sum_cpu = 0;
      for (unsigned i = 0; i < n; ++i) {
        const Clock c;
        const stream::RangeStats r = stream::ingest_range(input, work, i, n, plan, progress);
        const double wall = c.wall(), cpu = c.cpu();
        max_wall = std::max(max_wall, wall);
        sum_cpu += cpu;
        const uint64_t seg = fs::file_size(stream::segment_path(stream::ingest_ranges_dir(work), i, n));
        std::printf("N=%u range %u: %.2f s wall, %.2f s CPU; parsed %llu bytes [%llu, %llu) in %llu chunks; splitter skipped %llu chunks "
                    "before the range in %.2f s; segment %llu bytes\n",
                    n, i, wall, cpu, static_cast<unsigned long long>(r.parsed_end - r.parsed_begin),
                    static_cast<unsigned long long>(r.parsed_begin), static_cast<unsigned long long>(r.parsed_end),
                    static_cast<unsigned long long>(r.chunks), static_cast<unsigned long long>(r.skipped_chunks), r.skip_seconds,
                    static_cast<unsigned long long>(seg));
      }
      const Clock c;
      bool reused = false;
      stream::ingest(input, work.subdir("store"), plan, work, progress, &reused, stream::ingest_ranges_dir(work));
      const double join_wall = c.wall(), join_cpu = c.cpu();
      const bool same = same_store(fs::path(whole_dir) / "store", fs::path(dir) / "store");
      std::printf("N=%u join: %.2f s wall, %.2f s CPU; slowest range %.2f s wall, ranges' CPU %.2f s in all; store %s the one-machine store\n",
                  n, join_wall, join_cpu, max_wall, sum_cpu, same ? "byte-identical to" : "DIFFERS from");
      std::fflush(stdout);
      fs::remove_all(dir);
      if (!same) return 1;
    }
    fs::remove_all(whole_dir);
  } catch (const Failure& f) {
    std::fprintf(stderr, "bench_ingest_ranges: %s\n", f.what());
    return static_cast<int>(f.status());
  }
  return 0;
}

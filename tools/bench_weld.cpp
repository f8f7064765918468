// The weld (stream/distinct_count.h), measured on a store's position column: lodstream's weld_positions
// under a memory budget, beside meshoptimizer's meshopt_generateVertexRemap (the peer: one in-memory hash
// table over every position, one thread), in the same run, alternately, several times; prints each run
// and the medians. The peer's positions are read into memory before its clock starts; lodstream's are read
// from the mapped column (page cache warm after the first run).
//
// Checks that both agree: the distinct counts, and canonical[v] (read back from the weld map lodstream
// wrote) = the smallest id whose position has v's bytes (the peer's remap, which numbers positions in
// first-seen order, gives that id directly). The peer tells -0 from +0 and lodstream does not, so a
// scene with both zeros would show mismatches. Also prints lodstream's peak resident memory (VmHWM).
//
// With --units U, also the weld as U units (stream/grade_shares.h): each unit alone, one after another (as U
// machines would run them at once), then the map written from their runs by one process, and again as U
// map units in place (write_weld_map_unit, as the grading shares write it); prints every unit's time, the
// slowest unit plus the map's writing (the weld's wall time on U machines, either way) and the sum (its
// CPU cost on one), and checks that both maps are the same bytes as weld_positions'.
//
// usage: bench_weld [--runs R] [--memory SIZE_BYTES] [--threads T] [--no-peer] [--units U] [--work DIR] STORE_DIR
// DIR (default: a temporary directory) gets the weld map and the sort's scratch files.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#ifdef LODSTREAM_BENCH_MESHOPT
#include <meshoptimizer.h>
#endif

#include "core/status.h"
#include "io/file_writer.h"
#include "lodstream/lodstream.h"
#include "stream/distinct_count.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/weld_file.h"
#include "stream/work_dir.h"
#include "tools/bench_timing.h"

namespace {

using namespace lodstream;

using bench::Timing;
using bench::timed;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 3;
  uint64_t memory = 512ull << 20;
  int threads = 0;
  bool peer = true;
  unsigned units = 0;
  std::string store, work_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (a == "--memory" && i + 1 < argc) memory = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--no-peer") peer = false;
    else if (a == "--work" && i + 1 < argc) work_path = argv[++i];
    else if (a == "--units" && i + 1 < argc) units = static_cast<unsigned>(std::atoi(argv[++i]));
    else store = a;
  }
  if (store.empty()) {
    std::fprintf(stderr, "usage: bench_weld [--runs R] [--memory SIZE_BYTES] [--threads T] [--no-peer] [--units U] [--work DIR] STORE_DIR\n");
    return 2;
  }
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);
  try {
    nlohmann::json meta;
    std::ifstream(store + "/store.json") >> meta;
    const uint64_t n = meta.at("vertices").get<uint64_t>();
    const bool single = meta.at("positions").get<std::string>() == "f32";
    const std::string path = store + (single ? "/positions.f32" : "/positions.f64");
    fmt::print("store {}: {} vertices, {}; lodstream at --memory {} MiB for the weld, {} threads\n", store, n,
               single ? "f32" : "f64", memory >> 20, threads > 0 ? threads : tbb::this_task_arena::max_concurrency());

    Options options;
    stream::Progress progress(options);
    stream::WorkDir work(work_path);
    const std::string weld_path = work.file("weld.map");
    std::vector<double> ours_wall, ours_cpu, peer_wall, peer_cpu;
    uint64_t ours_distinct = 0, peer_distinct = 0;
#ifdef LODSTREAM_BENCH_MESHOPT
    std::vector<unsigned> remap;
    std::vector<char> bytes;
    if (peer) {
      bytes.resize(n * (single ? 12 : 24));
      std::ifstream(path, std::ios::binary).read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      remap.resize(n);
    }
#else
    if (peer) std::puts("peer: meshoptimizer not built in (libmeshoptimizer-dev missing): skipped");
    peer = false;
#endif
    for (int r = 0; r < runs; ++r) {
      const Timing t = timed([&] { ours_distinct = stream::weld_positions(path, n, single, memory, work, progress, weld_path); });
      ours_wall.push_back(t.wall);
      ours_cpu.push_back(t.cpu);
      fmt::print("run {}: lodstream weld_positions   {:7.2f} s wall {:7.2f} s CPU  {} distinct\n", r, t.wall, t.cpu, ours_distinct);
#ifdef LODSTREAM_BENCH_MESHOPT
      if (peer) {
        const Timing p = timed([&] {
          peer_distinct = meshopt_generateVertexRemap(remap.data(), nullptr, n, bytes.data(), n, single ? 12 : 24);
        });
        peer_wall.push_back(p.wall);
        peer_cpu.push_back(p.cpu);
        fmt::print("run {}: meshopt_generateVertexRemap {:7.2f} s wall {:7.2f} s CPU  {} distinct\n", r, p.wall, p.cpu, peer_distinct);
      }
#endif
    }
    fmt::print("median: lodstream {:.2f} s wall, {:.2f} s CPU, peak {} MiB", median(ours_wall), median(ours_cpu),
               stream::peak_rss_bytes() >> 20);
    if (peer) fmt::print("; meshoptimizer {:.2f} s wall, {:.2f} s CPU; wall ratio {:.2f}", median(peer_wall), median(peer_cpu),
                         median(ours_wall) / median(peer_wall));
    fmt::print("\n");
    if (units > 0) {
      std::vector<std::pair<std::string, uint64_t>> unit_runs;
      double slowest = 0, sum_cpu = 0;
      const std::string sizes = work.file("sizes.bin");  // the bucket sizes the first unit counts for the others
      std::filesystem::remove(sizes);
      for (unsigned u = 0; u < units; ++u) {
        const std::string run = work.file("unit-" + std::to_string(u) + ".pairs");
        stream::WeldUnitResult r;
        const Timing t = timed([&] { r = stream::weld_unit(path, n, single, memory, work, progress, u, units, run, sizes); });
        fmt::print("unit {} of {}: {:7.2f} s wall {:7.2f} s CPU  {} distinct, {} welded\n", u, units, t.wall, t.cpu, r.distinct, r.welded);
        unit_runs.emplace_back(run, r.welded);
        slowest = std::max(slowest, t.wall);
        sum_cpu += t.cpu;
      }
      const std::string map = work.file("units.map");
      const Timing m = timed([&] { stream::write_weld_map(unit_runs, n, memory, work, map); });
      fmt::print("map from {} units' runs: {:.2f} s wall {:.2f} s CPU\n", units, m.wall, m.cpu);
      // The map as units too (write_weld_map_unit, one process each on a cluster), in place.
      const std::string in_place = work.file("map-units.map");
      uint64_t welded = 0;
      for (const auto& run : unit_runs) welded += run.second;
      const Timing start = timed([&] { stream::start_weld_map(in_place, n, welded); });
      double slowest_map = 0, map_cpu = start.cpu;
      for (unsigned u = 0; u < units; ++u) {
        const Timing t = timed([&] { stream::write_weld_map_unit(unit_runs, n, memory, work, in_place, u, units); });
        fmt::print("map unit {} of {}: {:7.2f} s wall {:7.2f} s CPU\n", u, units, t.wall, t.cpu);
        slowest_map = std::max(slowest_map, t.wall);
        map_cpu += t.cpu;
      }
      fmt::print("units: slowest unit + map {:.2f} s wall, slowest unit + slowest map unit {:.2f} s (one process: median {:.2f} s); "
                 "CPU of all units + map {:.2f} s, + map units {:.2f} s\n",
                 slowest + m.wall, slowest + start.wall + slowest_map, median(ours_wall), sum_cpu + m.cpu, sum_cpu + map_cpu);
      const std::string one = ours_distinct == n ? std::string() : io::read_small_file(weld_path);
      const bool same = ours_distinct == n || (io::read_small_file(map) == one && io::read_small_file(in_place) == one);
      fmt::print("check: the units' maps (one writer, map units) are {} weld_positions' map\n", same ? "the same bytes as" : "NOT the same as");
      if (!same) return 1;
    }
#ifdef LODSTREAM_BENCH_MESHOPT
    if (peer) {
      std::vector<uint32_t> canonical(n);
      for (uint64_t v = 0; v < n; ++v) canonical[v] = static_cast<uint32_t>(v);
      if (ours_distinct < n) stream::WeldFile(weld_path, n).for_each_welded([&](uint64_t v, uint32_t c) { canonical[v] = c; });
      // remap numbers positions in first-seen order, so first[remap[v]] is the smallest id at v's position.
      std::vector<uint32_t> first(peer_distinct, UINT32_MAX);
      uint64_t mismatches = 0;
      for (uint64_t v = 0; v < n; ++v) {
        if (first[remap[v]] == UINT32_MAX) first[remap[v]] = static_cast<uint32_t>(v);
        mismatches += canonical[v] != first[remap[v]];
      }
      fmt::print("check: distinct {} (lodstream) {} (meshoptimizer); canonical ids differing: {}\n", ours_distinct,
                 peer_distinct, mismatches);
      if (mismatches || ours_distinct != peer_distinct) return 1;
    }
#endif
  } catch (const std::exception& e) {  // Failure, or a store.json that does not parse
    std::fprintf(stderr, "bench_weld: %s\n", e.what());
    return 1;
  }
  return 0;
}

// The region clusterer (core/floating_cell_region.h) against the whole-scene Clusterer (core/floating_cell.h)
// on one slab of a real scene's records (issue 19: what a clustering share's split level costs per
// record, against what one machine's pass costs).
//
// Usage: bench_region_clusterer POSITIONS CELL AXIS LO HI [--runs K]
//   POSITIONS: the records' positions in weight order, xyz float32 (a sharded run's
//   WORK/positions-w.f32); CELL: the cell size; the slab is LO <= x[AXIS] < HI (AXIS 0, 1 or 2).
// Loads the slab's records (the held vertices of a share with that box), then times, K times each (the
// median printed): the Clusterer's pass over them (assign_block, float positions, as one machine's cluster
// stage runs a level), the RegionClusterer one vertex at a time (assign) and in blocks of 4096
// (assign_block, as a share runs it). Prints ns per record, the settled share, and checks that both
// region runs decide alike (exit 1 if not).
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/floating_cell.h"
#include "core/floating_cell_region.h"
#include "io/mapped_file.h"
#include "tools/bench_timing.h"

using namespace lodstream;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 6) {
    std::fprintf(stderr, "usage: bench_region_clusterer POSITIONS CELL AXIS LO HI [--runs K]\n");
    return 64;
  }
  const std::string path = argv[1];
  const double cell = std::stod(argv[2]);
  const int axis = std::stoi(argv[3]);
  const double lo = std::stod(argv[4]), hi = std::stod(argv[5]);
  const int runs = argc >= 8 && std::string(argv[6]) == "--runs" ? std::stoi(argv[7]) : 3;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  try {
    // The slab's records.
    io::MappedFile file(path);
    const uint64_t records = file.size() / 12;
    std::vector<uint32_t> tags;
    std::vector<double> xyz;
    std::vector<float> buffer(3 * (uint64_t{1} << 20));
    for (uint64_t first = 0; first < records; first += uint64_t{1} << 20) {
      const uint64_t n = std::min<uint64_t>(uint64_t{1} << 20, records - first);
      file.read(first * 12, n * 12, buffer.data());
      for (uint64_t i = 0; i < n; ++i) {
        const float* p = &buffer[3 * i];
        if (!(lo <= p[axis] && p[axis] < hi)) continue;
        tags.push_back(static_cast<uint32_t>(first + i));
        xyz.insert(xyz.end(), {p[0], p[1], p[2]});
      }
    }
    const size_t n = tags.size();
    fmt::print("{}: {} records, slab {} <= x[{}] < {}: {} held; cell {}\n", path, records, lo, axis, hi, n, cell);
    std::array<double, 6> box = {-kInf, -kInf, -kInf, kInf, kInf, kInf};
    box[axis] = lo, box[3 + axis] = hi;
    core::ClusterOptions options;
    options.float_positions = true;
    // The slab's bounds, for the Clusterer's packed table (one machine's cluster stage gives it the scene's).
    std::vector<double> bounds = {kInf, kInf, kInf, -kInf, -kInf, -kInf};
    for (size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) bounds[a] = std::min(bounds[a], xyz[3 * i + a]), bounds[3 + a] = std::max(bounds[3 + a], xyz[3 * i + a]);
    std::vector<double> whole_s, packed_s, one_s, block_s;
    std::vector<uint32_t> cells(n);
    std::vector<core::RegionDecision> one(n), block(n);
    uint64_t cell_count = 0;
    for (int r = 0; r < runs; ++r) {
      whole_s.push_back(bench::timed([&] {
        const double sizes[] = {cell};
        core::Clusterer c(sizes, options);
        for (size_t first = 0; first < n; first += 4096) {
          const size_t k = std::min<size_t>(4096, n - first);
          c.assign_block(std::span<const uint32_t>(&tags[first], k), std::span<const double>(&xyz[3 * first], 3 * k),
                         std::span<uint32_t>(&cells[first], k));
        }
        cell_count = c.cell_count(0);
      }).wall);
      packed_s.push_back(bench::timed([&] {
        const double sizes[] = {cell};
        core::Clusterer c(sizes, options, bounds);
        for (size_t first = 0; first < n; first += 4096) {
          const size_t k = std::min<size_t>(4096, n - first);
          c.assign_block(std::span<const uint32_t>(&tags[first], k), std::span<const double>(&xyz[3 * first], 3 * k),
                         std::span<uint32_t>(&cells[first], k));
        }
      }).wall);
      one_s.push_back(bench::timed([&] {
        core::RegionClusterer rc(cell, options, box);
        for (size_t i = 0; i < n; ++i) one[i] = rc.assign(tags[i], std::span<const double, 3>(&xyz[3 * i], 3));
      }).wall);
      block_s.push_back(bench::timed([&] {
        core::RegionClusterer rc(cell, options, box);
        for (size_t first = 0; first < n; first += 4096) {
          const size_t k = std::min<size_t>(4096, n - first);
          rc.assign_block(std::span<const uint32_t>(&tags[first], k), std::span<const double>(&xyz[3 * first], 3 * k),
                          std::span<core::RegionDecision>(&block[first], k));
        }
      }).wall);
    }
    uint64_t settled = 0, differ = 0;
    for (size_t i = 0; i < n; ++i) {
      settled += one[i].cell_settled;
      differ += one[i].status != block[i].status || one[i].cell_settled != block[i].cell_settled || one[i].center != block[i].center;
    }
    const double per = 1e9 / static_cast<double>(std::max<size_t>(n, 1));
    fmt::print("Clusterer (whole-scene pass, assign_block): {:.1f} ns a record ({} cells)\n", median(whole_s) * per, cell_count);
    fmt::print("Clusterer with the slab's bounds:           {:.1f} ns a record\n", median(packed_s) * per);
    fmt::print("RegionClusterer assign:                     {:.1f} ns a record\n", median(one_s) * per);
    fmt::print("RegionClusterer assign_block:               {:.1f} ns a record ({:.2f}x the Clusterer)\n", median(block_s) * per,
               median(block_s) / median(whole_s));
    fmt::print("settled cells {:.2f} % of the held; decisions that differ between assign and assign_block: {}\n",
               100.0 * static_cast<double>(settled) / static_cast<double>(std::max<size_t>(n, 1)), differ);
    return differ ? 1 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_region_clusterer: %s\n", e.what());
    return 1;
  }
}

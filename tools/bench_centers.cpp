// The centers pass of a level split by records (core/floating_cell_centers.h) against the whole pass over
// the same records (core/floating_cell.h), on a real scene's records in weight order (issue 19: what the
// one sequential part of a coarse level's clustering costs, level by level).
//
// Usage: bench_centers POSITIONS CELL [CELL...] [--bitmap BYTES] [--bricks BYTES]
//   POSITIONS: the records' positions in weight order, xyz float32 (a sharded run's WORK/positions-w.f32);
//   CELL: a level's cell size (one line each); --bitmap: a bitmap's budget (default 64 MiB, as a share at
//   --memory 512M or more gives it; 0: none); --bricks: the bricks' (default 512 MiB, a share's at --memory 1G).
// Per cell size: the centers pass (wall, centers, records skipped, voxel), then the Clusterer's whole pass
// with the nearest choice (as one machine's cluster stage runs a level); exits 1 when their centers differ.
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
#include "core/floating_cell_centers.h"
#include "io/mapped_file.h"
#include "tools/bench_timing.h"

using namespace lodstream;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: bench_centers POSITIONS CELL [CELL...] [--bitmap BYTES] [--bricks BYTES]\n");
    return 64;
  }
  std::vector<double> cells;
  uint64_t bitmap = uint64_t{64} << 20, bricks = uint64_t{512} << 20;
  for (int i = 2; i < argc; ++i) {
    if (std::string(argv[i]) == "--bitmap" && i + 1 < argc) bitmap = std::stoull(argv[++i]);
    else if (std::string(argv[i]) == "--bricks" && i + 1 < argc) bricks = std::stoull(argv[++i]);
    else cells.push_back(std::stod(argv[i]));
  }
  try {
    const io::MappedFile file(argv[1]);
    const uint64_t records = file.size() / 12;
    constexpr uint64_t kBlock = uint64_t{1} << 16;
    std::vector<float> buffer(3 * kBlock);
    std::vector<double> xyz(3 * kBlock);
    auto for_each_block = [&](auto&& f) {
      for (uint64_t first = 0; first < records; first += kBlock) {
        const uint64_t n = std::min(kBlock, records - first);
        file.read(first * 12, n * 12, buffer.data());
        for (uint64_t i = 0; i < 3 * n; ++i) xyz[i] = buffer[i];
        f(first, n);
      }
    };
    std::array<double, 6> bounds = {1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
    for_each_block([&](uint64_t, uint64_t n) {
      for (uint64_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) bounds[a] = std::min(bounds[a], xyz[3 * i + a]), bounds[3 + a] = std::max(bounds[3 + a], xyz[3 * i + a]);
    });
    fmt::print("{}: {} records, bounds {} {} {} .. {} {} {}, budgets: bitmap {} bytes, bricks {} bytes\n", argv[1], records,
               bounds[0], bounds[1], bounds[2], bounds[3], bounds[4], bounds[5], bitmap, bricks);
    int status = 0;
    for (double c : cells) {
      core::ClusterOptions options;
      options.float_positions = true;
      std::vector<uint8_t> is_center(kBlock);
      std::vector<uint32_t> centers_a, centers_b;
      uint64_t skipped = 0, bytes = 0;
      double voxel = 0;
      const bench::Timing a = bench::timed([&] {
        core::CenterPass pass(c, options, bounds, bitmap, bricks);
        for_each_block([&](uint64_t first, uint64_t n) {
          pass.visit_block(std::span<const double>(xyz.data(), 3 * n), std::span<uint8_t>(is_center.data(), n));
          for (uint64_t i = 0; i < n; ++i)
            if (is_center[i]) centers_a.push_back(static_cast<uint32_t>(first + i));
        });
        skipped = pass.skipped(), voxel = pass.voxel(), bytes = pass.memory_bytes();
      });
      std::vector<uint32_t> ids(kBlock), out(kBlock);
      const bench::Timing b = bench::timed([&] {
        core::Clusterer whole(std::span<const double>(&c, 1), options, bounds);
        for_each_block([&](uint64_t first, uint64_t n) {
          for (uint64_t i = 0; i < n; ++i) ids[i] = static_cast<uint32_t>(first + i);
          uint32_t next = whole.cell_count(0);
          whole.assign_block(std::span<const uint32_t>(ids.data(), n), std::span<const double>(xyz.data(), 3 * n),
                             std::span<uint32_t>(out.data(), n));
          for (uint64_t i = 0; i < n; ++i)
            if (out[i] == next) centers_b.push_back(static_cast<uint32_t>(first + i)), ++next;
        });
      });
      fmt::print("cell {}: centers pass {:.2f} s ({:.1f} ns a record), {} centers, {:.1f} % skipped, voxel {}, {} MiB; "
                 "whole pass {:.2f} s ({:.1f} ns a record); {}\n",
                 c, a.wall, 1e9 * a.wall / records, centers_a.size(), 100.0 * skipped / records, voxel, bytes >> 20, b.wall,
                 1e9 * b.wall / records, centers_a == centers_b ? "same centers" : "CENTERS DIFFER");
      if (centers_a != centers_b) status = 1;
    }
    return status;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_centers: %s\n", e.what());
    return 1;
  }
}

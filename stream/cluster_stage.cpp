// Stage 4: the clustering pass. See cluster_stage.h.
#include "stream/cluster_stage.h"

#include <algorithm>
#include <memory>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/grade_stage.h"

namespace lodstream::stream {

std::string cells_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".u32"; }
std::string cell_info_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".info"; }
std::string order_path(const std::string& prefix) { return prefix + "order.u32"; }

ClusterSummary cluster_levels(const std::string& index_path, uint64_t records, bool single_precision,
                              std::span<const double> bounds, std::span<const double> cell_sizes,
                              const core::ClusterOptions& options,
                              const WorkDir& work, Progress& progress, const std::string& prefix) {
  const size_t levels = cell_sizes.size();
  const uint64_t record_bytes = weight_record_bytes(single_precision);
  io::MappedFile index(index_path);
  if (index.size() != records * record_bytes) fail(Status::io_error, index_path + ": size does not match");

  // Levels are split into one group per thread, each group one multi-level Clusterer (whose staged
  // prefetch overlaps the levels' cache misses). Measured on a 48M-triangle scene, the finest level costs
  // about as much as three coarser ones (its probes miss the cache; theirs mostly hit), so levels are dealt,
  // finest first, to the group with the least estimated cost (3 for level 0, 1 for any other; ties to the
  // lowest group): with two threads and five levels, {0, 4} and {1, 2, 3}. Levels are independent, so the
  // split changes no result.
  struct Level {
    std::vector<CellInfo> info;
    io::FileWriter cells;
    std::vector<uint32_t> block;
  };
  struct Group {
    std::vector<size_t> levels;  // increasing
    std::unique_ptr<core::Clusterer> clusterer;
    std::vector<uint32_t> cells;  // the block's cells, level-major (Clusterer::assign_block)
  };
  std::vector<Level> state(levels);
  for (size_t l = 0; l < levels; ++l) state[l].cells.open(cells_path(prefix, l), 1 << 20);
  const size_t n_groups = std::clamp<size_t>(static_cast<size_t>(tbb::this_task_arena::max_concurrency()), 1, levels);
  std::vector<Group> groups(n_groups);
  {
    std::vector<unsigned> cost(n_groups, 0);
    for (size_t l = 0; l < levels; ++l) {
      const size_t g = static_cast<size_t>(std::min_element(cost.begin(), cost.end()) - cost.begin());
      groups[g].levels.push_back(l);
      cost[g] += l == 0 ? 3 : 1;
    }
  }
  for (Group& grp : groups) {
    std::vector<double> sizes;
    for (size_t l : grp.levels) sizes.push_back(cell_sizes[l]);
    grp.clusterer = std::make_unique<core::Clusterer>(sizes, options, bounds);
  }
  // Each group runs through the whole index on its own task, unpacking the records itself: no barrier per
  // block, so a group held up (its core busy with page-cache writeback, say) does not stall the other.
  // Group 0 also writes the order file and reports progress; every group checks for cancellation per
  // block, and stops when another has failed.
  io::FileWriter order(order_path(prefix), 1 << 20);
  constexpr uint64_t block = 1 << 16;
  constexpr uint64_t kAhead = 8;
  ClusterSummary summary;
  summary.cells.resize(levels);
  tbb::parallel_for(size_t{0}, n_groups, [&](size_t g) {
    Group& grp = groups[g];
    std::vector<uint32_t> ids;
    std::vector<double> grades, xyz;
    for (uint64_t first = 0; first < records; first += block) {
      progress.check();
      if (tbb::is_current_task_group_canceling()) return;
      const uint64_t n = std::min(block, records - first);
      {
        const io::Window w = index.map(first * record_bytes, (first + n) * record_bytes);
        // The block's records as plain arrays, positions widened to double (exact for float).
        ids.resize(n);
        grades.resize(n);
        xyz.resize(3 * n);
        auto unpack = [&](const auto* rec) {
          for (uint64_t i = 0; i < n; ++i) {
            ids[i] = rec[i].id;
            grades[i] = rec[i].grade;
            for (int k = 0; k < 3; ++k) xyz[3 * i + k] = rec[i].position[k];
          }
        };
        if (single_precision) unpack(reinterpret_cast<const WeightRecord32*>(w.data()));
        else unpack(reinterpret_cast<const WeightRecord64*>(w.data()));
      }
      if (g == 0) order.write_array(std::span<const uint32_t>(ids));
      grp.cells.resize(grp.levels.size() * n);
      grp.clusterer->assign_block(ids, xyz, grp.cells);
      for (size_t j = 0; j < grp.levels.size(); ++j)
        state[grp.levels[j]].block.assign(grp.cells.begin() + j * n, grp.cells.begin() + (j + 1) * n);
      // The cells' sums, level by level once the block's cells are known, so that the cell records can be
      // fetched kAhead vertices ahead; each cell still adds its vertices in weight order.
      for (size_t j = 0; j < grp.levels.size(); ++j) {
        Level& s = state[grp.levels[j]];
        for (uint64_t i = 0; i < n; ++i) {
          if (i + kAhead < n && s.block[i + kAhead] < s.info.size()) {
            const char* ahead = reinterpret_cast<const char*>(&s.info[s.block[i + kAhead]]);
            __builtin_prefetch(ahead);
            __builtin_prefetch(ahead + sizeof(CellInfo) - 1);
          }
          const double* p = &xyz[3 * i];
          const double grade = grades[i];
          const uint32_t cell = s.block[i];
          if (cell == s.info.size()) {
            CellInfo c{};
            std::copy(p, p + 3, c.center);
            c.center_vertex = ids[i];
            s.info.push_back(c);
          }
          CellInfo& c = s.info[cell];
          for (int k = 0; k < 3; ++k) {
            c.weighted[k] += grade * p[k];
            c.sum[k] += p[k];
          }
          c.weight += grade;
          ++c.vertices;
        }
        s.cells.write_array(std::span<const uint32_t>(s.block));
      }
      if (g == 0) progress.report("cluster", static_cast<double>(first + n) / static_cast<double>(records));
    }
    // The group's levels' files, while the other groups may still be clustering.
    for (size_t l : grp.levels) {
      Level& s = state[l];
      s.cells.commit();
      summary.cells[l] = s.info.size();
      io::FileWriter info(cell_info_path(prefix, l), 1 << 20);
      info.write_array(std::span<const CellInfo>(s.info));
      info.commit();
      std::vector<CellInfo>().swap(s.info);
    }
  });
  progress.check();  // a group that saw the cancellation returned early
  order.commit();
  return summary;
}

}  // namespace lodstream::stream

// Stage 4: the clustering pass. See cluster_stage.h.
#include "stream/cluster_stage.h"

#include <algorithm>
#include <atomic>
#include <memory>
#include <string>

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

namespace {

// One CellInfo per cell, in chunks of kChunk: unlike a vector, it never holds twice its size while it
// grows, nor copies what it holds.
class CellInfos {
 public:
  static constexpr uint32_t kShift = 12, kChunk = 1u << kShift;
  uint64_t size() const { return size_; }
  CellInfo& operator[](uint64_t i) { return chunks_[i >> kShift][i & (kChunk - 1)]; }
  const CellInfo* address(uint64_t i) const { return &chunks_[i >> kShift][i & (kChunk - 1)]; }
  void push_back(const CellInfo& c) {
    if ((size_ & (kChunk - 1)) == 0) chunks_.push_back(std::make_unique_for_overwrite<CellInfo[]>(kChunk));
    (*this)[size_++] = c;
  }
  uint64_t bytes() const { return chunks_.size() * (kChunk * sizeof(CellInfo) + sizeof(void*)); }
  void write(io::FileWriter& out) const {
    for (uint64_t first = 0; first < size_; first += kChunk)
      out.write_array(std::span<const CellInfo>(chunks_[first >> kShift].get(), std::min<uint64_t>(kChunk, size_ - first)));
  }
  void clear() {
    std::vector<std::unique_ptr<CellInfo[]>>().swap(chunks_);
    size_ = 0;
  }

 private:
  std::vector<std::unique_ptr<CellInfo[]>> chunks_;
  uint64_t size_ = 0;
};

}  // namespace

ClusterSummary cluster_levels(const std::string& index_path, uint64_t records, bool single_precision,
                              std::span<const double> bounds, std::span<const double> cell_sizes,
                              const core::ClusterOptions& options, uint64_t memory_bytes,
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
    CellInfos info;
    std::atomic<uint64_t> count{0};  // info.size() after the group's last block, for other groups to read
    io::FileWriter cells;
  };
  struct Group {
    std::vector<size_t> levels;  // increasing
    std::unique_ptr<core::Clusterer> clusterer;
    std::vector<uint32_t> cells;  // the block's cells, level-major (Clusterer::assign_block)
    std::atomic<uint64_t> bytes{0};  // the group's tables and cell records, after its last block
  };
  std::vector<Level> state(levels);
  constexpr size_t kWriterBuffer = 256 << 10;
  for (size_t l = 0; l < levels; ++l) state[l].cells.open(cells_path(prefix, l), kWriterBuffer);
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
  // The memory contract: what the cells need grows with the cells, and when it outgrows `memory_bytes`
  // the stage stops with a usage error instead of going past it. Checked after every block against the
  // groups' tables (with the headroom of their next growth step) and cell records; the fixed buffers
  // (index windows, the block's arrays, the writers' buffers) come off first, and the coarse levels' dense
  // arrays (faster than hashing, but 8 bytes a square of the bounds) take at most an eighth of the rest.
  constexpr uint64_t block = 1 << 14;
  const uint64_t fixed = (levels + 1) * kWriterBuffer + n_groups * block * (4 + 8 + 24 + 4 * levels + record_bytes);
  const uint64_t cell_budget = memory_bytes > fixed ? memory_bytes - fixed : 0;
  const uint64_t max_dense = cell_budget / 8 / levels / sizeof(core::Clusterer::DenseSquare);
  for (Group& grp : groups) {
    std::vector<double> sizes;
    for (size_t l : grp.levels) sizes.push_back(cell_sizes[l]);
    grp.clusterer = std::make_unique<core::Clusterer>(sizes, options, bounds, max_dense);
  }
  // Each group runs through the whole index on its own task, unpacking the records itself: no barrier per
  // block, so a group held up (its core busy with page-cache writeback, say) does not stall the other.
  // Group 0 also writes the order file and reports progress; every group checks for cancellation per
  // block, and stops when another has failed.
  io::FileWriter order(order_path(prefix), kWriterBuffer);
  auto check_memory = [&](Group& grp, uint64_t first, uint64_t n) {
    uint64_t mine = grp.clusterer->memory_bytes() + grp.clusterer->growth_bytes();
    for (size_t l : grp.levels) {
      mine += state[l].info.bytes();
      state[l].count.store(state[l].info.size(), std::memory_order_relaxed);
    }
    grp.bytes.store(mine, std::memory_order_relaxed);
    uint64_t total = 0;
    for (const Group& other : groups) total += other.bytes.load(std::memory_order_relaxed);
    if (total <= cell_budget) return;
    std::string counts;
    for (size_t l = 0; l < levels; ++l)
      counts += (counts.empty() ? "" : ", ") + std::string("level ") + std::to_string(l) + ": " +
                std::to_string(state[l].count.load(std::memory_order_relaxed));
    fail(Status::usage, "clustering needs more memory than --memory allows (cells after about " +
                            std::to_string(first + n) + " of " + std::to_string(records) + " vertices: " + counts + "; about " +
                            std::to_string(total >> 20) + " MiB for the cells, " + std::to_string(cell_budget >> 20) +
                            " MiB available): raise --memory, or make the finest level coarser (--cell-sizes, "
                            "--target-triangles)");
  };
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
      // The cells' sums, level by level once the block's cells are known, so that the cell records can be
      // fetched kAhead vertices ahead; each cell still adds its vertices in weight order.
      for (size_t j = 0; j < grp.levels.size(); ++j) {
        Level& s = state[grp.levels[j]];
        const std::span<const uint32_t> block_cells(grp.cells.data() + j * n, n);  // this level's, in the group's array
        for (uint64_t i = 0; i < n; ++i) {
          if (i + kAhead < n && block_cells[i + kAhead] < s.info.size()) {
            const char* ahead = reinterpret_cast<const char*>(s.info.address(block_cells[i + kAhead]));
            __builtin_prefetch(ahead);
            __builtin_prefetch(ahead + sizeof(CellInfo) - 1);
          }
          const double* p = &xyz[3 * i];
          const double grade = grades[i];
          const uint32_t cell = block_cells[i];
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
        s.cells.write_array(block_cells);
      }
      check_memory(grp, first, n);
      if (g == 0) progress.report("cluster", static_cast<double>(first + n) / static_cast<double>(records));
    }
    // The group's levels' files, while the other groups may still be clustering.
    for (size_t l : grp.levels) {
      Level& s = state[l];
      s.cells.commit();
      summary.cells[l] = s.info.size();
      io::FileWriter info(cell_info_path(prefix, l), kWriterBuffer);
      s.info.write(info);
      info.commit();
      s.info.clear();
    }
    grp.clusterer.reset();  // its memory goes to the groups still running
    grp.bytes.store(0, std::memory_order_relaxed);
  });
  progress.check();  // a group that saw the cancellation returned early
  order.commit();
  return summary;
}

}  // namespace lodstream::stream

// Stage 4: the clustering pass. See cluster_stage.h.
#include "stream/cluster_stage.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <memory>
#include <string>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/cell_map_file.h"
#include "stream/grade_stage.h"
#include "stream/position_gather.h"

namespace lodstream::stream {

std::string cells_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".map"; }
std::string cell_info_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".info"; }
std::string order_path(const std::string& prefix) { return prefix + "order.u32"; }
std::string grades_path(const std::string& prefix) { return prefix + "grades.f64"; }

CellInfoKind cell_info_kind(Representative r) {
  return r == Representative::center ? CellInfoKind::center : r == Representative::mean ? CellInfoKind::mean : CellInfoKind::quadric;
}

uint64_t cell_info_bytes(CellInfoKind kind, bool single_precision) {
  const uint64_t center = single_precision ? 12 : 24, mean = 24;
  return kind == CellInfoKind::center ? center : kind == CellInfoKind::mean ? mean : center + mean;
}

CellInfoReader::CellInfoReader(const std::string& path, uint64_t cells, CellInfoKind kind, bool single_precision)
    : file_(path), kind_(kind), single_(single_precision), bytes_(cell_info_bytes(kind, single_precision)) {
  if (file_.size() != cells * bytes_) fail(Status::io_error, path + ": size does not match");
}

io::Window CellInfoReader::map(uint64_t first, uint64_t end) const { return file_.map(first * bytes_, end * bytes_); }

CellInfo CellInfoReader::get(const io::Window& w, uint64_t i) const {
  CellInfo ci{};
  ci.vertices = 1;
  const char* p = w.data() + i * bytes_;
  if (kind_ != CellInfoKind::mean) {
    if (single_) {
      float c[3];
      std::memcpy(c, p, sizeof c);
      for (int k = 0; k < 3; ++k) ci.center[k] = c[k];
      p += sizeof c;
    } else {
      std::memcpy(ci.center, p, sizeof ci.center);
      p += sizeof ci.center;
    }
  }
  if (kind_ != CellInfoKind::center) {
    std::memcpy(ci.sum, p, sizeof ci.sum);
    std::copy(ci.sum, ci.sum + 3, ci.weighted);
    ci.weight = 1;
  }
  return ci;
}

namespace {

constexpr size_t kWriterBuffer = 256 << 10;
constexpr uint64_t kBlock = 1 << 14;

size_t thread_groups(size_t levels) {
  return std::clamp<size_t>(static_cast<size_t>(tbb::this_task_arena::max_concurrency()), 1, levels);
}

uint64_t positions_bytes(uint64_t vertices, bool single_precision) { return vertices * (single_precision ? 12 : 24); }

size_t gathering_threads() { return static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency())); }

// Records whose ids and positions are held at once (a multiple of kBlock). The mapped column: one block
// per thread, fetched ahead record by record. Read through the page cache (position_gather.h): one batch,
// gathered once for every clusterer (or sums chunk) and by all threads, taking a quarter of the budget
// (capped by --chunk-bytes), since each batch costs a copy of the column's segments that hold its ids (all
// of them, at these sizes): 7 batches a pass on the 48.6 M city at 512M, 14 on the 193 M one at 1G.
uint64_t gather_batch(uint64_t memory_bytes, uint64_t chunk_cap, bool mapped) {
  if (mapped) return kBlock;
  constexpr uint64_t per_record = 4 + 24 + kGatherBytesPerId;  // id, position as doubles, slot
  uint64_t bytes = memory_bytes / 4;
  if (chunk_cap) bytes = std::min(bytes, chunk_cap);
  return std::max<uint64_t>(bytes / per_record / kBlock, 1) * kBlock;
}

// What `memory_bytes` leaves the clusterers: the positions' share (the column mapped whole, where it fits
// comfortably: the records come in weight order, spread over the whole column; else the one batch and a
// segment buffer per thread) and the fixed buffers (the writers', the index windows, the block's arrays per group)
// come off first.
uint64_t cell_budget(size_t levels, uint64_t vertices, bool single_precision, uint64_t memory_bytes, uint64_t chunk_cap) {
  const uint64_t column = positions_bytes(vertices, single_precision);
  const bool mapped = map_positions_whole(column, memory_bytes, chunk_cap);
  const uint64_t positions = mapped ? column
                                    : gather_batch(memory_bytes, chunk_cap, false) * (4 + 24 + kGatherBytesPerId) +
                                          gathering_threads() * kGatherSegmentBytes;
  const uint64_t fixed = positions + (2 * levels + 1) * kWriterBuffer + thread_groups(levels) * kBlock * (4 + 24 + 4 * levels + 4);
  return memory_bytes > fixed ? memory_bytes - fixed : 0;
}

// A center at the store's precision (a stored position: exact), at q; returns the byte after it.
char* put_center(char* q, const double* p, bool single_precision) {
  if (single_precision) {
    const float f[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
    std::memcpy(q, f, sizeof f);
    return q + sizeof f;
  }
  std::memcpy(q, p, 24);
  return q + 24;
}

void write_center(io::FileWriter& out, const double* p, bool single_precision) {
  char bytes[24];
  out.write(bytes, static_cast<size_t>(put_center(bytes, p, single_precision) - bytes));
}

// The coarse levels' dense arrays take at most an eighth of the cells' budget.
uint64_t max_dense_squares(uint64_t budget, size_t levels) {
  return budget / 8 / levels / sizeof(core::Clusterer::DenseSquare);
}

// The fine masks of records [first, first + n) for a group's levels (bit j: level levels[j]'s fine grid).
void fine_masks(const io::MappedFile& labels, const FineCells& fine, const std::vector<size_t>& levels, uint64_t first,
                uint64_t n, std::vector<uint32_t>& masks) {
  const io::Window w = labels.map(first * 4, (first + n) * 4);
  const float* label = reinterpret_cast<const float*>(w.data());
  masks.assign(n, 0);
  for (size_t j = 0; j < levels.size(); ++j) {
    if (fine.sizes.at(levels[j]) == 0) continue;
    const double near = fine.near.at(levels[j]);
    for (uint64_t i = 0; i < n; ++i) masks[i] |= static_cast<uint32_t>(double(label[i]) <= near) << j;
  }
}



// Calls f(first, n, batch) for the blocks of records [lo, hi), in order: positions from `shared` (the read
// way), else loaded block by block. Stops early when the task group is cancelled.
template <class F>
void for_each_block(const io::MappedFile& index, const RecordPositions& positions, uint64_t lo, uint64_t hi,
                    const RecordBatch* shared, Progress& progress, F&& f) {
  RecordBatch own;
  for (uint64_t first = lo; first < hi; first += kBlock) {
    progress.check();
    if (tbb::is_current_task_group_canceling()) return;
    const uint64_t n = std::min(kBlock, hi - first);
    if (!shared) own.load(index, positions, first, n);
    f(first, n, shared ? *shared : own);
  }
}

// Which cells a sums pass makes, and how: the cells [first, end) of the levels' cells taken in level order
// (the levels' cells one after another), `threads` chunks summed at once. in_place: the info files are
// sized already and each range of cells is written at its place (a unit of the clustering merge,
// stream/cluster_merge.h); else each level's file is written whole, in order (the window then holds every cell).
struct SumWindow {
  uint64_t first = 0, end = UINT64_MAX;
  size_t threads = 0;  // 0: the arena's
  bool in_place = false;
  SumStart start;  // with plain cells, the records from start.record on (sum_cell_info_range)
};
constexpr size_t kPlaceBytes = 1 << 20;  // in place: the records written at once

// The sums pass (mean and quadric representatives) over the levels `level_ids` (their maps and info files
// under `prefix`), of `cells_per_level` cells each. `sum_bytes`: what the sums may hold at once.
void sum_cells(const io::MappedFile& index, const RecordPositions& positions, uint64_t batch, const io::MappedFile* grades,
               uint64_t records, std::span<const size_t> level_ids, std::span<const uint64_t> cells_per_level,
               CellInfoKind info_kind, bool single_precision, uint64_t sum_bytes, Progress& progress, const std::string& prefix,
               double progress_from, const SumWindow& window = {}) {
  constexpr uint64_t block = kBlock;
  // The sums pass (mean and quadric representatives): each level's CellInfo records, from the cluster maps
  // just written and the index, both read in order, so that every cell adds its vertices in weight order
  // (as a running sum in the pass above would) and its first vertex, the one that created it, gives its
  // center. The records are made in ranges of cell ids, packed into one chunk per thread that takes what
  // the clusterers held at their peak divided among the threads (so the sums never raise the stage's
  // peak), within the budget; a chunk costs one more sequential read of the index and of its levels'
  // maps, where holding every record at once would cost 88 bytes a cell.
  const size_t n_threads = window.threads ? window.threads : static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const size_t levels = level_ids.size();
  uint64_t all_cells = 0;
  for (uint64_t c : cells_per_level) all_cells += c;
  const uint64_t window_end = std::min(window.end, all_cells), window_first = std::min(window.first, window_end);
  const uint64_t total_cells = window_end - window_first;
  if (total_cells == 0 && window.in_place) return;  // else the levels' empty files are written below
  const bool entered = !window.start.entries.empty();
  const uint64_t first_record = entered ? std::min(window.start.record, records) : 0;
  // As many chunks as that takes, rounded up to whole rounds of one per thread, and as even as can be.
  const uint64_t most_per_chunk = std::max<uint64_t>(1, sum_bytes / n_threads / sizeof(CellInfo));
  const uint64_t rounds = std::max<uint64_t>(1, (total_cells + most_per_chunk * n_threads - 1) / (most_per_chunk * n_threads));
  const uint64_t per_chunk = std::max<uint64_t>(1, (total_cells + rounds * n_threads - 1) / (rounds * n_threads));
  struct Range {
    size_t level;
    uint64_t first, end;  // cell ids
  };
  std::vector<std::vector<Range>> chunks(1);
  uint64_t room = per_chunk;
  for (size_t l = 0, before = 0; l < levels; before += cells_per_level[l], ++l) {
    // The level's cells in the window: [first, last).
    const uint64_t first_here = std::clamp(window_first, before, before + cells_per_level[l]) - before;
    const uint64_t last = std::clamp(window_end, before, before + cells_per_level[l]) - before;
    if (first_here == last && !(cells_per_level[l] == 0 && !window.in_place)) continue;
    uint64_t first = first_here;
    do {
      if (room == 0) chunks.emplace_back(), room = per_chunk;
      const uint64_t end = std::min(last, first + room);
      chunks.back().push_back({l, first, end});
      room -= end - first;
      first = end;
    } while (first < last);
  }
  std::unique_ptr<io::FileWriter> info;  // the level of the range being written
  std::vector<char> record(cell_info_bytes(info_kind, single_precision));
  uint64_t done_cells = 0;
  for (size_t round = 0; round < chunks.size(); round += n_threads) {
    const size_t round_end = std::min(chunks.size(), round + n_threads);
    std::vector<std::vector<std::vector<CellInfo>>> sums(round_end - round);
    std::vector<std::vector<std::unique_ptr<CellMapReader>>> chunk_cells(round_end - round);
    for (size_t k = round; k < round_end; ++k)
      for (const Range& range : chunks[k]) {
        sums[k - round].emplace_back(range.end - range.first, CellInfo{});
        chunk_cells[k - round].push_back(std::make_unique<CellMapReader>(
            cells_path(prefix, level_ids[range.level]), entered ? window.start.entries.at(range.level) : MapEntry{}));
      }
    // Chunk k's sums over records [lo, hi): positions from `shared` (the read way), else fetched per block.
    auto sum_records = [&](size_t k, uint64_t lo, uint64_t hi, const RecordBatch* shared) {
      const std::vector<Range>& chunk = chunks[k];
      std::vector<std::vector<CellInfo>>& outs = sums[k - round];
      std::vector<std::unique_ptr<CellMapReader>>& readers = chunk_cells[k - round];
      constexpr uint64_t kAhead = 8;
      std::vector<uint32_t> cells(block);
      std::vector<double> grade(block, 0.0);
      for_each_block(index, positions, lo, hi, shared, progress, [&](uint64_t first, uint64_t n, const RecordBatch& b) {
        const double* xyz = b.xyz.data() + 3 * (first - b.at);
        if (grades) grades->read(first * 8, n * 8, grade.data());
        for (size_t r = 0; r < chunk.size(); ++r) {
          std::vector<CellInfo>& out = outs[r];
          readers[r]->read(std::span<uint32_t>(cells.data(), n));
          if (out.empty()) continue;
          const uint64_t base = chunk[r].first;
          for (uint64_t i = 0; i < n; ++i) {
            if (i + kAhead < n) {
              const uint64_t ahead = cells[i + kAhead] - base;  // wraps below the range
              if (ahead < out.size()) {
                __builtin_prefetch(&out[ahead]);
                __builtin_prefetch(reinterpret_cast<const char*>(&out[ahead]) + sizeof(CellInfo) - 1);
              }
            }
            const uint64_t cell = cells[i] - base;
            if (cell >= out.size()) continue;
            CellInfo& c = out[cell];
            const double* p = &xyz[3 * i];
            const double g = grade[i];
            if (c.vertices == 0) std::copy(p, p + 3, c.center);
            for (int a = 0; a < 3; ++a) {
              c.weighted[a] += g * p[a];
              c.sum[a] += p[a];
            }
            c.weight += g;
            ++c.vertices;
          }
        }
      });
    };
    if (positions.per_block()) {
      tbb::parallel_for(round, round_end, [&](size_t k) { sum_records(k, first_record, records, nullptr); });
    } else {
      RecordBatch shared;
      for (uint64_t at = first_record; at < records; at += batch) {
        progress.check();
        shared.load(index, positions, at, std::min(batch, records - at));
        tbb::parallel_for(round, round_end, [&](size_t k) { sum_records(k, at, shared.at + shared.ids.size(), &shared); });
      }
    }
    progress.check();
    for (size_t k = round; k < round_end; ++k)
      for (size_t r = 0; r < chunks[k].size(); ++r) chunk_cells[k - round][r]->finish(records, cells_per_level[chunks[k][r].level]);
    for (size_t k = round; k < round_end; ++k)
      for (size_t r = 0; r < chunks[k].size(); ++r) {
        const Range& range = chunks[k][r];
        // In place: the range's records, a MiB at a time, from cell `placed_at` on.
        std::unique_ptr<io::OffsetFile> placed_file;
        std::vector<char> placed;
        uint64_t placed_at = range.first;
        auto place = [&] {
          placed_file->write(placed.data(), placed.size(), placed_at * record.size());
          placed_at += placed.size() / record.size();
          placed.clear();
        };
        if (window.in_place) placed_file = std::make_unique<io::OffsetFile>(cell_info_path(prefix, level_ids[range.level]), O_WRONLY);
        else if (range.first == 0) info = std::make_unique<io::FileWriter>(cell_info_path(prefix, level_ids[range.level]), kWriterBuffer);
        for (const CellInfo& c : sums[k - round][r]) {
          // The mean as the emit stage computes it (emit_stage.cpp, representatives), in the same operations.
          double mean[3];
          for (int a = 0; a < 3; ++a) mean[a] = c.sum[a] / static_cast<double>(c.vertices);
          char* q = record.data();
          if (info_kind == CellInfoKind::quadric) q = put_center(q, c.center, single_precision);
          for (int a = 0; a < 3; ++a) {
            const double m = info_kind == CellInfoKind::mean && c.weight > 0 ? c.weighted[a] / c.weight : mean[a];
            std::memcpy(q + 8 * a, &m, 8);
          }
          if (!window.in_place) {
            info->write(record.data(), record.size());
            continue;
          }
          placed.insert(placed.end(), record.begin(), record.end());
          if (placed.size() >= kPlaceBytes) place();
        }
        std::vector<CellInfo>().swap(sums[k - round][r]);
        if (window.in_place && !placed.empty()) place();
        else if (!window.in_place && range.end == cells_per_level[range.level]) info->commit();
        done_cells += range.end - range.first;
      }
    if (!window.in_place)  // a unit's share of the cells says little of the stage's
      progress.report("cluster", progress_from + (1 - progress_from) * static_cast<double>(done_cells) /
                                                   static_cast<double>(std::max<uint64_t>(total_cells, 1)));
  }
}
}  // namespace

uint64_t estimated_cells(const AreaHistogram& areas, double cell_size, uint64_t records) {
  uint64_t triangles = 0;
  for (uint64_t n : areas.count) triangles += n;
  if (triangles == 0) return 0;
  const double per_triangle = static_cast<double>(records) / static_cast<double>(triangles);
  double cells = 0;
  for (int b = 0; b < kAreaBins; ++b)
    if (areas.count[b])
      cells += std::min(per_triangle * static_cast<double>(areas.count[b]),
                        kEstimatedCellsPerArea * areas.area[b] / (cell_size * cell_size));
  return static_cast<uint64_t>(std::min(cells, static_cast<double>(records)));
}

void check_cluster_estimate(const AreaHistogram& areas, uint64_t records, uint64_t vertices, bool single_precision,
                            std::span<const double> bounds, std::span<const double> cell_sizes,
                            uint64_t memory_bytes, uint64_t chunk_cap) {
  const uint64_t budget = cell_budget(cell_sizes.size(), vertices, single_precision, memory_bytes, chunk_cap);
  uint64_t dense = 0;  // bytes of the dense arrays, chosen as core::Clusterer chooses them
  for (double c : cell_sizes) {
    uint64_t squares = bounds.empty() ? UINT64_MAX : 1;
    for (size_t a = 0; a < 3 && !bounds.empty(); ++a) {
      const uint64_t dims = static_cast<uint64_t>(core::grid_square(bounds[3 + a], c) - core::grid_square(bounds[a], c) + 3);
      squares = dims <= core::Clusterer::kMaxDenseSquares && squares <= core::Clusterer::kMaxDenseSquares ? squares * dims : UINT64_MAX;
    }
    if (squares <= max_dense_squares(budget, cell_sizes.size())) dense += squares * sizeof(core::Clusterer::DenseSquare);
  }
  uint64_t cells = 0;
  std::string per_level;
  for (size_t l = 0; l < cell_sizes.size(); ++l) {
    const uint64_t n = estimated_cells(areas, cell_sizes[l], records);
    cells += n;
    per_level += (per_level.empty() ? "" : ", ") + std::to_string(n);
  }
  const uint64_t need = cells * kClusterBytesPerCell[single_precision ? 1 : 0] + dense;
  if (need <= budget) return;
  fail(Status::usage, "clustering would need more memory than --memory allows (estimated cells per level: " + per_level +
                          "; about " + std::to_string(need >> 20) + " MiB at " +
                          std::to_string(kClusterBytesPerCell[single_precision ? 1 : 0]) + " bytes a cell" +
                          (dense ? " and " + std::to_string(dense >> 20) + " MiB of dense squares" : std::string()) + ", " +
                          std::to_string(budget >> 20) + " MiB available): raise --memory, or make the finest level "
                          "coarser (--cell-sizes, --target-triangles)");
}

ClusterSummary cluster_levels(const WeightIndex& weights, std::span<const double> bounds, std::span<const double> cell_sizes,
                              const core::ClusterOptions& cluster_options, CellInfoKind info_kind, uint64_t memory_bytes,
                              const WorkDir&, Progress& progress, const std::string& prefix,
                              const FineCells* fine, uint64_t chunk_cap) {
  const size_t levels = cell_sizes.size();
  const uint64_t records = weights.records;
  const bool single_precision = weights.single_precision;
  io::MappedFile index(weights.order_path);
  if (index.size() != records * 4) fail(Status::io_error, weights.order_path + ": size does not match");
  std::unique_ptr<io::MappedFile> grades;
  if (info_kind == CellInfoKind::mean) {
    grades = std::make_unique<io::MappedFile>(weights.grades_path);
    if (grades->size() != records * 8) fail(Status::io_error, weights.grades_path + ": size does not match");
  }
  const RecordPositions positions = record_positions(weights, memory_bytes, chunk_cap);
  const uint64_t batch = gather_batch(memory_bytes, chunk_cap, positions.per_block());
  // A float store's positions are all floats: the clusterer keeps its centers as floats (same ids).
  core::ClusterOptions options = cluster_options;
  options.float_positions = single_precision;

  // Levels are split into one group per thread, each group one multi-level Clusterer (whose staged
  // prefetch overlaps the levels' cache misses). Measured on a 48M-triangle scene, the finest level costs
  // about as much as three coarser ones (its probes miss the cache; theirs mostly hit), so levels are dealt,
  // finest first, to the group with the least estimated cost (3 for level 0, 1 for any other; ties to the
  // lowest group): with two threads and five levels, {0, 4} and {1, 2, 3}. Levels are independent, so the
  // split changes no result.
  struct Level {
    std::atomic<uint64_t> count{0};  // cells after the group's last block, for other groups to read
    CellMapWriter cells;
    io::FileWriter centers;  // CellInfoKind::center: the info, one center per new cell
    uint64_t made = 0;       // cells whose center is written
  };
  struct Group {
    std::vector<size_t> levels;  // increasing
    std::unique_ptr<core::Clusterer> clusterer;
    std::vector<uint32_t> cells;  // the block's cells, level-major (Clusterer::assign_block)
    std::atomic<uint64_t> bytes{0};  // the group's clusterer, after its last block
  };
  std::vector<Level> state(levels);
  for (size_t l = 0; l < levels; ++l) {
    state[l].cells.open(cells_path(prefix, l), kWriterBuffer);
    if (info_kind == CellInfoKind::center) state[l].centers.open(cell_info_path(prefix, l), kWriterBuffer);
  }
  const size_t n_groups = thread_groups(levels);
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
  // groups' clusterers (with the headroom of their next growth step); the fixed buffers (index windows,
  // the block's arrays, the writers' buffers) come off first, and the coarse levels' dense arrays (faster
  // than hashing, but 8 bytes a square of the bounds) take at most an eighth of the rest.
  const uint64_t cell_budget = stream::cell_budget(levels, weights.vertices, single_precision, memory_bytes, chunk_cap);
  // Fine grids count as levels here: the dense arrays keep their eighth of the budget in all.
  size_t grids = levels;
  if (fine)
    for (double f : fine->sizes) grids += f > 0;
  const uint64_t max_dense = max_dense_squares(cell_budget, grids);
  for (Group& grp : groups) {
    std::vector<double> sizes, fine_sizes;
    for (size_t l : grp.levels) sizes.push_back(cell_sizes[l]);
    if (fine)
      for (size_t l : grp.levels) fine_sizes.push_back(fine->sizes.at(l));
    grp.clusterer = std::make_unique<core::Clusterer>(sizes, options, bounds, max_dense, fine_sizes);
  }
  std::unique_ptr<io::MappedFile> labels;
  if (fine) {
    labels = std::make_unique<io::MappedFile>(fine->labels_path);
    if (labels->size() != records * 4) fail(Status::io_error, fine->labels_path + ": size does not match the weight index");
  }
  // Each group runs through the whole index on its own task, fetching the positions itself: no barrier per
  // block, so a group held up (its core busy with page-cache writeback, say) does not stall the other.
  // Group 0 also reports progress; every group checks for cancellation per block, and stops when another
  // has failed.
  std::atomic<uint64_t> peak{0};  // the most the groups held together
  auto check_memory = [&](Group& grp, uint64_t first, uint64_t n) {
    const uint64_t mine = grp.clusterer->memory_bytes() + grp.clusterer->growth_bytes();
    for (size_t j = 0; j < grp.levels.size(); ++j)
      state[grp.levels[j]].count.store(grp.clusterer->cell_count(j), std::memory_order_relaxed);
    grp.bytes.store(mine, std::memory_order_relaxed);
    uint64_t total = 0;
    for (const Group& other : groups) total += other.bytes.load(std::memory_order_relaxed);
    uint64_t seen = peak.load(std::memory_order_relaxed);
    while (seen < total && !peak.compare_exchange_weak(seen, total, std::memory_order_relaxed)) {
    }
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
  // Progress: the clustering pass is about three quarters of the stage, the sums pass the rest.
  constexpr double kClusterShare = 0.75;
  ClusterSummary summary;
  summary.cells.resize(levels);
  // Runs records [lo, hi) through group g's clusterer, block by block: positions from `shared` (the read
  // way), else fetched by the group itself.
  auto run_group = [&](size_t g, uint64_t lo, uint64_t hi, const RecordBatch* shared) {
    Group& grp = groups[g];
    std::vector<uint32_t> masks;
    for_each_block(index, positions, lo, hi, shared, progress, [&](uint64_t first, uint64_t n, const RecordBatch& b) {
      const std::span<const uint32_t> ids(b.ids.data() + (first - b.at), n);
      const std::span<const double> xyz(b.xyz.data() + 3 * (first - b.at), 3 * n);
      grp.cells.resize(grp.levels.size() * n);
      if (labels) fine_masks(*labels, *fine, grp.levels, first, n, masks);
      grp.clusterer->assign_block(ids, xyz, grp.cells, labels ? std::span<const uint32_t>(masks) : std::span<const uint32_t>());
      for (size_t j = 0; j < grp.levels.size(); ++j) {
        Level& L = state[grp.levels[j]];
        const std::span<const uint32_t> cells(grp.cells.data() + j * n, n);
        L.cells.write(cells);
        if (info_kind == CellInfoKind::center)
          for (uint64_t i = 0; i < n; ++i)
            if (cells[i] == L.made) write_center(L.centers, &xyz[3 * i], single_precision), ++L.made;
      }
      check_memory(grp, first, n);
      if (g == 0) progress.report("cluster", kClusterShare * static_cast<double>(first + n) / static_cast<double>(records));
    });
  };
  auto finish_group = [&](size_t g) {
    Group& grp = groups[g];
    for (size_t j = 0; j < grp.levels.size(); ++j) {
      Level& L = state[grp.levels[j]];
      L.cells.commit();
      if (info_kind == CellInfoKind::center) L.centers.commit();
      summary.cells[grp.levels[j]] = grp.clusterer->cell_count(j);
    }
    grp.clusterer.reset();  // its memory goes to the groups still running
    grp.bytes.store(0, std::memory_order_relaxed);
  };
  if (positions.per_block()) {
    tbb::parallel_for(size_t{0}, n_groups, [&](size_t g) {
      run_group(g, 0, records, nullptr);
      if (!tbb::is_current_task_group_canceling()) finish_group(g);
    });
  } else {
    // One batch at a time, gathered once (by all threads) for every group: a barrier per batch of
    // millions of records, where each group gathering its own would copy the column once per group.
    RecordBatch shared;
    for (uint64_t at = 0; at < records; at += batch) {
      progress.check();
      shared.load(index, positions, at, std::min(batch, records - at));
      tbb::parallel_for(size_t{0}, n_groups, [&](size_t g) { run_group(g, at, shared.at + shared.ids.size(), &shared); });
    }
    progress.check();
    for (size_t g = 0; g < n_groups; ++g) finish_group(g);
  }
  progress.check();  // a group that saw the cancellation returned early
  if (info_kind == CellInfoKind::center) {
    progress.report("cluster", 1);
    return summary;
  }

  constexpr uint64_t kMinSumBytes = 16 << 20;
  const uint64_t sum_bytes = std::min(std::max(peak.load(), kMinSumBytes), std::max<uint64_t>(cell_budget, 1));
  std::vector<size_t> all(levels);
  for (size_t l = 0; l < levels; ++l) all[l] = l;
  sum_cells(index, positions, batch, grades.get(), records, all, summary.cells, info_kind, single_precision, sum_bytes,
            progress, prefix, kClusterShare);
  return summary;
}

namespace {

void sum_cell_info_in(const WeightIndex& weights, std::span<const size_t> levels, std::span<const uint64_t> cells,
                      CellInfoKind info_kind, uint64_t memory_bytes, uint64_t chunk_cap, Progress& progress,
                      const std::string& prefix, const SumWindow& window) {
  if (info_kind == CellInfoKind::center || levels.empty()) return;
  io::MappedFile index(weights.order_path);
  if (index.size() != weights.records * 4) fail(Status::io_error, weights.order_path + ": size does not match");
  std::unique_ptr<io::MappedFile> grades;
  if (info_kind == CellInfoKind::mean) {
    grades = std::make_unique<io::MappedFile>(weights.grades_path);
    if (grades->size() != weights.records * 8) fail(Status::io_error, weights.grades_path + ": size does not match");
  }
  const RecordPositions positions = record_positions(weights, memory_bytes, chunk_cap);
  // No clusterer is held here: the sums take what cluster_levels leaves its cells.
  const uint64_t budget = std::max<uint64_t>(cell_budget(levels.size(), weights.vertices, weights.single_precision, memory_bytes, chunk_cap), 1);
  sum_cells(index, positions, gather_batch(memory_bytes, chunk_cap, positions.per_block()), grades.get(), weights.records, levels, cells,
            info_kind, weights.single_precision, budget, progress, prefix, 0, window);
}

}  // namespace

void sum_cell_info(const WeightIndex& weights, std::span<const size_t> levels, std::span<const uint64_t> cells,
                   CellInfoKind info_kind, uint64_t memory_bytes, uint64_t chunk_cap, Progress& progress,
                   const std::string& prefix) {
  sum_cell_info_in(weights, levels, cells, info_kind, memory_bytes, chunk_cap, progress, prefix, {});
}

void sum_cell_info_range(const WeightIndex& weights, std::span<const size_t> levels, std::span<const uint64_t> cells,
                         CellInfoKind info_kind, uint64_t memory_bytes, uint64_t chunk_cap, Progress& progress,
                         const std::string& prefix, uint64_t first, uint64_t end, unsigned threads, const SumStart& start) {
  if (!start.entries.empty() && start.entries.size() != levels.size()) fail(Status::internal, "sum_cell_info_range: an entry a level");
  sum_cell_info_in(weights, levels, cells, info_kind, memory_bytes, chunk_cap, progress, prefix,
                   {first, end, std::max<size_t>(threads, 1), true, start});
}

// Where a pass's positions come from (position_gather.h): the index's weight-ordered file when it names
// one, else the store's column by id, mapped whole where it takes at most half the budget (and no
// --chunk-bytes asks for small reads), else read the read way.
RecordPositions record_positions(const WeightIndex& weights, uint64_t memory_bytes, uint64_t chunk_cap) {
  return RecordPositions(weights.positions_path, weights.single_precision, weights.vertices, weights.ordered_positions_path,
                         weights.records,
                         map_positions_whole(positions_bytes(weights.vertices, weights.single_precision), memory_bytes, chunk_cap));
}

}  // namespace lodstream::stream

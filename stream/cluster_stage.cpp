// Stage 4: the clustering pass. See cluster_stage.h.
#include "stream/cluster_stage.h"

#include <algorithm>
#include <memory>

#include <tbb/parallel_for.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/grade_stage.h"

namespace lodstream::stream {

std::string cells_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".u32"; }
std::string cell_info_path(const std::string& prefix, size_t level) { return prefix + "cells-" + std::to_string(level) + ".info"; }
std::string order_path(const std::string& prefix) { return prefix + "order.u32"; }

ClusterSummary cluster_levels(const std::string& index_path, uint64_t records, std::span<const double> cell_sizes,
                              const core::ClusterOptions& options, const WorkDir& work, Progress& progress,
                              const std::string& prefix) {
  const size_t levels = cell_sizes.size();
  io::MappedFile index(index_path);
  if (index.size() != records * sizeof(WeightRecord)) fail(Status::io_error, index_path + ": size does not match");

  struct Level {
    std::unique_ptr<core::Clusterer> clusterer;
    std::vector<CellInfo> info;
    io::FileWriter cells;
    std::vector<uint32_t> block;
  };
  std::vector<Level> state(levels);
  for (size_t l = 0; l < levels; ++l) {
    state[l].clusterer = std::make_unique<core::Clusterer>(std::span<const double>(&cell_sizes[l], 1), options);
    state[l].cells.open(cells_path(prefix, l), 1 << 20);
  }
  io::FileWriter order(order_path(prefix), 1 << 20);
  std::vector<uint32_t> ids;

  constexpr uint64_t block = 1 << 16;
  ClusterSummary summary;
  for (uint64_t first = 0; first < records; first += block) {
    const uint64_t n = std::min(block, records - first);
    const io::Window w = index.map(first * sizeof(WeightRecord), (first + n) * sizeof(WeightRecord));
    const WeightRecord* rec = reinterpret_cast<const WeightRecord*>(w.data());
    ids.resize(n);
    for (uint64_t i = 0; i < n; ++i) ids[i] = rec[i].id;
    order.write_array(std::span<const uint32_t>(ids));
    tbb::parallel_for(size_t{0}, levels, [&](size_t l) {
      Level& s = state[l];
      s.block.resize(n);
      for (uint64_t i = 0; i < n; ++i) {
        const WeightRecord& r = rec[i];
        uint32_t cell;
        s.clusterer->assign(r.id, std::span<const double, 3>(r.position, 3), std::span<uint32_t>(&cell, 1));
        s.block[i] = cell;
        if (cell == s.info.size()) {
          CellInfo c{};
          std::copy(r.position, r.position + 3, c.center);
          c.center_vertex = r.id;
          s.info.push_back(c);
        }
        CellInfo& c = s.info[cell];
        for (int k = 0; k < 3; ++k) {
          c.weighted[k] += r.grade * r.position[k];
          c.sum[k] += r.position[k];
        }
        c.weight += r.grade;
        ++c.vertices;
      }
      s.cells.write_array(std::span<const uint32_t>(s.block));
    });
    uint64_t bytes = 0;
    for (const Level& s : state) bytes += s.clusterer->memory_bytes() + s.info.capacity() * sizeof(CellInfo);
    summary.memory_bytes = std::max(summary.memory_bytes, bytes);
    progress.report("cluster", static_cast<double>(first + n) / static_cast<double>(records));
  }
  order.commit();
  for (size_t l = 0; l < levels; ++l) {
    Level& s = state[l];
    s.cells.commit();
    summary.cells.push_back(s.info.size());
    io::FileWriter info(cell_info_path(prefix, l), 1 << 20);
    info.write_array(std::span<const CellInfo>(s.info));
    info.commit();
    s.clusterer.reset();
    std::vector<CellInfo>().swap(s.info);
  }
  return summary;
}

}  // namespace lodstream::stream

// The emit stage's regions, batches and representatives (see stream/emit_regions.h).
#include "stream/emit_regions.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/status.h"
#include "io/mapped_file.h"
#include "stream/cluster_stage.h"
#include "stream/emit_stage.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kWindowCells = 1 << 16;

// Calls visit(first cell, infos) over the level's cell table in windows of kWindowCells cells (read through
// CellInfoReader: the table holds what `representative` reads, at the store's precision).
template <class Visit>
void for_cell_infos(const std::string& prefix, size_t level, uint64_t cells, uint64_t first, uint64_t end,
                    Representative representative, bool single_precision, Visit&& visit) {
  const CellInfoReader f(cell_info_path(prefix, level), cells, cell_info_kind(representative), single_precision);
  std::vector<CellInfo> infos;
  for (uint64_t c = first; c < end; c += kWindowCells) {
    const uint64_t n = std::min(kWindowCells, end - c);
    const io::Window w = f.map(c, c + n);
    infos.resize(n);
    for (uint64_t i = 0; i < n; ++i) infos[i] = f.get(w, i);
    visit(c, std::span<const CellInfo>(infos));
  }
}

// Where a cell is in the octree: its center vertex's stored position (core/octree_regions.h), or, for the mean
// representative, whose cell table holds no center, the cell's mean.
const double* cell_anchor(const CellInfo& ci, Representative representative) {
  return representative == Representative::mean ? ci.sum : ci.center;
}

}  // namespace

core::SceneCube scene_cube_of(const StoreMeta& meta) {
  if (meta.bbox.empty) return core::SceneCube{};
  return core::scene_cube(meta.bbox.min.data(), meta.bbox.max.data());
}

std::vector<LevelCut> cut_levels(const std::string& prefix, std::span<const uint64_t> cells, const core::SceneCube& cube,
                                 uint64_t max_cells, Representative representative, bool single_precision,
                                 std::span<const core::SideBound> sides) {
  std::vector<LevelCut> cuts(cells.size());
  std::vector<uint64_t> codes;
  for (size_t l = cells.size(); l-- > 0;) {
    codes.clear();
    codes.reserve(cells[l]);
    for_cell_infos(prefix, l, cells[l], 0, cells[l], representative, single_precision, [&](uint64_t, std::span<const CellInfo> infos) {
      for (const CellInfo& ci : infos) codes.push_back(core::point_code(cube, cell_anchor(ci, representative)));
    });
    tbb::parallel_sort(codes.begin(), codes.end());
    const std::span<const core::RegionKey> coarser =
        l + 1 < cells.size() ? std::span<const core::RegionKey>(cuts[l + 1].regions) : std::span<const core::RegionKey>();
    LevelCut& cut = cuts[l];
    cut.regions = core::cut_regions(codes, coarser, max_cells, l < sides.size() ? sides[l] : core::SideBound{});
    cut.cells.assign(cut.regions.size(), 0);
    for (uint64_t code : codes) ++cut.cells[core::region_of_code(cut.regions, code)];
  }
  std::vector<uint64_t>().swap(codes);
  return cuts;
}

CellRegions load_cell_regions(const std::string& prefix, size_t level, uint64_t cells, const core::SceneCube& cube,
                              const LevelCut& cut, Representative representative, bool single_precision, uint32_t first,
                              uint32_t end) {
  const uint32_t regions = static_cast<uint32_t>(cut.regions.size());
  if (end == 0 || end > regions) end = regions;
  CellRegions out;
  out.first = first, out.end = end;
  const bool whole = first == 0 && end == regions;
  uint64_t run_cells = 0;
  for (uint32_t r = first; r < end; ++r) run_cells += cut.cells[r];
  out.region.reserve(whole ? cells : run_cells);
  if (!whole) out.in = RankedBits(cells);
  std::vector<uint32_t> window;
  for_cell_infos(prefix, level, cells, 0, cells, representative, single_precision, [&](uint64_t c0, std::span<const CellInfo> infos) {
    window.resize(infos.size());
    tbb::parallel_for(size_t{0}, infos.size(), [&](size_t i) {
      window[i] = core::region_of_code(cut.regions, core::point_code(cube, cell_anchor(infos[i], representative)));
    });
    for (size_t i = 0; i < window.size(); ++i) {
      if (whole) {
        out.region.push_back(window[i]);
      } else if (window[i] >= first && window[i] < end) {
        out.in.set(c0 + i);
        out.region.push_back(window[i]);
      }
    }
  });
  if (!whole) out.in.count();
  if (out.region.size() != (whole ? cells : run_cells))
    fail(Status::internal, "emit: level " + std::to_string(level) + "'s cells do not match its cut");
  return out;
}

uint64_t cell_regions_bytes(uint64_t cells, uint64_t run_cells) {
  return run_cells == cells ? 4 * cells : (cells + 63) / 64 * 12 + 4 * run_cells;
}

void for_cell_anchors(const std::string& prefix, size_t level, uint64_t cells, Representative representative, bool single_precision,
                      const std::function<bool(uint64_t)>& wanted, const std::function<void(uint64_t, const double*)>& visit) {
  // Only the wanted cells are decoded (a task's batch wants a few of a level's cells, three times a group).
  const CellInfoReader f(cell_info_path(prefix, level), cells, cell_info_kind(representative), single_precision);
  for (uint64_t first = 0; first < cells; first += kWindowCells) {
    const uint64_t end = std::min(cells, first + kWindowCells);
    io::Window w;
    for (uint64_t c = first; c < end; ++c) {
      if (!wanted(c)) continue;
      if (!w.data()) w = f.map(first, end);
      visit(c, cell_anchor(f.get(w, c - first), representative));
    }
  }
}

std::vector<std::pair<uint32_t, uint32_t>> region_batches(const LevelCut& cut, uint64_t batch_cells) {
  std::vector<std::pair<uint32_t, uint32_t>> batches;
  const uint32_t n = static_cast<uint32_t>(cut.regions.size());
  for (uint32_t first = 0; first < n;) {
    uint64_t held = cut.cells[first];
    uint32_t end = first + 1;
    while (end < n && held + cut.cells[end] <= batch_cells) held += cut.cells[end++];
    batches.emplace_back(first, end);
    first = end;
  }
  return batches;
}

void cell_representative(const CellInfo& ci, const core::Quadric* quadric, Representative representative,
                         const core::ClusterOptions& cluster, double cell_size, double* p) {
  double mean[3];
  for (int k = 0; k < 3; ++k) mean[k] = ci.sum[k] / static_cast<double>(ci.vertices);
  if (representative == Representative::center) {
    std::copy(ci.center, ci.center + 3, p);
  } else if (representative == Representative::mean) {
    for (int k = 0; k < 3; ++k) p[k] = ci.weight > 0 ? ci.weighted[k] / ci.weight : mean[k];
  } else {
    double lo[3], hi[3];
    for (int k = 0; k < 3; ++k) {
      if (cluster.clustering == core::Clustering::uniform) {
        const double sq = static_cast<double>(core::grid_square(ci.center[k], cell_size));
        lo[k] = sq * cell_size, hi[k] = (sq + 1) * cell_size;
      } else {
        lo[k] = ci.center[k] - cell_size / 2, hi[k] = ci.center[k] + cell_size / 2;
      }
    }
    const std::array<double, 3> x = core::quadric_minimizer(quadric ? *quadric : core::Quadric(), mean, lo, hi);
    std::copy(x.begin(), x.end(), p);
  }
}

std::string representatives_path(const std::string& prefix, size_t level) {
  return prefix + "reps-" + std::to_string(level) + ".f64";
}

void write_representative_range(const std::string& prefix, size_t level, uint64_t cells, uint64_t first, uint64_t count,
                                std::span<const core::Quadric> quadrics, Representative representative,
                                const core::ClusterOptions& cluster, double cell_size, bool single_precision) {
  const std::string path = representatives_path(prefix, level);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) fail(Status::io_error, path + ": cannot open: " + std::strerror(errno));
  std::vector<double> out;
  bool ok = true;
  for_cell_infos(prefix, level, cells, first, first + count, representative, single_precision,
                 [&](uint64_t c0, std::span<const CellInfo> infos) {
    out.resize(3 * infos.size());
    tbb::parallel_for(size_t{0}, infos.size(), [&](size_t i) {
      const uint64_t c = c0 + i;
      cell_representative(infos[i], quadrics.empty() ? nullptr : &quadrics[c - first], representative, cluster, cell_size,
                          &out[3 * i]);
    });
    const size_t bytes = out.size() * sizeof(double);
    if (ok && ::pwrite(fd, out.data(), bytes, static_cast<off_t>(c0 * 24)) != static_cast<ssize_t>(bytes)) ok = false;
  });
  if (::close(fd) != 0) ok = false;
  if (!ok) fail(Status::io_error, path + ": cannot write (disk full?)");
}

void write_representatives(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                           const std::string& prefix, size_t level, uint64_t cells, double cell_size, uint64_t records,
                           const core::ClusterOptions& cluster, Representative representative, uint64_t range_cells,
                           Progress& progress, EmitScratch& scratch) {
  std::filesystem::remove(representatives_path(prefix, level));
  if (representative != Representative::quadric) {
    write_representative_range(prefix, level, cells, 0, cells, {}, representative, cluster, cell_size, meta.single_precision);
    return;
  }
  EmitOptions options;
  options.representative = representative;
  options.representatives_only = true;
  range_cells = std::max<uint64_t>(range_cells, 1);
  for (uint64_t first = 0; first < cells; first += range_cells) {
    EmitLevel l;
    l.level = level, l.cells = cells, l.cell_size = cell_size;
    l.first_cell = first, l.end_cell = std::min(cells, first + range_cells);
    emit_levels(store_dir, meta, canonical_path, prefix, std::span<const EmitLevel>(&l, 1), records, cluster, options, progress,
                scratch, [](size_t, RegionPart&) {});
  }
}

}  // namespace lodstream::stream

// Stages 2 and 3: weld by position, grade per id range (each range reads the store's blocks that touch
// it), sort into the weight index. See grade_stage.h for the contract.
#include "stream/grade_stage.h"

#include <fcntl.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <type_traits>
#include <vector>

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/distinct_count.h"
#include "stream/external_sort.h"
#include "stream/store_access.h"
#include "stream/weld_file.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

namespace {


// Stored vertex id -> canonical id: the identity, or the weld map file.
class Canonical {
 public:
  Canonical(const std::string& path, uint64_t vertices) {
    if (!path.empty()) file_ = std::make_unique<WeldFile>(path, vertices);
  }
  void acquire() {
    if (file_) file_->acquire(), acquired_ = true;
  }
  void release() {
    if (file_) file_->release(), acquired_ = false;
  }
  uint32_t operator()(uint32_t v) const { return acquired_ ? (*file_)(v) : v; }

 private:
  std::unique_ptr<WeldFile> file_;
  bool acquired_ = false;
};

struct Columns {
  std::string path[3];
  uint64_t count[3];
  static constexpr int arity[3] = {3, 2, 1};
};
Columns store_columns(const std::string& store_dir, const StoreMeta& meta) {
  return {{store_dir + "/triangles.u32", store_dir + "/lines.u32", store_dir + "/points.u32"},
          {meta.triangles, meta.lines, meta.points}};
}

// Mapped pages count as resident (the memory contract): the columns are remapped after every block of
// the block pass and every range of the grading, which drops the pages they touched from the process
// (the page cache keeps them). Without it, a pass over a 193M-triangle scene held 1.9 GB of them.
void drop_mapped_pages(StorePositions& positions, Canonical& canonical) {
  positions.release();
  canonical.release();
  positions.acquire();
  canonical.acquire();
}

// Visits the store's primitives of each kind (0 triangles, 1 segments, 2 points) in fixed blocks of kGradeBlock
// primitives, with ids mapped to canonical ids: visit(kind, block number, ids), for the blocks for which
// want(kind, block number) holds.
template <class Want, class Visit>
void visit_store(const Columns& c, const Canonical& canonical, Want&& want, Visit&& visit) {
  std::vector<uint32_t> mapped;
  for (int kind = 0; kind < 3; ++kind) {
    if (c.count[kind] == 0) continue;
    io::MappedFile file(c.path[kind]);
    const uint64_t stride = 4ull * static_cast<uint64_t>(Columns::arity[kind]);
    if (file.size() != c.count[kind] * stride) fail(Status::io_error, c.path[kind] + ": size does not match store.json");
    for (uint64_t first = 0, b = 0; first < c.count[kind]; first += kGradeBlock, ++b) {
      if (!want(kind, b)) continue;
      const uint64_t n = std::min(kGradeBlock, c.count[kind] - first);
      const io::Window w = file.map(first * stride, (first + n) * stride);
      const std::span<const uint32_t> ids(reinterpret_cast<const uint32_t*>(w.data()), n * stride / 4);
      mapped.resize(ids.size());
      tbb::parallel_for(tbb::blocked_range<size_t>(0, ids.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) mapped[i] = canonical(ids[i]);
      });
      visit(kind, b, std::span<const uint32_t>(mapped));
    }
  }
}


double triangle_area(const double* a, const double* b, const double* c) {
  const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  return 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

struct BinnedArea {
  double area;
  int bin;
};

// A block's triangle areas by bin (block_area), added to the histogram block after block in store order
// (add_block_areas), by whichever process computed them: the block pass, a block unit, or a single
// range's grading. The sums are the same bits every run and every way: a block's in triangle order, the
// blocks' in block order.
struct AreaScratch {
  std::vector<BinnedArea> triangles;
  std::vector<uint32_t> count = std::vector<uint32_t>(kAreaBins, 0);
  std::vector<double> area = std::vector<double>(kAreaBins, 0.0);
};

// The areas and their bins are computed in parallel; only the sums run serially, in triangle order.
// Returns the block's bins with triangles, in bin order, in `out`.
void block_area(std::span<const uint32_t> tris, const StorePositions& pos, AreaScratch& scratch, std::vector<BlockAreaBin>& out) {
  std::vector<BinnedArea>& t = scratch.triangles;
  t.resize(tris.size() / 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, t.size(), 1 << 12), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      double a[3], b[3], c[3];
      pos.get(tris[3 * i], a), pos.get(tris[3 * i + 1], b), pos.get(tris[3 * i + 2], c);
      const double area = triangle_area(a, b, c);
      int bin = 0;
      if (area > 0) bin = std::clamp(static_cast<int>(std::floor(4 * std::log2(area))) + kAreaBias, 0, kAreaBins - 1);
      t[i] = {area, bin};
    }
  });
  for (const BinnedArea& x : t) {
    ++scratch.count[static_cast<size_t>(x.bin)];
    scratch.area[static_cast<size_t>(x.bin)] += x.area;
  }
  out.clear();
  for (uint32_t bin = 0; bin < kAreaBins; ++bin)
    if (scratch.count[bin]) {
      out.push_back({bin, scratch.count[bin], scratch.area[bin]});
      scratch.count[bin] = 0, scratch.area[bin] = 0;
    }
}

void add_block_areas(AreaHistogram& h, std::span<const BlockAreaBin> bins) {
  for (const BlockAreaBin& b : bins) h.count[b.bin] += b.count, h.area[b.bin] += b.area;
}

// The ranges of `range` ids each that a block's canonical ids fall in.
RangeMask block_mask(std::span<const uint32_t> ids, uint64_t range) {
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, ids.size(), 1 << 14), RangeMask{},
      [&](const tbb::blocked_range<size_t>& r, RangeMask m) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const uint64_t range_of = ids[i] / range;
          m[range_of / 64] |= uint64_t{1} << (range_of % 64);
        }
        return m;
      },
      [](RangeMask a, const RangeMask& b2) {
        for (size_t k = 0; k < a.size(); ++k) a[k] |= b2[k];
        return a;
      });
}

}  // namespace

uint64_t grade_range_size(const StoreMeta& meta, const MemoryPlan& plan, uint64_t max_range_vertices, uint64_t min_ranges) {
  // Per vertex its offsets, counters, a record, and its share of incidence entries (two per triangle
  // corner, one per segment end). At least `min_ranges` ranges (the shares').
  const uint64_t n_vertices = meta.vertices;
  const double incidences = n_vertices ? static_cast<double>(6 * meta.triangles + 2 * meta.lines) / static_cast<double>(n_vertices) : 0;
  const uint64_t per_vertex = 8 + 4 + 8 + sizeof(GradeRecord) + static_cast<uint64_t>(std::ceil(4 * incidences));
  const uint64_t range_budget = std::max<uint64_t>(plan.stage_bytes / 3, 16 << 20);
  uint64_t range = std::max<uint64_t>(range_budget / per_vertex, 4096);
  if (max_range_vertices) range = std::min(range, max_range_vertices);
  if (min_ranges > 1) range = std::min(range, (n_vertices + min_ranges - 1) / min_ranges);
  return std::max<uint64_t>({range, (n_vertices + kMaxGradeRanges - 1) / kMaxGradeRanges, 1});
}

std::array<uint64_t, 3> grade_blocks(const StoreMeta& meta) {
  auto blocks = [](uint64_t n) { return (n + kGradeBlock - 1) / kGradeBlock; };
  return {blocks(meta.triangles), blocks(meta.lines), blocks(meta.points)};
}

std::pair<uint64_t, uint64_t> block_unit_blocks(uint64_t blocks, unsigned unit, unsigned units) {
  return {blocks * unit / units, blocks * (unit + 1) / units};
}

void block_pass_unit(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path, uint64_t range,
                     unsigned unit, unsigned units, const std::string& masks_path, const std::string& areas_path,
                     Progress& progress) {
  const Columns columns = store_columns(store_dir, meta);
  Canonical canonical(canonical_path, meta.vertices);
  StorePositions positions(store_dir, meta);
  canonical.acquire();
  positions.acquire();
  const std::array<uint64_t, 3> blocks = grade_blocks(meta);
  const io::OffsetFile masks(masks_path, O_WRONLY);
  io::FileWriter areas(areas_path, 1 << 20);
  AreaScratch scratch;
  std::vector<BlockAreaBin> bins;
  auto in_unit = [&](int kind, uint64_t b) {
    const auto [first, end] = block_unit_blocks(blocks[kind], unit, units);
    return b >= first && b < end;
  };
  visit_store(columns, canonical, in_unit, [&](int kind, uint64_t b, std::span<const uint32_t> ids) {
    progress.check();
    uint64_t at = b;
    for (int k = 0; k < kind; ++k) at += blocks[k];
    const RangeMask mask = block_mask(ids, range);
    masks.write(&mask, sizeof mask, at * sizeof mask);
    if (kind == 0) {
      block_area(ids, positions, scratch, bins);
      const uint32_t n = static_cast<uint32_t>(bins.size());
      areas.write(&n, sizeof n);
      areas.write_array(std::span<const BlockAreaBin>(bins));
    }
    drop_mapped_pages(positions, canonical);
  });
  areas.commit();
  positions.release();
  canonical.release();
}

// Pass 1: weld, then the range size; with more than one range (or `sum_areas`), the block pass.
GradePlan plan_grading(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan, const WorkDir& work,
                       Progress& progress, const std::string& canonical_path, uint64_t max_range_vertices, uint64_t min_ranges,
                       bool sum_areas, const PlanUnits& units) {
  GradePlan gp;
  const uint64_t n_vertices = meta.vertices;

  // Weld. STL stores are welded at ingest already.
  if (meta.format.rfind("stl", 0) == 0 || n_vertices == 0) {
    gp.distinct_positions = n_vertices;
  } else if (!units.weld_runs.empty()) {
    uint64_t welded = 0;
    for (const auto& run : units.weld_runs) welded += run.second;
    gp.distinct_positions = n_vertices - welded;
    gp.welded = welded > 0;
    if (gp.welded && !units.weld_map.empty()) link_file(units.weld_map, canonical_path);
    else if (gp.welded) write_weld_map(units.weld_runs, n_vertices, plan.stage_bytes, work, canonical_path);
  } else {
    gp.distinct_positions = weld_positions(positions_column_path(store_dir, meta), n_vertices,
                                           meta.single_precision, plan.stage_bytes, work, progress, canonical_path);
    gp.welded = gp.distinct_positions < n_vertices;
  }

  gp.range = grade_range_size(meta, plan, max_range_vertices, min_ranges);
  gp.ranges = std::max<uint64_t>((n_vertices + gp.range - 1) / gp.range, 1);
  if (gp.ranges == 1 && !sum_areas) return gp;  // the single range's pass sums the areas

  // The block pass: the ranges each block touches, and the area; from the block units' files when they ran.
  const std::array<uint64_t, 3> blocks = grade_blocks(meta);
  if (units.block_units > 0) {
    const std::string masks = io::read_small_file(units.block_dir + "blocks.bin");
    if (masks.size() != (blocks[0] + blocks[1] + blocks[2]) * sizeof(RangeMask))
      fail(Status::io_error, units.block_dir + "blocks.bin: not the store's blocks (block units)");
    const char* at = masks.data();
    for (int kind = 0; kind < 3; ++kind) {
      gp.block_ranges[kind].resize(blocks[kind]);
      std::memcpy(gp.block_ranges[kind].data(), at, blocks[kind] * sizeof(RangeMask));
      at += blocks[kind] * sizeof(RangeMask);
    }
    // Each unit's blocks of triangles in order, the units in order: the store's block order.
    std::vector<BlockAreaBin> bins;
    for (unsigned u = 0; u < units.block_units; ++u) {
      const std::string path = units.block_dir + fmt::format("areas-{}.bin", u);
      const std::string bytes = io::read_small_file(path);
      const auto [first, end] = block_unit_blocks(blocks[0], u, units.block_units);
      size_t pos = 0;
      for (uint64_t b = first; b < end; ++b) {
        uint32_t n = 0;
        if (pos + 4 > bytes.size()) fail(Status::io_error, path + ": cut short (block units)");
        std::memcpy(&n, bytes.data() + pos, 4);
        pos += 4;
        if (n > kAreaBins || pos + n * sizeof(BlockAreaBin) > bytes.size()) fail(Status::io_error, path + ": not a block unit's areas");
        bins.resize(n);
        std::memcpy(bins.data(), bytes.data() + pos, n * sizeof(BlockAreaBin));
        pos += n * sizeof(BlockAreaBin);
        for (const BlockAreaBin& x : bins)
          if (x.bin >= kAreaBins) fail(Status::io_error, path + ": not a block unit's areas");
        add_block_areas(gp.areas, bins);
      }
      if (pos != bytes.size()) fail(Status::io_error, path + ": not a block unit's areas");
    }
    gp.areas_summed = true;
    return gp;
  }
  Columns columns = store_columns(store_dir, meta);
  Canonical canonical(gp.welded ? canonical_path : std::string(), n_vertices);
  StorePositions positions(store_dir, meta);
  canonical.acquire();
  positions.acquire();
  AreaScratch scratch;
  std::vector<BlockAreaBin> bins;
  uint64_t done = 0;
  const uint64_t total = meta.primitives();
  visit_store(columns, canonical, [](int, uint64_t) { return true; }, [&](int kind, uint64_t b, std::span<const uint32_t> ids) {
    if (kind == 0) block_area(ids, positions, scratch, bins), add_block_areas(gp.areas, bins);
    gp.block_ranges[kind].resize(b + 1);
    gp.block_ranges[kind][b] = block_mask(ids, gp.range);
    done += ids.size() / static_cast<size_t>(Columns::arity[kind]);
    drop_mapped_pages(positions, canonical);
    progress.report("grade", 0.3 * static_cast<double>(done) / static_cast<double>(std::max<uint64_t>(total, 1)));
  });
  positions.release();
  canonical.release();
  gp.areas_summed = true;
  return gp;
}

uint64_t grade_ranges(const std::string& store_dir, const StoreMeta& meta, core::Grading mode, GradePlan& gp,
                      const std::string& canonical_path, uint64_t first, uint64_t end, GradeSorter& sorter, Progress& progress) {
  const uint64_t n_vertices = meta.vertices;
  const uint64_t range = gp.range, n_ranges = gp.ranges;
  const bool sum_areas = !gp.areas_summed;  // the single range of a plan without the block pass
  const Columns columns = store_columns(store_dir, meta);
  Canonical canonical(gp.welded ? canonical_path : std::string(), n_vertices);
  StorePositions positions(store_dir, meta);
  canonical.acquire();
  positions.acquire();
  uint64_t records = 0;
  AreaScratch area_scratch;
  std::vector<BlockAreaBin> area_bins;
  std::vector<uint32_t> count;
  std::vector<uint64_t> offset;
  std::vector<uint32_t> neighbours;
  std::vector<uint8_t> used;
  std::vector<double> grades;
  struct Local {
    core::GradeScratch scratch;
    std::vector<double> nbr;
  };
  tbb::enumerable_thread_specific<Local> locals;

  for (uint64_t r = first; r < end; ++r) {
    progress.check();
    const uint64_t lo = r * range, hi = std::min(n_vertices, lo + range), n = hi - lo;
    // The range's primitives: the blocks that touch it, or the whole store.
    auto visit = [&](auto&& fn) {
      visit_store(
          columns, canonical,
          [&](int kind, uint64_t b) { return n_ranges == 1 || (gp.block_ranges[kind][b][r / 64] >> (r % 64) & 1); },
          [&](int kind, uint64_t, std::span<const uint32_t> ids) { fn(kind, ids); });
    };
    // Calls corner(local id, primitive ids, arity, k) for every corner k in the range. Each task owns a
    // slice of the range's vertices and scans the whole block for their corners: no two tasks touch one
    // vertex, so the counts and fills below need no atomic operations (which cost more than reading the
    // block once per task), and each list is filled in primitive order.
    const size_t slices = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
    auto for_range_corners = [&](std::span<const uint32_t> ids, size_t arity, auto&& corner) {
      tbb::parallel_for(size_t{0}, slices, [&](size_t slice) {
        const uint64_t s_lo = lo + n * slice / slices, s_hi = lo + n * (slice + 1) / slices;
        for (size_t i = 0; i < ids.size(); i += arity) {
          const uint32_t* p = &ids[i];
          for (size_t k = 0; k < arity; ++k)
            if (p[k] >= s_lo && p[k] < s_hi) corner(p[k] - lo, p, arity, k);
        }
      });
    };
    // Incidence counts (and, without the block pass, the area).
    count.assign(n, 0);
    used.assign(n, 0);
    visit([&](int kind, std::span<const uint32_t> ids) {
      if (kind == 0 && sum_areas) block_area(ids, positions, area_scratch, area_bins), add_block_areas(gp.areas, area_bins);
      for_range_corners(ids, static_cast<size_t>(Columns::arity[kind]), [&](uint64_t l, const uint32_t* p, size_t arity, size_t k) {
        used[l] = 1;
        uint32_t others = 0;
        for (size_t j = 0; j < arity; ++j) others += j != k && p[j] != p[k];
        count[l] += others;
      });
    });
    offset.assign(n + 1, 0);
    for (uint64_t i = 0; i < n; ++i) offset[i + 1] = offset[i] + count[i];
    neighbours.resize(offset[n]);
    for (uint64_t i = 0; i < n; ++i) count[i] = 0;
    // Fill (each list is sorted below).
    visit([&](int kind, std::span<const uint32_t> ids) {
      if (Columns::arity[kind] == 1) return;
      for_range_corners(ids, static_cast<size_t>(Columns::arity[kind]), [&](uint64_t l, const uint32_t* p, size_t arity, size_t k) {
        for (size_t j = 0; j < arity; ++j) {
          if (j == k || p[j] == p[k]) continue;
          neighbours[offset[l] + count[l]++] = p[j];
        }
      });
    });
    // Grade.
    grades.assign(n, 0);
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, n, 1 << 10), [&](const tbb::blocked_range<uint64_t>& b) {
      Local& loc = locals.local();
      for (uint64_t l = b.begin(); l < b.end(); ++l) {
        if (!used[l]) continue;
        uint32_t* first_n = neighbours.data() + offset[l];
        uint32_t* last_n = neighbours.data() + offset[l + 1];
        std::sort(first_n, last_n);
        last_n = std::unique(first_n, last_n);
        loc.nbr.resize(3 * static_cast<size_t>(last_n - first_n));
        for (uint32_t* it = first_n; it != last_n; ++it) positions.get(*it, &loc.nbr[3 * (it - first_n)]);
        double p[3];
        positions.get(lo + l, p);
        grades[l] = core::grade_vertex(std::span<const double, 3>(p, 3), loc.nbr, mode, loc.scratch).grade;
      }
    });
    for (uint64_t l = 0; l < n; ++l) {
      if (!used[l]) continue;
      sorter.push(GradeRecord{grades[l], static_cast<uint32_t>(lo + l)});
      ++records;
    }
    drop_mapped_pages(positions, canonical);
    progress.report("grade", 0.3 + 0.5 * static_cast<double>(r + 1 - first) / static_cast<double>(end - first));
  }
  if (sum_areas) gp.areas_summed = true;
  positions.release();
  canonical.release();
  return records;
}

void write_weight_index(GradeSorter& sorter, uint64_t records, const std::string& order_path, const std::string& grades_path,
                        Progress& progress) {
  io::FileWriter order(order_path, 4 << 20);
  std::unique_ptr<io::FileWriter> grade_out;
  if (!grades_path.empty()) grade_out = std::make_unique<io::FileWriter>(grades_path, 4 << 20);
  uint64_t written = 0;
  sorter.merge([&](const GradeRecord& rec) {
    const uint32_t id = rec.id;
    order.write(&id, sizeof id);
    if (grade_out) {
      const double grade = rec.grade;
      grade_out->write(&grade, sizeof grade);
    }
    if ((++written & 0xFFFFF) == 0) progress.report("sort", static_cast<double>(written) / static_cast<double>(std::max<uint64_t>(records, 1)));
  });
  if (written != records)
    fail(Status::io_error, order_path + ": the weight index has " + std::to_string(written) + " records, not " + std::to_string(records));
  order.commit();
  if (grade_out) grade_out->commit();
  progress.report("sort", 1);
}

GradeSummary grade_and_sort(const std::string& store_dir, const StoreMeta& meta, core::Grading mode,
                            const MemoryPlan& plan, const WorkDir& work, Progress& progress,
                            const std::string& canonical_path, const std::string& order_path,
                            const std::string& grades_path, uint64_t max_range_vertices) {
  GradePlan gp = plan_grading(store_dir, meta, plan, work, progress, canonical_path, max_range_vertices, 1, false);
  GradeSorter sorter(work, "weights", std::max<uint64_t>(plan.stage_bytes / 3, 4 << 20));
  sorter.expect(gp.distinct_positions);  // at least the records: one per used canonical vertex
  const uint64_t records = grade_ranges(store_dir, meta, mode, gp, canonical_path, 0, gp.ranges, sorter, progress);
  progress.report("grade", 1);
  write_weight_index(sorter, records, order_path, grades_path, progress);
  return summary_of(gp, records);
}

GradeSummary summary_of(const GradePlan& gp, uint64_t records) {
  GradeSummary summary;
  summary.records = records;
  summary.distinct_positions = gp.distinct_positions;
  summary.ranges = gp.ranges;
  summary.areas = gp.areas;
  for (double a : summary.areas.area) summary.surface_area += a;
  return summary;
}

}  // namespace lodstream::stream

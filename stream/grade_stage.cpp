// Stages 2 and 3: weld by position, grade per id range (each range reads the store's blocks that touch
// it), sort into the weight index. See grade_stage.h for the contract.
#include "stream/grade_stage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>
#include <type_traits>
#include <vector>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/distinct_count.h"
#include "stream/external_sort.h"
#include "stream/store_access.h"
#include "stream/weld_file.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kBlock = 1 << 18;  // primitives per mapped block
constexpr uint64_t kMaxRanges = 256;

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

// Visits the store's primitives of each kind (0 triangles, 1 segments, 2 points) in fixed blocks of kBlock
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
    for (uint64_t first = 0, b = 0; first < c.count[kind]; first += kBlock, ++b) {
      if (!want(kind, b)) continue;
      const uint64_t n = std::min(kBlock, c.count[kind] - first);
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

// The ranges (of kMaxRanges at most) that the corners of a block fall in, one bit each.
using RangeMask = std::array<uint64_t, kMaxRanges / 64>;

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

// Adds a block of triangles to the area histogram, in triangle order (a fixed order: the same bits every
// run, since blocks are fixed and come in store order). The areas and their bins are computed in parallel
// into `scratch`; only the sums run serially, in triangle order.
void block_area(std::span<const uint32_t> tris, const StorePositions& pos, AreaHistogram& h,
                std::vector<BinnedArea>& scratch) {
  scratch.resize(tris.size() / 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, scratch.size(), 1 << 12), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t < r.end(); ++t) {
      double a[3], b[3], c[3];
      pos.get(tris[3 * t], a), pos.get(tris[3 * t + 1], b), pos.get(tris[3 * t + 2], c);
      const double area = triangle_area(a, b, c);
      int bin = 0;
      if (area > 0) bin = std::clamp(static_cast<int>(std::floor(4 * std::log2(area))) + kAreaBias, 0, kAreaBins - 1);
      scratch[t] = {area, bin};
    }
  });
  for (const BinnedArea& x : scratch) {
    ++h.count[x.bin];
    h.area[x.bin] += x.area;
  }
}

}  // namespace

GradeSummary grade_and_sort(const std::string& store_dir, const StoreMeta& meta, core::Grading mode,
                            const MemoryPlan& plan, const WorkDir& work, Progress& progress,
                            const std::string& canonical_path, const std::string& order_path,
                            const std::string& grades_path, uint64_t max_range_vertices) {
  GradeSummary summary;
  const uint64_t n_vertices = meta.vertices;
  Columns columns{{store_dir + "/triangles.u32", store_dir + "/lines.u32", store_dir + "/points.u32"},
                  {meta.triangles, meta.lines, meta.points}};

  // Weld. STL stores are welded at ingest already.
  bool welded = false;
  if (meta.format.rfind("stl", 0) == 0 || n_vertices == 0) {
    summary.distinct_positions = n_vertices;
  } else {
    // The weld map is the one array per stored vertex held whole (4 bytes each): with the smallest key
    // batches beside it (one of the 256 hash buckets and a table per thread), about 4.7 bytes a vertex.
    const uint64_t held = n_vertices * 4;
    const uint64_t least = held + n_vertices * 3 / 4 + (16 << 20);
    if (least > plan.stage_bytes)
      fail(Status::usage, "welding " + std::to_string(n_vertices) + " stored vertices needs at least " +
                              std::to_string(least >> 20) + " MiB, more than --memory allows (" +
                              std::to_string(plan.stage_bytes >> 20) + " MiB for the stage): raise --memory");
    std::vector<uint32_t> canonical(n_vertices);
    summary.distinct_positions = weld_positions(
        store_dir + (meta.single_precision ? "/positions.f32" : "/positions.f64"), n_vertices, meta.single_precision,
        plan.stage_bytes > held + (16 << 20) ? plan.stage_bytes - held : (16 << 20), progress, canonical);
    if (summary.distinct_positions < n_vertices) {
      write_weld_file(canonical_path, canonical);
      welded = true;
    }
  }
  Canonical canonical(welded ? canonical_path : std::string(), n_vertices);
  StorePositions positions(store_dir, meta);

  // Range size from the budget: per vertex its offsets, counters, a record, and its share of incidence
  // entries (two per triangle corner, one per segment end).
  const double incidences = n_vertices ? static_cast<double>(6 * meta.triangles + 2 * meta.lines) / static_cast<double>(n_vertices) : 0;
  const uint64_t per_vertex = 8 + 4 + 8 + sizeof(GradeRecord) + static_cast<uint64_t>(std::ceil(4 * incidences));
  const uint64_t range_budget = std::max<uint64_t>(plan.stage_bytes / 3, 16 << 20);
  uint64_t range = std::max<uint64_t>(range_budget / per_vertex, 4096);
  if (max_range_vertices) range = std::min(range, max_range_vertices);
  range = std::max<uint64_t>({range, (n_vertices + kMaxRanges - 1) / kMaxRanges, 1});
  const uint64_t n_ranges = std::max<uint64_t>((n_vertices + range - 1) / range, 1);
  summary.ranges = n_ranges;

  // With more than one range, a first pass notes the ranges each block touches, and sums the area.
  std::vector<RangeMask> block_ranges[3];
  std::vector<BinnedArea> area_scratch;
  canonical.acquire();
  positions.acquire();
  // Mapped pages count as resident (the memory contract): the columns are remapped after every block of
  // the first pass and every range of the grading, which drops the pages they touched from the process
  // (the page cache keeps them). Without it, a pass over a 193M-triangle scene held 1.9 GB of them.
  auto drop_mapped_pages = [&] {
    positions.release();
    canonical.release();
    positions.acquire();
    canonical.acquire();
  };
  if (n_ranges > 1) {
    uint64_t done = 0;
    const uint64_t total = meta.primitives();
    visit_store(columns, canonical, [](int, uint64_t) { return true; }, [&](int kind, uint64_t b, std::span<const uint32_t> ids) {
      if (kind == 0) block_area(ids, positions, summary.areas, area_scratch);
      RangeMask mask = tbb::parallel_reduce(
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
      block_ranges[kind].resize(b + 1);
      block_ranges[kind][b] = mask;
      done += ids.size() / static_cast<size_t>(Columns::arity[kind]);
      drop_mapped_pages();
      progress.report("grade", 0.3 * static_cast<double>(done) / static_cast<double>(std::max<uint64_t>(total, 1)));
    });
  }

  // The rest: grading by range, the sort.
  auto grade_ranges = [&] {
    using Record = GradeRecord;
    ExternalSorter<Record, WeightLess> sorter(work, "weights", std::max<uint64_t>(plan.stage_bytes / 3, 4 << 20));
    sorter.expect(summary.distinct_positions);  // at least the records: one per used canonical vertex
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

    for (uint64_t r = 0; r < n_ranges; ++r) {
      progress.check();
      const uint64_t lo = r * range, hi = std::min(n_vertices, lo + range), n = hi - lo;
      // The range's primitives: the blocks that touch it, or the whole store.
      auto visit = [&](auto&& fn) {
        visit_store(
            columns, canonical,
            [&](int kind, uint64_t b) { return n_ranges == 1 || (block_ranges[kind][b][r / 64] >> (r % 64) & 1); },
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
      // Pass 1: incidence counts (and, with one range, the area).
      count.assign(n, 0);
      used.assign(n, 0);
      visit([&](int kind, std::span<const uint32_t> ids) {
        if (kind == 0 && n_ranges == 1) block_area(ids, positions, summary.areas, area_scratch);
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
      // Pass 2: fill (each list is sorted below).
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
          uint32_t* first = neighbours.data() + offset[l];
          uint32_t* last = neighbours.data() + offset[l + 1];
          std::sort(first, last);
          last = std::unique(first, last);
          loc.nbr.resize(3 * static_cast<size_t>(last - first));
          for (uint32_t* it = first; it != last; ++it) positions.get(*it, &loc.nbr[3 * (it - first)]);
          double p[3];
          positions.get(lo + l, p);
          grades[l] = core::grade_vertex(std::span<const double, 3>(p, 3), loc.nbr, mode, loc.scratch).grade;
        }
      });
      for (uint64_t l = 0; l < n; ++l) {
        if (!used[l]) continue;
        Record rec{};
        rec.grade = grades[l];
        rec.id = static_cast<uint32_t>(lo + l);
        sorter.push(rec);
        ++summary.records;
      }
      drop_mapped_pages();
      progress.report("grade", 0.3 + 0.5 * static_cast<double>(r + 1) / static_cast<double>(n_ranges));
    }
    for (double a : summary.areas.area) summary.surface_area += a;
    progress.report("grade", 1);
    positions.release();
    canonical.release();
    std::vector<uint32_t>().swap(count);
    std::vector<uint64_t>().swap(offset);
    std::vector<uint32_t>().swap(neighbours);
    std::vector<uint8_t>().swap(used);
    std::vector<double>().swap(grades);

    io::FileWriter order(order_path, 4 << 20);
    std::unique_ptr<io::FileWriter> grade_out;
    if (!grades_path.empty()) grade_out = std::make_unique<io::FileWriter>(grades_path, 4 << 20);
    uint64_t written = 0;
    sorter.merge([&](const Record& rec) {
      const uint32_t id = rec.id;
      order.write(&id, sizeof id);
      if (grade_out) {
        const double grade = rec.grade;
        grade_out->write(&grade, sizeof grade);
      }
      if ((++written & 0xFFFFF) == 0)
        progress.report("sort", static_cast<double>(written) / static_cast<double>(summary.records));
    });
    order.commit();
    if (grade_out) grade_out->commit();
    progress.report("sort", 1);
  };
  grade_ranges();
  return summary;
}

}  // namespace lodstream::stream

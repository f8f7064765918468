// Stages 2 and 3 of the pipeline (../shared/DESIGN.md): grade every vertex exactly, then sort the grades
// into the weight index.
//
// Vertices are graded by position: all stored vertices at one exact position (an indexed file repeats a
// position wherever normals or texture coordinates split it) are welded to the smallest such id, their
// "canonical" vertex, and graded as one, from the union of their neighbours. Clustering then sees each
// position once, so duplicates can never be torn into different cells.
//
// Grading runs over ranges of canonical ids, as many as the memory budget needs. A first pass over the
// store notes, for every fixed block of primitives, the ranges its corners fall in; a range then reads
// the blocks that touch it, straight from the store (no copy on disk), and builds its vertices' complete
// incidence, so a vertex whose primitives lie in many blocks (a seam vertex) is graded from all of them,
// with the same bits as in a single-range run. Files whose vertex ids are local (as exporters write them)
// read each block about once; ids scattered over the whole file make every range read most of the store. The
// grade kernel (core/grade.h) depends only on the set of neighbour positions, never on their order.
//
// Grades of vertices no triangle or segment touches: a vertex used only by points has grade 0 (it is
// clustered like any other); a vertex no primitive uses is left out of the weight index altogether, so it
// can neither start a cell nor appear in an output.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/grade.h"
#include "stream/external_sort.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// One record of the sort that makes the weight order: a canonical vertex and its grade, 12 bytes. The
// positions are not carried (the cluster stage reads them from the store by id), so that the sort's runs
// and its output stay small: the output is the order alone, 4 bytes a record (`order.u32`), and, when a
// later stage sums grades (the mean representative), the grades beside it, 8 bytes a record.
struct __attribute__((packed, aligned(4))) GradeRecord {
  double grade;
  uint32_t id;  // canonical vertex id
};
static_assert(sizeof(GradeRecord) == 12);
// Non-increasing grade, ties by increasing id: a total order, since ids are unique.
struct WeightLess {
  template <class Record>
  bool operator()(const Record& a, const Record& b) const {
    if (a.grade != b.grade) return a.grade > b.grade;
    return a.id < b.id;
  }
};

// Triangle areas in bins of a quarter power of two: bin b holds areas in [2^((b - kAreaBias)/4), ...).
// Default cell sizes are estimated from it (simplify.cpp).
inline constexpr int kAreaBins = 2048;
inline constexpr int kAreaBias = 1024;
struct AreaHistogram {
  std::vector<uint64_t> count = std::vector<uint64_t>(kAreaBins, 0);
  std::vector<double> area = std::vector<double>(kAreaBins, 0.0);
};

struct GradeSummary {
  uint64_t records = 0;             // vertices in the weight index
  uint64_t distinct_positions = 0;  // among all stored vertices
  double surface_area = 0;          // sum of triangle areas, scene units²
  uint64_t ranges = 0;              // id ranges graded one after another (1 = everything at once)
  AreaHistogram areas;
  bool ordered_positions = false;   // the records' positions in weight order were written (position_gather.h)
};

// Writes `canonical_path` (the weld map: every stored vertex's canonical id, stream/weld_file.h) unless every position is distinct
// (then it writes nothing and returns distinct == vertices), and the weight index: the used canonical
// vertices in WeightLess order, their ids in `order_path` (uint32 each) and, unless `grades_path` is
// empty, their grades in `grades_path` (double each). `max_range_vertices` caps the range size
// (0 = from the budget; tests force small ranges to exercise the seams). Throws Failure.
// It runs the passes below in order: plan_grading, grade_ranges over every range, write_weight_index.
GradeSummary grade_and_sort(const std::string& store_dir, const StoreMeta& meta, core::Grading mode,
                            const MemoryPlan& plan, const WorkDir& work, Progress& progress,
                            const std::string& canonical_path, const std::string& order_path,
                            const std::string& grades_path, uint64_t max_range_vertices);

// The passes of grade_and_sort, which the grading shares (stream/grade_shares.h) run in different processes.
inline constexpr uint64_t kGradeBlock = 1 << 18;      // primitives per block of the store's columns
inline constexpr uint64_t kMaxGradeRanges = 256;      // id ranges at most
using RangeMask = std::array<uint64_t, kMaxGradeRanges / 64>;  // the ranges a block's corners fall in, a bit each
using GradeSorter = ExternalSorter<GradeRecord, WeightLess>;

struct GradePlan {
  uint64_t distinct_positions = 0;
  bool welded = false;          // the weld map was written (some positions repeat)
  uint64_t range = 0;           // canonical ids per range: range r is [r·range, (r+1)·range)
  uint64_t ranges = 0;
  bool areas_summed = false;    // `areas` holds the whole store's triangles
  AreaHistogram areas;
  std::vector<RangeMask> block_ranges[3];  // per block of triangles, segments, points (more than one range)
};
// What the grading shares' units made before the plan (stream/grade_shares.h): the weld units' runs (path,
// pairs), the map the weld map's units wrote (empty: write it from the runs), and the block units'
// directory (blocks.bin and areas-U.bin; block_units 0: none ran).
struct PlanUnits {
  std::vector<std::pair<std::string, uint64_t>> weld_runs;
  std::string weld_map;
  std::string block_dir;
  unsigned block_units = 0;
};
// A block of triangles' areas in one bin of the histogram, summed in triangle order: what the block pass
// adds to the histogram, block after block in store order, so that a block computed by another process
// (a block unit) adds the same bits.
struct BlockAreaBin {
  uint32_t bin, count;
  double area;
};
static_assert(sizeof(BlockAreaBin) == 16);
// The range size plan_grading picks (ids per range).
uint64_t grade_range_size(const StoreMeta& meta, const MemoryPlan& plan, uint64_t max_range_vertices, uint64_t min_ranges);
// The store's blocks of kGradeBlock triangles, segments and points.
std::array<uint64_t, 3> grade_blocks(const StoreMeta& meta);
// The blocks [first, end) of a kind of `blocks` that block unit `unit` of `units` visits.
std::pair<uint64_t, uint64_t> block_unit_blocks(uint64_t blocks, unsigned unit, unsigned units);
// The block pass as units (the grading shares', stream/grade_shares.h): unit `unit` of `units` visits its
// blocks of each kind (ids mapped by the weld map at `canonical_path`, empty: none), writes each block's
// ranges (RangeMask of `range` ids a range) in place at its index in `masks_path` (the kinds' blocks one
// after another, the file sized beforehand) and, per block of triangles in order, its bins' areas to
// `areas_path` (a u32 count, then that many BlockAreaBin).
void block_pass_unit(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path, uint64_t range,
                     unsigned unit, unsigned units, const std::string& masks_path, const std::string& areas_path,
                     Progress& progress);
// Pass 1: the weld (writes `canonical_path` when positions repeat; from the weld units' runs when given,
// linked from the map the weld map's units wrote when given: stream/grade_shares.h), the range size (from the budget, at most
// `max_range_vertices` when non-zero, and small enough for `min_ranges` ranges), and, with more than one
// range or `sum_areas`, the block pass: every block's ranges, and the area histogram.
GradePlan plan_grading(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan, const WorkDir& work,
                       Progress& progress, const std::string& canonical_path, uint64_t max_range_vertices, uint64_t min_ranges,
                       bool sum_areas, const PlanUnits& units = {});
// Pass 2: grades the vertices of ranges [first, end), pushing a record for every used one into `sorter`;
// returns the records pushed. A plan without its areas (one range, no block pass) gets them here.
uint64_t grade_ranges(const std::string& store_dir, const StoreMeta& meta, core::Grading mode, GradePlan& plan,
                      const std::string& canonical_path, uint64_t first, uint64_t end, GradeSorter& sorter, Progress& progress);
// Pass 3: the sorter's records, `records` of them, in order into `order_path` and, unless empty, `grades_path`.
void write_weight_index(GradeSorter& sorter, uint64_t records, const std::string& order_path, const std::string& grades_path,
                        Progress& progress);
GradeSummary summary_of(const GradePlan& plan, uint64_t records);

}  // namespace lodstream::stream

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

#include <cstdint>
#include <string>

#include "core/grade.h"
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
};

// Writes `canonical_path` (the weld map: every stored vertex's canonical id, stream/weld_file.h) unless every position is distinct
// (then it writes nothing and returns distinct == vertices), and the weight index: the used canonical
// vertices in WeightLess order, their ids in `order_path` (uint32 each) and, unless `grades_path` is
// empty, their grades in `grades_path` (double each). `max_range_vertices` caps the range size
// (0 = from the budget; tests force small ranges to exercise the seams). Throws Failure.
GradeSummary grade_and_sort(const std::string& store_dir, const StoreMeta& meta, core::Grading mode,
                            const MemoryPlan& plan, const WorkDir& work, Progress& progress,
                            const std::string& canonical_path, const std::string& order_path,
                            const std::string& grades_path, uint64_t max_range_vertices);

}  // namespace lodstream::stream

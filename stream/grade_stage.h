// Stages 2 and 3 of the pipeline (../shared/DESIGN.md): grade every vertex exactly, then sort the grades
// into the weight index.
//
// Vertices are graded by position: all stored vertices at one exact position (an indexed file repeats a
// position wherever normals or texture coordinates split it) are welded to the smallest such id, their
// "canonical" vertex, and graded as one, from the union of their neighbours. Clustering then sees each
// position once, so duplicates can never be torn into different cells.
//
// Grading runs over ranges of canonical ids, as many as the memory budget needs. Every primitive is routed,
// once per range its corners fall in, to that range's bucket file (with one range, the store is read
// directly); a range then builds its vertices' complete incidence, so a vertex whose primitives lie in many
// chunks (a seam vertex) is graded from all of them, with the same bits as in a single-chunk run. The
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

// One weight-index record. The position is kept at the scene store's precision: 24 bytes for a
// single-precision store (most inputs: PLY/STL/OBJ floats), 40 for a double one. The index is written
// and read back in full (about 1.4 GB for 35 M vertices at 40 bytes), so its record size is a large share
// of the grade and cluster stages' I/O; widening float to double in the cluster pass is exact, so the
// clustering sees the same values either way.
struct WeightRecord32 {
  double grade;
  uint32_t id;  // canonical vertex id
  float position[3];
};
struct WeightRecord64 {
  double grade;
  uint32_t id;        // canonical vertex id
  uint32_t reserved;  // 0 (no indeterminate padding bytes in the file)
  double position[3];
};
static_assert(sizeof(WeightRecord32) == 24 && sizeof(WeightRecord64) == 40);
inline uint64_t weight_record_bytes(bool single_precision) {
  return single_precision ? sizeof(WeightRecord32) : sizeof(WeightRecord64);
}
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

// Writes `canonical_path` (uint32 per stored vertex: its canonical id) unless every position is distinct
// (then it writes nothing and returns distinct == vertices), and `index_path`, the weight index: one
// record (WeightRecord32 if meta.single_precision, else WeightRecord64) per used canonical vertex in
// WeightLess order. `max_range_vertices` caps the range size
// (0 = from the budget; tests force small ranges to exercise the seams). Throws Failure.
GradeSummary grade_and_sort(const std::string& store_dir, const StoreMeta& meta, core::Grading mode,
                            const MemoryPlan& plan, const WorkDir& work, Progress& progress,
                            const std::string& canonical_path, const std::string& index_path,
                            uint64_t max_range_vertices);

}  // namespace lodstream::stream

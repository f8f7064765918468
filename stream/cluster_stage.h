// Stage 4 of the pipeline: one ordered pass over the weight index assigns every vertex to a cell in every
// level (core/floating_cell.h). Levels are independent given the order, so each level runs as its own task
// over the same blocks of records; the result does not depend on how the levels are spread over threads.
//
// Input: the weight index (grade stage: `order.u32`, the canonical ids in weight order, and `grades.f64`
// when the mean representative needs them) and the records' positions: in weight order from
// `positions-w.f32` (or .f64; position_gather.h), read sequentially, or, when the index names no such file,
// the store's positions read by id.
// Output, in the work directory:
//   cells-L.map          per level L: the cell of each record, in weight order, bit-packed (cell_map_file.h)
//   cells-L.info         per level L: per cell, in cell-id order, what the emit stage's representative reads
//                        (CellInfoKind): its center's position (written during the pass), its mean, or both
// Memory: the clusterers' tables and cell records (about 46 bytes a cell: kClusterBytesPerCell; it grows
// with the cells, not the vertices), and the positions: a block of records at a time per clusterer from
// the weight-ordered file; without it, the store's column mapped whole where it takes at most half the
// budget, else read by id through the page cache, one batch of records (a quarter of the budget) at a time
// for every clusterer (position_gather.h; the same bytes every way). The sums for a mean are
// made afterwards, from the maps and the index read again, in ranges of cells that fit in what the
// clusterers held. When the clusterers would outgrow `memory_bytes` (what the process may add to its
// resident set while the stage runs), the stage stops with Failure(Status::usage) naming the cells so far,
// rather than pass the budget.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/floating_cell.h"
#include "io/mapped_file.h"
#include "lodstream/lodstream.h"
#include "stream/grade_stage.h"
#include "stream/position_gather.h"
#include "stream/cell_map_file.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// A cell's sums, as the sums pass makes them and as CellInfoReader gives them back to the emit stage.
struct CellInfo {
  double center[3];     // the center vertex's position (uniform: the first vertex that fell in the square)
  double weighted[3];   // Σ grade · position over the cell's vertices
  double sum[3];        // Σ position
  double weight;        // Σ grade
  uint32_t center_vertex;
  uint32_t vertices;    // canonical vertices in the cell
};
static_assert(sizeof(CellInfo) == 88);

// What a level's cells-L.info holds per cell, by representative (lodstream.h): the center's position at
// the store's precision (center), the mean of the cell's vertices as the emit stage computes it: Σ grade ·
// position / Σ grade, or the plain mean when Σ grade is 0 (mean), or the center and the plain mean
// (quadric). 12 to 48 bytes a cell, where every sum took 88.
enum class CellInfoKind { center, mean, quadric };
CellInfoKind cell_info_kind(Representative r);
uint64_t cell_info_bytes(CellInfoKind kind, bool single_precision);

// Reads a level's cells-L.info back as CellInfo records that give the emit stage's arithmetic the same
// bits as the full sums: the center as stored; a mean m as weighted = m, weight = 1 (m / 1 = m) and as
// sum = m, vertices = 1. The other fields are 0.
class CellInfoReader {
 public:
  // Throws Failure(io_error) when the file does not hold `cells` records of `kind`.
  CellInfoReader(const std::string& path, uint64_t cells, CellInfoKind kind, bool single_precision);
  // The records of cells [first, end); thread-safe.
  io::Window map(uint64_t first, uint64_t end) const;
  // Record i of a window from map().
  CellInfo get(const io::Window& w, uint64_t i) const;

 private:
  io::MappedFile file_;
  CellInfoKind kind_;
  bool single_;
  uint64_t bytes_;
};

struct ClusterSummary {
  std::vector<uint64_t> cells;       // per level
  std::vector<char> vertex_cells;    // per level: its cells by vertex are written (merge_cluster_shares), or empty
};

// Cells of two sizes in a level (simplify's silhouette labels, core/silhouette_labels.h): a record whose
// label is at most near[l] (scene units) joins level l's fine grid, of cell size sizes[l] (0: the level
// has none; core/floating_cell.h). labels_path: one float per weight-index record, in weight order,
// read in blocks beside the index.
struct FineCells {
  std::string labels_path;
  std::vector<double> sizes;
  std::vector<double> near;
};

// The weight index and where its positions are: `order_path` holds `records` canonical ids (uint32) in
// weight order, `grades_path` their grades (double; read for CellInfoKind::mean only),
// `positions_path` the store's positions of `vertices` vertices (float if single_precision, else double),
// and `ordered_positions_path`, unless empty, the records' positions in weight order (position_gather.h:
// the passes in weight order read them sequentially instead of by id; the same values, the same bytes out).
struct WeightIndex {
  std::string order_path, grades_path, positions_path;
  uint64_t records = 0, vertices = 0;
  bool single_precision = true;
  std::string ordered_positions_path{};
};
// Where a pass's positions come from (position_gather.h): the index's weight-ordered file when it names
// one, else the store's column by id, mapped whole where it takes at most half the budget.
RecordPositions record_positions(const WeightIndex& weights, uint64_t memory_bytes, uint64_t chunk_cap);
// The ids of records [at, at + size) and their positions as plain arrays, widened to double (exact for
// float): a pass's block in weight order (the clustering passes' shared batch or a group's own block, the
// clustering shares' centers and ranges).
struct RecordBatch {
  uint64_t at = 0;
  std::vector<uint32_t> ids;
  std::vector<double> xyz;
  PositionGather::Scratch scratch;
  void load(const io::MappedFile& order, const RecordPositions& positions, uint64_t first, uint64_t n) {
    at = first;
    ids.resize(n);
    xyz.resize(3 * n);
    order.read(first * 4, n * 4, ids.data());
    positions.load(first, ids, xyz.data(), scratch);
  }
};
// bounds: empty, or the min and max corners (6 values) of a box holding every position in the index,
// which lets the coarse levels index their squares directly (core::Clusterer); the result is the same
// either way.
ClusterSummary cluster_levels(const WeightIndex& index, std::span<const double> bounds, std::span<const double> cell_sizes,
                              const core::ClusterOptions& options, CellInfoKind info, uint64_t memory_bytes,
                              const WorkDir& work, Progress& progress, const std::string& prefix,
                              const FineCells* fine = nullptr, uint64_t chunk_cap = 0);

// The sums pass of cluster_levels on its own, for maps written another way (stream/cluster_shares.h): the
// info files cells-L.info of `levels` (level numbers; cells[j] cells in levels[j]) from their cluster maps
// under `prefix`, the index and the positions, the same bytes cluster_levels writes. Nothing to do for
// CellInfoKind::center (the pass that makes the maps writes the centers).
void sum_cell_info(const WeightIndex& index, std::span<const size_t> levels, std::span<const uint64_t> cells,
                   CellInfoKind info, uint64_t memory_bytes, uint64_t chunk_cap, Progress& progress, const std::string& prefix);
// The same pass for the cells [first, end) of `levels` only (their cells taken one level after another),
// written in place into info files already sized to their cells (a unit of the clustering merge,
// stream/cluster_merge.h): those cells' bytes of sum_cell_info, since each cell adds its vertices in weight
// order whichever cells are summed beside it. `threads`: the ranges of cells summed at once (each reads
// every record); `memory_bytes`: this call's budget.
// `start`: where the pass begins and what it reads. A level's cells are numbered in their centers' weight
// order and a cell's center is its first record, so no record before the center of the range's first
// cell of each level is in one of its cells: start.record may be the first of those centers. start.entries:
// per level, where start.record's cell starts in its map (MapEntry, stream/cell_map_file.h), which is read
// from there; empty: the maps, decoded from their first record (start.record is then ignored: a packed map
// cannot be entered in the middle without the bits and the cells before).
struct SumStart {
  uint64_t record = 0;
  std::vector<MapEntry> entries;
};
void sum_cell_info_range(const WeightIndex& index, std::span<const size_t> levels, std::span<const uint64_t> cells,
                         CellInfoKind info, uint64_t memory_bytes, uint64_t chunk_cap, Progress& progress,
                         const std::string& prefix, uint64_t first, uint64_t end, unsigned threads, const SumStart& start);

// The early estimate (before the stage runs, so that a run that cannot fit stops at once rather than
// after minutes of clustering). Cells of a level of size c: a surface of area A cut into cells of side c
// gives about kEstimatedCellsPerArea · A/c² cells (calibrated on the 48.6 M-triangle city: 1.07× the finest
// level's cells, 1.1× over its five default levels; 1.12× and 1.14× on the 193 M one), but a triangle
// larger than that keeps only its corners,
// so each bin of the area histogram gives at most its share of the index's vertices (records per
// triangle); and no level has more cells than the index has records.
inline constexpr double kEstimatedCellsPerArea = 0.8;
uint64_t estimated_cells(const AreaHistogram& areas, double cell_size, uint64_t records);
// Bytes the clustering pass holds per cell at its peak (tables, records, the headroom of a growth step),
// for double and float stores: the float figure as measured over the levels of the 48.6 M-triangle city
// and the 193 M-triangle one (README, "Cluster stage: bytes per cell"); the double one adds the 16 bytes by which a
// DoubleCell record is larger (not measured: the real scenes at hand are float stores).
inline constexpr uint64_t kClusterBytesPerCell[2] = {62, 46};
// Fails with Status::usage, one line with the estimated cells per level, the bytes they need and the
// budget, when the estimate, with the coarse levels' dense arrays over `bounds`, does not fit in what
// `memory_bytes` leaves the cells (the same share the stage's own check uses). Levels with no triangle
// area (lines, points) estimate 0: the stage's check is then the only one.
// `vertices`: the store's, whose positions the stage maps or reads (`chunk_cap`: --chunk-bytes, as
// cluster_levels takes it).
void check_cluster_estimate(const AreaHistogram& areas, uint64_t records, uint64_t vertices, bool single_precision,
                            std::span<const double> bounds, std::span<const double> cell_sizes,
                            uint64_t memory_bytes, uint64_t chunk_cap = 0);

std::string cells_path(const std::string& prefix, size_t level);
std::string cell_info_path(const std::string& prefix, size_t level);
// The grade stage's files, read by this stage and the emit stage.
std::string order_path(const std::string& prefix);
std::string grades_path(const std::string& prefix);

}  // namespace lodstream::stream

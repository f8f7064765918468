// Stage 4 of the pipeline: one ordered pass over the weight index assigns every vertex to a cell in every
// level (core/floating_cell.h). Levels are independent given the order, so each level runs as its own task
// over the same blocks of records; the result does not depend on how the levels are spread over threads.
//
// Output, in the work directory:
//   order.u32            the canonical vertex id of each weight-index record, in weight order
//   cells-L.u32          per level L: the cell id of each record, in weight order
//   cells-L.info         per level L: one CellInfo per cell, in cell-id order
// Memory: the clusterers' tables and cell records (about 46 bytes a cell: kClusterBytesPerCell; it grows
// with the cells, not the vertices). The CellInfo records are summed afterwards, from the maps and the
// index read again, in ranges of cells that fit in what the clusterers held. When the clusterers would
// outgrow `memory_bytes` (what the process may add to its resident set while the stage runs), the stage
// stops with Failure(Status::usage) naming the cells so far, rather than pass the budget.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/floating_cell.h"
#include "stream/grade_stage.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

struct CellInfo {
  double center[3];     // the center vertex's position (uniform: the first vertex that fell in the square)
  double weighted[3];   // Σ grade · position over the cell's vertices
  double sum[3];        // Σ position
  double weight;        // Σ grade
  uint32_t center_vertex;
  uint32_t vertices;    // canonical vertices in the cell
};
static_assert(sizeof(CellInfo) == 88);

struct ClusterSummary {
  std::vector<uint64_t> cells;  // per level
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

// index_path: the weight index of `records` records (WeightRecord32 if single_precision, else
// WeightRecord64; stream/grade_stage.h). bounds: empty, or the min and max corners (6 values) of a box
// holding every position in the index, which lets the coarse levels index their squares directly
// (core::Clusterer); the result is the same either way.
ClusterSummary cluster_levels(const std::string& index_path, uint64_t records, bool single_precision,
                              std::span<const double> bounds, std::span<const double> cell_sizes,
                              const core::ClusterOptions& options, uint64_t memory_bytes,
                              const WorkDir& work, Progress& progress, const std::string& prefix,
                              const FineCells* fine = nullptr);

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
void check_cluster_estimate(const AreaHistogram& areas, uint64_t records, bool single_precision,
                            std::span<const double> bounds, std::span<const double> cell_sizes,
                            uint64_t memory_bytes);

std::string cells_path(const std::string& prefix, size_t level);
std::string cell_info_path(const std::string& prefix, size_t level);
std::string order_path(const std::string& prefix);

}  // namespace lodstream::stream

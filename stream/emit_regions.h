// The spatial regions the emit stage works in (core/octree_regions.h, the contract with the 3D Tiles
// writer): every level's cut, the region of each of its cells, the batches of regions
// that the memory plan lets one pass hold, and each cell's representative written ahead to the work
// directory, so that a batch reads the representatives of its neighbours' cells as they will be.
//
// Memory: cutting a level holds 8 bytes per cell of that level (the cells' codes, sorted); a level's region
// table 4 bytes per cell; the representatives pass, with quadric representatives, one quadric (80 bytes)
// per cell of the range it sums (ranges as large as the budget allows; the result does not depend on them).
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "core/floating_cell.h"
#include "core/mesh.h"
#include "core/octree_regions.h"
#include "core/quadric.h"
#include "lodstream/lodstream.h"
#include "stream/progress.h"
#include "stream/ranked_bits.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

struct EmitScratch;

struct LevelCut {
  std::vector<core::RegionKey> regions;  // in region order
  std::vector<uint64_t> cells;           // per region: the level's cells in it
};

// What the region sink (the 3D Tiles output) is told about a region.
struct RegionInfo {
  size_t level = 0;
  core::RegionKey key;
  double cell_size = 0;
  uint64_t cells = 0;
  double box_min[3] = {0, 0, 0}, box_max[3] = {0, 0, 0};  // scene units, the scene's own frame
};
// Called, per level, for each region of its cut in region order, once, with the primitives it owns
// (RegionPart::mesh, stream/emit_stage.h). May not keep `part`.
using RegionSink = std::function<void(size_t level, const RegionInfo& info, const core::LodMesh& part)>;

core::SceneCube scene_cube_of(const StoreMeta& meta);

// Cuts every level (levels of `cells` cells, finest first; cut coarsest first), from the cells' center
// positions (their means for the mean representative, whose tables hold no center) in the cluster stage's
// files under `prefix`, written for `representative` at the store's precision.
// sides: empty, or per level the bound on the side of regions that hold much (3D Tiles: stream/tiles.h
// tile_side_bounds).
std::vector<LevelCut> cut_levels(const std::string& prefix, std::span<const uint64_t> cells, const core::SceneCube& cube,
                                 uint64_t max_cells, Representative representative, bool single_precision,
                                 std::span<const core::SideBound> sides = {});

// The regions of a level's cells that lie in a run [first, end) of its cut. One machine loads the whole
// cut: a region a cell (4 bytes), looked up by cell. A sharded task loads its own run: a bit a cell of the
// level (`in`, with its rank: 12 bytes a 64 cells) and a region a cell of its run, by rank, so that what it
// holds for the whole level is about a bit and a half a cell.
struct CellRegions {
  uint32_t first = 0, end = 0;
  RankedBits in;                 // empty when the run is the whole cut (every cell is in it)
  std::vector<uint32_t> region;  // per cell of the run: by cell when `in` is empty, else by rank in `in`
  // The index in the cut of cell c's region, or UINT32_MAX when it is not in the run.
  uint32_t of(uint64_t c) const {
    if (in.bits.empty()) return region[c];
    return in.has(c) ? region[in.rank(c)] : UINT32_MAX;
  }
  uint64_t bytes() const { return in.bytes() + region.capacity() * 4; }
};

// The regions of level `level`'s cells in regions [first, end) of its cut (end 0: to the cut's end).
CellRegions load_cell_regions(const std::string& prefix, size_t level, uint64_t cells, const core::SceneCube& cube,
                              const LevelCut& cut, Representative representative, bool single_precision,
                              uint32_t first = 0, uint32_t end = 0);
// Bytes load_cell_regions holds for a level of `cells` cells whose run holds `run_cells` of them.
uint64_t cell_regions_bytes(uint64_t cells, uint64_t run_cells);

// Calls visit(cell, anchor) for each cell c of level `level` with wanted(c), in cell order: the position by
// which the cell is placed in a region, its center vertex's (the mean for the mean representative). Every
// vertex of the cell is within one cell size of it on every axis (block_bounds.h).
void for_cell_anchors(const std::string& prefix, size_t level, uint64_t cells, Representative representative, bool single_precision,
                      const std::function<bool(uint64_t)>& wanted, const std::function<void(uint64_t, const double*)>& visit);

// Batches: consecutive regions in region order whose cells together are at most `batch_cells` (a region
// larger than that is a batch alone), as [first, end) pairs.
std::vector<std::pair<uint32_t, uint32_t>> region_batches(const LevelCut& cut, uint64_t batch_cells);

// A cell's representative (emit_stage.h): center, mean, or the minimiser of `quadric` (its sum over the
// triangles touching the cell) around the cell's mean, clamped into its box.
struct CellInfo;
void cell_representative(const CellInfo& ci, const core::Quadric* quadric, Representative representative,
                         const core::ClusterOptions& cluster, double cell_size, double* out);

// Path of level `level`'s representatives (3 doubles per cell, in cell order).
std::string representatives_path(const std::string& prefix, size_t level);
// Writes them: center and mean from the cell table; quadric from the area-weighted plane quadrics of every
// input triangle touching the cell (summed per fixed store block in primitive order, blocks merged in
// order, as the emit stage does), minimised around the cell's mean and clamped into its box. Quadrics are
// summed for ranges of cells of at most `range_cells` cells, one pass over the triangles each (emit_levels
// with EmitOptions::representatives_only, which calls write_representative_range).
void write_representatives(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                           const std::string& prefix, size_t level, uint64_t cells, double cell_size,
                           uint64_t records, const core::ClusterOptions& cluster, Representative representative,
                           uint64_t range_cells, Progress& progress, EmitScratch& scratch);

// Writes the representatives of cells [first, first + count) of the level; quadrics: one per cell, or empty.
void write_representative_range(const std::string& prefix, size_t level, uint64_t cells, uint64_t first, uint64_t count,
                                std::span<const core::Quadric> quadrics, Representative representative,
                                const core::ClusterOptions& cluster, double cell_size, bool single_precision);

}  // namespace lodstream::stream

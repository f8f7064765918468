// Where the store's primitives are, block by block: the bounding box of the corners of every run of
// kBoundsBlock primitives (triangles, segments, points, in store order). A task of a sharded emit
// (stream/shard.h) owns a few regions of each level; without the boxes each of its passes reads the whole
// input to find the primitives that touch its cells (README "simplify as N tasks": a task cost about a third
// of one machine's emit whatever N). With them it reads only the blocks whose box comes near its regions.
//
// Why a box test is exact (nothing a task needs is skipped): a cell's vertices and its anchor (the center,
// mean or quadric point, all inside the cell, by which emit_regions.h places the cell in a region) are
// within one cell size c of each other on every axis, for floating cubes and balls (within c/2 of the
// center each) and for uniform squares (side c) alike, and in a level with fine cells (core/floating_cell.h)
// those are smaller. So a primitive with a corner in a task's cell, or in a halo cell, has a corner within c
// of that cell's representative.
// A block whose box is farther than that from all of them holds no primitive the task visits; which blocks
// are read never changes which primitives are visited, so it changes no byte of the parts.
//
// The boxes are written once, by the shared stages (WORK/block-bounds.f64, 48 bytes a block: 12 KB per
// million primitives), and tested against a coarse occupancy grid of what the task needs (ReachGrid).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/octree_regions.h"
#include "stream/progress.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

// Primitives per box: a multiple of 64, so that a run of boxes is also a run of emit's 64-primitive words.
inline constexpr uint64_t kBoundsBlock = 4096;

struct BlockBounds {
  // Per kind (0 triangles, 1 segments, 2 points): per block of kBoundsBlock primitives, min xyz then max xyz.
  // A block of the store's order; an empty box (min > max) cannot occur, every block has a corner.
  std::vector<double> box[3];
  uint64_t count[3] = {0, 0, 0};  // primitives per kind
  uint64_t blocks(int kind) const { return (count[kind] + kBoundsBlock - 1) / kBoundsBlock; }
};

std::string block_bounds_path(const std::string& prefix);

// Computes the boxes from the store (one pass over its primitive columns, positions read by id, their
// pages dropped after every step) and writes them to `path` (atomically).
void write_block_bounds(const std::string& store_dir, const StoreMeta& meta, const std::string& path, Progress& progress);

// The same boxes as units (the prepare jobs of a sharded run, stream/units.h): unit u of `units` writes the
// u-th `units`-th of each kind's blocks in place into `path` (sized beforehand).
void write_block_bounds_unit(const std::string& store_dir, const StoreMeta& meta, const std::string& path, unsigned unit,
                             unsigned units, Progress& progress);
// Every unit, taken up by every process that calls it (take_units_on_threads from unit `index`, one at a
// time) in `dir`, the file sized once for `key`; returns the units' figures (seconds, runners).
nlohmann::ordered_json write_block_bounds_in_units(const std::string& store_dir, const StoreMeta& meta, const std::string& path,
                                                   const std::string& dir, unsigned units, unsigned index,
                                                   const nlohmann::ordered_json& key, Progress& progress);

// Reads them back; Failure(io_error) when the file does not hold the store's blocks.
BlockBounds read_block_bounds(const std::string& path, const StoreMeta& meta);

// A coarse grid (kSide³ voxels over the scene cube) of the places a task needs: mark() the boxes, finish(),
// then reaches() tells whether a box touches a marked voxel (a summed-volume table: one lookup per box).
// Conservative: every voxel a marked box touches, and one more on every side, is marked; a coordinate
// outside the cube counts as its border voxel. The voxel index of a coordinate, floor((x - min) · scale) in
// floating point, never decreases as x grows (a subtraction and a product by one constant are monotonic
// under rounding), so a box's voxels in reaches() lie within those of a marked box that holds a point of it
// even without the extra voxel, which is kept as a margin. kSide = 128: on the 193 M-triangle city a voxel
// is 25 units, about a building; at 64 the tasks' passes read about a third more.
class ReachGrid {
 public:
  static constexpr int kSide = 128;
  explicit ReachGrid(const core::SceneCube& cube);
  void mark(const double* lo, const double* hi);
  void finish();
  bool reaches(const double* lo, const double* hi) const;

 private:
  void range(const double* lo, const double* hi, int widen, int* a, int* b) const;
  core::SceneCube cube_;
  std::vector<uint8_t> marked_;  // kSide³
  std::vector<uint32_t> sums_;   // (kSide + 1)³: marked voxels below and before
};

}  // namespace lodstream::stream

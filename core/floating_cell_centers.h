// The centers of one floating-cell level, without the members' cells (issue 19: a level too coarse to
// split by region, split by ranges of records instead).
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.2 (floating cells), as
// core/floating_cell.h runs it: vertices in weight order; a vertex inside no earlier cell starts one; a
// vertex inside some joins one of them (the heaviest, or the nearest of §3.2.3). Which vertices start cells
// does not depend on the choice, and a member changes nothing that a later vertex sees (a cell keeps its
// center and its id only). So once the centers are known, any range of the weight order can be clustered
// on its own: a Clusterer given first the centers before the range (each starts its cell, in order) then
// the range's vertices makes the whole-scene pass's decisions for them (stream/cluster_shares.cpp). The
// centers themselves are this pass, which must see the whole order but can skip most of it:
//
// Covered voxels. A grid of voxels of side v (a power of two, so that a voxel's index floor(x / v) and its
// bounds j·v are exact), at most about c/4, marks a voxel once it lies wholly inside a cell: every vertex
// in it is then inside that cell, hence a member, and needs no query. The cube cell holds its closed cube
// of half side h = c/2 (the exact test); a sphere cell, the cube of half side 0.5773·h inscribed in its
// ball (every point of it has d² <= 0.99982·h², far from the rounding of the sum of squares). A voxel
// [j·v, (j + 1)·v) is marked when j·v >= lo and (j + 1)·v <= hi with lo >= the exact c − h and hi <= the
// exact c + h (the rounded bounds moved one ulp inwards), so the marks are conservative.
// Invariant (where it holds: visit_block): a vertex is skipped only if an earlier cell holds it; every
// other vertex goes to a Clusterer in weight order, which starts its cell exactly when no earlier cell
// holds it. Skipped vertices are members, which a Clusterer would not have changed: the Clusterer's
// centers are the whole pass's.
//
// Where a bitmap over the scene's bounds does not fit at voxels of c/4, the voxels (of side at most c/4) are
// kept in bricks of 8³ (64 bytes) in a hash table, made only where a cell marks: a scene's surfaces, not its
// volume. A table at its budget makes no more bricks; the marks it drops only cost queries.
//
// Memory: the bitmap (a bit a voxel of the bounds) or the bricks' table, at most bitmap_bytes, and the
// Clusterer's cells.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/floating_cell.h"

namespace lodstream::core {

class CenterPass {
 public:
  // cell_size: the level's c; options: floating cells (shape; the choice does not matter); bounds: {min x,
  // min y, min z, max x, max y, max z} of every position visited; bitmap_bytes: what a bitmap over the
  // bounds may take; brick_bytes: what the bricks' table may take where no bitmap fits (0: bitmap_bytes).
  // Neither fits voxels of at most c/4 (or under 4 KiB): no covered voxels, and every vertex is queried.
  CenterPass(double cell_size, ClusterOptions options, std::span<const double, 6> bounds, uint64_t bitmap_bytes,
             uint64_t brick_bytes = 0);

  // Visits n vertices in weight order, at xyz[3i .. 3i + 3); is_center[i] = 1 when vertex i starts a cell,
  // else 0. Spans of equal n (else Failure(Status::internal)).
  void visit_block(std::span<const double> xyz, std::span<uint8_t> is_center);

  uint64_t centers() const { return clusterer_.cell_count(0); }
  uint64_t skipped() const { return skipped_; }  // vertices a covered voxel decided
  double voxel() const { return voxel_; }        // 0: no covered voxels
  bool sparse() const { return sparse_; }        // voxels in bricks (else a bitmap over the bounds)
  uint64_t memory_bytes() const {
    return bits_.capacity() * 8 + keys_.capacity() * 8 + bricks_.capacity() * sizeof(Brick) + clusterer_.memory_bytes() +
           clusterer_.growth_bytes();
  }

 private:
  struct Brick {
    uint64_t bits[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // voxel (x, y, z) of the brick at bit x | y << 3 | z << 6
  };
  static constexpr uint64_t kMinSparseBytes = 4096;
  static constexpr size_t kFirstSlots = 16;
  // Voxel j (per axis, from first_): its brick's packed coordinates and its bit in the brick, or its bit in
  // the dense bitmap.
  static uint64_t brick_key(const int64_t j[3]) {
    return static_cast<uint64_t>(j[0] >> 3) | static_cast<uint64_t>(j[1] >> 3) << 21 | static_cast<uint64_t>(j[2] >> 3) << 42;
  }
  static unsigned brick_bit(const int64_t j[3]) { return static_cast<unsigned>((j[0] & 7) | (j[1] & 7) << 3 | (j[2] & 7) << 6); }
  uint64_t dense_bit(const int64_t j[3]) const {
    return (static_cast<uint64_t>(j[2]) * static_cast<uint64_t>(dims_[1]) + static_cast<uint64_t>(j[1])) *
               static_cast<uint64_t>(dims_[0]) +
           static_cast<uint64_t>(j[0]);
  }
  bool covered(const double* p) const;
  void mark(const double* p);
  const Brick* find_brick(uint64_t key) const;  // null: none
  Brick* add_brick(uint64_t key);               // null: the table is at its budget

  Clusterer clusterer_;
  double half_ = 0;         // the half side of the cube a cell holds surely (h, or 0.5773·h for spheres)
  double voxel_ = 0, inverse_ = 0;  // v = 2^e and 1 / v, exact
  int64_t first_[3] = {0, 0, 0}, dims_[3] = {0, 0, 0};
  std::vector<uint64_t> bits_;  // dense: voxel (x, y, z) at bit (z·dims_y + y)·dims_x + x
  bool sparse_ = false;          // else: bricks of 8³ voxels by their packed coordinates (key + 1; 0: empty slot),
  std::vector<uint64_t> keys_;   // linear probing, at most half full
  std::vector<Brick> bricks_;
  uint64_t used_ = 0, budget_ = 0;
  uint64_t skipped_ = 0;
  // Scratch for a block's queried vertices.
  std::vector<uint32_t> ids_, cells_;
  std::vector<double> xyz_;
  std::vector<size_t> where_;
};

}  // namespace lodstream::core

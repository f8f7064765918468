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
// Memory: the bitmap (a bit a voxel of the bounds, at most bitmap_bytes) and the Clusterer's cells.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/floating_cell.h"

namespace lodstream::core {

class CenterPass {
 public:
  // cell_size: the level's c; options: floating cells (shape; the choice does not matter); bounds: {min x,
  // min y, min z, max x, max y, max z} of every position visited; bitmap_bytes: what the covered voxels may
  // take (0, or too little for voxels of at most c/4: none, and every vertex is queried).
  CenterPass(double cell_size, ClusterOptions options, std::span<const double, 6> bounds, uint64_t bitmap_bytes);

  // Visits n vertices in weight order, at xyz[3i .. 3i + 3); is_center[i] = 1 when vertex i starts a cell,
  // else 0. Spans of equal n (else Failure(Status::internal)).
  void visit_block(std::span<const double> xyz, std::span<uint8_t> is_center);

  uint64_t centers() const { return clusterer_.cell_count(0); }
  uint64_t skipped() const { return skipped_; }  // vertices a covered voxel decided
  double voxel() const { return voxel_; }        // 0: no bitmap
  uint64_t memory_bytes() const { return bits_.capacity() * 8 + clusterer_.memory_bytes() + clusterer_.growth_bytes(); }

 private:
  bool covered(const double* p) const;
  void mark(const double* p);

  Clusterer clusterer_;
  double half_ = 0;         // the half side of the cube a cell holds surely (h, or 0.5773·h for spheres)
  double voxel_ = 0, inverse_ = 0;  // v = 2^e and 1 / v, exact
  int64_t first_[3] = {0, 0, 0}, dims_[3] = {0, 0, 0};
  std::vector<uint64_t> bits_;  // voxel (x, y, z) at bit (z·dims_y + y)·dims_x + x
  uint64_t skipped_ = 0;
  // Scratch for a block's queried vertices.
  std::vector<uint32_t> ids_, cells_;
  std::vector<double> xyz_;
  std::vector<size_t> where_;
};

}  // namespace lodstream::core

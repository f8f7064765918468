// The spatial regions a level is emitted in, and that the 3D Tiles output reuses as its tiles: disjoint
// nodes of one octree over the scene's bounding cube (the contract with the tiles writer). Node numbering
// and order as in the 3D Tiles implicit tiling scheme (OGC 3D Tiles 1.1, "Implicit Tiling": octree
// subdivision, Morton order).
//
// - Scene cube: the bounding box (float positions as stored, read as double) expanded to a cube about its
//   center, side = largest extent · (1 + 2^-20), at least 1e-30, so that every position is inside.
// - A node (RegionKey) at depth d <= kMaxRegionDepth has integer coordinates x, y, z < 2^d. Nodes are
//   ordered by (Morton code of (x, y, z) shifted to depth kMaxRegionDepth, then depth): a parent comes before
//   its children, siblings in Morton order, and the nodes of a cut (disjoint) are ordered by their codes.
// - A point's node at depth d: floor((p - cube_min) / side · 2^d) per axis in double, clamped to [0, 2^d - 1].
//   Its code at kMaxRegionDepth (point_code) locates it in every node that holds it: node n holds the codes
//   [code(n), code(n) + 8^(kMaxRegionDepth - depth(n))).
// - The cut of a level (cut_regions): starting from the next coarser level's cut (or the root), a node is
//   split into its eight children (empty ones included) while it holds more than max_cells of the level's
//   cells, or more than side.min_cells and is shallower than side.min_depth (bounding the side of regions
//   that hold much, for 3D Tiles), and its depth is below kMaxRegionDepth. So a cut tiles the whole cube, and every region of a level
//   is inside exactly one region of the next coarser level. The cut depends on the cells' points and
//   max_cells only.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace lodstream::core {

inline constexpr unsigned kMaxRegionDepth = 20;

struct SceneCube {
  double min[3] = {0, 0, 0};
  double side = 1;
};

// lo, hi: the scene's bounding box (hi >= lo per axis, or an empty box given as lo > hi: a unit cube at 0).
SceneCube scene_cube(const double* lo, const double* hi);

struct RegionKey {
  uint8_t depth = 0;
  uint32_t x = 0, y = 0, z = 0;
  bool operator==(const RegionKey&) const = default;
};

// Morton code of (x, y, z) << (kMaxRegionDepth - depth): 60 bits, x in the lowest bit of each triple.
uint64_t region_code(const RegionKey& key);
// The number of depth-kMaxRegionDepth codes a node spans: 8^(kMaxRegionDepth - depth).
uint64_t region_span(const RegionKey& key);
// The order above: (region_code, depth).
bool region_before(const RegionKey& a, const RegionKey& b);
RegionKey region_parent(const RegionKey& key);
// The node holding `p` at `depth`, and its code at kMaxRegionDepth.
RegionKey point_node(const SceneCube& cube, const double* p, unsigned depth);
uint64_t point_code(const SceneCube& cube, const double* p);
// The node's box in scene units: lo = cube.min + side · (x, y, z) / 2^depth, hi likewise at + 1.
void region_box(const SceneCube& cube, const RegionKey& key, double* lo, double* hi);

// The cut described above. sorted_codes: point_code of every cell of the level, sorted ascending.
// coarser: the next coarser level's cut in region order (empty for the coarsest level: the root).
// max_cells >= 1. Returns the regions in region order.
struct SideBound {
  unsigned min_depth = 0;
  uint64_t min_cells = 0;
};
std::vector<RegionKey> cut_regions(std::span<const uint64_t> sorted_codes, std::span<const RegionKey> coarser,
                                   uint64_t max_cells, const SideBound& side = {});

// The index in `regions` (a cut in region order) of the region holding `code`; every code of the level
// the cut was made from is held by one.
uint32_t region_of_code(std::span<const RegionKey> regions, uint64_t code);

}  // namespace lodstream::core

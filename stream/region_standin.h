// STAND-IN for the region sink of /work/REGIONS.md (issue 13.1, branch h-pemit), so that 3D Tiles output
// (stream/tiles.h) works end to end before the streamed, partitioned emit lands: it cuts one whole level
// mesh, held in memory, by the same octree rules, and reports its regions in the same order with the same
// ownership. The lead replaces it with the real sink at merge; nothing else depends on it.
//
// The rules (REGIONS.md):
// - Scene cube: the scene's bounding box expanded to a cube about its center, side = largest extent times
//   (1 + 2^-20), at least 1e-30. A node (depth d, x, y, z) has the box min + side·(x, y, z)/2^d, side/2^d.
// - A point's node at depth d: floor((p - min) / side · 2^d) per axis, in double, clamped to [0, 2^d - 1]
//   (the depth-20 coordinates shifted right by 20 - d: scaling by 2^k is exact, so both agree).
// - Cut: starting from the next coarser level's cut (the root for the coarsest), a node is split into its 8
//   children while it holds more than max_cells cells and its depth is below 20. Here a level's cells are
//   its vertices (the stand-in sees no cells; a cell split by crease normals counts once per normal).
// - Ownership: a triangle, edge or point belongs to the region of its smallest vertex id (the stand-in's
//   cell id); its part numbers the vertices it uses locally, in order of first use over the part's
//   triangles, then edges, then points, each vertex copied bit for bit.
// - Order: regions by (Morton code at depth 20, depth); all regions of the cut are reported, empty ones
//   with an empty part.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace lodstream::stream::standin {

constexpr unsigned kMaxDepth = 20;

struct Cube {
  double min[3] = {0, 0, 0};
  double side = 1;
};
Cube scene_cube(const double bbox_min[3], const double bbox_max[3]);

struct Key {
  uint8_t depth = 0;
  uint32_t x = 0, y = 0, z = 0;
  bool operator==(const Key&) const = default;
};
// Morton code of the node's first depth-20 cell (x, y, z interleaved, x lowest).
uint64_t morton20(const Key& k);
// The node's box: min corner and side, scene units.
void node_box(const Cube& cube, const Key& k, double min[3], double* side);

struct Region {
  Key key;
  uint64_t cells = 0;  // the level's cells (here: vertices) whose position lies in the node
};

// Cuts `mesh` (one level) below `coarser` (the next coarser level's cut, in region order; empty: the
// root), as the rules above say. Returns the regions in region order.
std::vector<Region> cut_level(const Cube& cube, const core::LodMesh& mesh, const std::vector<Region>& coarser, uint64_t max_cells);

// Calls sink(region, part) for every region of `cut` (from cut_level on this mesh), in order.
void split_level(const Cube& cube, const core::LodMesh& mesh, const std::vector<Region>& cut,
                 const std::function<void(const Region&, const core::LodMesh&)>& sink);

// A level mesh to and from a scratch file (raw arrays), so that the levels, emitted finest first, can be
// cut coarsest first one at a time. Failure(io_error) when the file cannot be written or read back.
void save_mesh(const std::string& path, const core::LodMesh& mesh);
core::LodMesh load_mesh(const std::string& path);

}  // namespace lodstream::stream::standin

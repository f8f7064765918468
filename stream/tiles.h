// 3D Tiles 1.1 output of simplify (`--tiles`): OUTDIR/tiles/tileset.json and one GLB per region of every
// level, fed by the emit stage's region sink (stream/emit_regions.h) as each region is emitted.
//
// The tree: a level's regions are disjoint octree nodes and each lies inside exactly one region of the
// next coarser level (the cuts nest, core/octree_regions.h), whose tile is its parent. The coarsest level is the root
// when it is one region, the whole cube; else a root without content holds its regions. Refinement is
// REPLACE: a tile's children together hold its whole region at the finer level. A tile whose region has no
// primitive has no content; one with neither content nor children (kept) is left out.
//
// Crack-free by construction: every tile of a level is a part of the level's one mesh (one global
// floating-cell pass), each triangle, edge and point in exactly one part (the owner rule of stream/emit_regions.h), and
// a vertex shared across a border is written in every part that uses it, snapped to the level's one grid
// (io/glb_compact.h), so that it is the same point in each.
//
// Geometric error of a tile of cell size c (scene units): sqrt(3)·c + r + 2^-23·m, where r is the largest
// expansion radius of its thick edges and points (core/thick_primitives.h; 0 with lines), m the largest
// coordinate magnitude of the scene (float rounding of the representatives), raised to the largest of its
// children's so that errors never increase from parent to child; plus sqrt(3)/2·q when positions snap to the
// level's grid of step q (io/glb_compact.h; q = the largest power of two <= c/32). Why it bounds the two-sided Hausdorff
// distance between the level and the original within the tile: every representative lies in its cell's box
// (center vertex, mean of the cell's vertices, or quadric clamped into the box; uniform squares alike),
// which holds every vertex of the cell, so a vertex moves by at most the box's diagonal sqrt(3)·c; a point
// αa + βb + γc of an input triangle and the point αA + βB + γC of the primitive it became (a kept
// triangle, edge or point, or the kept one it was eliminated into, which has the same representatives or
// contains them) are then at most sqrt(3)·c apart, both ways. Thick primitives hold the edge or point they
// replace and stay within r of it. tests/test_tiles.cpp checks the bound against report's Hausdorff.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "core/octree_regions.h"
#include "io/glb_compact.h"

namespace lodstream::stream {

// One region of a level as the sink reports it (stream/emit_regions.h RegionInfo).
struct TileRegion {
  uint8_t depth = 0;
  uint32_t x = 0, y = 0, z = 0;
  double cell_size = 0;
  uint64_t cells = 0;
};

struct TilesOptions {
  std::string dir;                 // OUTDIR/tiles: replaced whole
  unsigned levels = 0;             // level count; level 0 finest
  bool thick = true;               // edges and points as triangles (core/thick_primitives.h), else LINES/POINTS
  io::TileEncoding encoding = io::TileEncoding::meshopt;  // tile GLBs (io/glb_compact.h)
  double pixels_per_cell = 5;      // thin edges and points are one pixel at their level's switching distance: c / X
  double scene_magnitude = 0;      // largest |coordinate| of the scene (float rounding margin)
  double cube_min[3] = {0, 0, 0};  // the scene cube (core/octree_regions.h)
  double cube_side = 1;
  std::vector<double> transform;   // empty or 16 numbers (column-major) for the root
  std::string generator;
};

struct TilesSummary {
  uint64_t tiles = 0;              // in tileset.json
  uint64_t content_tiles = 0;      // with a GLB
  uint64_t bytes = 0;              // GLBs and tileset.json
  uint64_t max_triangles = 0;      // largest tile's triangles (after expansion)
  uint64_t triangles = 0;          // over all tiles (after expansion)
};

// Per level (finest first), how the emit stage's cut bounds the side of regions when tiles are written
// (core/octree_regions.h SideBound). Refining a tile loads its children (the next finer level) in view;
// CesiumJS refines a tile of error e ≈ 1.8·c from about 40·e away (800 x 600 pixels,
// maximumScreenSpaceError 16), so a parent much wider than that loads children far from the camera. A
// region of level l >= 1 expected to hold more than kTileChildCells cells of level l - 1 (its own cells
// times the levels' cell count ratio) is split until its side is at most kTileSideCells · c_l; level 0's
// regions nest in level 1's.
inline constexpr double kTileSideCells = 128;
inline constexpr uint64_t kTileChildCells = 25'000;
std::vector<core::SideBound> tile_side_bounds(std::span<const double> cell_sizes, std::span<const uint64_t> cells,
                                              double cube_side);

// The grid step positions of a level of cell size `cell_size` snap to in its tiles (a power of two).
double tile_quantum(double cell_size);

class TilesetBuilder {
 public:
  explicit TilesetBuilder(TilesOptions options);
  ~TilesetBuilder();
  // One region of level `level`, with the primitives it owns (any level order, regions in order).
  void add(size_t level, const TileRegion& region, const core::LodMesh& part);
  // Builds the tree and writes tileset.json (last: its presence means the tiles are complete).
  TilesSummary finish();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// A placement of the scene on the globe for TilesOptions::transform: the east-north-up frame at WGS84
// longitude, latitude (degrees) and ellipsoidal height (metres), as a column-major 4x4 matrix.
std::vector<double> enu_transform(double lon_degrees, double lat_degrees, double height);

// `transform` (empty: the identity) times the rotation that undoes the runtime's Y-up to Z-up turn for a
// scene whose own up axis is Z: (x, y, z) -> (x, z, -y) in the tileset frame, so the scene's Z points up.
std::vector<double> z_up_transform(const std::vector<double>& transform);

}  // namespace lodstream::stream

// 3D Tiles 1.1 tileset.json writer (OGC 3D Tiles 1.1, "Tileset JSON", "Bounding volumes", "Tile
// transforms"; CesiumGS/3d-tiles specification/README) and its tile contents as single-mesh GLB files
// (io/glb_writer.h).
//
// Frames: glTF is Y-up, 3D Tiles Z-up. A 3D Tiles 1.1 runtime rotates glTF content by +90° about x
// (y-up to z-up: (x, y, z) -> (x, -z, y)) before the tile transforms (3D Tiles 1.1 §"glTF transforms";
// CesiumJS applies Axis.Y_UP_TO_Z_UP to glTF content, the default of its 1.1 loader, with no gltfUpAxis in
// the tileset). So content is written as the scene is (Y-up, scene units) and every bounding volume is
// given in the tileset's Z-up frame: to_tileset_frame below. The root's optional transform then places
// the Z-up frame (e.g. east-north-up at a point of the globe).
//
// The JSON depends only on the arguments (fixed key order, shortest round-trip numbers), written through a
// temporary and renamed.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh.h"
#include "io/glb_compact.h"

namespace lodstream::io {

struct TilesetTile {
  std::array<double, 12> box{};  // 3D Tiles "box": center, then the x, y, z half-axis vectors (tileset frame)
  double geometric_error = 0;    // scene units
  std::string content_uri;       // relative to tileset.json; empty: a tile without content
  std::vector<std::pair<std::string, double>> extras;  // numbers only, in this order
  std::vector<uint32_t> children;                      // indices into Tileset::tiles
};

struct Tileset {
  std::vector<TilesetTile> tiles;
  uint32_t root = 0;
  double geometric_error = 0;      // the tileset's (error when nothing is drawn); >= the root's
  std::vector<double> transform;   // empty, or the root's 4x4 transform, 16 numbers, column-major
  std::string generator;           // asset.generator
  std::vector<std::pair<std::string, std::string>> asset_extras;  // strings, in this order
};

// The box holding the glTF-frame (Y-up) axis-aligned bounds [min, max], in the tileset frame (Z-up).
// A zero extent is widened to `min_half` on that axis (a flat box is degenerate for some runtimes).
std::array<double, 12> to_tileset_frame(const double min[3], const double max[3], double min_half);

// Writes `tileset` to `path` (3D Tiles 1.1: asset.version "1.1", refine REPLACE on the root, inherited).
// Failure(internal) when a child index is out of range, a tile is reached twice, or an error increases
// from parent to child; Failure(io_error) when it cannot be written.
void write_tileset(const std::string& path, const Tileset& tileset);

// One tile's content: `mesh` as a GLB with one node and one mesh (io/glb_writer.h layout), named `name`,
// re-encoded as `encoding` says with positions on the grid of step `quantum` (io/glb_compact.h).
// Returns the file's size in bytes.
uint64_t write_tile_glb(const std::string& path, const core::LodMesh& mesh, const std::string& name, const std::string& generator,
                        double quantum, TileEncoding encoding);

}  // namespace lodstream::io

// 3D Tiles 1.1 tileset.json and tile GLBs (see io/tileset_writer.h).
#include "io/tileset_writer.h"

#include <cmath>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"

namespace lodstream::io {

namespace {

using Json = nlohmann::ordered_json;

Json tile_json(const Tileset& ts, uint32_t index, std::vector<char>& seen, bool root) {
  if (index >= ts.tiles.size()) fail(Status::internal, "tileset: child index out of range");
  if (seen[index]) fail(Status::internal, "tileset: a tile is reached twice");
  seen[index] = 1;
  const TilesetTile& t = ts.tiles[index];
  Json j;
  if (root && !ts.transform.empty()) j["transform"] = ts.transform;
  j["boundingVolume"]["box"] = t.box;
  j["geometricError"] = t.geometric_error;
  if (root) j["refine"] = "REPLACE";
  if (!t.content_uri.empty()) j["content"]["uri"] = t.content_uri;
  if (!t.extras.empty()) {
    Json e = Json::object();
    for (const auto& [k, v] : t.extras) {
      // Counts and indices as JSON integers, other values as they are.
      if (v == std::trunc(v) && std::abs(v) < 0x1p53) e[k] = static_cast<int64_t>(v);
      else e[k] = v;
    }
    j["extras"] = std::move(e);
  }
  if (!t.children.empty()) {
    Json children = Json::array();
    for (uint32_t c : t.children) {
      if (c < ts.tiles.size() && ts.tiles[c].geometric_error > t.geometric_error)
        fail(Status::internal, "tileset: a child's geometric error exceeds its parent's");
      children.push_back(tile_json(ts, c, seen, false));
    }
    j["children"] = std::move(children);
  }
  return j;
}

}  // namespace

std::array<double, 12> to_tileset_frame(const double min[3], const double max[3], double min_half) {
  // (x, y, z) glTF -> (x, -z, y) tileset: the center maps as a point, half extents swap y and z.
  const double c[3] = {(min[0] + max[0]) / 2, (min[1] + max[1]) / 2, (min[2] + max[2]) / 2};
  double h[3];
  for (int k = 0; k < 3; ++k) h[k] = std::max((max[k] - min[k]) / 2, min_half);
  return {c[0], -c[2], c[1], h[0], 0, 0, 0, h[2], 0, 0, 0, h[1]};
}

void write_tileset(const std::string& path, const Tileset& ts) {
  if (ts.transform.size() != 0 && ts.transform.size() != 16) fail(Status::internal, "tileset: a transform has 16 numbers");
  std::vector<char> seen(ts.tiles.size(), 0);
  Json j;
  j["asset"]["version"] = "1.1";
  j["asset"]["generator"] = ts.generator;
  if (!ts.asset_extras.empty()) {
    Json e = Json::object();
    for (const auto& [k, v] : ts.asset_extras) e[k] = v;
    j["asset"]["extras"] = std::move(e);
  }
  if (ts.root >= ts.tiles.size()) fail(Status::internal, "tileset: no root tile");
  if (ts.tiles[ts.root].geometric_error > ts.geometric_error)
    fail(Status::internal, "tileset: the root's geometric error exceeds the tileset's");
  j["geometricError"] = ts.geometric_error;
  j["root"] = tile_json(ts, ts.root, seen, true);
  write_file_atomic(path, j.dump(1) + "\n", Sync::durable);
}

uint64_t write_tile_glb(const std::string& path, const core::LodMesh& mesh, const std::string& name, const std::string& generator,
                        double quantum, TileEncoding encoding) {
  const GlbLevel level{&mesh, name, 0.0};
  write_glb(path, {&level, 1}, generator, Sync::none);
  // Re-encoded from the file just written (in the page cache), so that the tile holds whatever write_glb
  // puts in a level (io/glb_compact.h).
  if (encoding != TileEncoding::plain) write_file_atomic(path, compact_glb(read_small_file(path), quantum, encoding), Sync::none);
  std::error_code ec;
  const uint64_t bytes = std::filesystem::file_size(path, ec);
  if (ec) fail(Status::io_error, path + ": cannot read its size");
  return bytes;
}

}  // namespace lodstream::io

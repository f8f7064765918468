// A chunk of an original as Embree scenes, for the out-of-core ray casts of `report` (stream/report.cpp)
// and of simplify's silhouette labels (stream/labels_stage.h): one place that turns a StoreChunks chunk
// into scenes, so both trace an original alike. The chunk's triangles are built once; its lines and
// points, drawn as segments and discs of a radius given per use (half a pixel at the viewing distance),
// in a second scene built for that radius. Traced in store order with core::cast_view's accumulate and
// the nearest-hit tie rule (core/nearest_hit.h), the chunks give the image of the whole original.
#pragma once

#include <cstdint>
#include <memory>

#include "core/ray_scene.h"
#include "stream/store_chunks.h"

namespace lodstream::stream {

// Bytes of a chunk of the original while its scene is built, as Embree's memory monitor counts them (it
// counts what Embree reserves, more than becomes resident) plus the chunk's own arrays: measured on the
// city scenes (README, "report out of core"), rounded up.
inline constexpr ChunkCosts kChunkSceneCosts{.triangle = 80, .line = 224, .point = 160, .vertex = 28};

struct ChunkScene {
  ChunkGeometry geometry;  // without its triangles, which Embree holds
  std::unique_ptr<core::RayScene> triangles;
  uint64_t triangle_count = 0;
  bool has_wire() const { return !geometry.lines.empty() || !geometry.points.empty(); }
};

// Reads chunk `index` and builds its triangle scene within `embree_limit` bytes; with `colors`, its
// primitives carry their colours (core::RayScene::set_colors, for the report's renders).
std::unique_ptr<ChunkScene> load_chunk_scene(StoreChunks& chunks, size_t index, uint64_t embree_limit, bool colors = false);

// Builds the triangle scene of a chunk read into `g` (taken) within `embree_limit` bytes. Returns null
// when Embree's memory monitor refused an allocation (the chunk does not fit the limit: the caller may cut
// it smaller and try again; nothing of it is left allocated); throws on any other failure.
std::unique_ptr<ChunkScene> build_chunk_scene(ChunkGeometry&& g, uint64_t embree_limit);

// Bytes the chunk's own arrays (ChunkScene::geometry, and its triangles until Embree has copied them) hold.
uint64_t chunk_geometry_bytes(const ChunkGeometry& g);

// The chunk's lines and points as segments and discs of the given radii (what a renderer draws one pixel
// wide, at the radii of the caller's pixel rule).
std::unique_ptr<core::RayScene> build_wire(const ChunkGeometry& g, float line_radius, float point_radius,
                                           uint64_t embree_limit);

}  // namespace lodstream::stream

// Chunks of an original as Embree scenes; see chunk_scene.h.
#include "stream/chunk_scene.h"

#include <vector>

#include "core/status.h"

namespace lodstream::stream {
namespace {

// Builds `chunk`'s triangle scene from its geometry; throws Failure(usage) over the limit.
void build_triangles(ChunkScene& chunk, uint64_t embree_limit) {
  chunk.triangles = std::make_unique<core::RayScene>(embree_limit);
  chunk.triangles->add_triangles(chunk.geometry.xyz, chunk.geometry.triangles);
  if (!chunk.geometry.triangle_rgb.empty()) chunk.triangles->set_colors(std::move(chunk.geometry.triangle_rgb));
  chunk.triangle_count = chunk.geometry.triangles.size() / 3;
  chunk.geometry.triangles = {};
  chunk.triangles->commit();
}

}  // namespace

std::unique_ptr<ChunkScene> load_chunk_scene(StoreChunks& chunks, size_t index, uint64_t embree_limit, bool colors) {
  auto chunk = std::make_unique<ChunkScene>();
  chunks.read(index, &chunk->geometry, colors);
  build_triangles(*chunk, embree_limit);
  return chunk;
}

std::unique_ptr<ChunkScene> build_chunk_scene(ChunkGeometry&& g, uint64_t embree_limit) {
  auto chunk = std::make_unique<ChunkScene>();
  chunk->geometry = std::move(g);
  try {
    build_triangles(*chunk, embree_limit);
  } catch (const Failure&) {
    if (!chunk->triangles || !chunk->triangles->over_limit()) throw;
    return nullptr;
  }
  return chunk;
}

uint64_t chunk_geometry_bytes(const ChunkGeometry& g) {
  return 4 * (g.xyz.capacity() + g.triangles.capacity() + g.lines.capacity() + g.points.capacity()) +
         g.triangle_rgb.capacity() + g.line_rgb.capacity() + g.point_rgb.capacity();
}

std::unique_ptr<core::RayScene> build_wire(const ChunkGeometry& g, float line_radius, float point_radius,
                                           uint64_t embree_limit) {
  auto scene = std::make_unique<core::RayScene>(embree_limit);
  scene->add_segments(g.xyz, g.lines, std::vector<float>(g.lines.size() / 2, line_radius));
  if (!g.line_rgb.empty()) scene->set_colors(g.line_rgb);
  scene->add_points(g.xyz, g.points, point_radius);
  if (!g.point_rgb.empty()) scene->set_colors(g.point_rgb);
  scene->commit();
  return scene;
}

}  // namespace lodstream::stream

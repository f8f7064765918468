// Chunks of an original as Embree scenes; see chunk_scene.h.
#include "stream/chunk_scene.h"

#include <vector>

namespace lodstream::stream {

std::unique_ptr<ChunkScene> load_chunk_scene(StoreChunks& chunks, size_t index, uint64_t embree_limit, bool colors) {
  auto chunk = std::make_unique<ChunkScene>();
  chunks.read(index, &chunk->geometry, colors);
  chunk->triangles = std::make_unique<core::RayScene>(embree_limit);
  chunk->triangles->add_triangles(chunk->geometry.xyz, chunk->geometry.triangles);
  if (!chunk->geometry.triangle_rgb.empty()) chunk->triangles->set_colors(std::move(chunk->geometry.triangle_rgb));
  chunk->triangle_count = chunk->geometry.triangles.size() / 3;
  chunk->geometry.triangles = {};
  chunk->triangles->commit();
  return chunk;
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

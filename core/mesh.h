// One level of detail as the writers see it: plain arrays, nothing about how it was made.
//
// Conventions (the emit stage guarantees them; the writers may rely on them):
// - positions: xyz per vertex, finite.
// - normals: empty, or xyz per vertex. Vertices used by triangles have unit normals; vertices used only by
//   edges or points have (0, 0, 0) (their normal is dynamic: it depends on the camera, Low & Tan §3.3.2).
// - triangles: 3 vertex ids each, counter-clockwise seen from the front; no id repeated within a triangle.
// - edges: 2 vertex ids each (distinct), with thickness[i] >= 0 in scene units (D_A + D_B, §3.3.1).
// - points: 1 vertex id each; point_size empty (sizes unknown) or one per point, >= 0 in scene units: the
//   diameter of what collapsed into the point (twice the mean distance of the collapsed primitives' corners
//   to their mean, the point's analogue of an edge's D_A + D_B); 0 for a point that replaces nothing wider
//   (an input point), which a renderer draws one pixel wide.
// - Every id is < vertex_count().
// - materials: the scene's material table (the same for every level), empty when the input has none; then
//   triangle_materials, edge_materials and point_materials hold one id < materials.size() per primitive,
//   else they are empty.
// - colors: empty, or RGBA (0..255) per vertex, when the input has vertex colours.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace lodstream::core {

// A material as every output format can carry it (glTF metallic-roughness, MTL Kd/d, PLY colours): a base
// colour (RGBA, 0..1, with a base colour texture already reduced to its mean), metallic and roughness
// factors, glTF's alpha mode and double-sidedness.
struct Material {
  enum class Alpha : uint8_t { opaque, mask, blend };
  std::string name;
  float base_color[4] = {1, 1, 1, 1};
  float metallic = 0, roughness = 1;
  Alpha alpha = Alpha::opaque;
  float alpha_cutoff = 0.5f;
  bool double_sided = true;
  bool operator==(const Material&) const = default;
};

struct LodMesh {
  std::vector<float> positions;
  std::vector<float> normals;
  std::vector<uint32_t> triangles;
  std::vector<uint32_t> edges;
  std::vector<float> thickness;
  std::vector<uint32_t> points;
  std::vector<Material> materials;
  std::vector<uint32_t> triangle_materials, edge_materials, point_materials;
  std::vector<uint8_t> colors;
  std::vector<float> point_size;

  uint64_t vertex_count() const { return positions.size() / 3; }
  uint64_t triangle_count() const { return triangles.size() / 3; }
  uint64_t edge_count() const { return edges.size() / 2; }
  uint64_t point_count() const { return points.size(); }
};

// What breaks the conventions above that a file layout depends on (array shapes, 32-bit addressable
// vertices, indices in range), or "" when nothing does. Writers check it before writing a byte.
inline std::string convention_violation(const LodMesh& mesh) {
  const uint64_t n = mesh.vertex_count();
  if (mesh.positions.size() % 3 != 0) return "positions are not xyz triples";
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) return "normals do not match positions";
  if (mesh.triangles.size() % 3 != 0) return "triangles are not index triples";
  if (mesh.edges.size() % 2 != 0) return "edges are not index pairs";
  if (mesh.thickness.size() != mesh.edge_count()) return "one thickness per edge expected";
  if (!mesh.point_size.empty() && mesh.point_size.size() != mesh.point_count()) return "one size per point expected";
  if (n > UINT32_MAX) return "more vertices than 32-bit indices can address";
  if (!mesh.colors.empty() && mesh.colors.size() != 4 * n) return "colors do not match positions";
  const bool materials = !mesh.materials.empty();
  if ((materials ? mesh.triangle_count() : 0) != mesh.triangle_materials.size() ||
      (materials ? mesh.edge_count() : 0) != mesh.edge_materials.size() ||
      (materials ? mesh.point_count() : 0) != mesh.point_materials.size())
    return "one material per primitive expected (none without a material table)";
  for (const auto* ids : {&mesh.triangle_materials, &mesh.edge_materials, &mesh.point_materials})
    for (uint32_t id : *ids)
      if (id >= mesh.materials.size()) return "material " + std::to_string(id) + " out of range";
  for (const auto* ids : {&mesh.triangles, &mesh.edges, &mesh.points})
    for (uint32_t id : *ids)
      if (id >= n) return "vertex index " + std::to_string(id) + " out of range";
  return {};
}

}  // namespace lodstream::core

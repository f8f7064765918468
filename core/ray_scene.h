// Embree 3 scenes for the error report (../shared/DESIGN.md "Error report"): what a renderer would draw
// of an original or a level of detail, for ray casting and closest-point queries.
//
// Primitives:
// - triangles: an Embree triangle mesh;
// - thick edges: Embree flat linear curves (RTC_GEOMETRY_TYPE_FLAT_LINEAR_CURVE), one segment of constant
//   radius per edge. A flat curve is a ribbon that always faces the ray, which is exactly how Low & Tan
//   (§3.3.2) draw a thick edge: a line T/R pixels wide whose normal lies in the plane of edge and camera;
// - points: ray-facing discs (RTC_GEOMETRY_TYPE_DISC_POINT).
// Geometry is copied into Embree-owned buffers (Embree needs 16 readable bytes at every vertex, which a
// mapped column does not promise at its end). Scenes are built with RTC_SCENE_FLAG_ROBUST, so that a ray
// through a shared edge never slips between two triangles (that would count as a silhouette mismatch), and
// RTC_SCENE_FLAG_COMPACT, to keep the original's BVH small.
//
// Scenes accept a context filter (RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION): a cast through a
// core/nearest_hit.h NearestHitContext, whose filter is nearest_hit_filter, counts of the hits at equal
// distance the lowest (scene, geometry id, primitive id), whatever the BVH, so that a scene traced in chunks
// gives the same images as in one piece. A plain RTCIntersectContext (no filter) traces as Embree does.
//
// Closest points (Metro-style Hausdorff sampling) use rtcPointQuery with one callback for every geometry:
// the distance to a triangle, to an edge's axis (its thickness is a rendering width, not geometry), or to
// a point.
//
// Memory: every byte Embree allocates passes through a device memory monitor; when the scene would take
// more than the limit given at construction, the build fails with Status::usage and a message saying
// how much it needed.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace lodstream::core {

// Geometry kinds, as stored per pixel by the ray caster.
enum class PrimitiveKind : uint8_t { none = 0, triangle = 1, edge = 2, point = 3 };

class RayScene {
 public:
  // memory_limit: bytes Embree may hold for this scene (0 = no limit). threads: 0 = all.
  explicit RayScene(uint64_t memory_limit = 0);
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  // A triangle mesh whose buffers the caller fills before commit(): `vertices` xyz triples, `triangles`
  // index triples (every index < vertex_count). Returns the buffers.
  struct TriangleBuffers {
    std::span<float> xyz;
    std::span<uint32_t> indices;
  };
  TriangleBuffers add_triangles(uint64_t vertex_count, uint64_t triangle_count);
  void add_triangles(std::span<const float> xyz, std::span<const uint32_t> triangles);
  // Segments between xyz[edges[2i]] and xyz[edges[2i+1]], of radius radius[i] (> 0).
  void add_segments(std::span<const float> xyz, std::span<const uint32_t> edges, std::span<const float> radius);
  // Discs at xyz[ids[i]], of the given radius (> 0).
  void add_points(std::span<const float> xyz, std::span<const uint32_t> ids, float radius);
  // Discs at xyz[ids[i]], of radius radius[i] (> 0).
  void add_points(std::span<const float> xyz, std::span<const uint32_t> ids, std::span<const float> radius);
  // Colours of the primitives of the geometry added last (RGB per primitive, in its order), for the
  // coloured renders of the report (core/view_cast.h ViewImage::color). A geometry without them has none.
  void set_colors(std::vector<uint8_t> rgb);
  // The colour of primitive `prim` of geometry `geom`, or null.
  const uint8_t* color(unsigned geom, unsigned prim) const;
  bool has_colors() const;
  // Builds the BVH. Throws Failure(usage) when the memory limit is exceeded, Failure(internal) on any
  // other Embree error.
  void commit();

  // Distance from p to the nearest primitive, or +infinity when the scene is empty. Thread-safe after
  // commit(). `closest` (optional) receives the nearest point. With `within`, primitives further than that
  // may be skipped (the result is then > within, possibly +infinity): min(within, result) is the same
  // either way, and a scene far from p costs little (a chunk of an original, p already close to another).
  float closest_distance(const float p[3], float* closest = nullptr,
                         float within = std::numeric_limits<float>::infinity()) const;

  PrimitiveKind kind_of(unsigned geom_id) const;
  // The canonical hit of a ray (origin org, direction dir) on triangle `prim` of geometry `geom`: where the
  // ray meets the triangle's plane, t in units of dir, and the plane's unit normal (either side), computed
  // in double from the stored corners, so the same bits whatever intersector reported the hit. False for
  // a geometry that is not triangles, or a ray parallel to the plane (or a zero-area triangle).
  bool triangle_hit(unsigned geom, unsigned prim, const float org[3], const float dir[3], float* t,
                    double normal[3] = nullptr) const;
  // The canonical distance of a hit on primitive `prim` of geometry `geom`, in units of dir, computed in
  // double from the stored vertices so that it does not depend on which intersector (packet or single ray)
  // reported the hit, nor on the ray's tfar then: a triangle's as triangle_hit; a segment's (a ribbon facing
  // the ray) at the point of its axis nearest the ray as seen along it; a point's (a disc facing the ray)
  // at its centre's depth. False where there is none (see triangle_hit).
  bool canonical_t(unsigned geom, unsigned prim, const float org[3], const float dir[3], float* t) const;
  // Triangles only (no segments or points): rays may be cast in packets (core/nearest_hit.h).
  bool only_triangles() const;
  uint64_t embree_bytes() const;  // bytes Embree holds now
  uint64_t peak_embree_bytes() const;
  // True once the memory monitor refused an allocation (the Failure(usage) above): the scene is unusable,
  // and a caller that can cut its work smaller may release it and try again.
  bool over_limit() const;
  void* handle() const;           // the RTCScene, for the ray caster
  bool empty() const;

 private:
  template <class Radius>
  void add_discs(std::span<const float> xyz, std::span<const uint32_t> ids, Radius&& radius);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lodstream::core

// Primary-ray images of a RayScene (../shared/DESIGN.md "Error report"): one ray through the centre of
// every pixel of a square pinhole camera, traced one ray at a time (rtcIntersect1) over 4×4 pixel tiles,
// tiles in parallel. Not as 16-ray packets: Embree's packet traversal falls back to its single-ray
// intersector where few rays of a packet remain, the two can round a hit's distance or normal differently,
// and where that happens depends on the BVH, so an image would depend on how the scene is chunked. Each
// pixel gets the hit distance along its unit ray, the geometric normal turned to face the camera (so one-
// and two-sided faces compare alike), and the kind of primitive hit. A pixel's result depends on that
// pixel's ray only, so images are the same for any thread count.
//
// Views for the report lie on a Fibonacci sphere (González, "Measurement of areas on a sphere using
// Fibonacci and latitude–longitude lattices", 2010): K directions of near-equal spacing, deterministic.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/ray_scene.h"

namespace lodstream::core {

struct Camera {
  double eye[3] = {0, 0, 0};
  double forward[3] = {0, 0, 1}, right[3] = {1, 0, 0}, up[3] = {0, 1, 0};  // orthonormal
  double tan_half_fov = 0.5773502691896257;
  unsigned resolution = 512;
  // Object-space width of one pixel at distance `range` from the eye (along the view axis).
  double pixel_size(double range) const { return 2 * range * tan_half_fov / resolution; }
};

// A camera at `eye` looking at `target` with vertical (and horizontal) field of view fov_degrees. Its up
// vector is the coordinate axis least aligned with the view direction (z first on ties), made orthogonal.
Camera look_at(const double eye[3], const double target[3], double fov_degrees, unsigned resolution);

// Unit direction k of K on the Fibonacci sphere: z = 1 - (2k + 1) / K, longitude k·π(3 − √5).
void fibonacci_direction(unsigned k, unsigned count, double out[3]);

struct ViewImage {
  unsigned resolution = 0;
  std::vector<float> depth;        // distance along the pixel's unit ray; +inf where nothing was hit
  std::vector<float> normal;       // xyz per pixel, unit, facing the camera; 0 where nothing was hit
  std::vector<uint8_t> kind;       // PrimitiveKind per pixel (none = background)
  bool covered(uint64_t pixel) const { return kind[pixel] != 0; }
};

// Row-major, row 0 at the top. The nearest hit over all `scenes` counts (an original's triangles and its
// one-pixel lines live in separate scenes); of hits at equal distance, the first scene's, then the lowest
// geometry id's, then the lowest primitive id's (core/nearest_hit.h). With `accumulate`, `out` holds the
// image of earlier chunks of the same scene list (same camera): a pixel changes only where this chunk's hit
// is strictly nearer, so tracing the chunks of a scene in order, each as `scenes`, gives the image of the
// whole scene when a chunk's primitives come after every earlier chunk's in that key order. Returns the
// number of rays cast.
uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out,
                   bool accumulate = false);

}  // namespace lodstream::core

// Primary-ray images of a RayScene (../shared/DESIGN.md "Error report"): a square pinhole camera, traced
// over 4×4 pixel tiles, tiles in parallel. The pixel rule, the same for an original and a level: a pixel is
// covered when its centre ray hits, or else when any of k × k rays spread evenly over it (camera.supersample
// = k, at ((i + ½) / k, (j + ½) / k) of the pixel) hits; its depth, normal and kind are the centre ray's hit,
// or else the nearest of the k × k hits. So a part of a scene that crosses a pixel without meeting its
// centre still covers it, when it is wider than about 1/k pixel, whatever kind of primitive it is.
//
// Rays go in 16-ray packets (rtcIntersect16): every hit's distance, and a triangle's normal, are recomputed
// from the primitive's vertices (core/nearest_hit.h), so they do not depend on which of Embree's
// intersectors found the hit; on a scene of lines and points, a ray whose packet found a hit there is
// traced again alone (rtcIntersect1), so whether a curve or a disc is hit is always Embree's single-ray
// intersector's call. Each pixel gets the hit distance along its unit ray, the geometric normal
// turned to face the camera (so one- and two-sided faces compare alike), and the kind of primitive hit. A
// pixel's result depends on that pixel's rays only, so images are the same for any thread count.
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
  unsigned supersample = 1;  // k: k × k rays a pixel where the centre ray misses (1 = the centre ray only)
  // Object-space width of one pixel at distance `range` from the eye (along the view axis).
  double pixel_size(double range) const { return 2 * range * tan_half_fov / resolution; }
};

// A camera at `eye` looking at `target` with vertical (and horizontal) field of view fov_degrees. Its up
// vector is the coordinate axis least aligned with the view direction (z first on ties), made orthogonal.
Camera look_at(const double eye[3], const double target[3], double fov_degrees, unsigned resolution);

// Unit direction k of K on the Fibonacci sphere: z = 1 - (2k + 1) / K, longitude k·π(3 − √5).
void fibonacci_direction(unsigned k, unsigned count, double out[3]);

// Embree radii that draw a line or a point one pixel wide under the pixel rule, as a renderer draws an
// original's lines and points: with k × k rays a pixel spaced s = pixel / k apart, a line of radius s / 2
// meets one of them in every pixel it crosses, and a disc of radius s / √2 (the square lattice's covering
// radius) always meets one, in its pixel or a neighbour. `pixel`: the width of a pixel where they are.
struct OnePixelRadii {
  float line = 0, point = 0;
};
OnePixelRadii one_pixel_radii(double pixel, unsigned k);

struct ViewImage {
  unsigned resolution = 0;
  std::vector<float> depth;        // distance along the pixel's unit ray; +inf where nothing was hit
  std::vector<float> normal;       // xyz per pixel, unit, facing the camera; 0 where nothing was hit
  std::vector<uint8_t> kind;       // PrimitiveKind per pixel (none = background)
  std::vector<uint8_t> centre;     // 1 where the pixel's hit is its centre ray's (else one of its k × k rays')
  // RGB per pixel, the colour of the primitive hit (RayScene::set_colors; white for one without), when a
  // scene cast into the image has colours; else empty.
  std::vector<uint8_t> color;
  bool covered(uint64_t pixel) const { return kind[pixel] != 0; }
};

// Row-major, row 0 at the top. The nearest hit over all `scenes` counts (an original's triangles and its
// lines and points live in separate scenes); of hits at equal distance, the first scene's, then the lowest
// geometry id's, then the lowest primitive id's (core/nearest_hit.h), then, among a pixel's k × k rays, the
// first's. With `accumulate`, `out` holds the image of earlier chunks of the same scene list (same camera):
// a pixel changes only where this chunk's hit is strictly nearer (a centre hit always replaces a k × k
// one), so tracing the chunks of a scene in order, each as `scenes`, gives the image of the whole scene
// when a chunk's primitives come after every earlier chunk's in that key order. The k × k rays of a pixel
// are cast only while no chunk's centre ray has hit it. Returns the number of rays cast (per scene).
uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out,
                   bool accumulate = false);

// Sort-last compositing: the scene's primitives cast in consecutive parts, each part into a fresh image (no
// accumulate), give the whole scene's image when the parts' images are composited in part order. A later
// part's hit replaces the pixel's hit so far when its centre ray hit and the pixel's had not, or when both
// are hits of the same sort (centre, or k × k) and the later is strictly nearer: cast_view with accumulate
// makes the same choice (an earlier chunk's hit wins ties, a centre hit beats any k × k hit), so the
// composite is cast_view's image of the parts in order, bit for bit. A pixel the part did not cover
// (kind none, depth +inf, not centre) never replaces anything.
inline bool later_hit_wins(bool earlier_centre, float earlier_depth, bool later_centre, float later_depth) {
  return later_centre ? (!earlier_centre || later_depth < earlier_depth) : (!earlier_centre && later_depth < earlier_depth);
}

// An empty image (nothing hit) of resolution × resolution pixels, as cast_view starts one.
void clear_view(ViewImage* image, unsigned resolution);

// Before a part is composited into `into`: cleared when it has another resolution, and given colours
// (white) when the part was cast with colours, as cast_view gives an image colours when a scene has them.
void begin_composite(ViewImage* into, unsigned resolution, bool colored);

// Composites one pixel of a later part into `into` (see later_hit_wins): `rgb` is the hit's colour, or null
// for a part cast without colours (white, as cast_view stores it, when `into` has colours). `into` gets a
// colour array (white) the first time a coloured hit arrives.
void composite_pixel(ViewImage* into, uint64_t pixel, float depth, const float normal[3], uint8_t kind, bool centre,
                     const uint8_t* rgb);

// Composites every pixel of `part` (same resolution; its primitives after every one already in `into`).
void composite_view(ViewImage* into, const ViewImage& part);

// An axis-aligned box, as the bounds of what a scene list holds (its segments and discs widened by their
// radii).
struct Box {
  double min[3] = {0, 0, 0}, max[3] = {0, 0, 0};
};

// Pixels [x0, x1) × [y0, y1) of the camera's image that a ray can meet `box` through: its corners'
// projection, widened by two pixels for the rays' float rounding; the whole image when the box reaches
// the eye's plane, and nothing when it lies behind it. Pixels outside cannot hit anything in the box.
struct PixelRect {
  unsigned x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty() const { return x0 >= x1 || y0 >= y1; }
};
PixelRect project_box(const Box& box, const Camera& camera);

// cast_view over the pixels of `rect` only (with accumulate: the others keep their earlier chunks' hits).
// Same image as cast_view when every primitive of `scenes` lies in a box whose project_box is inside rect.
uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out, bool accumulate,
                   const PixelRect& rect);

}  // namespace lodstream::core

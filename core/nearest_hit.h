// The tie rule of the report's ray casts (../shared/DESIGN.md "Error report"): of the hits at the nearest
// distance, the one with the lowest key counts, key = (scene index, geometry id, primitive id). Embree
// alone takes whichever of two hits at equal t its BVH visits last (its depth test is t <= tfar), and the
// BVH depends on what else is in the scene; an original traced chunk by chunk (stream/report.cpp) must
// pick the same hit as in one scene. So a cast that needs the rule passes a NearestHitContext whose
// embree.filter is nearest_hit_filter (a context filter: RayScene's scenes enable them), and a caller that
// does not, with a plain RTCIntersectContext, gets Embree's own behaviour and no read past its context.
//
// The filter reads and keeps each ray's best (t, key) in the NearestHitContext, passed to rtcIntersect1 or
// rtcIntersect16 in place of a plain RTCIntersectContext (its first member), indexed by the ray's id (0..15:
// its lane).
//
// Canonical distances: every hit's t is recomputed by the filter from the primitive's stored vertices
// (RayScene::canonical_t, in double), not taken from Embree. Embree's packet intersector and its single-ray
// one (which its packet traversal falls back to where few rays of a packet remain, at places that depend
// on the BVH) can round the same hit differently, so Embree's own t would make an image depend on the
// chunking: for curves, a packet's t a ulp above the single-ray t of the same segment once kept an earlier
// chunk's hit where the whole scene took the later one. Whether a ray meets a curve or a disc at all is
// still Embree's single-ray intersector's call: a ray that hits them is traced again alone
// (core/view_cast.cpp).
// Since Embree culls by its own t, the filter leaves the ray's tfar a little beyond the best canonical t
// (enlarged_tfar): a primitive whose canonical t ties or beats the best still reaches the filter (Embree
// keeps a filter's tfar, and offers the other hits of a leaf while their t <= tfar).
#pragma once

#include <embree3/rtcore.h>

#include <cstdint>

namespace lodstream::core {

class RayScene;

struct NearestHitContext {
  RTCIntersectContext embree;  // first: Embree hands this pointer back to the filter
  unsigned scene = 0;          // index of the scene being traced, the key's high part
  const RayScene* ray_scene = nullptr;  // that scene, for canonical triangle distances
  float best_t[16];
  uint64_t best_key[16];       // 0 = the best hit comes from an earlier chunk, which wins every tie
  int best_scene[16];          // the scene whose hit is the best so far in this cast; -1 = none yet
};

// The tfar that lets every hit within rounding of t reach the filter: t (1 + 2^-12). Embree's float t of a
// triangle differs from the canonical one by a few ulps (2^-23 each) away from grazing incidence.
inline float enlarged_tfar(float t) { return t + t * 0x1p-12f; }

// Key of a hit: scene index (24 bits), geometry id (8 bits), primitive id (32 bits).
inline uint64_t hit_key(unsigned scene, unsigned geom, unsigned prim) {
  return (uint64_t{scene} << 40) | (uint64_t{geom} << 32) | prim;
}

void nearest_hit_filter(const RTCFilterFunctionNArguments* args);

}  // namespace lodstream::core

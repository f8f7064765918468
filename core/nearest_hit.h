// The tie rule of the report's ray casts (../shared/DESIGN.md "Error report"): of the hits at the nearest
// distance, the one with the lowest key counts, key = (scene index, geometry id, primitive id). Embree
// alone takes whichever of two hits at equal t its BVH visits last (its depth test is t <= tfar), and the
// BVH depends on what else is in the scene; an original traced chunk by chunk (stream/report.cpp) must
// pick the same hit as in one scene. So a cast that needs the rule passes a NearestHitContext whose
// embree.filter is nearest_hit_filter (a context filter: RayScene's scenes enable them), and a caller that
// does not, with a plain RTCIntersectContext, gets Embree's own behaviour and no read past its context.
//
// The filter reads and keeps each ray's best (t, key) in the NearestHitContext, passed to rtcIntersect1 in
// place of a plain RTCIntersectContext (its first member), indexed by the ray's id (0..15: its lane).
// Embree sets a ray's tfar to the candidate's distance before calling the filter and restores it when
// the filter rejects the hit, so tfar == best_t outside the filter.
#pragma once

#include <embree3/rtcore.h>

#include <cstdint>

namespace lodstream::core {

struct NearestHitContext {
  RTCIntersectContext embree;  // first: Embree hands this pointer back to the filter
  unsigned scene = 0;          // index of the scene being traced, the key's high part
  float best_t[16];
  uint64_t best_key[16];       // 0 = the best hit comes from an earlier chunk, which wins every tie
  int best_scene[16];          // the scene whose hit is the best so far in this cast; -1 = none yet
};

void nearest_hit_filter(const RTCFilterFunctionNArguments* args);

}  // namespace lodstream::core

// Primary-ray images; see view_cast.h.
#include "core/view_cast.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>

#include "core/nearest_hit.h"

namespace lodstream::core {
namespace {

void normalize(double v[3]) {
  const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (len > 0) v[0] /= len, v[1] /= len, v[2] /= len;
}
void cross(const double a[3], const double b[3], double out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

constexpr unsigned kTile = 4;  // 4×4 pixels, traced in turn

}  // namespace

Camera look_at(const double eye[3], const double target[3], double fov_degrees, unsigned resolution) {
  Camera c;
  for (int k = 0; k < 3; ++k) c.eye[k] = eye[k], c.forward[k] = target[k] - eye[k];
  normalize(c.forward);
  // The axis least aligned with the view (z, then y, then x on ties) serves as up.
  int axis = 2;
  for (int k : {1, 0})
    if (std::fabs(c.forward[k]) < std::fabs(c.forward[axis])) axis = k;
  double world_up[3] = {0, 0, 0};
  world_up[axis] = 1;
  cross(c.forward, world_up, c.right);
  normalize(c.right);
  cross(c.right, c.forward, c.up);
  normalize(c.up);
  c.tan_half_fov = std::tan(fov_degrees * M_PI / 360.0);
  c.resolution = resolution;
  return c;
}

void fibonacci_direction(unsigned k, unsigned count, double out[3]) {
  const double z = 1.0 - (2.0 * k + 1.0) / count;
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  const double phi = k * M_PI * (3.0 - std::sqrt(5.0));
  out[0] = r * std::cos(phi);
  out[1] = r * std::sin(phi);
  out[2] = z;
}

uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out, bool accumulate) {
  const unsigned h = camera.resolution;
  const uint64_t pixels = uint64_t{h} * h;
  if (!accumulate || out->resolution != h || out->depth.size() != pixels) {
    out->resolution = h;
    out->depth.assign(pixels, std::numeric_limits<float>::infinity());
    out->normal.assign(3 * pixels, 0.0f);
    out->kind.assign(pixels, 0);
  }
  if (h == 0) return pixels;
  const unsigned tiles = (h + kTile - 1) / kTile;
  tbb::parallel_for(tbb::blocked_range<unsigned>(0, tiles), [&](const tbb::blocked_range<unsigned>& rows) {
    alignas(64) RTCRayHit16 packet;
    alignas(64) int valid[16];
    NearestHitContext context;
    for (unsigned ty = rows.begin(); ty != rows.end(); ++ty) {
      for (unsigned tx = 0; tx < tiles; ++tx) {
        for (unsigned i = 0; i < 16; ++i) {
          const unsigned x = tx * kTile + i % kTile, y = ty * kTile + i / kTile;
          valid[i] = (x < h && y < h) ? -1 : 0;
          const double sx = (2.0 * (x + 0.5) / h - 1.0) * camera.tan_half_fov;
          const double sy = (1.0 - 2.0 * (y + 0.5) / h) * camera.tan_half_fov;
          double d[3];
          for (int k = 0; k < 3; ++k) d[k] = camera.forward[k] + sx * camera.right[k] + sy * camera.up[k];
          normalize(d);
          packet.ray.org_x[i] = static_cast<float>(camera.eye[0]);
          packet.ray.org_y[i] = static_cast<float>(camera.eye[1]);
          packet.ray.org_z[i] = static_cast<float>(camera.eye[2]);
          packet.ray.dir_x[i] = static_cast<float>(d[0]);
          packet.ray.dir_y[i] = static_cast<float>(d[1]);
          packet.ray.dir_z[i] = static_cast<float>(d[2]);
          // An earlier chunk's hit bounds the ray and wins ties (key 0).
          const float best = valid[i] ? out->depth[uint64_t{y} * h + x] : std::numeric_limits<float>::infinity();
          packet.ray.tnear[i] = 0.0f;
          packet.ray.tfar[i] = best;
          context.best_t[i] = best;
          context.best_key[i] = best < std::numeric_limits<float>::infinity() ? 0 : UINT64_MAX;
          context.best_scene[i] = -1;
          packet.ray.time[i] = 0.0f;
          packet.ray.mask[i] = 0xFFFFFFFFu;
          packet.ray.id[i] = i;
          packet.ray.flags[i] = 0;
          packet.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
          packet.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        }
        for (unsigned s = 0; s < scenes.size(); ++s) {
          if (scenes[s]->empty()) continue;
          rtcInitIntersectContext(&context.embree);
          context.embree.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
          context.embree.filter = &nearest_hit_filter;
          context.scene = s;
          // One ray at a time: Embree's packet traversal switches to single-ray traversal where few rays
          // of a packet remain, and its two intersectors may round a hit differently; which one runs
          // depends on the BVH, so on the chunking. The single-ray one alone gives every primitive's hit
          // the same bits in any scene.
          for (unsigned i = 0; i < 16; ++i) {
            if (!valid[i]) continue;
            RTCRayHit r;
            r.ray.org_x = packet.ray.org_x[i], r.ray.org_y = packet.ray.org_y[i], r.ray.org_z = packet.ray.org_z[i];
            r.ray.dir_x = packet.ray.dir_x[i], r.ray.dir_y = packet.ray.dir_y[i], r.ray.dir_z = packet.ray.dir_z[i];
            r.ray.tnear = packet.ray.tnear[i], r.ray.tfar = packet.ray.tfar[i], r.ray.time = 0.0f;
            r.ray.mask = 0xFFFFFFFFu, r.ray.id = i, r.ray.flags = 0;
            r.hit.geomID = RTC_INVALID_GEOMETRY_ID, r.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(static_cast<RTCScene>(scenes[s]->handle()), &context.embree, &r);
            if (r.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
            packet.ray.tfar[i] = r.ray.tfar;
            packet.hit.geomID[i] = r.hit.geomID, packet.hit.primID[i] = r.hit.primID;
            packet.hit.Ng_x[i] = r.hit.Ng_x, packet.hit.Ng_y[i] = r.hit.Ng_y, packet.hit.Ng_z[i] = r.hit.Ng_z;
          }
        }
        for (unsigned i = 0; i < 16; ++i) {
          // Embree's hit is the filter's best: the last hit it accepted.
          if (!valid[i] || context.best_scene[i] < 0) continue;
          const unsigned x = tx * kTile + i % kTile, y = ty * kTile + i / kTile;
          const uint64_t p = uint64_t{y} * h + x;
          out->depth[p] = packet.ray.tfar[i];
          const PrimitiveKind kind = scenes[context.best_scene[i]]->kind_of(packet.hit.geomID[i]);
          out->kind[p] = static_cast<uint8_t>(kind);
          double n[3] = {packet.hit.Ng_x[i], packet.hit.Ng_y[i], packet.hit.Ng_z[i]};
          const double dir[3] = {packet.ray.dir_x[i], packet.ray.dir_y[i], packet.ray.dir_z[i]};
          normalize(n);
          if (kind == PrimitiveKind::edge) {
            // Embree reports a flat curve's tangent as Ng. The ribbon's normal (Low & Tan's dynamic normal)
            // is perpendicular to the edge in the plane of edge and ray: -dir without its part along the
            // tangent. Left at 0 (so -dir below) for a ray along the edge.
            const double along = n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2];
            for (int k = 0; k < 3; ++k) n[k] = along * n[k] - dir[k];
            const double len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
            if (len2 > 1e-12) normalize(n);
            else n[0] = n[1] = n[2] = 0;
          }
          const double facing = n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2];
          if (n[0] == 0 && n[1] == 0 && n[2] == 0) {
            for (int k = 0; k < 3; ++k) n[k] = -dir[k];
          } else if (facing > 0) {
            for (int k = 0; k < 3; ++k) n[k] = -n[k];
          }
          for (int k = 0; k < 3; ++k) out->normal[3 * p + k] = static_cast<float>(n[k]);
        }
      }
    }
  });
  uint64_t cast = 0;
  for (const RayScene* s : scenes) cast += s->empty() ? 0 : pixels;
  return cast;
}

}  // namespace lodstream::core

// Primary-ray images; see view_cast.h.
#include "core/view_cast.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
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

// Up to 16 rays traced together through a scene list under the tie rule: in one packet; on a scene that is
// not triangles only, the rays that hit it again one at a time.
struct Batch {
  alignas(64) RTCRayHit16 packet;
  alignas(64) int valid[16];
  NearestHitContext context;
  float ng[16][3];  // Embree's geometric normal of each lane's best hit so far
  unsigned count = 0;

  bool full() const { return count == 16; }
  // A ray from `org` along unit `dir`, bounded by an earlier chunk's hit at `bound` (+inf: none), which
  // wins every tie (key 0). Returns its lane.
  unsigned add(const float org[3], const double dir[3], float bound) {
    const unsigned i = count++;
    valid[i] = -1;
    packet.ray.org_x[i] = org[0], packet.ray.org_y[i] = org[1], packet.ray.org_z[i] = org[2];
    packet.ray.dir_x[i] = static_cast<float>(dir[0]);
    packet.ray.dir_y[i] = static_cast<float>(dir[1]);
    packet.ray.dir_z[i] = static_cast<float>(dir[2]);
    packet.ray.tnear[i] = 0.0f;
    packet.ray.tfar[i] = enlarged_tfar(bound);
    context.best_t[i] = bound;
    context.best_key[i] = bound < std::numeric_limits<float>::infinity() ? 0 : UINT64_MAX;
    context.best_scene[i] = -1;
    packet.ray.time[i] = 0.0f;
    packet.ray.mask[i] = 0xFFFFFFFFu;
    packet.ray.id[i] = i;
    packet.ray.flags[i] = 0;
    return i;
  }

  // Traces the batch through every scene; returns the rays cast.
  uint64_t trace(std::span<const RayScene* const> scenes) {
    for (unsigned i = count; i < 16; ++i) valid[i] = 0;
    uint64_t cast = 0;
    for (unsigned s = 0; s < scenes.size(); ++s) {
      if (scenes[s]->empty() || count == 0) continue;
      rtcInitIntersectContext(&context.embree);
      context.embree.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      context.embree.filter = &nearest_hit_filter;
      context.scene = s;
      context.ray_scene = scenes[s];
      const auto scene = static_cast<RTCScene>(scenes[s]->handle());
      cast += count;
      if (scenes[s]->only_triangles()) {
        for (unsigned i = 0; i < 16; ++i) packet.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID, packet.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect16(valid, scene, &context.embree, &packet);
        for (unsigned i = 0; i < count; ++i)
          if (packet.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID)
            ng[i][0] = packet.hit.Ng_x[i], ng[i][1] = packet.hit.Ng_y[i], ng[i][2] = packet.hit.Ng_z[i];
        continue;
      }
      // Lines and points: a packet first, which for most rays finds nothing here; a ray whose hit the
      // filter accepted is traced again alone from where it was, so that its hit always has the single-ray
      // intersector's bits.
      float tfar[16], best_t[16];
      uint64_t best_key[16];
      int best_scene[16];
      for (unsigned i = 0; i < count; ++i) {
        tfar[i] = packet.ray.tfar[i], best_t[i] = context.best_t[i], best_key[i] = context.best_key[i];
        best_scene[i] = context.best_scene[i];
        packet.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID, packet.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
      }
      rtcIntersect16(valid, scene, &context.embree, &packet);
      for (unsigned i = 0; i < count; ++i) {
        if (packet.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
        context.best_t[i] = best_t[i], context.best_key[i] = best_key[i], context.best_scene[i] = best_scene[i];
        RTCRayHit r;
        r.ray.org_x = packet.ray.org_x[i], r.ray.org_y = packet.ray.org_y[i], r.ray.org_z = packet.ray.org_z[i];
        r.ray.dir_x = packet.ray.dir_x[i], r.ray.dir_y = packet.ray.dir_y[i], r.ray.dir_z = packet.ray.dir_z[i];
        r.ray.tnear = packet.ray.tnear[i], r.ray.tfar = tfar[i], r.ray.time = 0.0f;
        r.ray.mask = 0xFFFFFFFFu, r.ray.id = i, r.ray.flags = 0;
        r.hit.geomID = RTC_INVALID_GEOMETRY_ID, r.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &context.embree, &r);
        packet.ray.tfar[i] = r.ray.tfar;
        if (r.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
        ng[i][0] = r.hit.Ng_x, ng[i][1] = r.hit.Ng_y, ng[i][2] = r.hit.Ng_z;
      }
    }
    return cast;
  }
};

// A lane's best hit, as a pixel receives it.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  uint64_t key = UINT64_MAX;
  unsigned sub = 0;             // which of the pixel's k × k rays
  PrimitiveKind kind = PrimitiveKind::none;
  double normal[3] = {0, 0, 0};  // raw: canonical for a triangle, Embree's Ng otherwise
  double dir[3] = {0, 0, 0};
  const uint8_t* color = nullptr;  // the primitive's (RayScene::color), or null
  bool operator<(const Hit& o) const {
    return t < o.t || (t == o.t && (key < o.key || (key == o.key && sub < o.sub)));
  }
};

// Lane i's hit, when the filter accepted one (false when an earlier chunk's stays the best).
bool lane_hit(const Batch& b, unsigned i, std::span<const RayScene* const> scenes, Hit* out) {
  if (b.context.best_scene[i] < 0) return false;
  const RayScene* scene = scenes[static_cast<size_t>(b.context.best_scene[i])];
  out->t = b.context.best_t[i];
  out->key = b.context.best_key[i];
  const unsigned geom = static_cast<unsigned>(out->key >> 32) & 0xFFu, prim = static_cast<unsigned>(out->key);
  out->kind = scene->kind_of(geom);
  out->color = scene->color(geom, prim);
  const float org[3] = {b.packet.ray.org_x[i], b.packet.ray.org_y[i], b.packet.ray.org_z[i]};
  const float dir[3] = {b.packet.ray.dir_x[i], b.packet.ray.dir_y[i], b.packet.ray.dir_z[i]};
  for (int k = 0; k < 3; ++k) out->dir[k] = dir[k], out->normal[k] = b.ng[i][k];
  float t;
  if (out->kind == PrimitiveKind::triangle) scene->triangle_hit(geom, prim, org, dir, &t, out->normal);
  return true;
}

// Writes a hit into pixel p.
void store(const Hit& h, bool centre, uint64_t p, ViewImage* out) {
  out->depth[p] = h.t;
  out->kind[p] = static_cast<uint8_t>(h.kind);
  out->centre[p] = centre ? 1 : 0;
  if (!out->color.empty())
    for (int k = 0; k < 3; ++k) out->color[3 * p + k] = h.color ? h.color[k] : 255;
  double n[3] = {h.normal[0], h.normal[1], h.normal[2]};
  const double* dir = h.dir;
  normalize(n);
  if (h.kind == PrimitiveKind::edge) {
    // Embree reports a flat curve's tangent as Ng. The ribbon's normal (Low & Tan's dynamic normal) is
    // perpendicular to the edge in the plane of edge and ray: -dir without its part along the tangent.
    // Left at 0 (so -dir below) for a ray along the edge.
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

OnePixelRadii one_pixel_radii(double pixel, unsigned k) {
  const double s = pixel / std::max(1u, k);
  return {static_cast<float>(s / 2), static_cast<float>(s * M_SQRT1_2)};
}

PixelRect project_box(const Box& box, const Camera& camera) {
  const unsigned h = camera.resolution;
  for (int c = 0; c < 3; ++c)
    if (!(box.min[c] <= box.max[c])) return {};  // nothing in it
  double u0 = std::numeric_limits<double>::infinity(), u1 = -u0, v0 = u0, v1 = -u0;
  bool ahead = false, behind = false;
  // Widened by the float rounding of the rays' origin (the eye as float) and of the box's coordinates.
  double magnitude = 0;
  for (int c = 0; c < 3; ++c)
    magnitude = std::max({magnitude, std::fabs(camera.eye[c]), std::fabs(box.min[c]), std::fabs(box.max[c])});
  const double slack = magnitude * 0x1p-20;
  for (int corner = 0; corner < 8; ++corner) {
    double p[3];
    for (int c = 0; c < 3; ++c) p[c] = ((corner >> c) & 1 ? box.max[c] + slack : box.min[c] - slack) - camera.eye[c];
    const double z = p[0] * camera.forward[0] + p[1] * camera.forward[1] + p[2] * camera.forward[2];
    const double x = p[0] * camera.right[0] + p[1] * camera.right[1] + p[2] * camera.right[2];
    const double y = p[0] * camera.up[0] + p[1] * camera.up[1] + p[2] * camera.up[2];
    // A corner near the eye's plane projects arbitrarily far: then no bound.
    const double near = 1e-6 * (std::fabs(x) + std::fabs(y) + std::fabs(z));
    if (z <= near) {
      behind = true;
      continue;
    }
    ahead = true;
    const double u = (x / z / camera.tan_half_fov + 1) * h / 2, v = (1 - y / z / camera.tan_half_fov) * h / 2;
    u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
  }
  // Every ray leaves the eye forwards (tnear = 0): a box wholly behind its plane is never met.
  if (!ahead) return {};
  if (behind) return {0, 0, h, h};
  const auto clamp_to = [h](double t) { return static_cast<unsigned>(std::clamp(t, 0.0, double(h))); };
  PixelRect r{clamp_to(std::floor(u0) - 2), clamp_to(std::floor(v0) - 2), clamp_to(std::ceil(u1) + 2),
              clamp_to(std::ceil(v1) + 2)};
  if (r.empty()) return {};
  return r;
}

void clear_view(ViewImage* image, unsigned resolution) {
  const uint64_t pixels = uint64_t{resolution} * resolution;
  image->resolution = resolution;
  image->depth.assign(pixels, std::numeric_limits<float>::infinity());
  image->normal.assign(3 * pixels, 0.0f);
  image->kind.assign(pixels, 0);
  image->centre.assign(pixels, 0);
  image->color.clear();
}

void composite_pixel(ViewImage* into, uint64_t p, float depth, const float normal[3], uint8_t kind, bool centre,
                     const uint8_t* rgb) {
  if (rgb && into->color.empty()) into->color.assign(3 * into->depth.size(), 255);
  if (!later_hit_wins(into->centre[p] != 0, into->depth[p], centre, depth)) return;
  into->depth[p] = depth;
  for (int k = 0; k < 3; ++k) into->normal[3 * p + k] = normal[k];
  into->kind[p] = kind;
  into->centre[p] = centre ? 1 : 0;
  if (!into->color.empty())
    for (int k = 0; k < 3; ++k) into->color[3 * p + k] = rgb ? rgb[k] : 255;
}

void begin_composite(ViewImage* into, unsigned resolution, bool colored) {
  if (into->resolution != resolution || into->depth.size() != uint64_t{resolution} * resolution) clear_view(into, resolution);
  if (colored && into->color.empty()) into->color.assign(3 * into->depth.size(), 255);
}

void composite_view(ViewImage* into, const ViewImage& part) {
  begin_composite(into, part.resolution, !part.color.empty());
  for (uint64_t p = 0; p < part.depth.size(); ++p)
    if (part.kind[p] != 0)
      composite_pixel(into, p, part.depth[p], &part.normal[3 * p], part.kind[p], part.centre[p] != 0,
                      part.color.empty() ? nullptr : &part.color[3 * p]);
}

uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out, bool accumulate) {
  return cast_view(scenes, camera, out, accumulate, PixelRect{0, 0, camera.resolution, camera.resolution});
}

uint64_t cast_view(std::span<const RayScene* const> scenes, const Camera& camera, ViewImage* out, bool accumulate,
                   const PixelRect& rect) {
  const unsigned h = camera.resolution;
  const unsigned k = std::max(1u, camera.supersample);
  const uint64_t pixels = uint64_t{h} * h;
  if (!accumulate || out->resolution != h || out->depth.size() != pixels || out->centre.size() != pixels) clear_view(out, h);
  bool colors = false;
  for (const RayScene* scene : scenes) colors = colors || scene->has_colors();
  if (colors && out->color.size() != 3 * pixels) out->color.assign(3 * pixels, 255);
  if (h == 0) return 0;
  const float eye[3] = {static_cast<float>(camera.eye[0]), static_cast<float>(camera.eye[1]), static_cast<float>(camera.eye[2])};
  // The unit ray through (u, v) of the image, in pixels from its top left corner.
  const auto ray = [&](double u, double v, double d[3]) {
    const double sx = (2.0 * u / h - 1.0) * camera.tan_half_fov;
    const double sy = (1.0 - 2.0 * v / h) * camera.tan_half_fov;
    for (int c = 0; c < 3; ++c) d[c] = camera.forward[c] + sx * camera.right[c] + sy * camera.up[c];
    normalize(d);
  };
  if (rect.empty()) return 0;
  // The tiles that meet the rectangle; a tile's pixels outside it are traced too (same rays, same hits).
  const unsigned tx0 = rect.x0 / kTile, tx1 = std::min((rect.x1 + kTile - 1) / kTile, (h + kTile - 1) / kTile);
  const unsigned ty0 = rect.y0 / kTile, ty1 = std::min((rect.y1 + kTile - 1) / kTile, (h + kTile - 1) / kTile);
  std::atomic<uint64_t> cast{0};
  tbb::parallel_for(tbb::blocked_range<unsigned>(ty0, ty1), [&](const tbb::blocked_range<unsigned>& rows) {
    Batch batch;
    uint64_t rays = 0;
    unsigned lane_pixel[16], lane_sub[16];
    Hit best[kTile * kTile];
    Hit hit;
    for (unsigned ty = rows.begin(); ty != rows.end(); ++ty) {
      for (unsigned tx = tx0; tx < tx1; ++tx) {
        // Centre rays. An earlier chunk's centre hit bounds them; a k × k hit does not.
        batch.count = 0;
        for (unsigned i = 0; i < kTile * kTile; ++i) {
          const unsigned x = tx * kTile + i % kTile, y = ty * kTile + i / kTile;
          if (x >= h || y >= h) continue;
          const uint64_t p = uint64_t{y} * h + x;
          double d[3];
          ray(x + 0.5, y + 0.5, d);
          lane_pixel[batch.add(eye, d, out->centre[p] ? out->depth[p] : std::numeric_limits<float>::infinity())] = i;
        }
        rays += batch.trace(scenes);
        for (unsigned l = 0; l < batch.count; ++l) {
          if (!lane_hit(batch, l, scenes, &hit)) continue;
          const unsigned i = lane_pixel[l];
          store(hit, true, uint64_t{ty * kTile + i / kTile} * h + tx * kTile + i % kTile, out);
        }
        if (k == 1) continue;
        // k × k rays of the pixels no centre ray has hit, bounded by an earlier chunk's k × k hit.
        bool any = false;
        for (Hit& b : best) b = Hit{};
        batch.count = 0;
        const auto flush = [&] {
          rays += batch.trace(scenes);
          for (unsigned l = 0; l < batch.count; ++l) {
            if (!lane_hit(batch, l, scenes, &hit)) continue;
            hit.sub = lane_sub[l];
            Hit& b = best[lane_pixel[l]];
            if (hit < b) b = hit;
          }
          batch.count = 0;
        };
        for (unsigned i = 0; i < kTile * kTile; ++i) {
          const unsigned x = tx * kTile + i % kTile, y = ty * kTile + i / kTile;
          if (x >= h || y >= h) continue;
          const uint64_t p = uint64_t{y} * h + x;
          if (out->centre[p]) continue;
          any = true;
          for (unsigned sub = 0; sub < k * k; ++sub) {
            // With k odd, the middle ray is the centre ray, which missed this chunk (and no earlier
            // chunk's hit can make it hit): not cast again.
            if (k % 2 == 1 && sub == k * k / 2) continue;
            double d[3];
            ray(x + (sub % k + 0.5) / k, y + (sub / k + 0.5) / k, d);
            const unsigned l = batch.add(eye, d, out->depth[p]);
            lane_pixel[l] = i, lane_sub[l] = sub;
            if (batch.full()) flush();
          }
        }
        if (!any) continue;
        if (batch.count) flush();
        for (unsigned i = 0; i < kTile * kTile; ++i)
          if (best[i].kind != PrimitiveKind::none)
            store(best[i], false, uint64_t{ty * kTile + i / kTile} * h + tx * kTile + i % kTile, out);
      }
    }
    cast += rays;
  });
  return cast.load();
}

}  // namespace lodstream::core

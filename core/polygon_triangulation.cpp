// Polygon triangulation in the best-fit plane (sources and guarantees in the header).
//
// Steps, each a static function over flat arrays:
//   1. newell_normal: N = sum over edges (i, j = i+1) of (y_i - y_j)(z_i + z_j), ... (Newell). |N| is
//      twice the area of the polygon projected onto its best-fit plane; N points to the side from which
//      the ring turns counter-clockwise.
//   2. project: drop the axis k where |N_k| is largest (the projection that shrinks areas least: by the
//      factor |N_k| / |N| >= 1/sqrt(3)), keep axes (k+1, k+2) in cyclic order, and mirror the second when
//      N_k < 0, so that the ring is counter-clockwise in (u, v). Coordinates are taken relative to corner 0
//      for precision. Projection along an axis is an affine map of the plane: it keeps inside/outside,
//      collinearity and area ratios, so a triangulation valid in (u, v) is valid in the plane. A face that
//      is not quite planar (real models: up to a few % of its extent) is triangulated as seen along k.
//   3. fan_is_inside: the fan (0, i, i+1) is kept whenever every one of its triangles turns
//      counter-clockwise (within the tolerance). For a simple polygon that means the chain 1..n-1 is
//      angularly monotone around corner 0, i.e. the polygon is star-shaped from corner 0 and the fan is a
//      triangulation of it. Every convex polygon passes, so convex faces keep exactly the triangles a fan
//      triangulator gave them.
//   4. quads: the other diagonal (1-3) when both its triangles turn counter-clockwise.
//   5. is_simple: ear clipping assumes a simple ring; a ring whose edges cross has no inside to keep to.
//      clip_ears: Meisters' two-ears theorem says a simple polygon always has an ear: a strictly convex
//      corner v whose triangle (prev, v, next) contains no other corner. The loop walks the ring, clips
//      the first ear it meets (emitting (prev, v, next), which keeps the ring's orientation), and goes on
//      from the next corner. Corners at the same position as the ear's own corners (a ring touching
//      itself, keyhole bridges) do not block it. When a whole turn of the ring finds no ear, a corner that
//      is collinear with its neighbours (within the tolerance) is clipped as a zero-area triangle; when
//      there is none either, the polygon is not simple (or is numerically degenerate).
//   6. covers_exactly: ear clipping may also run to the end on a self-intersecting ring, with triangles
//      that overlap or leave it; the sum of their unsigned areas then exceeds the polygon's.
//   When 5 or 6 fails, the polygon gets the fan (0, i, i+1): deterministic, n - 2 triangles, and what the
//   file's order gives; a self-intersecting ring has no inside to keep to.
// Invariant of the loop: the triangles emitted so far and the remaining ring of `left` corners together
// cover the polygon, and emitted + (left - 2) == n - 2 (each clip emits one triangle and removes one corner).
//
// Tolerance: "turns counter-clockwise" means cross >= -eps, "strictly convex" cross > eps, and "collinear"
// |cross| <= eps, with eps = 1e-12 * (extent of the projected polygon)^2: relative, so the same polygon in
// millimetres or kilometres is treated the same.
#include "core/polygon_triangulation.h"

#include <algorithm>
#include <cmath>

namespace lodstream::core {

namespace {

void newell_normal(const double* xyz, uint32_t n, double normal[3]) {
  double nx = 0, ny = 0, nz = 0;
  // Relative to corner 0: the same sums, with less cancellation far from the origin.
  const double ox = xyz[0], oy = xyz[1], oz = xyz[2];
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t j = i + 1 == n ? 0 : i + 1;
    const double xi = xyz[3 * i] - ox, yi = xyz[3 * i + 1] - oy, zi = xyz[3 * i + 2] - oz;
    const double xj = xyz[3 * j] - ox, yj = xyz[3 * j + 1] - oy, zj = xyz[3 * j + 2] - oz;
    nx += (yi - yj) * (zi + zj);
    ny += (zi - zj) * (xi + xj);
    nz += (xi - xj) * (yi + yj);
  }
  normal[0] = nx, normal[1] = ny, normal[2] = nz;
}

// Projects onto the plane of `normal` (see step 2); returns false when the normal is zero or not finite.
// *eps receives the tolerance for this polygon.
bool project(const double* xyz, uint32_t n, const double normal[3], double* uv, double* eps) {
  int k = 0;
  for (int a = 1; a < 3; ++a)
    if (std::fabs(normal[a]) > std::fabs(normal[k])) k = a;
  const double nk = normal[k];
  if (!(std::fabs(nk) > 0) || !std::isfinite(nk)) return false;
  const int a = (k + 1) % 3, b = (k + 2) % 3;
  const double mirror = nk > 0 ? 1.0 : -1.0;
  double umin = 0, umax = 0, vmin = 0, vmax = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const double u = xyz[3 * i + a] - xyz[a];
    const double v = mirror * (xyz[3 * i + b] - xyz[b]);
    uv[2 * i] = u, uv[2 * i + 1] = v;
    umin = std::min(umin, u), umax = std::max(umax, u);
    vmin = std::min(vmin, v), vmax = std::max(vmax, v);
  }
  const double extent = std::max(umax - umin, vmax - vmin);
  *eps = 1e-12 * extent * extent;
  // A plane whose area is at the tolerance's level is no plane: the corners are (nearly) collinear.
  return std::fabs(nk) > *eps;
}

inline double cross(const double* uv, uint32_t p, uint32_t v, uint32_t q) {
  const double ax = uv[2 * v] - uv[2 * p], ay = uv[2 * v + 1] - uv[2 * p + 1];
  const double bx = uv[2 * q] - uv[2 * p], by = uv[2 * q + 1] - uv[2 * p + 1];
  return ax * by - ay * bx;
}

inline bool same_point(const double* uv, uint32_t a, uint32_t b) {
  return uv[2 * a] == uv[2 * b] && uv[2 * a + 1] == uv[2 * b + 1];
}

void write_fan(uint32_t n, uint32_t* tri) {
  for (uint32_t i = 1; i + 1 < n; ++i) {
    *tri++ = 0;
    *tri++ = i;
    *tri++ = i + 1;
  }
}

bool fan_is_inside(const double* uv, uint32_t n, double eps) {
  for (uint32_t i = 1; i + 1 < n; ++i)
    if (cross(uv, 0, i, i + 1) < -eps) return false;
  return true;
}

// w inside or on the boundary of the counter-clockwise triangle (p, v, q), within eps.
inline bool in_triangle(const double* uv, uint32_t p, uint32_t v, uint32_t q, uint32_t w, double eps) {
  return cross(uv, p, v, w) >= -eps && cross(uv, v, q, w) >= -eps && cross(uv, q, p, w) >= -eps;
}

bool is_ear(const double* uv, const uint32_t* next, uint32_t p, uint32_t v, uint32_t q, double eps) {
  if (cross(uv, p, v, q) <= eps) return false;
  for (uint32_t w = next[q]; w != p; w = next[w]) {
    if (same_point(uv, w, p) || same_point(uv, w, v) || same_point(uv, w, q)) continue;
    if (in_triangle(uv, p, v, q, w, eps)) return false;
  }
  return true;
}

// Step 5a: no two edges cross at a point inside both (beyond eps on each side). Edges that only touch (a
// corner on another edge, coincident corners of a keyhole bridge) are allowed. O(n^2), run only on the
// faces whose fan failed (about 1 % of the n-gons of real models).
bool is_simple(const double* uv, uint32_t n, double eps) {
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t i1 = i + 1 == n ? 0 : i + 1;
    for (uint32_t j = i + 2; j < n; ++j) {
      const uint32_t j1 = j + 1 == n ? 0 : j + 1;
      if (j1 == i) continue;
      const double d1 = cross(uv, i, i1, j), d2 = cross(uv, i, i1, j1);
      if (!((d1 > eps && d2 < -eps) || (d1 < -eps && d2 > eps))) continue;
      const double d3 = cross(uv, j, j1, i), d4 = cross(uv, j, j1, i1);
      if ((d3 > eps && d4 < -eps) || (d3 < -eps && d4 > eps)) return false;
    }
  }
  return true;
}

// Step 6: the triangles' unsigned areas sum to the polygon's area (within n * eps). Ear clipping can run
// to the end on a self-intersecting ring; then its triangles overlap or leave the ring, and this fails.
bool covers_exactly(const double* uv, uint32_t n, const uint32_t* tri, double eps) {
  double polygon = 0, sum = 0;
  for (uint32_t i = 1; i + 1 < n; ++i) polygon += cross(uv, 0, i, i + 1);
  for (uint32_t t = 0; t + 2 < n; ++t) sum += std::fabs(cross(uv, tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]));
  return std::fabs(sum - polygon) <= n * eps;
}

// Step 5. Returns false when it had to fan the rest (not a simple polygon).
bool clip_ears(const double* uv, uint32_t n, double eps, uint32_t* prev, uint32_t* next, uint32_t* tri) {
  for (uint32_t i = 0; i < n; ++i) {
    prev[i] = i == 0 ? n - 1 : i - 1;
    next[i] = i + 1 == n ? 0 : i + 1;
  }
  auto clip = [&](uint32_t v) {
    const uint32_t p = prev[v], q = next[v];
    *tri++ = p;
    *tri++ = v;
    *tri++ = q;
    next[p] = q;
    prev[q] = p;
  };
  uint32_t left = n, v = 0, tried = 0;
  bool simple = true;
  while (left > 3) {
    if (is_ear(uv, next, prev[v], v, next[v], eps)) {
      const uint32_t q = next[v];
      clip(v);
      --left;
      v = q;
      tried = 0;
      continue;
    }
    v = next[v];
    if (++tried < left) continue;
    // A whole turn without an ear: clip a collinear corner (zero area), else give up on this ring.
    uint32_t c = v;
    bool found = false;
    for (uint32_t k = 0; k < left; ++k, c = next[c]) {
      if (std::fabs(cross(uv, prev[c], c, next[c])) <= eps) {
        found = true;
        break;
      }
    }
    if (!found) {
      simple = false;
      break;
    }
    const uint32_t q = next[c];
    clip(c);
    --left;
    v = q;
    tried = 0;
  }
  // The last three corners, or the fallback fan of the remaining ring from v.
  for (uint32_t a = next[v]; next[a] != v; a = next[a]) {
    *tri++ = v;
    *tri++ = a;
    *tri++ = next[a];
  }
  return simple;
}

}  // namespace

Triangulation triangulate_polygon(const double* xyz, uint32_t n, uint32_t* triangles, PolygonScratch* s) {
  if (n == 3) {
    triangles[0] = 0, triangles[1] = 1, triangles[2] = 2;
    return Triangulation::fan;
  }
  double normal[3];
  newell_normal(xyz, n, normal);
  if (s->uv.size() < 2 * size_t{n}) s->uv.resize(2 * size_t{n});
  double* uv = s->uv.data();
  double eps = 0;
  if (!project(xyz, n, normal, uv, &eps)) {
    write_fan(n, triangles);
    return Triangulation::fallback;
  }
  if (fan_is_inside(uv, n, eps)) {
    write_fan(n, triangles);
    return Triangulation::fan;
  }
  if (n == 4) {
    if (cross(uv, 0, 1, 3) >= -eps && cross(uv, 1, 2, 3) >= -eps) {
      const uint32_t t[6] = {0, 1, 3, 1, 2, 3};
      std::copy(t, t + 6, triangles);
      return Triangulation::diagonal;
    }
    write_fan(n, triangles);
    return Triangulation::fallback;
  }
  if (s->prev.size() < n) s->prev.resize(n), s->next.resize(n);
  if (is_simple(uv, n, eps) && clip_ears(uv, n, eps, s->prev.data(), s->next.data(), triangles) &&
      covers_exactly(uv, n, triangles, eps))
    return Triangulation::ear_clipping;
  write_fan(n, triangles);
  return Triangulation::fallback;
}

double polygon_area2(const double* xyz, uint32_t n) {
  double normal[3];
  newell_normal(xyz, n, normal);
  return std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
}

}  // namespace lodstream::core

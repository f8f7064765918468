// This work is based on:
// Michael A. DeHaemer Jr. Simplification of objects rendered by polygonal approximation. M.S. thesis,
//   Naval Postgraduate School, 1989: adaptive subdivision (ch. II: trial polygons, edge gaps, extra
//   vertices, fill polygons, divide by two, split at center / first / greatest error / curvature /
//   random), polygon growth (ch. III).
// Francis J. M. Schmitt, Brian A. Barsky, Wen-hui Du. An adaptive subdivision method for surface-fitting
//   from sampled data. SIGGRAPH 1986 (the basic method the thesis starts from).
//
// Differences from the thesis, on purpose:
// - The accuracy test measures each sample against the triangles that are drawn (draw_triangles), not a
//   bilinear patch, and a trial rectangle takes whichever of its two diagonals fits better. After the
//   subdivision, every polygon is verified again with its final vertices (extra vertices change its
//   triangles); one that fails is split at its sample of greatest error and refined, until none fails.
//   invariant (after subdivide): every valid sample under a drawn polygon lies within tolerance of that
//   polygon's drawn triangles, for every gap mode.
// - Polygon growth grows rectangles (east, south, west, north in turn, one row or column of cells at a
//   time), so that its polygons go through the same gap treatment and error check as the subdivision's.
// - Cylindrical scans (thesis §II.B) are measured in 3D: a sample's error is the distance, along its ray
//   from the axis, between its radius and the drawn triangle's plane (CylinderFrame in the header). The
//   trial test computes exactly that for both diagonals, and the verification measures every triangle
//   each ray meets, so the invariant above holds for radii along rays. Longitude wraps: the seam's
//   corners are shared, so its T-junctions are closed like any other.
#include "core/adaptive_subdivision.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <numbers>
#include <optional>
#include <queue>
#include <ctime>
#include <stdexcept>

#include "core/surface_sampling.h"  // mix64

namespace lodstream::core {

namespace {

struct Point {
  uint32_t i, j;
};

// NODATA: flagged invalid, or a non-finite height (or, for a cylinder, a radius that is not > 0).
bool sample_valid(const GridSamples& g, uint64_t s) {
  return (g.valid.empty() || g.valid[s]) && std::isfinite(g.z[s]) && (!g.cylinder || g.z[s] > 0);
}

// Cylindrical grids (CylinderFrame): each column's direction and each row's height, computed once. The
// wrap column takes column 0's angle (0, not 2 pi: cos and sin of 2 pi are not exactly 1 and 0).
struct CylinderGeometry {
  std::vector<double> cos, sin, h;
  explicit CylinderGeometry(const GridSamples& g) {
    const CylinderFrame& f = *g.cylinder;
    cos.resize(g.width);
    sin.resize(g.width);
    for (uint32_t i = 0; i < g.width; ++i) {
      const double a = double(f.wrap && i == g.width - 1 ? 0 : i) * f.angle_step;
      cos[i] = std::cos(a);
      sin[i] = std::sin(a);
    }
    h.resize(g.height);
    for (uint32_t j = 0; j < g.height; ++j) h[j] = f.y_bottom + double(g.height - 1 - j) * f.height_step;
  }
  void point(const GridSamples& g, uint32_t s, double p[3]) const {
    const uint32_t i = s % g.width, j = s / g.width;
    p[0] = double(g.z[s]) * cos[i];
    p[1] = double(g.z[s]) * sin[i];
    p[2] = h[j];
  }
};

// Which side of the plane through the axis point O = (0, 0, h), P and Q the ray from O in direction
// D = (c, s, 0) lies on: D . ((P - O) x (Q - O)). Zero in that plane.
inline double ray_side(const double* P, const double* Q, double c, double s, double h) {
  const double pa = P[2] - h, qa = Q[2] - h;
  return c * (P[1] * qa - pa * Q[1]) + s * (pa * Q[0] - P[0] * qa);
}

// The plane through P, Q, R as n . X = d, and the distance along the ray from (0, 0, h) in direction
// (c, s, 0) to it (+infinity when the ray is parallel to it or meets it behind the axis: a failure).
struct Plane {
  double n[3], d;
  Plane() = default;
  Plane(const double* P, const double* Q, const double* R) {
    const double u[3] = {Q[0] - P[0], Q[1] - P[1], Q[2] - P[2]}, v[3] = {R[0] - P[0], R[1] - P[1], R[2] - P[2]};
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
    d = n[0] * P[0] + n[1] * P[1] + n[2] * P[2];
  }
  double radius(double c, double s, double h) const {
    const double t = (d - n[2] * h) / (n[0] * c + n[1] * s);
    return std::isfinite(t) && t >= 0 ? t : std::numeric_limits<double>::infinity();
  }
};

// Whether the ray from (0, 0, h) in direction (c, s, 0) meets triangle PQR, whose plane pl is through P,
// Q, R in that order: 1 inside, 0 on its border (within a relative 1e-9), -1 outside or parallel to it (a
// triangle edge-on from there). Inside, the three ray_side values share one sign, that of their sum,
// which is pl.n . (c, s, 0) whatever the ray's origin. (Not the sign at a vertex's own ray: a steep
// triangle's plane can cross the axis between its rows, and the sides' signs flip with the origin.)
inline int ray_meets(const double* P, const double* Q, const double* R, const Plane& pl, double c, double s, double h) {
  const double den = pl.n[0] * c + pl.n[1] * s;
  const double nn = std::abs(pl.n[0]) + std::abs(pl.n[1]) + std::abs(pl.n[2]);
  if (!(std::abs(den) > 1e-12 * nn)) return -1;
  const double sg = den > 0 ? 1 : -1, eps = 1e-9 * std::abs(den);
  const double a = sg * ray_side(P, Q, c, s, h), b = sg * ray_side(Q, R, c, s, h), d = sg * ray_side(R, P, c, s, h);
  if (a < -eps || b < -eps || d < -eps) return -1;
  return a > eps && b > eps && d > eps ? 1 : 0;
}

// Visits every sample whose ray from the axis meets the 3D triangle (a, b, c) (edges included, within a
// relative 1e-9 of the triangle's size seen from the axis), with the radius of the triangle's plane along
// that ray. Only samples in the triangle's (i, j) bounding box can: a point of the triangle is a convex
// combination of its vertices, whose directions span less than 180 degrees (CylinderFrame), so its
// longitude lies between theirs, and its height is between theirs. Triangles seen edge-on from the axis
// (fill polygons) are skipped. round_to_float: the vertices as a mesh file stores them.
template <class F>
void for_each_ray_hit(const GridSamples& g, const CylinderGeometry& cg, uint32_t a, uint32_t b, uint32_t c,
                      bool round_to_float, F&& f) {
  const uint32_t ids[3] = {a, b, c};
  double P[3][3], Q[3][3];  // exact, and as given (rounded or not)
  for (int k = 0; k < 3; ++k) {
    cg.point(g, ids[k], P[k]);
    for (int x = 0; x < 3; ++x) Q[k][x] = round_to_float ? double(float(P[k][x])) : P[k][x];
  }
  const uint32_t w = g.width;
  // A triangle on one column or one row (a fill polygon's) lies in a longitude's half-plane or a height's
  // plane: edge-on from the axis. Known from the ids, so that rounding cannot make it look otherwise.
  if ((a % w == b % w && b % w == c % w) || (a / w == b / w && b / w == c / w)) return;
  // Which rays meet the triangle is decided on the exact points (rounded to float, the vertices leave the
  // rays through them, and a ray along a shared edge could slip between both triangles); the radius is
  // that of the plane of the points as given (rounded or not). Near an edge both triangles' rounded
  // planes agree to that rounding, so this is what a watertight ray caster meets on the written mesh.
  const Plane exact(P[0], P[1], P[2]), plane(Q[0], Q[1], Q[2]);
  const uint32_t i0 = std::min({a % w, b % w, c % w}), i1 = std::max({a % w, b % w, c % w});
  const uint32_t j0 = std::min({a / w, b / w, c / w}), j1 = std::max({a / w, b / w, c / w});
  for (uint32_t j = j0; j <= j1; ++j)
    for (uint32_t i = i0; i <= i1; ++i) {
      const uint32_t s = j * w + i;
      if (!round_to_float && (s == a || s == b || s == c)) {
        f(s, double(g.z[s]));  // at a vertex the surface is exactly the vertex: error 0
        continue;
      }
      const double co = cg.cos[i], si = cg.sin[i], h = cg.h[j];
      if (ray_meets(P[0], P[1], P[2], exact, co, si, h) < 0) continue;
      f(s, plane.radius(co, si, h));
    }
}

// x rounded up to a float (an upper bound is what verify_and_draw needs).
float float_up(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

bool is_cell(const Rect& r) { return r.i1 - r.i0 == 1 && r.j1 - r.j0 == 1; }

// Visits every sample inside or on triangle (a, b, c) with the height of the triangle's plane there.
// Exact integer inside test in sample coordinates; the triangle is oriented counter-clockwise from above
// (x = i, y = -j) or skipped when vertical.
template <class F>
void for_each_sample(const GridSamples& g, uint32_t a, uint32_t b, uint32_t c, F&& f) {
  const int64_t ax = a % g.width, ay = -int64_t(a / g.width);
  const int64_t bx = b % g.width, by = -int64_t(b / g.width);
  const int64_t cx = c % g.width, cy = -int64_t(c / g.width);
  int64_t area2 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
  if (area2 == 0) return;
  double za = g.z[a], zb = g.z[b], zc = g.z[c];
  int64_t Bx = bx, By = by, Cx = cx, Cy = cy;
  if (area2 < 0) {
    std::swap(Bx, Cx);
    std::swap(By, Cy);
    std::swap(zb, zc);
    area2 = -area2;
  }
  const int64_t xmin = std::min({ax, Bx, Cx}), xmax = std::max({ax, Bx, Cx});
  const int64_t ymin = std::min({ay, By, Cy}), ymax = std::max({ay, By, Cy});
  const double inv = 1.0 / static_cast<double>(area2);
  for (int64_t y = ymin; y <= ymax; ++y) {
    for (int64_t x = xmin; x <= xmax; ++x) {
      const int64_t wa = (Bx - x) * (Cy - y) - (By - y) * (Cx - x);
      const int64_t wb = (Cx - x) * (ay - y) - (Cy - y) * (ax - x);
      const int64_t wc = area2 - wa - wb;
      if (wa < 0 || wb < 0 || wc < 0) continue;
      // At a vertex the height is exactly the vertex's: corners and extra vertices fit with error 0.
      const double h = wa == area2 ? za
                       : wb == area2 ? zb
                       : wc == area2 ? zc
                                     : (static_cast<double>(wa) * za + static_cast<double>(wb) * zb +
                                        static_cast<double>(wc) * zc) * inv;
      f(static_cast<uint32_t>(-y) * g.width + static_cast<uint32_t>(x), h);
    }
  }
}

class Subdivider {
 public:
  Subdivider(const GridSamples& g, const SubdivisionOptions& o, const SubdivisionProgress& p)
      : g_(g), o_(o), progress_(p), tol_(o.tolerance) {
    const uint64_t n = uint64_t(g.width) * g.height;
    valid_.resize(n);
    for (uint64_t s = 0; s < n; ++s) valid_[s] = sample_valid(g, s);
    any_nodata_ = std::find(valid_.begin(), valid_.end(), uint8_t{0}) != valid_.end();
    // verify_and_draw() measures a polygon's corner triangles with integer barycentric weights, evaluate()
    // with fractions of its sides: the same planes, each rounded a handful of times on values of at most
    // twice the largest |z|, so the two differ by far less than 2^-30 of it (the margin below). A trial
    // error at least that far within tolerance therefore passes the verification too.
    double zmax = 0;
    for (uint64_t s = 0; s < n; ++s)
      if (valid_[s]) zmax = std::max(zmax, std::abs(double(g.z[s])));
    proven_tol_ = tol_ - std::ldexp(zmax, -30);
    if (g.cylinder) {
      // The trial and the verification compute the same planes from the same points but decide which
      // triangle a ray near an edge meets with slightly different (1e-9 relative) margins: a wider margin.
      cyl_.emplace(g);
      max_cols_ = std::max<uint32_t>(1, uint32_t(std::floor(std::numbers::pi / 2 / g.cylinder->angle_step)));
      const double span = std::max(std::abs(cyl_->h.front()), std::abs(cyl_->h.back()));
      proven_tol_ = tol_ - std::ldexp(zmax + span, -24);
    }
    known_.resize(n);
    if (o.merge) failed_se_.assign(n, UINT32_MAX);
    if (o.split == SplitRule::curvature) compute_curvature();
    // 1.0 / k for every rectangle side length k: the same values the trial would divide for (IEEE
    // division is exact-rounded), without two divisions per trial.
    inverse_.resize(std::max(g.width, g.height));
    for (uint32_t k = 1; k < inverse_.size(); ++k) inverse_[k] = 1.0 / k;
    total_cells_ = double(g.width - 1) * double(g.height - 1);
  }

  Subdivision run() {
    const Rect root{0, 0, g_.width - 1, g_.height - 1, 0};
    if (o_.method == Method::growth) grow();
    else if (o_.target_polygons > 0) refine_to_target(root);
    else refine(root);
    if (o_.merge && std::isfinite(tol_)) merge();
    verify_and_draw();
    return std::move(out_);
  }

 private:
  bool valid(uint32_t i, uint32_t j) const { return valid_[id(i, j)] != 0; }
  uint32_t id(uint32_t i, uint32_t j) const { return j * g_.width + i; }
  double z(uint32_t i, uint32_t j) const { return g_.z[id(i, j)]; }

  // Thesis Figure 10: per sample, the length of the difference of the unit normals of its east and west
  // neighbours plus that of its north and south neighbours (one-sided at the border and next to NODATA).
  void compute_curvature() {
    const uint32_t w = g_.width, h = g_.height;
    std::vector<float> n(3 * uint64_t(w) * h);
    auto zs = [&](int64_t i, int64_t j, uint32_t i0, uint32_t j0) {
      i = std::clamp<int64_t>(i, 0, w - 1);
      j = std::clamp<int64_t>(j, 0, h - 1);
      return valid(uint32_t(i), uint32_t(j)) ? z(uint32_t(i), uint32_t(j)) : z(i0, j0);
    };
    for (uint32_t j = 0; j < h; ++j)
      for (uint32_t i = 0; i < w; ++i) {
        const double dx = (zs(int64_t(i) + 1, j, i, j) - zs(int64_t(i) - 1, j, i, j)) / (2 * g_.spacing);
        const double dy = (zs(i, int64_t(j) - 1, i, j) - zs(i, int64_t(j) + 1, i, j)) / (2 * g_.spacing);  // y is north
        const double len = std::sqrt(dx * dx + dy * dy + 1);
        float* v = &n[3 * uint64_t(id(i, j))];
        v[0] = float(-dx / len);
        v[1] = float(-dy / len);
        v[2] = float(1 / len);
      }
    curvature_.assign(uint64_t(w) * h, 0);
    auto diff = [&](uint32_t a, uint32_t b) {
      const float* p = &n[3 * uint64_t(a)];
      const float* q = &n[3 * uint64_t(b)];
      return std::sqrt(double(p[0] - q[0]) * (p[0] - q[0]) + double(p[1] - q[1]) * (p[1] - q[1]) +
                       double(p[2] - q[2]) * (p[2] - q[2]));
    };
    for (uint32_t j = 0; j < h; ++j)
      for (uint32_t i = 0; i < w; ++i)
        curvature_[id(i, j)] = float(diff(id(std::min(i + 1, w - 1), j), id(i > 0 ? i - 1 : 0, j)) +
                                     diff(id(i, j > 0 ? j - 1 : 0), id(i, std::min(j + 1, h - 1))));
  }

  struct Eval {
    bool nodata = false;
    double error = 0;   // of the better diagonal, the one kept
    uint8_t diagonal = 0;
    Point split{0, 0};  // where to split when error > tolerance (or nodata)
  };

  // The trial polygon's accuracy test with corners only (both diagonals at once), and its split point.
  // decide_only: the caller needs only whether it passes and, if it does, the diagonal, or a split point
  // that depends on no sample (center, random): the scan stops as soon as both diagonals are over
  // tolerance (error is then only known to be > tolerance), and the other rules' split points are unset.
  Eval evaluate(const Rect& r, bool decide_only = false) {
    ++out_.trials;
    Eval e;
    const uint32_t w = r.i1 - r.i0, h = r.j1 - r.j0;
    const Point center{r.i0 + w / 2, r.j0 + h / 2};
    if (cyl_ && w > max_cols_) {  // wider than 90 degrees (CylinderFrame): split across longitude first
      e.error = std::numeric_limits<double>::infinity();
      e.split = {center.i, r.j0};
      return e;
    }
    for (uint32_t j = r.j0; any_nodata_ && j <= r.j1 && !e.nodata; ++j)
      for (uint32_t i = r.i0; i <= r.i1; ++i)
        if (!valid(i, j)) {
          e.nodata = true;
          break;
        }
    if (e.nodata) {
      e.error = std::numeric_limits<double>::infinity();
      e.split = center;
      return e;
    }
    const double znw = z(r.i0, r.j0), zne = z(r.i1, r.j0), zsw = z(r.i0, r.j1), zse = z(r.i1, r.j1);
    const double fw = inverse_[w], fh = inverse_[h];
    const int64_t W = w, H = h;
    double max_err[2] = {0, 0};
    Point arg[2] = {{r.i0, r.j0}, {r.i0, r.j0}}, first[2] = {{0, 0}, {0, 0}};
    bool over[2] = {false, false};
    double best_curv = -1;
    uint64_t best_dist = 0;
    Point curv{center};
    // The errors of sample (i0 + di, j0 + dj) against both diagonals' triangles.
    // Cylinder: the corners' points and the planes of both diagonals' triangles -- diagonal 0: (SW, SE,
    // NE), (SW, NE, NW); diagonal 1: (NW, NE, SE), (NW, SE, SW). A ray is measured against the triangles
    // it meets (ray_meets), both when it runs along the diagonal within the margin, as the verification
    // (for_each_ray_hit) does.
    double psw[3], pse[3], pne[3], pnw[3];
    Plane pl[4];
    if (cyl_) {
      cyl_->point(g_, id(r.i0, r.j1), psw);
      cyl_->point(g_, id(r.i1, r.j1), pse);
      cyl_->point(g_, id(r.i1, r.j0), pne);
      cyl_->point(g_, id(r.i0, r.j0), pnw);
      pl[0] = Plane(psw, pse, pne);
      pl[1] = Plane(psw, pne, pnw);
      pl[2] = Plane(pnw, pne, pse);
      pl[3] = Plane(pnw, pse, psw);
    }
    // The sample's errors against both diagonals' triangles: along its ray for a cylinder, vertical
    // otherwise. Two functions, each scan instantiated for one, so the height grid's loop stays as lean.
    auto radial = [&](int64_t di, int64_t dj, double zs, double& e0, double& e1) {
      const uint32_t i = uint32_t(r.i0 + di), j = uint32_t(r.j0 + dj);
      const double c = cyl_->cos[i], s = cyl_->sin[i], hh = cyl_->h[j];
      auto err = [&](int t) { return std::abs(zs - pl[t].radius(c, s, hh)); };
      // Of two triangles, the one the ray meets; both when it meets both (the diagonal) or, from
      // rounding, neither.
      auto pick = [&](int a, int b, int ma, int mb) {
        return ma >= 0 && mb < 0 ? err(a) : mb >= 0 && ma < 0 ? err(b) : std::max(err(a), err(b));
      };
      e0 = pick(0, 1, ray_meets(psw, pse, pne, pl[0], c, s, hh), ray_meets(psw, pne, pnw, pl[1], c, s, hh));
      e1 = pick(2, 3, ray_meets(pnw, pne, pse, pl[2], c, s, hh), ray_meets(pnw, pse, psw, pl[3], c, s, hh));
    };
    auto planar = [&](int64_t di, int64_t dj, double zs, double& e0, double& e1) {
      const double u = di * fw, v = dj * fh;
      // Both triangles' planes are computed and one is selected, without a branch: which triangle a
      // sample falls in changes from sample to sample, a branch there is mispredicted often.
      // Diagonal 0 (SW-NE): triangles (SW, SE, NE) where u + v >= 1 and (SW, NE, NW) elsewhere.
      const double se0 = zse + (1 - u) * (zsw - zse) + (1 - v) * (zne - zse), nw0 = znw + u * (zne - znw) + v * (zsw - znw);
      const double p0 = di * H + dj * W >= W * H ? se0 : nw0;
      // Diagonal 1 (NW-SE): triangles (NW, NE, SE) where u >= v and (NW, SE, SW) elsewhere.
      const double ne1 = znw + u * (zne - znw) + v * (zse - zne), sw1 = znw + v * (zsw - znw) + u * (zse - zsw);
      const double p1 = di * H >= dj * W ? ne1 : sw1;
      e0 = std::abs(zs - p0);
      e1 = std::abs(zs - p1);
    };
    auto scan = [&](auto&& errors) {
      auto visit = [&](uint32_t i, uint32_t j) {
        double e0, e1;
        errors(int64_t(i) - r.i0, int64_t(j) - r.j0, z(i, j), e0, e1);
        if (e0 > max_err[0]) max_err[0] = e0, arg[0] = {i, j};
        if (e1 > max_err[1]) max_err[1] = e1, arg[1] = {i, j};
        if (!over[0] && e0 > tol_) over[0] = true, first[0] = {i, j};
        if (!over[1] && e1 > tol_) over[1] = true, first[1] = {i, j};
        if (!curvature_.empty() && !((i == r.i0 || i == r.i1) && (j == r.j0 || j == r.j1))) {
          const double c = curvature_[id(i, j)];
          const uint64_t d = uint64_t(std::abs(int64_t(i) - center.i)) * std::abs(int64_t(i) - center.i) +
                             uint64_t(std::abs(int64_t(j) - center.j)) * std::abs(int64_t(j) - center.j);
          if (c > best_curv || (c == best_curv && d < best_dist)) best_curv = c, best_dist = d, curv = {i, j};
        }
      };
      if (decide_only) {
        // Most trials (growth, merge, center and random splits): no sample to track, so a lean row-major
        // scan of the two maxima. Any scan order gives the same maxima, and the scan stops only when both
        // are over tolerance.
        for (uint32_t j = r.j0; j <= r.j1 && !(max_err[0] > tol_ && max_err[1] > tol_); ++j) {
          const float* row = &g_.z[id(0, j)];
          const int64_t dj = j - r.j0;
          for (uint32_t i = r.i0; i <= r.i1; ++i) {
            double e0, e1;
            errors(i - r.i0, dj, row[i], e0, e1);
            max_err[0] = std::max(max_err[0], e0);
            max_err[1] = std::max(max_err[1], e1);
          }
        }
      } else if (w >= h) {  // the scan order of "first error": north to south when at least as wide as tall
        for (uint32_t j = r.j0; j <= r.j1; ++j)
          for (uint32_t i = r.i0; i <= r.i1; ++i) visit(i, j);
      } else {  // else west to east
        for (uint32_t i = r.i0; i <= r.i1; ++i)
          for (uint32_t j = r.j0; j <= r.j1; ++j) visit(i, j);
      }
    };
    if (cyl_) scan(radial);
    else scan(planar);
    const int d = max_err[1] < max_err[0] ? 1 : 0;
    e.diagonal = uint8_t(d);
    e.error = max_err[d];
    // Within tolerance means the scan was complete (decide_only stops only when both diagonals are over),
    // so this is the polygon's exact error with diagonal d: kept for verify_and_draw().
    if (e.error <= tol_) known_[id(r.i0, r.j0)] = {id(r.i1, r.j1), e.diagonal ? -float_up(e.error) : float_up(e.error)};
    switch (o_.split) {
      case SplitRule::center: e.split = center; break;
      case SplitRule::first: e.split = over[d] ? first[d] : arg[d]; break;
      case SplitRule::greatest: e.split = arg[d]; break;
      case SplitRule::curvature: e.split = curv; break;
      case SplitRule::random: {
        const uint64_t key = mix64(o_.seed ^ mix64((uint64_t(r.i0) << 32 | r.j0) ^ mix64(uint64_t(r.i1) << 32 | r.j1)));
        e.split.i = w >= 2 ? r.i0 + 1 + uint32_t(key % (w - 1)) : r.i0;
        e.split.j = h >= 2 ? r.j0 + 1 + uint32_t(mix64(key) % (h - 1)) : r.j0;
        break;
      }
    }
    return e;
  }

  // At most four children, by value: split() runs once per failed trial, too often to allocate.
  struct Children {
    Rect r[4];
    int n = 0;
    const Rect* begin() const { return r; }
    const Rect* end() const { return r + n; }
  };

  // Children of `r` split through point p: four (or two when p lies on a side) with divide 4; two with
  // divide 2, across the longer side when p's coordinate there is inside, else across the other.
  Children split(const Rect& r, Point p) const {
    const uint32_t w = r.i1 - r.i0, h = r.j1 - r.j0;
    bool in_i = p.i > r.i0 && p.i < r.i1, in_j = p.j > r.j0 && p.j < r.j1;
    if (!in_i && !in_j) {  // a corner: cannot happen for errors (corners fit exactly); fall back to the center
      p = {r.i0 + w / 2, r.j0 + h / 2};
      in_i = w >= 2;
      in_j = h >= 2;
    }
    if (o_.divide == 2) {
      const bool across_i = w >= h ? in_i : !in_j;
      in_i = across_i;
      in_j = !across_i;
    }
    Children c;
    const uint32_t xs[3] = {r.i0, in_i ? p.i : r.i1, r.i1};
    const uint32_t ys[3] = {r.j0, in_j ? p.j : r.j1, r.j1};
    for (int b = 0; b < (in_j ? 2 : 1); ++b)
      for (int a = 0; a < (in_i ? 2 : 1); ++a) c.r[c.n++] = {xs[a], ys[b], in_i ? xs[a + 1] : r.i1, in_j ? ys[b + 1] : r.j1, 0};
    return c;
  }

  void add_hole(const Rect& r) { out_.hole_cells += uint64_t(r.i1 - r.i0) * (r.j1 - r.j0); }
  void add_done(const Rect& r) {
    done_cells_ += double(r.i1 - r.i0) * double(r.j1 - r.j0);
    if (progress_ && ++ticks_ % 1024 == 0) progress_(std::min(0.9, 0.9 * done_cells_ / total_cells_));
  }

  // Recursive subdivision to tolerance. The center and random split points do not depend on the samples,
  // so a failing trial can stop early there.
  void refine(const Rect& root) {
    const bool split_needs_no_scan = o_.split == SplitRule::center || o_.split == SplitRule::random;
    std::vector<Rect> stack{root};
    while (!stack.empty()) {
      Rect r = stack.back();
      stack.pop_back();
      const bool unit = is_cell(r);
      const Eval e = evaluate(r, split_needs_no_scan);
      if (e.nodata && unit) {
        add_hole(r);
        add_done(r);
      } else if (!e.nodata && (unit || e.error <= tol_)) {  // a single cell has nothing under it to miss
        r.diagonal = e.diagonal;
        leaves_.push_back(r);
        add_done(r);
      } else {
        if (!failed_se_.empty()) failed_se_[id(r.i0, r.j0)] = id(r.i1, r.j1);
        const Children c = split(r, e.split);
        for (int k = c.n - 1; k >= 0; --k) stack.push_back(c.r[k]);  // first child on top
      }
    }
  }

  // The thesis' search direction: always refine the polygon of greatest error next.
  void refine_to_target(const Rect& root) {
    struct Item {
      double error;
      Rect r;
      Point split;
    };
    auto less = [](const Item& a, const Item& b) {
      if (a.error != b.error) return a.error < b.error;
      if (a.r.j0 != b.r.j0) return a.r.j0 > b.r.j0;
      return a.r.i0 > b.r.i0;
    };
    std::priority_queue<Item, std::vector<Item>, decltype(less)> queue(less);
    const double stop = std::isinf(tol_) ? 0 : tol_;
    auto push = [&](const Rect& r) {
      const Eval e = evaluate(r);
      const bool unit = is_cell(r);
      if (e.nodata && unit) return add_hole(r);
      Rect k = r;
      k.diagonal = e.diagonal;
      queue.push({unit ? 0.0 : e.error, k, e.split});
    };
    push(root);
    while (!queue.empty()) {
      const Item top = queue.top();
      const bool nodata = std::isinf(top.error);
      if (!nodata && queue.size() >= o_.target_polygons) {
        // Stopped by the count: the tolerance is not a promise any more, the extra vertices are drawn as
        // they come (the verification splits nothing).
        tol_ = std::numeric_limits<double>::infinity();
        break;
      }
      if (!nodata && top.error <= stop) break;
      queue.pop();
      for (const Rect& c : split(top.r, top.split)) push(c);
      if (progress_ && ++ticks_ % 256 == 0) progress_(0.9 * std::min(1.0, double(queue.size()) / double(o_.target_polygons)));
    }
    for (; !queue.empty(); queue.pop()) leaves_.push_back(queue.top().r);
  }

  // Polygon growth (thesis ch. III) with sequential seeds: each unclaimed cell in row order seeds a
  // rectangle that grows by a row or column of unclaimed, NODATA-free cells while the trial passes.
  void grow() {
    const uint32_t cw = g_.width - 1, ch = g_.height - 1;
    std::vector<uint8_t> claimed(uint64_t(cw) * ch, 0);
    auto cell_ok = [&](uint32_t i, uint32_t j) {
      return !claimed[uint64_t(j) * cw + i] && valid(i, j) && valid(i + 1, j) && valid(i, j + 1) && valid(i + 1, j + 1);
    };
    for (uint32_t j = 0; j < ch; ++j) {
      for (uint32_t i = 0; i < cw; ++i) {
        if (claimed[uint64_t(j) * cw + i]) continue;
        Rect r{i, j, i + 1, j + 1, 0};
        if (!cell_ok(i, j)) {
          claimed[uint64_t(j) * cw + i] = 1;
          add_hole(r);
          continue;
        }
        r.diagonal = evaluate(r).diagonal;
        for (bool grew = true; grew;) {
          grew = false;
          for (int dir = 0; dir < 4; ++dir) {
            Rect t = r;
            bool ok = true;
            if (dir == 0 && r.i1 < cw) {  // east: cells (r.i1, r.j0 .. r.j1-1)
              for (uint32_t y = r.j0; y < r.j1 && ok; ++y) ok = cell_ok(r.i1, y);
              t.i1 = r.i1 + 1;
            } else if (dir == 1 && r.j1 < ch) {  // south
              for (uint32_t x = r.i0; x < r.i1 && ok; ++x) ok = cell_ok(x, r.j1);
              t.j1 = r.j1 + 1;
            } else if (dir == 2 && r.i0 > 0) {  // west
              for (uint32_t y = r.j0; y < r.j1 && ok; ++y) ok = cell_ok(r.i0 - 1, y);
              t.i0 = r.i0 - 1;
            } else if (dir == 3 && r.j0 > 0) {  // north
              for (uint32_t x = r.i0; x < r.i1 && ok; ++x) ok = cell_ok(x, r.j0 - 1);
              t.j0 = r.j0 - 1;
            } else {
              ok = false;
            }
            if (!ok) continue;
            const Eval e = evaluate(t, true);
            if (e.nodata || e.error > tol_) continue;
            t.diagonal = e.diagonal;
            r = t;
            grew = true;
          }
        }
        for (uint32_t y = r.j0; y < r.j1; ++y)
          for (uint32_t x = r.i0; x < r.i1; ++x) claimed[uint64_t(y) * cw + x] = 1;
        leaves_.push_back(r);
        add_done(r);
      }
    }
  }

  // Merge pass (not in the thesis): two polygons that share a whole side become one when their union
  // passes the trial polygon test. The subdivision cannot find these unions (it only ever tests a
  // polygon's own children) nor can growth (the neighbour's cells were claimed, or the first row or column
  // of them failed where the whole neighbour passes), yet each one saves two triangles and often
  // T-junctions. In rounds of growing union area (2, 4, 8, ... cells), so that small polygons pair up with
  // each other before big ones absorb them one at a time (on the Fuji tile, center/2/fill: 0.2% and 0.8%
  // fewer triangles at 5 and 20 m than one uncapped round, the same at 1 m). A round is one pass over the
  // polygons in (j0, i0) order, each trying its east then its south neighbour; the last, uncapped round
  // repeats until nothing merges. Deterministic.
  //
  // A pass visits only a worklist, not every polygon (18 rounds of ~240,000 polygons on the Fuji tile at
  // 1 m cost more than the tests did). Visiting polygon k tests its union with the polygon whose NW corner
  // is k's NE (east) or SW (south) corner, unless that union is the one k last saw fail or exceeds the
  // round's cap. So a visit that tests nothing can only test something later when
  //   (a) k grew: k goes on the next pass's list;
  //   (b) the polygon at k's NE or SW corner grew: when polygon m grows, the polygons with their NE or SW
  //       corner at m's NW corner go on this pass's list if after m (the full pass reaches them after the
  //       change too), else on the next pass's (a polygon that dies tests nothing: at[] forgets it, and NW
  //       corners never move);
  //   (c) the cap reached the union's area: k waits on the list of that round.
  // An extra polygon on a list costs a visit and changes nothing, so the lists may over-approximate; they
  // never miss a union a full pass would test. The same unions are tested in the same order with the same
  // outcomes, so the result and the trial count are those of full passes.
  void merge() {
    constexpr uint32_t kNone = UINT32_MAX;
    // Polygon by its NW corner (what a visit looks up), by its NE and by its SW corner (for (b)).
    std::vector<uint32_t> at;
    sort_leaves(&at);
    const uint32_t n = uint32_t(leaves_.size());
    const uint64_t samples = uint64_t(g_.width) * g_.height;
    std::vector<uint32_t> ne_at(samples, kNone), sw_at(samples, kNone);
    for (uint32_t k = 0; k < n; ++k) {
      const Rect& r = leaves_[k];
      ne_at[id(r.i1, r.j0)] = sw_at[id(r.i0, r.j1)] = k;
    }
    std::vector<uint8_t> alive(n, 1);
    // The last union that failed per polygon and direction, by its SE corner (its NW corner is the
    // polygon's, which never moves): the same union fails again, so it is not tested again.
    std::vector<uint32_t> failed(2 * uint64_t(n), kNone);
    // Round r caps the union area at 2^(r+1) cells; the last round's cap covers the whole grid.
    const double all_cells = double(g_.width - 1) * double(g_.height - 1);
    int rounds = 1;
    for (double cap = 2; cap < all_cells; cap *= 2) ++rounds;
    auto round_of = [&](uint64_t area) {  // the first round whose cap fits `area`
      return std::min(rounds - 1, std::max(0, int(std::bit_width(area - 1)) - 1));
    };
    // Worklists as bitsets over polygon indices (the pass order): `now` this pass, `later` the next;
    // due[r]: polygons waiting for round r's cap.
    const size_t words = (uint64_t(n) + 63) / 64;
    std::vector<uint64_t> now(words, 0), later(words, ~uint64_t{0});
    if (n % 64) later.back() = (uint64_t{1} << (n % 64)) - 1;
    std::vector<std::vector<uint32_t>> due(static_cast<size_t>(rounds));
    uint32_t pos = 0;  // the polygon being visited
    auto touch = [&](uint32_t m) {
      if (m == kNone) return;
      (m > pos ? now : later)[m >> 6] |= uint64_t{1} << (m & 63);
    };
    double cap = 2;
    auto visit = [&](uint32_t k) {
      for (int dir = 0; dir < 2 && alive[k]; ++dir) {
        Rect& p = leaves_[k];
        const bool east = dir == 0;
        if (east ? p.i1 == g_.width - 1 : p.j1 == g_.height - 1) continue;
        const uint32_t q = east ? at[id(p.i1, p.j0)] : at[id(p.i0, p.j1)];
        if (q == kNone || !alive[q]) continue;
        const Rect& nb = leaves_[q];
        if (east ? nb.j1 != p.j1 : nb.i1 != p.i1) continue;  // not the whole side
        Rect u{p.i0, p.j0, nb.i1, nb.j1, 0};
        const uint64_t area = uint64_t(u.i1 - u.i0) * (u.j1 - u.j0);
        if (double(area) > cap) {
          due[size_t(round_of(area))].push_back(k);
          continue;
        }
        if (failed[2 * k + dir] == id(u.i1, u.j1)) continue;
        // A union that refine() already saw fail (two children of one parent, often) fails again: it
        // counts as a trial, as it did when it was measured, but is not measured again.
        const bool refined_away = !failed_se_.empty() && failed_se_[id(u.i0, u.j0)] == id(u.i1, u.j1);
        if (refined_away) ++out_.trials;
        const Eval e = refined_away ? Eval{} : evaluate(u, true);
        if (refined_away || e.nodata || e.error > tol_) {
          failed[2 * k + dir] = id(u.i1, u.j1);
          continue;
        }
        u.diagonal = e.diagonal;
        at[id(nb.i0, nb.j0)] = ne_at[id(nb.i1, nb.j0)] = sw_at[id(nb.i0, nb.j1)] = kNone;
        ne_at[id(p.i1, p.j0)] = sw_at[id(p.i0, p.j1)] = kNone;
        alive[q] = 0;
        p = u;
        ne_at[id(p.i1, p.j0)] = sw_at[id(p.i0, p.j1)] = k;
        touch(k);                          // (a)
        touch(ne_at[id(p.i0, p.j0)]);      // (b): k's west and north neighbours
        touch(sw_at[id(p.i0, p.j0)]);
        ++out_.merges;
      }
    };
    for (int round = 0; round < rounds; ++round, cap *= 2) {
      const bool last = round == rounds - 1;
      do {
        now.swap(later);
        std::fill(later.begin(), later.end(), 0);
        for (uint32_t k : due[size_t(round)]) now[k >> 6] |= uint64_t{1} << (k & 63);  // (c)
        due[size_t(round)].clear();
        for (size_t w = 0; w < words; ++w)
          while (now[w]) {  // re-read: a visit may add polygons after pos to this word
            pos = uint32_t(w * 64 + size_t(std::countr_zero(now[w])));
            now[w] &= now[w] - 1;
            visit(pos);
          }
      } while (last && std::any_of(later.begin(), later.end(), [](uint64_t x) { return x != 0; }));
    }
    size_t kept = 0;
    for (size_t k = 0; k < leaves_.size(); ++k)
      if (alive[k]) leaves_[kept++] = leaves_[k];
    leaves_.resize(kept);
  }

  // Sorts leaves_ by (j0, i0), that is by NW corner id. The polygons tile the grid, so no two share a NW
  // corner: one pass over a sample-sized map gives the order a comparison sort would (and is several
  // times faster than sorting a few hundred thousand rectangles). by_corner_out: that map, polygon index
  // by NW corner id (UINT32_MAX: none), after the sort.
  void sort_leaves(std::vector<uint32_t>* by_corner_out = nullptr) {
    constexpr uint32_t kNone = UINT32_MAX;
    auto before = [](const Rect& a, const Rect& b) { return a.j0 != b.j0 ? a.j0 < b.j0 : a.i0 < b.i0; };
    const bool sorted_already = std::is_sorted(leaves_.begin(), leaves_.end(), before);  // e.g. by merge()
    if (sorted_already && !by_corner_out) return;
    std::vector<uint32_t> by_corner(uint64_t(g_.width) * g_.height, kNone);
    for (uint32_t k = 0; k < leaves_.size(); ++k) by_corner[id(leaves_[k].i0, leaves_[k].j0)] = k;
    if (!sorted_already) {
      std::vector<Rect> sorted;
      sorted.reserve(leaves_.size());
      for (uint32_t& k : by_corner)
        if (k != kNone) {
          sorted.push_back(leaves_[k]);
          k = uint32_t(sorted.size() - 1);
        }
      leaves_ = std::move(sorted);
    }
    if (by_corner_out) *by_corner_out = std::move(by_corner);
  }

  // The points strictly inside the four sides of r that are corners of other polygons, in ring order.
  void side_points(const Rect& r, std::vector<uint32_t> (&sides)[4]) const {
    for (auto& s : sides) s.clear();
    for (uint32_t i = r.i0 + 1; i < r.i1; ++i)
      if (corner_[id(i, r.j1)]) sides[0].push_back(id(i, r.j1));
    for (uint32_t j = r.j1 - 1; j > r.j0; --j)
      if (corner_[id(r.i1, j)]) sides[1].push_back(id(r.i1, j));
    for (uint32_t i = r.i1 - 1; i > r.i0; --i)
      if (corner_[id(i, r.j0)]) sides[2].push_back(id(i, r.j0));
    for (uint32_t j = r.j0 + 1; j < r.j1; ++j)
      if (corner_[id(r.i0, j)]) sides[3].push_back(id(r.i0, j));
  }

  void mark_corners() {
    corner_.assign(uint64_t(g_.width) * g_.height, 0);
    for (const Rect& r : leaves_)
      corner_[id(r.i0, r.j0)] = corner_[id(r.i1, r.j0)] = corner_[id(r.i0, r.j1)] = corner_[id(r.i1, r.j1)] = 1;
    // The seam: columns 0 and width - 1 are one column, so a corner on either is a corner on both, and
    // the polygons on each side of it see the other side's corners as side points.
    if (cyl_ && g_.cylinder->wrap)
      for (uint32_t j = 0; j < g_.height; ++j) {
        uint8_t& west = corner_[id(0, j)];
        uint8_t& east = corner_[id(g_.width - 1, j)];
        west = east = west | east;
      }
  }

  // Cylinder: a horizontal side is the chord from a to b in their horizontal plane, not a linear
  // interpolation of radii; the gap at t is the difference of t's radius and the chord's along t's ray.
  // (A vertical side lies in its longitude's half-plane, where radius is linear in height: as above.)
  double chord_gap(uint32_t a, uint32_t b, uint32_t t) const {
    double A[3], B[3];
    cyl_->point(g_, a, A);
    cyl_->point(g_, b, B);
    const uint32_t ti = t % g_.width;
    const double ex = B[0] - A[0], ey = B[1] - A[1];
    const double chord = (A[0] * B[1] - A[1] * B[0]) / (cyl_->cos[ti] * ey - cyl_->sin[ti] * ex);
    return std::abs(double(g_.z[t]) - chord);
  }

  // Largest error over the samples under `tris`, and where (ties: the smallest sample id).
  std::pair<double, uint32_t> surface_error(const std::vector<uint32_t>& tris) const {
    double worst = -1;
    uint32_t at = 0;
    auto visit = [&](uint32_t s, double h) {
      const double e = std::abs(double(g_.z[s]) - h);
      if (e > worst || (e == worst && s < at)) worst = e, at = s;
    };
    for (size_t t = 0; t < tris.size(); t += 3) {
      if (cyl_) for_each_ray_hit(g_, *cyl_, tris[t], tris[t + 1], tris[t + 2], false, visit);
      else for_each_sample(g_, tris[t], tris[t + 1], tris[t + 2], visit);
    }
    return {worst, at};
  }

  // Whether the trial test already proves that r passes the verification: r is drawn with its corners
  // only (no extra vertices on its sides), with the diagonal the trial measured, and the trial's error is
  // within tolerance by more than the rounding margin (see the constructor). Skips re-measuring nearly
  // every polygon; one that is not proven is measured as before, so the result is the same.
  bool proven_by_trial(const Rect& r, const std::vector<uint32_t> (&sides)[4]) const {
    for (const auto& s : sides)
      if (!s.empty()) return false;
    const KnownError& k = known_[id(r.i0, r.j0)];
    return k.se == id(r.i1, r.j1) && std::signbit(k.error) == (r.diagonal == 1) && std::abs(double(k.error)) <= proven_tol_;
  }

  // Verifies every polygon against its final drawn triangles, splitting and refining the ones that fail,
  // until none does; then writes rings, triangles, fill polygons and the T-junction census.
  void verify_and_draw() {
    const bool extra = o_.gaps == GapMode::extra_vertices;
    std::vector<uint32_t> sides[4];
    const std::vector<uint32_t> none[4];
    std::vector<uint32_t> tris;
    for (;;) {
      mark_corners();
      // The polygons that pass are compacted in place (kept <= the polygon being verified).
      size_t kept = 0;
      std::vector<Rect> failed;
      std::vector<Point> where;
      for (Rect r : leaves_) {
        if (extra) side_points(r, sides);
        if (proven_by_trial(r, extra ? sides : none)) {
          leaves_[kept++] = r;
          continue;
        }
        bool ok = false;
        std::pair<double, uint32_t> worst{0, 0};
        for (int attempt = 0; attempt < 2 && !ok; ++attempt) {
          if (attempt == 1) r.diagonal ^= 1;
          tris.clear();
          draw_triangles(g_, r, extra ? sides : none, &tris);
          const auto e = surface_error(tris);
          if (attempt == 0) worst = e;
          ok = e.first <= tol_;
        }
        if (ok || is_cell(r)) {
          leaves_[kept++] = r;
        } else {
          r.diagonal ^= 1;
          failed.push_back(r);
          where.push_back({worst.second % g_.width, worst.second / g_.width});
        }
      }
      leaves_.resize(kept);  // with the diagonals that passed
      if (failed.empty()) break;
      out_.verify_splits += failed.size();
      for (size_t f = 0; f < failed.size(); ++f)
        for (const Rect& c : split(failed[f], where[f])) refine(c);
    }
    if (progress_) progress_(0.95);

    sort_leaves();
    // corner_ still holds these polygons' corners: the last pass split nothing.
    // Reserved once, for at most as much as can be drawn, rather than grown by doubling (each doubling
    // copies and touches fresh pages; capacity never written is address space, not memory). A side point
    // is a corner strictly inside one side (two polygons' sides through it would leave no room for the
    // polygon it is a corner of), so there are at most C (the distinct corners) of them in all. Per polygon 4
    // ring entries and 2 triangles, plus one ring entry and one triangle per side point with extra
    // vertices; with fill, per side with k >= 1 points, one fill polygon of k + 2 <= 3k entries and k
    // triangles.
    const uint64_t polys = leaves_.size(), corner_points = uint64_t(std::count(corner_.begin(), corner_.end(), uint8_t{1}));
    out_.ring_offsets.reserve(polys + 1 + corner_points);
    out_.rings.reserve(4 * polys + 3 * corner_points);
    out_.triangles.reserve(3 * (2 * polys + corner_points));
    out_.ring_offsets.push_back(0);
    std::vector<uint32_t> fill_rings;  // (size, ids...) per fill polygon
    for (const Rect& r : leaves_) {
      side_points(r, sides);
      const uint32_t ci[4] = {r.i0, r.i1, r.i1, r.i0}, cj[4] = {r.j1, r.j1, r.j0, r.j0};  // SW SE NE NW
      for (int s = 0; s < 4; ++s) {
        const uint32_t a = id(ci[s], cj[s]), b = id(ci[(s + 1) % 4], cj[(s + 1) % 4]);
        out_.rings.push_back(a);
        if (extra) out_.rings.insert(out_.rings.end(), sides[s].begin(), sides[s].end());
        // T-junction census: heights against this side's straight line, exactly (integer weights). A
        // side point's distance from a, in samples, is its id's distance along the row or column
        // (sides are axis-aligned; no division per corner).
        const bool along_row = cj[s] == cj[(s + 1) % 4];
        const int64_t len = along_row ? std::abs(int64_t(ci[(s + 1) % 4]) - ci[s]) : std::abs(int64_t(cj[(s + 1) % 4]) - cj[s]);
        bool gap_here = false;
        for (uint32_t t : sides[s]) {
          const int64_t at = along_row ? std::abs(int64_t(t) - a) : std::abs(int64_t(t) - a) / g_.width;
          const double d = cyl_ && along_row ? chord_gap(a, b, t)
                                             : std::abs(double(g_.z[t]) * len - (double(g_.z[a]) * (len - at) + double(g_.z[b]) * at)) / len;
          ++out_.t_junctions;
          if (d > 0) {
            ++out_.gaps;
            gap_here = true;
            out_.max_gap = std::max(out_.max_gap, d);
          }
        }
        // Cylinders: a side with T-junctions and no gap still gets its (flat) fill polygon, so that the 3D
        // mesh is closed edge to edge (every edge in two triangles but at rims and holes) as mesh tools
        // check it; on quantized radii (16-bit PGM) gapless vertical sides are common.
        if (o_.gaps == GapMode::fill && (gap_here || (cyl_ && !sides[s].empty()))) {
          fill_rings.push_back(uint32_t(sides[s].size() + 2));
          fill_rings.push_back(a);
          fill_rings.insert(fill_rings.end(), sides[s].begin(), sides[s].end());
          fill_rings.push_back(b);
        }
      }
      out_.ring_offsets.push_back(out_.rings.size());
      draw_triangles(g_, r, extra ? sides : none, &out_.triangles);
    }
    // Fill polygons: (A, t1 .. tk, B) over side AB, drawn as a fan from A. Seen in the vertical plane of
    // the side, every point between AB and the polyline A t1 .. tk B is on a segment from A to the polyline,
    // so the fan covers the gap.
    for (size_t at = 0; at < fill_rings.size();) {
      const uint32_t n = fill_rings[at];
      const uint32_t* ring = &fill_rings[at + 1];
      out_.rings.insert(out_.rings.end(), ring, ring + n);
      out_.ring_offsets.push_back(out_.rings.size());
      for (uint32_t k = 1; k + 1 < n; ++k) {
        out_.triangles.insert(out_.triangles.end(), {ring[0], ring[k], ring[k + 1]});
        ++out_.fill_triangles;
      }
      ++out_.fill_polygons;
      at += n + 1;
    }
    out_.cracks = o_.gaps == GapMode::none ? out_.gaps : 0;
    out_.polygons = std::move(leaves_);
    if (progress_) progress_(1);
  }

  const GridSamples& g_;
  const SubdivisionOptions& o_;
  const SubdivisionProgress& progress_;
  double tol_;  // infinite once a polygon target stopped the refinement
  std::vector<uint8_t> valid_, corner_;
  bool any_nodata_ = false;
  std::vector<float> curvature_;
  std::vector<double> inverse_;  // inverse_[k] = 1.0 / k
  std::optional<CylinderGeometry> cyl_;
  uint32_t max_cols_ = 0;        // cylinder: the widest rectangle, in columns (90 degrees)
  std::vector<Rect> leaves_;
  // The last trial error within tolerance measured per NW corner, with the rectangle and diagonal it is
  // for (a cache of a function of those: an entry for another rectangle is simply not used).
  struct KnownError {
    uint32_t se = UINT32_MAX;  // the rectangle's SE corner id (its NW is the index); UINT32_MAX: none
    float error = 0;           // rounded up; its sign bit is the diagonal (8 bytes per sample, not 16)
  };
  std::vector<KnownError> known_;
  // With merge: the SE corner of the last rectangle refine() split, by its NW corner (UINT32_MAX: none).
  std::vector<uint32_t> failed_se_;
  double proven_tol_ = 0;
  Subdivision out_;
  double total_cells_ = 1, done_cells_ = 0;
  uint64_t ticks_ = 0;
};

}  // namespace

void draw_triangles(const GridSamples& g, const Rect& r, const std::vector<uint32_t> (&sides)[4], std::vector<uint32_t>* out) {
  const uint32_t w = g.width;
  const uint32_t c[4] = {r.j1 * w + r.i0, r.j1 * w + r.i1, r.j0 * w + r.i1, r.j0 * w + r.i0};  // SW SE NE NW
  auto dist2 = [w](uint32_t a, uint32_t b) {
    const int64_t di = int64_t(a % w) - int64_t(b % w), dj = int64_t(a / w) - int64_t(b / w);
    return di * di + dj * dj;
  };
  // Half k: diagonal c[k] - c[k+2], apex c[k+1]; its legs are sides[k] (c[k] to apex) and sides[k+1].
  auto half = [&](int k) {
    const uint32_t p = c[k], apex = c[(k + 1) % 4], q = c[(k + 2) % 4];
    const std::vector<uint32_t>& in = sides[k];
    const std::vector<uint32_t>& outl = sides[(k + 1) % 4];
    // chain 1: p, in[0], in[1], ... toward the apex; chain 2: q, outl[last], ... toward the apex.
    auto c1 = [&](size_t x) { return x == 0 ? p : in[x - 1]; };
    auto c2 = [&](size_t y) { return y == 0 ? q : outl[outl.size() - y]; };
    size_t x = 0, y = 0;
    const size_t n1 = in.size(), n2 = outl.size();
    while (x < n1 || y < n2) {
      const bool advance1 = y == n2 || (x < n1 && dist2(c1(x + 1), c2(y)) <= dist2(c1(x), c2(y + 1)));
      if (advance1) {
        out->insert(out->end(), {c1(x), c1(x + 1), c2(y)});
        ++x;
      } else {
        out->insert(out->end(), {c1(x), c2(y + 1), c2(y)});
        ++y;
      }
    }
    out->insert(out->end(), {c1(x), apex, c2(y)});
  };
  half(r.diagonal == 0 ? 0 : 1);
  half(r.diagonal == 0 ? 2 : 3);
}

Subdivision subdivide(const GridSamples& grid, const SubdivisionOptions& options, const SubdivisionProgress& progress) {
  if (grid.width < 2 || grid.height < 2) throw std::invalid_argument("subdivide: the grid needs at least 2 x 2 samples");
  if (uint64_t(grid.width) * grid.height > UINT32_MAX) throw std::invalid_argument("subdivide: more than 2^32 samples");
  if (grid.z.size() != uint64_t(grid.width) * grid.height) throw std::invalid_argument("subdivide: z size");
  if (!grid.valid.empty() && grid.valid.size() != grid.z.size()) throw std::invalid_argument("subdivide: valid size");
  if (!(options.tolerance >= 0)) throw std::invalid_argument("subdivide: tolerance must be >= 0");
  if (options.divide != 2 && options.divide != 4) throw std::invalid_argument("subdivide: divide must be 2 or 4");
  if (const CylinderFrame* f = grid.cylinder) {
    if (!(f->angle_step > 0 && f->angle_step < std::numbers::pi)) throw std::invalid_argument("subdivide: angle step must be in (0, pi)");
    if (!(f->height_step > 0) || !std::isfinite(f->height_step) || !std::isfinite(f->y_bottom))
      throw std::invalid_argument("subdivide: height step must be > 0");
    for (uint32_t j = 0; f->wrap && j < grid.height; ++j) {
      const uint64_t first = uint64_t(j) * grid.width, last = first + grid.width - 1;
      const bool same = (grid.z[first] == grid.z[last] || (std::isnan(grid.z[first]) && std::isnan(grid.z[last]))) &&
                        (grid.valid.empty() || grid.valid[first] == grid.valid[last]);
      if (!same) throw std::invalid_argument("subdivide: with wrap, the last column must repeat the first");
    }
  }
  return Subdivider(grid, options, progress).run();
}

void cylinder_point(const GridSamples& grid, uint32_t s, double out[3]) {
  const CylinderFrame& f = *grid.cylinder;
  const uint32_t i = s % grid.width, j = s / grid.width;
  // As CylinderGeometry computes it, so that the points agree to the bit.
  const double a = double(f.wrap && i == grid.width - 1 ? 0 : i) * f.angle_step;
  out[0] = double(grid.z[s]) * std::cos(a);
  out[1] = double(grid.z[s]) * std::sin(a);
  out[2] = f.y_bottom + double(grid.height - 1 - j) * f.height_step;
}

VerticalError vertical_error(const GridSamples& g, std::span<const uint32_t> triangles, bool round_to_float) {
  std::vector<double> err(uint64_t(g.width) * g.height, -1);
  VerticalError r;
  if (g.cylinder) {
    const CylinderGeometry cg(g);
    for (size_t t = 0; t + 2 < triangles.size(); t += 3)
      for_each_ray_hit(g, cg, triangles[t], triangles[t + 1], triangles[t + 2], round_to_float,
                       [&](uint32_t s, double h) { err[s] = std::max(err[s], std::abs(double(g.z[s]) - h)); });
    // Triangles do not overlap seen from the axis: the area is that of the domain cells they cover, as
    // for height grids (each rectangle's two halves).
    for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
      const uint32_t a = triangles[t], b = triangles[t + 1], c = triangles[t + 2];
      const int64_t ax = a % g.width, ay = a / g.width, bx = b % g.width, by = b / g.width, cx = c % g.width, cy = c / g.width;
      r.covered_area += 0.5 * double(std::abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax)));
    }
    const bool wrap = g.cylinder->wrap;
    double sum2 = 0;
    for (uint64_t s = 0; s < err.size(); ++s) {
      const uint64_t i = s % g.width;
      if (!sample_valid(g, s) || (wrap && i == g.width - 1)) continue;
      // A seam sample is one ray: the worst of what the polygons on both sides give it.
      const double e = wrap && i == 0 ? std::max(err[s], err[s + g.width - 1]) : err[s];
      if (e < 0) {
        ++r.uncovered;
        continue;
      }
      ++r.samples;
      r.max = std::max(r.max, e);
      sum2 += e * e;
    }
    r.rms = r.samples ? std::sqrt(sum2 / double(r.samples)) : 0;
    return r;
  }
  for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
    const uint32_t a = triangles[t], b = triangles[t + 1], c = triangles[t + 2];
    const int64_t ax = a % g.width, ay = a / g.width, bx = b % g.width, by = b / g.width, cx = c % g.width, cy = c / g.width;
    r.covered_area += 0.5 * double(std::abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax)));
    for_each_sample(g, a, b, c, [&](uint32_t s, double h) { err[s] = std::max(err[s], std::abs(double(g.z[s]) - h)); });
  }
  double sum2 = 0;
  for (uint64_t s = 0; s < err.size(); ++s) {
    if (!sample_valid(g, s)) continue;
    if (err[s] < 0) {
      ++r.uncovered;
      continue;
    }
    ++r.samples;
    r.max = std::max(r.max, err[s]);
    sum2 += err[s] * err[s];
  }
  r.rms = r.samples ? std::sqrt(sum2 / double(r.samples)) : 0;
  return r;
}

}  // namespace lodstream::core

// Quadric-placed representatives (core/quadric.h): the plane quadric of a triangle, the minimizer for
// three, two and one planes (corner, crease line, flat region), axis-aligned and rotated so that the Jacobi
// solve does real work, near-parallel planes (dropped eigenvalues), clamping into the cell box, degenerate
// and extreme input, and a property check against brute force on random triangle sets.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "core/quadric.h"
#include "core/status.h"

namespace lodstream {
namespace {

using core::Quadric;
using V = std::array<double, 3>;

constexpr V kBigMin{-1e9, -1e9, -1e9};
constexpr V kBigMax{1e9, 1e9, 1e9};

V minimize(const Quadric& q, const V& ref, const V& lo = kBigMin, const V& hi = kBigMax) {
  return core::quadric_minimizer(q, ref.data(), lo.data(), hi.data());
}

V add(const V& a, const V& b) {
  return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
V scale(const V& a, double s) {
  return {a[0] * s, a[1] * s, a[2] * s};
}
double dot(const V& a, const V& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
V cross(const V& a, const V& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
V normalized(const V& a) {
  return scale(a, 1 / std::sqrt(dot(a, a)));
}

void expect_near(const V& a, const V& b, double tol) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], tol) << "coordinate " << i;
}

// Adds two triangles (a square of side 2·size) of the plane through p spanned by the unit vectors e and f.
void add_square(Quadric& q, const V& p, const V& e, const V& f, double size = 1) {
  const V a = add(p, add(scale(e, -size), scale(f, -size)));
  const V b = add(p, add(scale(e, size), scale(f, -size)));
  const V c = add(p, add(scale(e, size), scale(f, size)));
  const V d = add(p, add(scale(e, -size), scale(f, size)));
  q.add_triangle(a.data(), b.data(), c.data());
  q.add_triangle(a.data(), c.data(), d.data());
}

// A random rotation (orthonormal frame) from a seed.
std::array<V, 3> frame(uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  const V a = normalized({g(rng), g(rng), g(rng)});
  V b = {g(rng), g(rng), g(rng)};
  b = normalized(add(b, scale(a, -dot(a, b))));
  return {a, b, cross(a, b)};
}

TEST(Quadric, TrianglePlaneQuadric) {
  // Triangle in z = 3 with area 2: A = 2·zzᵀ, b = 2·3·z, c = 2·9; the error is area × distance².
  Quadric q;
  const double p0[3] = {0, 0, 3}, p1[3] = {2, 0, 3}, p2[3] = {0, 2, 3};
  q.add_triangle(p0, p1, p2);
  EXPECT_EQ(q.a22, 2.0);
  EXPECT_EQ(q.a00, 0.0);
  EXPECT_EQ(q.a01, 0.0);
  EXPECT_EQ(q.b2, 6.0);
  EXPECT_EQ(q.c, 18.0);
  const double x[3] = {5, -7, 4.5};
  EXPECT_DOUBLE_EQ(q.error(x), 2 * 1.5 * 1.5);
  // The winding does not matter.
  Quadric r;
  r.add_triangle(p0, p2, p1);
  EXPECT_EQ(r.a22, q.a22);
  EXPECT_EQ(r.b2, q.b2);
  EXPECT_EQ(r.c, q.c);
}

TEST(Quadric, ThreeOrthogonalPlanesGiveTheirCorner) {
  const V corner{1, 2, 3};
  Quadric q;
  add_square(q, corner, {0, 1, 0}, {0, 0, 1});  // x = 1
  add_square(q, corner, {1, 0, 0}, {0, 0, 1});  // y = 2
  add_square(q, corner, {1, 0, 0}, {0, 1, 0});  // z = 3
  expect_near(minimize(q, {0, 0, 0}), corner, 1e-12);
  expect_near(minimize(q, {1.4, 2.2, 2.9}), corner, 1e-12);
  // The same corner with the planes rotated off the axes, and planes of unequal areas.
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    const auto [e0, e1, e2] = frame(seed);
    Quadric r;
    add_square(r, corner, e1, e2, 0.5);
    add_square(r, corner, e0, e2, 2.0);
    add_square(r, corner, e0, e1, 1.0);
    expect_near(minimize(r, {0.5, 2.5, 3.5}), corner, 1e-10);
  }
}

TEST(Quadric, TwoPlanesGiveThePointOnTheirLineNearestRef) {
  Quadric q;
  add_square(q, {1, 2, 0}, {0, 1, 0}, {0, 0, 1});  // x = 1
  add_square(q, {1, 2, 0}, {1, 0, 0}, {0, 0, 1});  // y = 2
  expect_near(minimize(q, {5, -3, 7}), {1, 2, 7}, 1e-12);
  // Rotated: planes through p with normals e0 and e1 meet in the line p + s·e2.
  const V p{0.3, -0.2, 0.7};
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    const auto [e0, e1, e2] = frame(seed);
    // Two planes at 60° to one another (normals e0 and cos60·e0 + sin60·e1).
    const V n1 = add(scale(e0, 0.5), scale(e1, std::sqrt(0.75)));
    Quadric r;
    add_square(r, p, e1, e2);
    add_square(r, p, normalized(cross(n1, e2)), e2);
    const V ref{0.1, 0.1, 0.1};
    const V expected = add(p, scale(e2, dot(add(ref, scale(p, -1)), e2)));
    expect_near(minimize(r, ref), expected, 1e-10);
  }
}

TEST(Quadric, OnePlaneProjectsRef) {
  Quadric q;
  add_square(q, {0, 0, 3}, {1, 0, 0}, {0, 1, 0});
  expect_near(minimize(q, {4, 5, 6}), {4, 5, 3}, 1e-12);
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    const auto [e0, e1, e2] = frame(seed);
    const V p{1, -1, 2};
    Quadric r;
    add_square(r, p, e1, e2, 3);
    const V ref{0.5, 0.25, -0.75};
    const V expected = add(ref, scale(e0, dot(add(p, scale(ref, -1)), e0)));
    expect_near(minimize(r, ref), expected, 1e-12);
  }
}

TEST(Quadric, NearlyParallelPlanesAreTreatedAsOne) {
  // Two planes 0.1° apart meeting far away (at x = 0 while the cell is near x = 100): their exact
  // intersection line is ill-conditioned, so the small eigenvalue is dropped and the result is ref
  // projected onto (nearly) the common plane instead of a point on the far line.
  const double angle = 0.1 * std::acos(-1.0) / 180;
  Quadric q;
  add_square(q, {100, 0, 0}, {1, 0, 0}, {0, 1, 0});
  const V tilted{std::cos(angle), 0, std::sin(angle)};
  add_square(q, scale(tilted, 100), tilted, {0, 1, 0});
  // Near x = 100 the planes are at z = 0 and z = 100·tan(0.1°) ≈ 0.1745: ref moves along their mean normal
  // (0.05° off z) onto their mean plane, z ≈ 0.087.
  const V ref{100, 0.5, 1};
  const V x = minimize(q, ref);
  EXPECT_NEAR(x[0], 100, 2e-3);
  EXPECT_NEAR(x[1], 0.5, 1e-12);
  EXPECT_NEAR(x[2], 0.0873, 1e-3);
  // With no threshold the exact intersection line, the y axis, is used: the point on it nearest ref.
  const V exact = core::quadric_minimizer(q, ref.data(), kBigMin.data(), kBigMax.data(), 0);
  expect_near(exact, {0, 0.5, 0}, 1e-6);
}

TEST(Quadric, ClampsIntoTheCellBox) {
  Quadric q;
  const V corner{1, 2, 3};
  add_square(q, corner, {0, 1, 0}, {0, 0, 1});
  add_square(q, corner, {1, 0, 0}, {0, 0, 1});
  add_square(q, corner, {1, 0, 0}, {0, 1, 0});
  expect_near(minimize(q, {0.25, 2, 3}, {0, 0, 0}, {0.5, 10, 10}), {0.5, 2, 3}, 1e-12);
  EXPECT_EQ(minimize(q, {0, 0, 0}, {4, 5, 6}, {7, 8, 9}), (V{4, 5, 6}));
  // Inside the box nothing changes (exact when the minimizer is inside).
  expect_near(minimize(q, {1, 1, 1}, {0, 0, 0}, {5, 5, 5}), corner, 1e-12);
  // A degenerate box (a point) gives that point.
  EXPECT_EQ(minimize(q, {0, 0, 0}, {7, 7, 7}, {7, 7, 7}), (V{7, 7, 7}));
}

TEST(Quadric, ZeroQuadricGivesRef) {
  Quadric q;
  EXPECT_EQ(minimize(q, {1.5, -2, 3}), (V{1.5, -2, 3}));
  EXPECT_EQ(minimize(q, {1.5, -2, 3}, {0, 0, 0}, {1, 1, 1}), (V{1, 0, 1}));
  // Degenerate triangles add nothing.
  const double a[3] = {0, 0, 0}, b[3] = {1, 1, 1}, c[3] = {2, 2, 2};
  q.add_triangle(a, b, c);
  q.add_triangle(a, a, b);
  const double big0[3] = {1e300, 0, 0}, big1[3] = {0, 1e300, 0}, big2[3] = {0, 0, 1e300};
  q.add_triangle(big0, big1, big2);  // cross product overflows
  EXPECT_EQ(q.a00, 0.0);
  EXPECT_EQ(q.c, 0.0);
  EXPECT_EQ(minimize(q, {1.5, -2, 3}), (V{1.5, -2, 3}));
}

TEST(Quadric, NonFiniteQuadricGivesRefAndBadArgumentsThrow) {
  Quadric q;
  q.a00 = std::numeric_limits<double>::infinity();
  q.a11 = 1;
  EXPECT_EQ(minimize(q, {1, 2, 3}), (V{1, 2, 3}));
  q.a00 = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(minimize(q, {1, 2, 3}), (V{1, 2, 3}));
  Quadric ok;
  const V nan{std::numeric_limits<double>::quiet_NaN(), 0, 0};
  EXPECT_THROW(minimize(ok, nan), Failure);
  EXPECT_THROW(minimize(ok, {0, 0, 0}, {1, 0, 0}, {0, 1, 1}), Failure);
}

TEST(Quadric, ScaleFreeAndAddIsFieldwise) {
  // The same corner at tiny and huge scales (areas of 1e-20 and 1e20): the result scales with it.
  for (double s : {1e-10, 1e-3, 1.0, 1e4, 1e10}) {
    SCOPED_TRACE(s);
    const V corner{1 * s, 2 * s, 3 * s};
    const auto [e0, e1, e2] = frame(5);
    Quadric a, b;
    add_square(a, corner, e1, e2, s);
    add_square(a, corner, e0, e2, s);
    add_square(b, corner, e0, e1, s);
    Quadric sum = a;
    sum.add(b);
    EXPECT_EQ(sum.a00, a.a00 + b.a00);
    EXPECT_EQ(sum.c, a.c + b.c);
    const V lo{-1e12, -1e12, -1e12}, hi{1e12, 1e12, 1e12};
    expect_near(minimize(sum, {0, 0, 0}, lo, hi), corner, 1e-9 * s);
  }
}

TEST(Quadric, MinimizerBeatsRandomPointsOnRandomTriangles) {
  // Property: without clamping, no point does better than the minimizer (up to the dropped directions,
  // which can only cost a fraction relative_threshold of the curvature in them), and ref's own error is
  // never lower. Also: the result is the same bits on a second call.
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    Quadric q;
    const int count = 1 + trial % 6;
    for (int i = 0; i < count; ++i) {
      const V p0{u(rng), u(rng), u(rng)}, p1{u(rng), u(rng), u(rng)}, p2{u(rng), u(rng), u(rng)};
      q.add_triangle(p0.data(), p1.data(), p2.data());
    }
    const V ref{u(rng) * 0.1, u(rng) * 0.1, u(rng) * 0.1};
    const V x = minimize(q, ref);
    for (double c : x) ASSERT_TRUE(std::isfinite(c));
    EXPECT_EQ(minimize(q, ref), x);
    const double ex = q.error(x.data());
    EXPECT_LE(ex, q.error(ref.data()) + 1e-12);
    // The gradient at x lies in the dropped directions only, where it is at most
    // sqrt(λ_dropped · E(ref)) < sqrt(1e-3 · trace(A) · E(ref)) per direction: a step h can gain at most
    // twice |h| times that per dropped direction (at most two).
    const double slack = 4 * std::sqrt(1e-3 * (q.a00 + q.a11 + q.a22) * q.error(ref.data()));
    for (int k = 0; k < 20; ++k) {
      const V h{u(rng) * 1e-3, u(rng) * 1e-3, u(rng) * 1e-3};
      const V y = add(x, h);
      EXPECT_LE(ex, q.error(y.data()) + slack * std::sqrt(dot(h, h)) + 1e-12);
    }
  }
}

}  // namespace
}  // namespace lodstream

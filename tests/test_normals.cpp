// Crease-angle vertex normals (core/normals.h): exact small cases (two faces, the cube at both extremes of
// the crease, flat and tilted tessellated squares, a faceted cylinder), degenerate input, the cube-map
// fallback at a pathological vertex, and a brute-force reference of the per-corner definition on random
// meshes, with determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <span>
#include <vector>

#include "core/normals.h"
#include "core/status.h"

namespace lodstream {
namespace {

using core::CreaseNormals;
constexpr double kPi = std::numbers::pi;

struct Mesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
  uint32_t add(double x, double y, double z) {
    positions.insert(positions.end(), {x, y, z});
    return static_cast<uint32_t>(positions.size() / 3 - 1);
  }
  void tri(uint32_t a, uint32_t b, uint32_t c) { triangles.insert(triangles.end(), {a, b, c}); }
};

CreaseNormals run(const Mesh& m, double crease) {
  CreaseNormals out;
  core::crease_normals(m.positions, m.triangles, crease, out);
  return out;
}

std::array<float, 3> normal(const CreaseNormals& out, uint32_t o) {
  return {out.normals[3 * o], out.normals[3 * o + 1], out.normals[3 * o + 2]};
}

// Output invariants every result must satisfy.
void expect_well_formed(const Mesh& m, const CreaseNormals& out) {
  const size_t nv = out.vertex.size();
  ASSERT_EQ(out.normals.size(), 3 * nv);
  ASSERT_EQ(out.triangles.size(), m.triangles.size());
  for (size_t j = 0; j < m.triangles.size(); ++j) {
    ASSERT_LT(out.triangles[j], nv);
    EXPECT_EQ(out.vertex[out.triangles[j]], m.triangles[j]) << "corner " << j;
  }
  for (size_t o = 0; o < nv; ++o) {
    const auto n = normal(out, static_cast<uint32_t>(o));
    for (float x : n) ASSERT_TRUE(std::isfinite(x));
    const double len = std::sqrt(double{n[0]} * n[0] + double{n[1]} * n[1] + double{n[2]} * n[2]);
    EXPECT_NEAR(len, 1.0, 1e-6) << "output vertex " << o;
  }
  // Output vertices appear in order of first use, and two of the same input vertex never share bits.
  uint32_t next = 0;
  for (uint32_t id : out.triangles) {
    ASSERT_LE(id, next);
    if (id == next) ++next;
  }
  EXPECT_EQ(next, nv);
  for (size_t a = 0; a < nv; ++a) {
    for (size_t b = a + 1; b < nv && nv < 2000; ++b) {
      if (out.vertex[a] == out.vertex[b]) {
        EXPECT_NE(normal(out, static_cast<uint32_t>(a)), normal(out, static_cast<uint32_t>(b)));
      }
    }
  }
}

// Unit cube, vertex x + 2y + 4z at (x, y, z). Every face is split along the diagonal joining its two
// even-parity corners (x + y + z even), so each corner meets the same number of triangles (two at even
// corners, one at odd ones) on each of its three faces: area-weighted smooth normals are exactly diagonal.
Mesh cube() {
  Mesh m;
  for (int i = 0; i < 8; ++i) m.add(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  // Faces, counter-clockwise from outside.
  const uint32_t faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  auto even = [](uint32_t v) { return std::popcount(v) % 2 == 0; };
  for (const auto& f : faces) {
    const int s = even(f[0]) ? 0 : 1;
    const uint32_t a = f[s], b = f[(s + 1) % 4], c = f[(s + 2) % 4], d = f[(s + 3) % 4];
    m.tri(a, b, c);
    m.tri(a, c, d);
  }
  return m;
}

TEST(Normals, TwoFacesSplitOrShareInFirstAppearanceOrder) {
  // Two right triangles meeting at 90° along the edge 0–1: A = (0 1 2) faces +z, B = (0 3 1) faces +y.
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0), m.add(0, 0, 1);
  m.tri(0, 1, 2);
  m.tri(0, 3, 1);
  const CreaseNormals sharp = run(m, 30);
  EXPECT_EQ(sharp.vertex, (std::vector<uint32_t>{0, 1, 2, 0, 3, 1}));
  EXPECT_EQ(sharp.triangles, (std::vector<uint32_t>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(sharp.normals, (std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 1, 0}));
  expect_well_formed(m, sharp);

  // Above 90° the edge is smooth: both faces have the same area, so 0 and 1 get (0, 1, 1)/√2.
  const CreaseNormals smooth = run(m, 100);
  EXPECT_EQ(smooth.vertex, (std::vector<uint32_t>{0, 1, 2, 3}));
  EXPECT_EQ(smooth.triangles, (std::vector<uint32_t>{0, 1, 2, 0, 3, 1}));
  const float h = static_cast<float>(1 / std::sqrt(2.0));
  EXPECT_EQ(normal(smooth, 0), (std::array<float, 3>{0, h, h}));
  EXPECT_EQ(normal(smooth, 1), (std::array<float, 3>{0, h, h}));
  EXPECT_EQ(normal(smooth, 2), (std::array<float, 3>{0, 0, 1}));
  EXPECT_EQ(normal(smooth, 3), (std::array<float, 3>{0, 1, 0}));
  expect_well_formed(m, smooth);
}

TEST(Normals, CubeWithCreaseHas24VerticesWithAxisNormals) {
  const Mesh m = cube();
  for (double crease : {0.0, 1.0, 30.0, 89.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    ASSERT_EQ(out.vertex.size(), 24u);
    std::vector<int> uses(8, 0);
    for (uint32_t o = 0; o < 24; ++o) {
      const uint32_t v = out.vertex[o];
      ++uses[v];
      const auto n = normal(out, o);
      // Exactly one component is ±1, the others +0, and it points out of the cube at this corner.
      int axis = -1;
      for (int a = 0; a < 3; ++a) {
        if (n[a] != 0) {
          ASSERT_EQ(axis, -1);
          axis = a;
        } else {
          EXPECT_FALSE(std::signbit(n[a]));
        }
      }
      ASSERT_NE(axis, -1);
      const int coordinate = (v >> axis) & 1;
      EXPECT_EQ(n[axis], coordinate ? 1.0f : -1.0f);
    }
    EXPECT_EQ(uses, std::vector<int>(8, 3));
    // Every triangle's three corners carry its face normal.
    for (size_t t = 0; t < 12; ++t)
      for (int k = 1; k < 3; ++k)
        EXPECT_EQ(normal(out, out.triangles[3 * t]), normal(out, out.triangles[3 * t + k]));
  }
}

TEST(Normals, SmoothCubeHas8VerticesWithDiagonalNormals) {
  const Mesh m = cube();
  for (double crease : {91.0, 180.0, 360.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    ASSERT_EQ(out.vertex.size(), 8u);
    const float d = static_cast<float>(1 / std::sqrt(3.0));
    for (uint32_t o = 0; o < 8; ++o) {
      const uint32_t v = out.vertex[o];
      const auto n = normal(out, o);
      for (int a = 0; a < 3; ++a) EXPECT_EQ(n[a], ((v >> a) & 1) ? d : -d) << "vertex " << v << " axis " << a;
    }
  }
}

// An n × n grid of squares over [0, 1]², each split in two, with interior points jittered in the plane.
Mesh flat_grid(int n, uint32_t seed) {
  Mesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.3 / n, 0.3 / n);
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      const bool interior = i > 0 && i < n && j > 0 && j < n;
      m.add(double(i) / n + (interior ? jitter(rng) : 0), double(j) / n + (interior ? jitter(rng) : 0), 0);
    }
  }
  auto id = [n](int i, int j) { return static_cast<uint32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      if ((i + j) % 2 == 0) {
        m.tri(id(i, j), id(i + 1, j), id(i + 1, j + 1));
        m.tri(id(i, j), id(i + 1, j + 1), id(i, j + 1));
      } else {
        m.tri(id(i, j), id(i + 1, j), id(i, j + 1));
        m.tri(id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
      }
    }
  }
  return m;
}

TEST(Normals, FlatTessellatedSquareKeepsExactlyOneNormal) {
  const Mesh m = flat_grid(24, 7);
  for (double crease : {0.0, 30.0, 180.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    ASSERT_EQ(out.vertex.size(), 25u * 25u);
    for (uint32_t o = 0; o < out.vertex.size(); ++o)
      ASSERT_EQ(normal(out, o), (std::array<float, 3>{0, 0, 1})) << "output vertex " << o;
  }
}

TEST(Normals, TiltedFlatSquareStaysFlat) {
  // The same grid rotated off the axes: its unit face normals differ in the last bits, but all are within
  // any positive crease of one another, so every corner of a vertex includes the same faces.
  Mesh m = flat_grid(24, 11);
  const double a = 0.7, b = 0.4;  // rotation about x by a, then about z by b
  for (size_t v = 0; v < m.positions.size(); v += 3) {
    const double x = m.positions[v], y = m.positions[v + 1], z = m.positions[v + 2];
    const double y1 = std::cos(a) * y - std::sin(a) * z, z1 = std::sin(a) * y + std::cos(a) * z;
    m.positions[v] = std::cos(b) * x - std::sin(b) * y1 + 100;
    m.positions[v + 1] = std::sin(b) * x + std::cos(b) * y1 - 50;
    m.positions[v + 2] = z1 + 3;
  }
  const double expected[3] = {std::sin(b) * std::sin(a), -std::cos(b) * std::sin(a), std::cos(a)};
  for (double crease : {0.01, 30.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    ASSERT_EQ(out.vertex.size(), 25u * 25u);
    for (uint32_t o = 0; o < out.vertex.size(); ++o) {
      const auto n = normal(out, o);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(n[k], expected[k], 1e-6);
    }
  }
}

// A closed cylinder of radius 1 and height 2 with `segments` flat facets: rim vertices b_i (z = 0) and t_i
// (z = 2), then the two cap centers; the caps are fans.
Mesh cylinder(int segments) {
  Mesh m;
  for (int k = 0; k < 2; ++k)
    for (int i = 0; i < segments; ++i) {
      const double a = 2 * kPi * i / segments;
      m.add(std::cos(a), std::sin(a), 2.0 * k);
    }
  const uint32_t cb = m.add(0, 0, 0), ct = m.add(0, 0, 2);
  const uint32_t n = static_cast<uint32_t>(segments);
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t j = (i + 1) % n;
    m.tri(i, j, n + j);
    m.tri(i, n + j, n + i);
    m.tri(cb, j, i);
    m.tri(ct, n + i, n + j);
  }
  return m;
}

TEST(Normals, CylinderSidesAreSmoothAndCapsFlat) {
  const int n = 32;  // facets 11.25° apart
  const Mesh m = cylinder(n);
  const CreaseNormals out = run(m, 30);
  expect_well_formed(m, out);
  // Each rim vertex: one smooth side normal and one cap normal; each center: one.
  ASSERT_EQ(out.vertex.size(), size_t(4 * n + 2));
  for (uint32_t o = 0; o < out.vertex.size(); ++o) {
    const uint32_t v = out.vertex[o];
    const auto nn = normal(out, o);
    const double a = 2 * kPi * (v % n) / n;
    if (nn[2] != 0) {
      // A cap normal: exactly ±z.
      EXPECT_EQ(nn, (std::array<float, 3>{0, 0, m.positions[3 * v + 2] == 0 ? -1.0f : 1.0f}));
    } else {
      // A side normal: horizontal (the side faces' normals have z exactly 0), between the normals of the
      // two facets at the vertex, i.e. within half a facet of the radial direction.
      ASSERT_LT(v, uint32_t(2 * n));
      EXPECT_GE(nn[0] * std::cos(a) + nn[1] * std::sin(a), std::cos(kPi / n) - 1e-6);
    }
  }
  // Below the facet angle the sides are faceted too: two side normals per rim vertex.
  const CreaseNormals faceted = run(m, 5);
  expect_well_formed(m, faceted);
  EXPECT_EQ(faceted.vertex.size(), size_t(6 * n + 2));
}

TEST(Normals, DegenerateTrianglesNeverGiveNaN) {
  // A unit square in the xz plane facing −y, plus: a zero-area sliver along its bottom side through a new
  // vertex 4 (used by nothing else), and a triangle with a repeated id.
  Mesh m;
  m.add(0, 0, 0), m.add(0, 0, 1), m.add(1, 0, 1), m.add(1, 0, 0);
  m.add(0.5, 0, 0);
  m.tri(0, 2, 1);
  m.tri(0, 3, 2);
  m.tri(0, 4, 3);
  m.tri(2, 2, 3);
  for (double crease : {0.0, 30.0, 180.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    const std::array<float, 3> face{0, -1, 0}, up{0, 0, 1};
    for (size_t j = 0; j < m.triangles.size(); ++j) {
      const auto n = normal(out, out.triangles[j]);
      // Corners at vertex 4 meet only the sliver: (0, 0, 1). Every other corner, degenerate or not, sees
      // the square's faces.
      EXPECT_EQ(n, m.triangles[j] == 4 ? up : face) << "corner " << j;
    }
    EXPECT_EQ(out.vertex.size(), 5u);
  }
}

TEST(Normals, AllDegenerateAndOverflowingInput) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 1, 1), m.add(2, 2, 2);              // collinear
  m.add(1e200, 0, 0), m.add(0, 1e200, 0), m.add(0, 0, 1e200);  // the cross product overflows
  m.tri(0, 1, 2);
  m.tri(0, 0, 0);
  m.tri(3, 4, 5);
  const CreaseNormals out = run(m, 30);
  expect_well_formed(m, out);
  for (uint32_t o = 0; o < out.vertex.size(); ++o) EXPECT_EQ(normal(out, o), (std::array<float, 3>{0, 0, 1}));
  EXPECT_EQ(out.vertex.size(), 6u);
}

TEST(Normals, OppositeFacesThatCancelKeepTheirOwnNormals) {
  // A two-sided triangle: the same corners in both windings. Smoothed together the sum is exactly zero, so
  // each corner falls back to its own face's normal.
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0);
  m.tri(0, 1, 2);
  m.tri(0, 2, 1);
  const CreaseNormals out = run(m, 180);
  expect_well_formed(m, out);
  ASSERT_EQ(out.vertex.size(), 6u);
  for (uint32_t o = 0; o < 6; ++o)
    EXPECT_EQ(normal(out, o), (std::array<float, 3>{0, 0, o < 3 ? 1.0f : -1.0f}));
}

TEST(Normals, EmptyAndUnusedVertices) {
  Mesh m;
  m.add(5, 5, 5);  // unused
  CreaseNormals out;
  out.vertex = {9};
  core::crease_normals(m.positions, m.triangles, 30, out);
  EXPECT_TRUE(out.vertex.empty() && out.normals.empty() && out.triangles.empty());
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0);
  m.tri(1, 2, 3);
  out = run(m, 30);
  EXPECT_EQ(out.vertex, (std::vector<uint32_t>{1, 2, 3}));
}

TEST(Normals, BadInputThrows) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0);
  m.tri(0, 1, 3);
  CreaseNormals out;
  EXPECT_THROW(core::crease_normals(m.positions, m.triangles, 30, out), Failure);
  m.triangles = {0, 1};
  EXPECT_THROW(core::crease_normals(m.positions, m.triangles, 30, out), Failure);
  m.triangles = {0, 1, 2};
  try {
    core::crease_normals(m.positions, m.triangles, std::numeric_limits<double>::quiet_NaN(), out);
    ADD_FAILURE() << "NaN crease accepted";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::usage);
  }
}

TEST(Normals, FlatFanOfHighValenceStaysExact) {
  // A fan-triangulated disk, as a CAD cap polygon becomes: valence 20000 at the center, one direction.
  Mesh m;
  const int n = 20000;
  const uint32_t c = m.add(0, 0, 0);
  for (int i = 0; i < n; ++i) m.add(std::cos(2 * kPi * i / n), std::sin(2 * kPi * i / n), 0);
  for (int i = 0; i < n; ++i) m.tri(c, 1 + i, 1 + (i + 1) % n);
  const CreaseNormals out = run(m, 30);
  ASSERT_EQ(out.vertex.size(), size_t(n + 1));
  for (uint32_t o = 0; o < out.vertex.size(); ++o) ASSERT_EQ(normal(out, o), (std::array<float, 3>{0, 0, 1}));
}

// The definition of normals.h evaluated literally: per corner, the sum over every triangle incident on the
// vertex, in increasing index, of those within the crease (angle by atan2).
std::vector<std::array<double, 3>> reference(const Mesh& m, double crease) {
  const size_t nt = m.triangles.size() / 3;
  std::vector<std::array<double, 3>> c(nt), u(nt);
  std::vector<bool> ok(nt);
  for (size_t t = 0; t < nt; ++t) {
    const double* p[3];
    for (int k = 0; k < 3; ++k) p[k] = &m.positions[3 * m.triangles[3 * t + k]];
    const double e1[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double e2[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    c[t] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    const double len = std::hypot(c[t][0], c[t][1], c[t][2]);
    ok[t] = len > 0;
    if (ok[t]) u[t] = {c[t][0] / len, c[t][1] / len, c[t][2] / len};
  }
  const double radians = crease * kPi / 180;
  std::vector<std::vector<uint32_t>> incident(m.positions.size() / 3);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      auto& list = incident[m.triangles[3 * t + k]];
      if (list.empty() || list.back() != t) list.push_back(static_cast<uint32_t>(t));
    }
  std::vector<std::array<double, 3>> corners(3 * nt);
  for (size_t j = 0; j < 3 * nt; ++j) {
    const size_t t = j / 3;
    std::array<double, 3> sum{0, 0, 0};
    for (uint32_t s : incident[m.triangles[j]]) {
      if (!ok[s]) continue;
      bool in = !ok[t] || s == t || crease >= 180;
      if (!in) {
        const auto& a = u[t];
        const auto& b = u[s];
        const double cr =
            std::hypot(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]);
        in = std::atan2(cr, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) <= radians;
      }
      if (in)
        for (int k = 0; k < 3; ++k) sum[k] += c[s][k];
    }
    const double len = std::hypot(sum[0], sum[1], sum[2]);
    corners[j] = {sum[0] / len, sum[1] / len, sum[2] / len};
  }
  return corners;
}

// A bumpy closed surface: a sphere-like lat-long grid with noisy radius, plus some flat patches (shared
// planes) so that vertices see both repeated and distinct face directions.
Mesh bumpy(int rings, int segments, uint32_t seed) {
  Mesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> noise(0.9, 1.1);
  const uint32_t south = m.add(0, 0, -1);
  for (int r = 1; r < rings; ++r) {
    const double phi = kPi * r / rings - kPi / 2;
    for (int s = 0; s < segments; ++s) {
      const double th = 2 * kPi * s / segments;
      const double rad = (r % 3 == 0) ? 1.0 : noise(rng);
      m.add(rad * std::cos(phi) * std::cos(th), rad * std::cos(phi) * std::sin(th),
            r % 3 == 0 ? std::sin(phi) : rad * std::sin(phi));
    }
  }
  const uint32_t north = m.add(0, 0, 1);
  auto id = [segments](int r, int s) {
    return static_cast<uint32_t>(1 + (r - 1) * segments + (s % segments));
  };
  for (int s = 0; s < segments; ++s) m.tri(south, id(1, s + 1), id(1, s));
  for (int r = 1; r + 1 < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      m.tri(id(r, s), id(r, s + 1), id(r + 1, s + 1));
      m.tri(id(r, s), id(r + 1, s + 1), id(r + 1, s));
    }
  for (int s = 0; s < segments; ++s) m.tri(north, id(rings - 1, s), id(rings - 1, s + 1));
  return m;
}

TEST(Normals, MatchesLiteralDefinitionAndIsDeterministic) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    const Mesh m = bumpy(12, 17, seed);
    for (double crease : {0.0, 20.0, 45.0, 180.0}) {
      SCOPED_TRACE(::testing::Message() << "seed " << seed << " crease " << crease);
      const CreaseNormals out = run(m, crease);
      expect_well_formed(m, out);
      const auto ref = reference(m, crease);
      for (size_t j = 0; j < m.triangles.size(); ++j) {
        const auto n = normal(out, out.triangles[j]);
        for (int k = 0; k < 3; ++k) ASSERT_NEAR(n[k], ref[j][k], 1e-6) << "corner " << j;
      }
      const CreaseNormals again = run(m, crease);
      EXPECT_EQ(again.vertex, out.vertex);
      EXPECT_EQ(again.triangles, out.triangles);
      ASSERT_EQ(again.normals.size(), out.normals.size());
      for (size_t i = 0; i < out.normals.size(); ++i)
        ASSERT_EQ(std::bit_cast<uint32_t>(again.normals[i]), std::bit_cast<uint32_t>(out.normals[i]));
    }
  }
}

TEST(Normals, PathologicalValenceUsesTheCubeMapFallback) {
  // A cone whose apex meets 1500 facets, all in distinct directions (> kMaxPairwiseDirections): the
  // apex's crease is decided on cube-map bins, so it is approximate, but still finite, unit, and close to
  // the literal definition (within a bin or so: a few degrees).
  Mesh m;
  const int n = 1500;
  static_assert(n > core::kMaxPairwiseDirections);
  const uint32_t apex = m.add(0, 0, 1);
  for (int i = 0; i < n; ++i) m.add(std::cos(2 * kPi * i / n), std::sin(2 * kPi * i / n), 0);
  for (int i = 0; i < n; ++i) m.tri(apex, 1 + i, 1 + (i + 1) % n);
  for (double crease : {0.0, 30.0, 120.0}) {
    SCOPED_TRACE(crease);
    const CreaseNormals out = run(m, crease);
    expect_well_formed(m, out);
    const auto ref = reference(m, crease);
    for (size_t j = 0; j < m.triangles.size(); j += 3) {
      const auto nn = normal(out, out.triangles[j]);
      const double dot = nn[0] * ref[j][0] + nn[1] * ref[j][1] + nn[2] * ref[j][2];
      EXPECT_GT(dot, std::cos(10 * kPi / 180)) << "apex corner of triangle " << j / 3;
    }
    size_t apex_vertices = 0;
    for (uint32_t v : out.vertex) apex_vertices += v == apex;
    EXPECT_LE(apex_vertices, 6u * 16u * 16u);
  }
}

}  // namespace
}  // namespace lodstream

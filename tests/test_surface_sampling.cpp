// Metro-style surface sampling (core/surface_sampling.h): exact sample counts for every kind of mesh
// (triangles, segments, zero-area and zero-length elements, no vertices), every sample on the mesh (vertex
// samples bit-exact vertices), determinism in the seed and stream, uniformity in area (triangles of areas
// 1 and 3) and in length (the sides 3, 4, 5 of a right triangle), selection sampling of exactly n distinct
// vertices in visiting order, and the generator underneath (mix64, uniform01, sorted_uniform_positions).
#include <gtest/gtest.h>

#include "ref_geometry.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "core/surface_sampling.h"

namespace lodstream {
namespace {

using core::SurfaceSampler;

// ---------------------------------------------------------------------------------------------------------
// Meshes and the two passes

struct Mesh {
  std::vector<float> xyz;
  std::vector<uint32_t> triangles, segments;
  uint32_t add(double x, double y, double z) {
    xyz.insert(xyz.end(), {float(x), float(y), float(z)});
    return static_cast<uint32_t>(xyz.size() / 3 - 1);
  }
  const float* at(uint32_t i) const { return xyz.data() + 3 * static_cast<size_t>(i); }
  uint32_t vertex_count() const { return static_cast<uint32_t>(xyz.size() / 3); }
};

struct Samples {
  std::vector<float> faces, edges, vertices;
  uint64_t face_count = 0, edge_count = 0, vertex_count = 0;
  double area = 0, length = 0;
};

// Pass 1 and pass 2 in the same order: triangles, segments, then every vertex.
Samples sample(const Mesh& m, uint64_t n, uint64_t seed, uint64_t stream = 0) {
  SurfaceSampler s(n, seed, stream);
  for (size_t t = 0; t < m.triangles.size(); t += 3)
    s.measure_triangle(m.at(m.triangles[t]), m.at(m.triangles[t + 1]), m.at(m.triangles[t + 2]));
  for (size_t e = 0; e < m.segments.size(); e += 2) s.measure_segment(m.at(m.segments[e]), m.at(m.segments[e + 1]));
  for (uint32_t v = 0; v < m.vertex_count(); ++v) s.measure_vertex();
  s.begin_sampling();
  Samples out;
  for (size_t t = 0; t < m.triangles.size(); t += 3)
    s.sample_triangle(m.at(m.triangles[t]), m.at(m.triangles[t + 1]), m.at(m.triangles[t + 2]), out.faces, out.edges);
  for (size_t e = 0; e < m.segments.size(); e += 2)
    s.sample_segment(m.at(m.segments[e]), m.at(m.segments[e + 1]), out.edges);
  for (uint32_t v = 0; v < m.vertex_count(); ++v) s.sample_vertex(m.at(v), out.vertices);
  out.face_count = s.face_samples();
  out.edge_count = s.edge_samples();
  out.vertex_count = s.vertex_samples();
  out.area = s.area();
  out.length = s.length();
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// An independent closest-point reference, in double.

using namespace lodstream::test;  // V3 and its operations (ref_geometry.h)

double segment_distance(V3 p, V3 a, V3 b) {
  const V3 d = b - a;
  const double len2 = dot(d, d);
  const double t = len2 > 0 ? std::clamp(dot(p - a, d) / len2, 0.0, 1.0) : 0.0;
  return norm(p - (a + d * t));
}

double triangle_distance(V3 p, V3 a, V3 b, V3 c) {
  const V3 n = cross(b - a, c - a);
  const double n2 = dot(n, n);
  if (n2 > 0) {
    const V3 q = p - n * (dot(p - a, n) / n2);
    if (dot(cross(c - b, q - b), n) >= 0 && dot(cross(a - c, q - c), n) >= 0 && dot(cross(b - a, q - a), n) >= 0)
      return norm(p - q);
  }
  return std::min({segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
}

// ---------------------------------------------------------------------------------------------------------
// The generator

TEST(SplitMix, Mix64IsSplitMix64) {
  // SplitMix64 seeded with 0: its first two outputs are mix64(0) and mix64(0x9E3779B97F4A7C15).
  EXPECT_EQ(core::mix64(0), 0xE220A8397B1DCDAFull);
  EXPECT_EQ(core::mix64(0x9E3779B97F4A7C15ull), 0x6E789E6AA1B965F4ull);
  // Bijective: no collisions among many inputs.
  std::set<uint64_t> seen;
  for (uint64_t i = 0; i < 10000; ++i) seen.insert(core::mix64(i));
  EXPECT_EQ(seen.size(), 10000u);
}

TEST(SplitMix, Uniform01IsInTheHalfOpenUnitIntervalAndUniform) {
  double sum = 0, lo = 1, hi = 0;
  std::array<int, 10> deciles{};
  constexpr int kDraws = 200000;
  for (int i = 0; i < kDraws; ++i) {
    const double u = core::uniform01(42, 7, i);
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    lo = std::min(lo, u), hi = std::max(hi, u);
    sum += u;
    ++deciles[static_cast<int>(u * 10)];
  }
  EXPECT_NEAR(sum / kDraws, 0.5, 0.005);
  for (int d : deciles) EXPECT_NEAR(d, kDraws / 10, 0.05 * kDraws / 10);
  EXPECT_LT(lo, 1e-4);
  EXPECT_GT(hi, 1 - 1e-4);
  // Seed, stream and index each change the value.
  EXPECT_NE(core::uniform01(1, 2, 3), core::uniform01(2, 2, 3));
  EXPECT_NE(core::uniform01(1, 2, 3), core::uniform01(1, 3, 3));
  EXPECT_NE(core::uniform01(1, 2, 3), core::uniform01(1, 2, 4));
  EXPECT_EQ(core::uniform01(1, 2, 3), core::uniform01(1, 2, 3));
}

TEST(SortedUniformPositions, SortedInRangeAndUniform) {
  const std::vector<double> pos = core::sorted_uniform_positions(100000, 3.0, 11, 5);
  ASSERT_EQ(pos.size(), 100000u);
  EXPECT_TRUE(std::is_sorted(pos.begin(), pos.end()));
  EXPECT_GE(pos.front(), 0.0);
  EXPECT_LT(pos.back(), 3.0);
  double sum = 0;
  for (double p : pos) sum += p;
  EXPECT_NEAR(sum / pos.size(), 1.5, 0.015);
  // The median of 100000 uniform draws on [0, 3) is 1.5 within a few thousandths.
  EXPECT_NEAR(pos[50000], 1.5, 0.02);
  // Deterministic, and the same values as the unsorted draws.
  EXPECT_EQ(core::sorted_uniform_positions(100000, 3.0, 11, 5), pos);
  std::vector<double> raw(100000);
  for (uint64_t i = 0; i < raw.size(); ++i) raw[i] = core::uniform01(11, 5, i) * 3.0;
  std::sort(raw.begin(), raw.end());
  EXPECT_EQ(raw, pos);
}

TEST(SortedUniformPositions, EdgeCases) {
  EXPECT_TRUE(core::sorted_uniform_positions(10, 0.0, 1, 1).empty());
  EXPECT_TRUE(core::sorted_uniform_positions(10, -1.0, 1, 1).empty());
  EXPECT_TRUE(core::sorted_uniform_positions(10, std::numeric_limits<double>::quiet_NaN(), 1, 1).empty());
  EXPECT_TRUE(core::sorted_uniform_positions(0, 5.0, 1, 1).empty());
  // The smallest positive total: every position is 0, still < total.
  const double tiny = std::numeric_limits<double>::denorm_min();
  for (double p : core::sorted_uniform_positions(1000, tiny, 1, 1)) {
    ASSERT_GE(p, 0.0);
    ASSERT_LT(p, tiny);
  }
  // A total whose products with draws close to 1 round up to it: still strictly below.
  for (double total : {1.0, 0.1, 1e300, 3.0000000000000004}) {
    for (double p : core::sorted_uniform_positions(20000, total, 99, 3)) ASSERT_LT(p, total) << total;
  }
}

// ---------------------------------------------------------------------------------------------------------
// Counts

// The unit square as two triangles, plus a segment sticking out of a corner, 5 vertices:
//
//   3-----2
//   |   / |
//   | /   |
//   0-----1-----4
TEST(SurfaceSampler, CountsOnTrianglesAndSegments) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(1, 1, 0), m.add(0, 1, 0), m.add(2, 0, 0);
  m.triangles = {0, 1, 2, 0, 2, 3};
  m.segments = {1, 4};
  const Samples s = sample(m, 1000, 1);
  EXPECT_DOUBLE_EQ(s.area, 1.0);
  EXPECT_DOUBLE_EQ(s.length, 2 * (2 + std::sqrt(2.0)) + 1);  // sides counted per triangle, plus the segment
  EXPECT_EQ(s.face_count, 1000u);
  EXPECT_EQ(s.edge_count, 1000u);
  EXPECT_EQ(s.vertex_count, 5u);
  EXPECT_EQ(s.faces.size(), 3000u);
  EXPECT_EQ(s.edges.size(), 3000u);
  EXPECT_EQ(s.vertices, m.xyz);  // every vertex, in order
  // Fewer samples than vertices: exactly n of each kind.
  const Samples few = sample(m, 3, 1);
  EXPECT_EQ(few.face_count, 3u);
  EXPECT_EQ(few.edge_count, 3u);
  EXPECT_EQ(few.vertex_count, 3u);
  EXPECT_EQ(few.faces.size(), 9u);
  EXPECT_EQ(few.edges.size(), 9u);
  EXPECT_EQ(few.vertices.size(), 9u);
  // n = 0: nothing at all.
  const Samples none = sample(m, 0, 1);
  EXPECT_EQ(none.face_count + none.edge_count + none.vertex_count, 0u);
  EXPECT_TRUE(none.faces.empty() && none.edges.empty() && none.vertices.empty());
}

TEST(SurfaceSampler, SegmentsOnlyHaveNoFaceSamples) {
  Mesh m;
  m.add(0, 0, 0), m.add(3, 0, 0), m.add(3, 4, 0);
  m.segments = {0, 1, 1, 2};
  const Samples s = sample(m, 500, 9);
  EXPECT_EQ(s.area, 0.0);
  EXPECT_EQ(s.length, 7.0);
  EXPECT_EQ(s.face_count, 0u);
  EXPECT_TRUE(s.faces.empty());
  EXPECT_EQ(s.edge_count, 500u);
  EXPECT_EQ(s.edges.size(), 1500u);
  EXPECT_EQ(s.vertex_count, 3u);
}

// Zero-area triangles (collinear corners, or two corners at one point) still have sides to sample.
TEST(SurfaceSampler, ZeroAreaTrianglesHaveEdgeSamplesOnly) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(3, 0, 0), m.add(0, 0, 5);
  m.triangles = {0, 1, 2, 3, 3, 0};
  const Samples s = sample(m, 400, 2);
  EXPECT_EQ(s.area, 0.0);
  EXPECT_EQ(s.length, 6.0 + 10.0);
  EXPECT_EQ(s.face_count, 0u);
  EXPECT_TRUE(s.faces.empty());
  EXPECT_EQ(s.edge_count, 400u);
  for (size_t i = 0; i < s.edges.size(); i += 3) {
    const bool on_x = s.edges[i + 1] == 0 && s.edges[i + 2] == 0 && s.edges[i] >= 0 && s.edges[i] <= 3;
    const bool on_z = s.edges[i] == 0 && s.edges[i + 1] == 0 && s.edges[i + 2] >= 0 && s.edges[i + 2] <= 5;
    EXPECT_TRUE(on_x || on_z) << s.edges[i] << " " << s.edges[i + 1] << " " << s.edges[i + 2];
  }
}

// A triangle collapsed to one point and a zero-length segment: no length, no area, only vertex samples.
TEST(SurfaceSampler, CollapsedElementsHaveVertexSamplesOnly) {
  Mesh m;
  m.add(1, 2, 3), m.add(1, 2, 3);
  m.triangles = {0, 0, 1};
  m.segments = {0, 1};
  const Samples s = sample(m, 10, 3);
  EXPECT_EQ(s.area, 0.0);
  EXPECT_EQ(s.length, 0.0);
  EXPECT_EQ(s.face_count, 0u);
  EXPECT_EQ(s.edge_count, 0u);
  EXPECT_TRUE(s.faces.empty() && s.edges.empty());
  EXPECT_EQ(s.vertex_count, 2u);
  EXPECT_EQ(s.vertices, m.xyz);
}

// `count` triangles of areas from 1e-6 to 1e4 and sides likewise, in random places and order, and a segment
// on every `segment_every`-th of them.
Mesh random_sized_mesh(unsigned seed, int count, int segment_every) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Mesh m;
  for (int t = 0; t < count; ++t) {
    const double s = std::pow(10.0, -3 + 5 * u(rng));
    const double x = 100 * u(rng), y = 100 * u(rng), z = 100 * u(rng);
    const uint32_t a = m.add(x, y, z);
    m.add(x + s * u(rng), y + s * u(rng), z);
    m.add(x + s * u(rng), y, z + s * u(rng));
    m.triangles.insert(m.triangles.end(), {a, a + 1, a + 2});
    if (t % segment_every == 0) m.segments.insert(m.segments.end(), {a, a + 2});
  }
  return m;
}

// 2000 random triangles of every size: every one of the n drawn positions is reached (the invariant of the
// sampling pass), for many seeds.
TEST(SurfaceSampler, EveryPositionIsReachedWhateverTheSizes) {
  const Mesh m = random_sized_mesh(5, 2000, 3);
  for (uint64_t seed = 0; seed < 20; ++seed) {
    const Samples s = sample(m, 7777, seed, seed * 3);
    ASSERT_EQ(s.face_count, 7777u) << seed;
    ASSERT_EQ(s.edge_count, 7777u) << seed;
    ASSERT_EQ(s.vertex_count, 6000u) << seed;  // fewer vertices than n: all of them
    ASSERT_EQ(s.faces.size(), 3u * 7777);
    ASSERT_EQ(s.edges.size(), 3u * 7777);
  }
}

// ---------------------------------------------------------------------------------------------------------
// Samples lie on the mesh

TEST(SurfaceSampler, EverySampleLiesOnTheMesh) {
  const double scale = 10;
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-scale, scale), small(-2, 2);
  Mesh m;
  for (int t = 0; t < 150; ++t) {
    const uint32_t a = m.add(u(rng), u(rng), u(rng));
    m.add(m.at(a)[0] + small(rng), m.at(a)[1] + small(rng), m.at(a)[2] + small(rng));
    m.add(m.at(a)[0] + small(rng), m.at(a)[1] + small(rng), m.at(a)[2] + small(rng));
    m.triangles.insert(m.triangles.end(), {a, a + 1, a + 2});
  }
  for (int e = 0; e < 50; ++e) {
    const uint32_t a = m.add(u(rng), u(rng), u(rng));
    const uint32_t b = m.add(m.at(a)[0] + small(rng), m.at(a)[1] + small(rng), m.at(a)[2] + small(rng));
    m.segments.insert(m.segments.end(), {a, b});
  }
  const uint64_t n = 5000;
  const Samples s = sample(m, n, 123, 4);
  ASSERT_EQ(s.faces.size(), 3 * n);
  ASSERT_EQ(s.edges.size(), 3 * n);
  ASSERT_EQ(s.vertices.size(), 3 * 550u);  // 550 vertices < n: all of them
  const double tolerance = 1e-6 * scale;
  double worst_face = 0, worst_edge = 0;
  for (size_t i = 0; i < s.faces.size(); i += 3) {
    const V3 p = v3(s.faces.data() + i);
    double best = std::numeric_limits<double>::infinity();
    for (size_t t = 0; t < m.triangles.size(); t += 3)
      best = std::min(best, triangle_distance(p, v3(m.at(m.triangles[t])), v3(m.at(m.triangles[t + 1])),
                                              v3(m.at(m.triangles[t + 2]))));
    worst_face = std::max(worst_face, best);
  }
  for (size_t i = 0; i < s.edges.size(); i += 3) {
    const V3 p = v3(s.edges.data() + i);
    double best = std::numeric_limits<double>::infinity();
    for (size_t t = 0; t < m.triangles.size(); t += 3) {
      const V3 a = v3(m.at(m.triangles[t])), b = v3(m.at(m.triangles[t + 1])), c = v3(m.at(m.triangles[t + 2]));
      best = std::min({best, segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
    }
    for (size_t e = 0; e < m.segments.size(); e += 2)
      best = std::min(best, segment_distance(p, v3(m.at(m.segments[e])), v3(m.at(m.segments[e + 1]))));
    worst_edge = std::max(worst_edge, best);
  }
  EXPECT_LT(worst_face, tolerance);
  EXPECT_LT(worst_edge, tolerance);  // on a side or a segment, not merely on a face
  EXPECT_EQ(s.vertices, m.xyz);
}

// ---------------------------------------------------------------------------------------------------------
// Determinism

TEST(SurfaceSampler, SameSeedSameSamplesOtherSeedOrStreamOtherSamples) {
  Mesh m;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 300; ++i) m.add(u(rng), u(rng), u(rng));
  for (uint32_t t = 0; t + 2 < 300; t += 3) m.triangles.insert(m.triangles.end(), {t, t + 1, t + 2});
  m.segments = {0, 5, 7, 11};
  const Samples a = sample(m, 200, 10, 1), again = sample(m, 200, 10, 1);
  EXPECT_EQ(a.faces, again.faces);
  EXPECT_EQ(a.edges, again.edges);
  EXPECT_EQ(a.vertices, again.vertices);
  for (const Samples& other : {sample(m, 200, 11, 1), sample(m, 200, 10, 2)}) {
    EXPECT_NE(a.faces, other.faces);
    EXPECT_NE(a.edges, other.edges);
    EXPECT_NE(a.vertices, other.vertices);
    EXPECT_EQ(other.face_count, 200u);
    EXPECT_EQ(other.vertex_count, 200u);
  }
}

// ---------------------------------------------------------------------------------------------------------
// Uniformity

// Triangle A of area 1 at x ∈ [0, 2], triangle B of area 3 at x ∈ [10, 13]: 25 % and 75 % of the face
// samples (a binomial's standard deviation is 137 samples here, the tolerance 1000).
TEST(SurfaceSampler, FaceSamplesAreUniformInArea) {
  Mesh m;
  m.add(0, 0, 0), m.add(2, 0, 0), m.add(0, 1, 0);     // area 1
  m.add(10, 0, 0), m.add(13, 0, 0), m.add(10, 2, 0);  // area 3
  m.triangles = {0, 1, 2, 3, 4, 5};
  constexpr uint64_t n = 100000;
  const Samples s = sample(m, n, 2024, 8);
  EXPECT_DOUBLE_EQ(s.area, 4.0);
  ASSERT_EQ(s.face_count, n);
  uint64_t in_a = 0;
  for (size_t i = 0; i < s.faces.size(); i += 3) in_a += s.faces[i] < 5;
  EXPECT_NEAR(static_cast<double>(in_a), 0.25 * n, 0.01 * n);
  // Uniform inside a triangle too: the part of A with x ≥ 1 is the triangle (1,0) (2,0) (1,1/2), similar to
  // A at half the size, so a quarter of A's samples.
  uint64_t a_right_half = 0;
  double ax = 0, ay = 0;
  for (size_t i = 0; i < s.faces.size(); i += 3) {
    if (s.faces[i] >= 5) continue;
    a_right_half += s.faces[i] >= 1;
    ax += s.faces[i], ay += s.faces[i + 1];
  }
  EXPECT_NEAR(static_cast<double>(a_right_half) / in_a, 0.25, 0.01);
  EXPECT_NEAR(ax / in_a, 2.0 / 3, 0.01);  // the centroid (2/3, 1/3)
  EXPECT_NEAR(ay / in_a, 1.0 / 3, 0.01);
}

// Edge samples on the right triangle (0,0) (3,0) (3,4): sides of lengths 3 (y = 0), 4 (x = 3) and 5 (the
// hypotenuse) get 3/12, 4/12 and 5/12 of the samples, each spread uniformly along its side.
TEST(SurfaceSampler, EdgeSamplesAreUniformInLength) {
  Mesh m;
  m.add(0, 0, 0), m.add(3, 0, 0), m.add(3, 4, 0);
  m.triangles = {0, 1, 2};
  constexpr uint64_t n = 100000;
  const Samples s = sample(m, n, 77, 0);
  EXPECT_EQ(s.length, 12.0);
  ASSERT_EQ(s.edge_count, n);
  std::array<uint64_t, 3> count{};
  std::array<double, 3> along{};  // mean position along each side, as a fraction of it
  for (size_t i = 0; i < s.edges.size(); i += 3) {
    const V3 p = v3(s.edges.data() + i);
    const double d[3] = {segment_distance(p, {0, 0, 0}, {3, 0, 0}), segment_distance(p, {3, 0, 0}, {3, 4, 0}),
                         segment_distance(p, {3, 4, 0}, {0, 0, 0})};
    const int side = static_cast<int>(std::min_element(d, d + 3) - d);
    ASSERT_LT(d[side], 1e-6) << p[0] << " " << p[1];
    ++count[side];
    along[side] += side == 0 ? p[0] / 3 : side == 1 ? p[1] / 4 : 1 - p[0] / 3;
  }
  EXPECT_NEAR(static_cast<double>(count[0]), 3.0 / 12 * n, 0.01 * n);
  EXPECT_NEAR(static_cast<double>(count[1]), 4.0 / 12 * n, 0.01 * n);
  EXPECT_NEAR(static_cast<double>(count[2]), 5.0 / 12 * n, 0.01 * n);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(along[k] / count[k], 0.5, 0.01) << "side " << k;
}

// A segment of length 1 and a triangle of perimeter 12: 1/13 of the edge samples on the segment.
TEST(SurfaceSampler, SegmentsShareEdgeSamplesByLength) {
  Mesh m;
  m.add(0, 0, 0), m.add(3, 0, 0), m.add(3, 4, 0), m.add(10, 0, 0), m.add(10, 1, 0);
  m.triangles = {0, 1, 2};
  m.segments = {3, 4};
  constexpr uint64_t n = 100000;
  const Samples s = sample(m, n, 5, 5);
  EXPECT_EQ(s.length, 13.0);
  uint64_t on_segment = 0;
  for (size_t i = 0; i < s.edges.size(); i += 3) {
    if (s.edges[i] != 10) continue;
    ++on_segment;
    EXPECT_GE(s.edges[i + 1], 0);
    EXPECT_LE(s.edges[i + 1], 1);
  }
  EXPECT_NEAR(static_cast<double>(on_segment), n / 13.0, 0.01 * n);
}

// ---------------------------------------------------------------------------------------------------------
// Vertex samples: selection sampling

// 1000 distinct vertices, n = 100: exactly 100 of them, distinct, in visiting order, and different seeds
// pick different sets.
TEST(SurfaceSampler, SelectionSamplingPicksExactlyNDistinctVerticesInOrder) {
  Mesh m;
  for (int i = 0; i < 1000; ++i) m.add(i, 0, 0);  // vertex i at x = i
  std::set<std::vector<float>> sets;
  for (uint64_t seed = 0; seed < 30; ++seed) {
    const Samples s = sample(m, 100, seed);
    ASSERT_EQ(s.vertex_count, 100u);
    ASSERT_EQ(s.vertices.size(), 300u);
    for (size_t i = 0; i < s.vertices.size(); i += 3) {
      const float x = s.vertices[i];
      ASSERT_EQ(x, std::floor(x));  // an exact vertex
      ASSERT_TRUE(x >= 0 && x < 1000);
      ASSERT_EQ(s.vertices[i + 1], 0);
      ASSERT_EQ(s.vertices[i + 2], 0);
      if (i > 0) {
        ASSERT_LT(s.vertices[i - 3], x);  // strictly increasing: distinct and in visiting order
      }
    }
    sets.insert(s.vertices);
  }
  EXPECT_EQ(sets.size(), 30u);
}

// n = V: all of them; n = V - 1: all but one.
TEST(SurfaceSampler, SelectionSamplingAtTheBoundary) {
  Mesh m;
  for (int i = 0; i < 50; ++i) m.add(i, 1, 2);
  EXPECT_EQ(sample(m, 50, 1).vertices, m.xyz);
  EXPECT_EQ(sample(m, 51, 1).vertices, m.xyz);
  const Samples s = sample(m, 49, 1);
  EXPECT_EQ(s.vertex_count, 49u);
  EXPECT_EQ(s.vertices.size(), 3u * 49);
  const Samples one = sample(m, 1, 1);
  EXPECT_EQ(one.vertex_count, 1u);
}

// Every vertex is equally likely: 10 vertices, 3 picked, over 4000 seeds each vertex is picked 1200 times
// (standard deviation 29; tolerance 150).
TEST(SurfaceSampler, SelectionSamplingIsUniform) {
  Mesh m;
  for (int i = 0; i < 10; ++i) m.add(i, 0, 0);
  std::array<int, 10> picked{};
  for (uint64_t seed = 0; seed < 4000; ++seed) {
    const Samples s = sample(m, 3, seed, 1);
    ASSERT_EQ(s.vertex_count, 3u);
    for (size_t i = 0; i < s.vertices.size(); i += 3) ++picked[static_cast<int>(s.vertices[i])];
  }
  for (int i = 0; i < 10; ++i) EXPECT_NEAR(picked[i], 1200, 150) << "vertex " << i;
}

// Blocks: 1500 random triangles of every size and 375 segments cut into blocks of 97 elements (the
// segments after the triangles). One sampler measuring and sampling every block in turn, and samplers
// that each measure one block apart, then each sample up to three blocks apart from the blocks' sums
// (added in block order) and the sums before their first block, give the same samples, in the same
// order, bit for bit; every position is reached, and the totals are the blocks' sums added in order.
TEST(SurfaceSampler, BlocksMeasuredAndSampledApartGiveOneSamplersSamples) {
  const Mesh m = random_sized_mesh(9, 1500, 4);
  const size_t triangles = m.triangles.size() / 3, elements = triangles + m.segments.size() / 2;
  constexpr size_t kBlock = 97;
  const size_t blocks = (elements + kBlock - 1) / kBlock;
  // Element e of the mesh (triangles, then segments), measured or sampled by `s`.
  auto measure = [&](SurfaceSampler& s, size_t e) {
    if (e < triangles) s.measure_triangle(m.at(m.triangles[3 * e]), m.at(m.triangles[3 * e + 1]), m.at(m.triangles[3 * e + 2]));
    else s.measure_segment(m.at(m.segments[2 * (e - triangles)]), m.at(m.segments[2 * (e - triangles) + 1]));
  };
  auto sample_element = [&](SurfaceSampler& s, size_t e, Samples& out) {
    if (e < triangles)
      s.sample_triangle(m.at(m.triangles[3 * e]), m.at(m.triangles[3 * e + 1]), m.at(m.triangles[3 * e + 2]), out.faces, out.edges);
    else s.sample_segment(m.at(m.segments[2 * (e - triangles)]), m.at(m.segments[2 * (e - triangles) + 1]), out.edges);
  };
  const uint64_t n = 5003;
  // One sampler, block by block.
  SurfaceSampler one(n, 4, 2);
  std::vector<core::SamplerSums> sums(blocks), before(blocks);
  for (size_t b = 0; b < blocks; ++b) {
    for (size_t e = b * kBlock; e < std::min(elements, (b + 1) * kBlock); ++e) measure(one, e);
    sums[b] = one.end_block();
    before[b] = {one.area(), one.length()};
    one.add_block(sums[b]);
  }
  one.begin_sampling();
  Samples want;
  for (size_t b = 0; b < blocks; ++b) {
    one.begin_block(before[b]);
    for (size_t e = b * kBlock; e < std::min(elements, (b + 1) * kBlock); ++e) sample_element(one, e, want);
  }
  ASSERT_EQ(want.faces.size(), 3 * n);
  ASSERT_EQ(want.edges.size(), 3 * n);
  // Each block measured by a sampler of its own, then the blocks sampled three at a time by others.
  std::vector<core::SamplerSums> apart(blocks);
  for (size_t b = 0; b < blocks; ++b) {
    SurfaceSampler s(n, 4, 2);
    for (size_t e = b * kBlock; e < std::min(elements, (b + 1) * kBlock); ++e) measure(s, e);
    apart[b] = s.end_block();
    ASSERT_EQ(apart[b].area, sums[b].area) << b;
    ASSERT_EQ(apart[b].length, sums[b].length) << b;
  }
  Samples got;
  for (size_t first = 0; first < blocks; first += 3) {
    SurfaceSampler s(n, 4, 2);
    std::vector<core::SamplerSums> start(blocks);
    for (size_t b = 0; b < blocks; ++b) start[b] = {s.area(), s.length()}, s.add_block(apart[b]);
    EXPECT_EQ(s.area(), one.area());
    EXPECT_EQ(s.length(), one.length());
    s.begin_sampling();
    for (size_t b = first; b < std::min(blocks, first + 3); ++b) {
      s.begin_block(start[b]);
      for (size_t e = b * kBlock; e < std::min(elements, (b + 1) * kBlock); ++e) sample_element(s, e, got);
    }
  }
  EXPECT_EQ(got.faces, want.faces);
  EXPECT_EQ(got.edges, want.edges);
}

}  // namespace
}  // namespace lodstream

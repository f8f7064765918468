// Embree scenes and primary-ray images (core/ray_scene.h, core/view_cast.h).
//
// closest_distance: a point above a triangle's interior and in each vertex and edge Voronoi region (exact
// values, and an independent brute force: projection onto the plane when inside, else the nearest of the
// three sides), a zero-area triangle, segments (distance to the axis, the radius ignored), points, random
// queries against brute force over a random mesh of triangles, segments and points, the empty scene (+inf),
// and the memory limit (Status::usage, no crash).
// cast_view: an axis-aligned square seen head-on (the exact set of covered pixels, from pixel centres; depth
// along the unit ray; normals facing the camera for either winding), a segment seen from the side (a band
// 2r wide, normal perpendicular to the edge in the plane of edge and ray), a disc point (about π r²
// pixels, normal = -ray), two scenes together (the nearer hit and its kind), and the
// same bytes with 1 and 2 threads. look_at and fibonacci_direction: bases and directions.
#include <gtest/gtest.h>

#include "ref_geometry.h"
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <span>
#include <vector>

#include "core/ray_scene.h"
#include "core/status.h"
#include "core/view_cast.h"

namespace lodstream {
namespace {

using core::Camera;
using core::PrimitiveKind;
using core::RayScene;
using core::ViewImage;

// ---------------------------------------------------------------------------------------------------------
// An independent closest-point reference, in double.

using namespace lodstream::test;  // V3 and its operations (ref_geometry.h)

V3 ref_closest_on_segment(V3 p, V3 a, V3 b) {
  const V3 d = b - a;
  const double len2 = dot(d, d);
  if (len2 == 0) return a;
  return a + d * std::clamp(dot(p - a, d) / len2, 0.0, 1.0);
}

// Inside the prism over the triangle: the projection onto its plane; otherwise the nearest point of its
// three sides (the nearest point of a convex polygon is then on its boundary).
V3 ref_closest_on_triangle(V3 p, V3 a, V3 b, V3 c) {
  const V3 n = cross(b - a, c - a);
  const double n2 = dot(n, n);
  if (n2 > 0) {
    const V3 q = p - n * (dot(p - a, n) / n2);
    const double wa = dot(cross(c - b, q - b), n), wb = dot(cross(a - c, q - c), n), wc = dot(cross(b - a, q - a), n);
    if (wa >= 0 && wb >= 0 && wc >= 0) return q;
  }
  V3 best = a;
  double best_d = std::numeric_limits<double>::infinity();
  for (const auto& [u, v] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
    const V3 q = ref_closest_on_segment(p, u, v);
    if (norm(p - q) < best_d) best_d = norm(p - q), best = q;
  }
  return best;
}

struct Mesh {
  std::vector<float> xyz;
  std::vector<uint32_t> triangles, edges, points;
  std::vector<float> radius;  // per edge
  float point_radius = 0.1f;
  V3 at(uint32_t i) const { return v3(xyz.data() + 3 * static_cast<size_t>(i)); }
  uint32_t add(double x, double y, double z) {
    xyz.insert(xyz.end(), {float(x), float(y), float(z)});
    return static_cast<uint32_t>(xyz.size() / 3 - 1);
  }
};

double ref_distance(const Mesh& m, V3 p) {
  double best = std::numeric_limits<double>::infinity();
  for (size_t t = 0; t < m.triangles.size(); t += 3)
    best = std::min(best, norm(p - ref_closest_on_triangle(p, m.at(m.triangles[t]), m.at(m.triangles[t + 1]),
                                                           m.at(m.triangles[t + 2]))));
  for (size_t e = 0; e < m.edges.size(); e += 2)
    best = std::min(best, norm(p - ref_closest_on_segment(p, m.at(m.edges[e]), m.at(m.edges[e + 1]))));
  for (uint32_t i : m.points) best = std::min(best, norm(p - m.at(i)));
  return best;
}

void fill(RayScene& scene, const Mesh& m) {
  scene.add_triangles(m.xyz, m.triangles);
  scene.add_segments(m.xyz, m.edges, m.radius);
  scene.add_points(m.xyz, m.points, m.point_radius);
  scene.commit();
}

struct Closest {
  float distance;
  std::array<float, 3> point;
};
Closest query(const RayScene& scene, double x, double y, double z) {
  const float p[3] = {float(x), float(y), float(z)};
  Closest c{};
  c.distance = scene.closest_distance(p, c.point.data());
  return c;
}

// ---------------------------------------------------------------------------------------------------------
// closest_distance

// The right triangle a = (0,0,0), b = (4,0,0), c = (0,4,0) in the plane z = 0:
//
//   y
//   4 c
//     |`.
//     |  `.
//     |    `.
//   0 a------b  x
//     0      4
class ClosestTriangle : public ::testing::Test {
 protected:
  void SetUp() override {
    m.add(0, 0, 0), m.add(4, 0, 0), m.add(0, 4, 0);
    m.triangles = {0, 1, 2};
    fill(scene, m);
  }
  Mesh m;
  RayScene scene;
};

TEST_F(ClosestTriangle, AboveTheInteriorIsTheHeightAndTheProjection) {
  const Closest c = query(scene, 1, 1, 2.5);
  EXPECT_EQ(c.distance, 2.5f);
  EXPECT_EQ(c.point, (std::array<float, 3>{1, 1, 0}));
  const Closest below = query(scene, 0.5, 2, -3);
  EXPECT_EQ(below.distance, 3.0f);
  EXPECT_EQ(below.point, (std::array<float, 3>{0.5f, 2, 0}));
  const Closest on = query(scene, 1, 2, 0);
  EXPECT_EQ(on.distance, 0.0f);
  EXPECT_EQ(on.point, (std::array<float, 3>{1, 2, 0}));
}

TEST_F(ClosestTriangle, VertexRegionsGiveTheVertex) {
  struct Case {
    double p[3];
    std::array<float, 3> vertex;
    float distance;
  };
  const Case cases[] = {
      {{-1, -2, 2}, {0, 0, 0}, 3.0f},                  // behind a
      {{6, -1, 2}, {4, 0, 0}, 3.0f},                   // beyond b (2, -1, 2)
      {{-2, 5, 0}, {0, 4, 0}, std::sqrt(5.0f)},        // beyond c (-2, 1, 0)
      {{4.5, -0.25, 0}, {4, 0, 0}, std::sqrt(0.3125f)},  // just past b, between its two sides' normals
  };
  for (const Case& k : cases) {
    const Closest c = query(scene, k.p[0], k.p[1], k.p[2]);
    EXPECT_EQ(c.point, k.vertex) << k.p[0] << " " << k.p[1] << " " << k.p[2];
    EXPECT_FLOAT_EQ(c.distance, k.distance) << k.p[0] << " " << k.p[1] << " " << k.p[2];
  }
}

TEST_F(ClosestTriangle, EdgeRegionsGiveTheFootOnTheSide) {
  struct Case {
    double p[3];
    std::array<float, 3> foot;
    float distance;
  };
  const Case cases[] = {
      {{2, -1, 1}, {2, 0, 0}, std::sqrt(2.0f)},    // side ab
      {{-3, 1.5, -4}, {0, 1.5, 0}, 5.0f},           // side ca
      {{3, 3, 1}, {2, 2, 0}, std::sqrt(3.0f)},     // side bc (the hypotenuse x + y = 4)
      {{3.5, 1.5, 0}, {3, 1, 0}, std::sqrt(0.5f)},  // side bc, in the plane
  };
  for (const Case& k : cases) {
    const Closest c = query(scene, k.p[0], k.p[1], k.p[2]);
    for (int i = 0; i < 3; ++i) EXPECT_FLOAT_EQ(c.point[i], k.foot[i]) << k.p[0] << " " << k.p[1] << " " << k.p[2];
    EXPECT_FLOAT_EQ(c.distance, k.distance) << k.p[0] << " " << k.p[1] << " " << k.p[2];
  }
}

// A scalene triangle in general position, and points in each of its seven Voronoi regions (found from the
// reference itself: which of a, b, c, a side or the interior is nearest), against the reference.
TEST(ClosestDistance, EveryVoronoiRegionOfAGeneralTriangleMatchesTheReference) {
  Mesh m;
  m.add(0.3, -0.2, 0.1), m.add(2.1, 0.4, -0.5), m.add(0.7, 1.9, 0.8);
  m.triangles = {0, 1, 2};
  RayScene scene;
  fill(scene, m);
  const V3 a = m.at(0), b = m.at(1), c = m.at(2);
  const V3 n = cross(b - a, c - a) * (1 / norm(cross(b - a, c - a)));
  const V3 centroid = (a + b + c) * (1.0 / 3);
  // Region probes: outward from the centroid through each vertex and each side's midpoint, lifted off the
  // plane by ±0.7, plus one above the centroid.
  std::vector<V3> probes = {centroid + n * 0.9, centroid - n * 0.4};
  for (V3 target : {a, b, c, (a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5})
    for (double lift : {0.7, -0.7, 0.0}) probes.push_back(target + (target - centroid) * 0.8 + n * lift);
  std::array<int, 7> regions{};  // a, b, c, ab, bc, ca, face
  for (const V3& p : probes) {
    const V3 r = ref_closest_on_triangle(p, a, b, c);
    const Closest got = query(scene, p[0], p[1], p[2]);
    EXPECT_NEAR(got.distance, norm(p - r), 1e-6) << p[0] << " " << p[1] << " " << p[2];
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(got.point[i], r[i], 1e-6);
    if (norm(r - a) < 1e-12) ++regions[0];
    else if (norm(r - b) < 1e-12) ++regions[1];
    else if (norm(r - c) < 1e-12) ++regions[2];
    else if (norm(r - ref_closest_on_segment(r, a, b)) < 1e-12) ++regions[3];
    else if (norm(r - ref_closest_on_segment(r, b, c)) < 1e-12) ++regions[4];
    else if (norm(r - ref_closest_on_segment(r, c, a)) < 1e-12) ++regions[5];
    else ++regions[6];
  }
  for (int k = 0; k < 7; ++k) EXPECT_GT(regions[k], 0) << "no probe in region " << k;
}

// Zero area: a, b, c on the x axis at 0, 1 and 3 (c beyond b). Its nearest points are those of the segment
// [0, 3].
TEST(ClosestDistance, ZeroAreaTriangleIsItsLongestSide) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(3, 0, 0);
  m.triangles = {0, 1, 2};
  RayScene scene;
  fill(scene, m);
  Closest c = query(scene, 2, 1, 0);
  EXPECT_EQ(c.distance, 1.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{2, 0, 0}));
  c = query(scene, -3, 0, 4);
  EXPECT_EQ(c.distance, 5.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{0, 0, 0}));
  c = query(scene, 5, 2, 0);
  EXPECT_EQ(c.distance, std::sqrt(8.0f));
  EXPECT_EQ(c.point, (std::array<float, 3>{3, 0, 0}));
  c = query(scene, 0.5, 0, -2);
  EXPECT_EQ(c.distance, 2.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{0.5f, 0, 0}));
}

// All three corners at one point.
TEST(ClosestDistance, TriangleCollapsedToAPointIsThatPoint) {
  Mesh m;
  m.add(1, 2, 3), m.add(1, 2, 3), m.add(1, 2, 3);
  m.triangles = {0, 1, 2};
  RayScene scene;
  fill(scene, m);
  const Closest c = query(scene, 1, 5, 7);
  EXPECT_EQ(c.distance, 5.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{1, 2, 3}));
}

// A segment from (0,0,0) to (2,0,0) of radius 0.5: distances are to its axis, never to its surface.
TEST(ClosestDistance, SegmentIsItsAxisWhateverTheRadius) {
  Mesh m;
  m.add(0, 0, 0), m.add(2, 0, 0);
  m.edges = {0, 1};
  m.radius = {0.5f};
  RayScene scene;
  fill(scene, m);
  Closest c = query(scene, 1, 3, 0);
  EXPECT_EQ(c.distance, 3.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{1, 0, 0}));
  c = query(scene, 0.5, 0.25, 0);  // inside the rendered thickness: still the distance to the axis
  EXPECT_EQ(c.distance, 0.25f);
  EXPECT_EQ(c.point, (std::array<float, 3>{0.5f, 0, 0}));
  c = query(scene, -3, 4, 0);
  EXPECT_EQ(c.distance, 5.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{0, 0, 0}));
  c = query(scene, 5, 0, -4);
  EXPECT_EQ(c.distance, 5.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{2, 0, 0}));
  c = query(scene, 1.5, 0, 0);
  EXPECT_EQ(c.distance, 0.0f);
}

// Two segments of different radii: the thinner, farther axis is not preferred because the nearer one is
// thick, nor the other way round.
TEST(ClosestDistance, SegmentRadiusDoesNotChooseTheNearest) {
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0), m.add(1, 1, 0);
  m.edges = {0, 1, 2, 3};
  m.radius = {0.01f, 0.45f};  // y = 0 thin, y = 1 thick
  RayScene scene;
  fill(scene, m);
  const Closest c = query(scene, 0.5, 0.4, 0);  // 0.4 from the thin axis, 0.6 from the thick one
  EXPECT_FLOAT_EQ(c.distance, 0.4f);
  EXPECT_EQ(c.point, (std::array<float, 3>{0.5f, 0, 0}));
}

TEST(ClosestDistance, PointsAreTheirCentres) {
  Mesh m;
  m.add(1, 2, 3), m.add(-4, 0, 0), m.add(9, 9, 9);
  m.points = {0, 1};  // vertex 2 is not a point
  m.point_radius = 0.25f;
  RayScene scene;
  fill(scene, m);
  Closest c = query(scene, 1, 2, 5);
  EXPECT_EQ(c.distance, 2.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{1, 2, 3}));
  c = query(scene, -4, 3, 4);
  EXPECT_EQ(c.distance, 5.0f);
  EXPECT_EQ(c.point, (std::array<float, 3>{-4, 0, 0}));
  c = query(scene, 9, 9, 9);  // far from both discs
  EXPECT_FLOAT_EQ(c.distance, float(std::sqrt(64.0 + 49 + 36)));
  EXPECT_EQ(c.point, (std::array<float, 3>{1, 2, 3}));
}

TEST(ClosestDistance, EmptySceneIsInfinitelyFar) {
  const float p[3] = {0, 0, 0};
  {
    RayScene scene;
    scene.commit();
    EXPECT_TRUE(scene.empty());
    EXPECT_EQ(scene.closest_distance(p), std::numeric_limits<float>::infinity());
  }
  {
    RayScene scene;  // buffers of nothing leave it empty
    scene.add_triangles(std::span<const float>(), std::span<const uint32_t>());
    scene.add_segments(std::span<const float>(), std::span<const uint32_t>(), std::span<const float>());
    scene.add_points(std::span<const float>(), std::span<const uint32_t>(), 1.0f);
    scene.commit();
    EXPECT_TRUE(scene.empty());
    float closest[3] = {7, 7, 7};
    EXPECT_EQ(scene.closest_distance(p, closest), std::numeric_limits<float>::infinity());
  }
}

// A random mesh of 60 triangles, 40 segments and 20 points in a box of scale 10 (plus some slivers), and
// 4000 queries around and inside it, against the brute-force reference.
TEST(ClosestDistance, RandomQueriesMatchBruteForce) {
  const double scale = 10;
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> u(-scale, scale), small(-1, 1);
  Mesh m;
  for (int t = 0; t < 60; ++t) {
    const double cx = u(rng), cy = u(rng), cz = u(rng);
    const double s = t % 10 == 0 ? 0.01 : 2;  // every tenth a sliver
    const uint32_t a = m.add(cx + small(rng) * 2, cy + small(rng) * 2, cz + small(rng) * 2);
    const uint32_t b = m.add(cx + small(rng) * 2, cy + small(rng) * 2, cz + small(rng) * 2);
    const uint32_t c = m.add(m.at(a)[0] + small(rng) * s, m.at(a)[1] + small(rng) * s, m.at(a)[2] + small(rng) * s);
    m.triangles.insert(m.triangles.end(), {a, b, c});
  }
  for (int e = 0; e < 40; ++e) {
    const uint32_t a = m.add(u(rng), u(rng), u(rng));
    const uint32_t b = e % 2 ? m.add(m.at(a)[0] + small(rng) * 3, m.at(a)[1] + small(rng) * 3, m.at(a)[2] + small(rng) * 3)
                             : static_cast<uint32_t>(e);  // half of them end at a triangle corner
    m.edges.insert(m.edges.end(), {a, b});
    m.radius.push_back(float(0.05 + 0.5 * (small(rng) + 1)));
  }
  for (int k = 0; k < 20; ++k) m.points.push_back(m.add(u(rng), u(rng), u(rng)));
  m.point_radius = 0.3f;
  RayScene scene;
  fill(scene, m);

  double worst = 0;
  for (int q = 0; q < 4000; ++q) {
    const double f = q % 4 == 0 ? 2.0 : 1.0;  // a quarter of the queries well outside the box
    const V3 p = {float(u(rng) * f), float(u(rng) * f), float(u(rng) * f)};
    const Closest got = query(scene, p[0], p[1], p[2]);
    const double expected = ref_distance(m, p);
    worst = std::max(worst, std::fabs(got.distance - expected));
    // The reported point is at the reported distance and lies on the mesh.
    const V3 c = {got.point[0], got.point[1], got.point[2]};
    ASSERT_NEAR(norm(p - c), expected, 1e-5 * scale) << q;
    ASSERT_LT(ref_distance(m, c), 1e-5 * scale) << q;
  }
  EXPECT_LT(worst, 1e-5 * scale);
}

// ---------------------------------------------------------------------------------------------------------
// Memory limit

// A grid of 317 × 317 vertices, 2 × 316² = 199712 triangles.
Mesh grid_mesh() {
  constexpr uint32_t n = 317;
  Mesh m;
  for (uint32_t y = 0; y < n; ++y)
    for (uint32_t x = 0; x < n; ++x) m.add(x * 0.01, y * 0.01, std::sin(x * 0.1) * 0.05);
  for (uint32_t y = 0; y + 1 < n; ++y)
    for (uint32_t x = 0; x + 1 < n; ++x) {
      const uint32_t a = y * n + x;
      m.triangles.insert(m.triangles.end(), {a, a + 1, a + n, a + 1, a + n + 1, a + n});
    }
  return m;
}

Status build_status(uint64_t limit, const Mesh& m, std::string* message = nullptr) {
  try {
    RayScene scene(limit);
    scene.add_triangles(m.xyz, m.triangles);
    scene.commit();
  } catch (const Failure& f) {
    if (message) *message = f.what();
    return f.status();
  }
  return Status::ok;
}

TEST(RaySceneMemory, TinyLimitFailsWithUsage) {
  const Mesh m = grid_mesh();
  ASSERT_EQ(m.triangles.size() / 3, 199712u);
  std::string message;
  EXPECT_EQ(build_status(1u << 20, m, &message), Status::usage);
  EXPECT_NE(message.find("memory"), std::string::npos) << message;
  // Without a limit the same mesh builds, and takes more than the limit.
  RayScene scene;
  scene.add_triangles(m.xyz, m.triangles);
  scene.commit();
  EXPECT_GT(scene.embree_bytes(), 1u << 20);
  EXPECT_GE(scene.peak_embree_bytes(), scene.embree_bytes());
  const float p[3] = {1.0f, 1.0f, 5.0f};  // 5 above a surface whose height stays within ±0.05
  EXPECT_NEAR(scene.closest_distance(p), 5.0, 0.05);
}

// A limit that holds the buffers but not the BVH: the failure comes from commit() (Embree's parallel build),
// and the scene is destroyed cleanly.
TEST(RaySceneMemory, LimitReachedDuringTheBuildFailsWithUsage) {
  const Mesh m = grid_mesh();
  const uint64_t buffers = m.xyz.size() * sizeof(float) + m.triangles.size() * sizeof(uint32_t);
  const uint64_t limit = buffers + (256u << 10);
  RayScene scene(limit);
  scene.add_triangles(m.xyz, m.triangles);  // must not throw: the buffers fit
  EXPECT_LE(scene.embree_bytes(), limit);
  try {
    scene.commit();
    ADD_FAILURE() << "commit() did not fail; Embree holds " << scene.embree_bytes() << " bytes, limit " << limit;
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::usage) << f.what();
  }
  EXPECT_LE(scene.embree_bytes(), limit);
  EXPECT_LE(scene.peak_embree_bytes(), limit);  // a refused allocation never happened
}

// A limit that holds the vertex buffer but not the index buffer: add_triangles fails, and the geometry it
// had started is released with the buffer it already held (Embree reports the bytes returned).
TEST(RaySceneMemory, FailedAddReleasesItsGeometry) {
  const Mesh m = grid_mesh();
  const uint64_t vertex_bytes = m.xyz.size() * sizeof(float);
  RayScene scene(vertex_bytes + (64u << 10));
  try {
    scene.add_triangles(m.xyz, m.triangles);
    ADD_FAILURE() << "add_triangles did not fail; Embree holds " << scene.embree_bytes() << " bytes";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::usage) << f.what();
  }
  EXPECT_GE(scene.peak_embree_bytes(), vertex_bytes);  // the vertex buffer was allocated
  EXPECT_LT(scene.embree_bytes(), vertex_bytes);        // and is gone with its geometry
}

// Many scenes failing in a row (and succeeding afterwards): no crash, no stuck state.
TEST(RaySceneMemory, RepeatedFailuresThenSuccess) {
  const Mesh m = grid_mesh();
  for (uint64_t limit : {uint64_t{1} << 10, uint64_t{1} << 16, uint64_t{1} << 20, uint64_t{4} << 20})
    EXPECT_EQ(build_status(limit, m), Status::usage) << limit;
  EXPECT_EQ(build_status(uint64_t{1} << 30, m), Status::ok);
  EXPECT_EQ(build_status(0, m), Status::ok);
}

// ---------------------------------------------------------------------------------------------------------
// Chunks: a scene traced in consecutive parts, each image accumulated over the parts in order, is the image
// of the whole scene bit for bit, ties included: the wavy grid with every triangle twice (the copy's corners
// rotated, so the two give equal or nearly equal distances and one of two normals' rounding), cut in 3.

TEST(RaySceneChunks, PartsTracedInOrderGiveTheWholeImage) {
  Mesh m = grid_mesh();
  const size_t n = m.triangles.size();
  for (size_t t = 0; t < n; t += 3) m.triangles.insert(m.triangles.end(), {m.triangles[t + 1], m.triangles[t + 2], m.triangles[t]});
  RayScene whole;
  whole.add_triangles(m.xyz, m.triangles);
  whole.commit();
  std::vector<std::unique_ptr<RayScene>> parts;
  const size_t per = (m.triangles.size() / 3 + 2) / 3;
  for (size_t first = 0; first < m.triangles.size() / 3; first += per) {
    const size_t end = std::min(m.triangles.size() / 3, first + per);
    parts.push_back(std::make_unique<RayScene>());
    parts.back()->add_triangles(m.xyz, std::span<const uint32_t>(m.triangles.data() + 3 * first, 3 * (end - first)));
    parts.back()->commit();
  }
  for (const auto& [eye, target] : {std::pair{std::array<double, 3>{1.6, 1.5, 2.0}, std::array<double, 3>{1.6, 1.6, 0.0}},
                                    std::pair{std::array<double, 3>{-1.0, -0.5, 0.8}, std::array<double, 3>{1.5, 1.5, 0.0}}}) {
    const core::Camera cam = core::look_at(eye.data(), target.data(), 60, 128);
    core::ViewImage a, b;
    const RayScene* w[] = {&whole};
    core::cast_view(w, cam, &a);
    for (const auto& p : parts) {
      const RayScene* one[] = {p.get()};
      core::cast_view(one, cam, &b, true);
    }
    uint64_t covered = 0;
    for (uint8_t k : a.kind) covered += k != 0;
    EXPECT_GT(covered, 1000u);
    EXPECT_EQ(a.kind, b.kind);
    EXPECT_EQ(0, std::memcmp(a.depth.data(), b.depth.data(), a.depth.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(a.normal.data(), b.normal.data(), a.normal.size() * sizeof(float)));
  }
}

// Sort-last: the same scene (the doubled wavy grid, and thin segments over it, thinner than a pixel so that
// the k × k rays find them) cut into parts that each hold a range of the primitives in key order
// (triangles, then segments), every part cast into a fresh image and the images composited in part order,
// is the whole scene's image bit for bit, with 3 × 3 rays a pixel and with one; and so is the accumulated
// cast of the parts in order. A part that sees nothing changes nothing.
TEST(RaySceneChunks, PartsCastAloneThenCompositedGiveTheWholeImage) {
  Mesh m = grid_mesh();
  const size_t n = m.triangles.size();
  for (size_t t = 0; t < n; t += 3) m.triangles.insert(m.triangles.end(), {m.triangles[t + 2], m.triangles[t], m.triangles[t + 1]});
  for (uint32_t i = 0; i < 40; ++i) {
    const uint32_t a = m.add(0.3 + 0.06 * i, 0.2, 0.2 + 0.001 * i), b = m.add(0.5 + 0.05 * i, 2.9, 0.15);
    m.edges.insert(m.edges.end(), {a, b});
    m.radius.push_back(0.0008f + 0.0001f * float(i % 5));
  }
  for (uint32_t i = 0; i < 40; ++i) m.edges.insert(m.edges.end(), {m.edges[2 * i + 1], m.edges[2 * i]}), m.radius.push_back(m.radius[i]);
  const size_t triangles = m.triangles.size() / 3, segments = m.edges.size() / 2;
  // A part: triangles [t0, t1) and segments [s0, s1), each kind in its own scene (the key order).
  struct Part {
    std::unique_ptr<RayScene> triangles, wire;
  };
  auto part = [&](size_t t0, size_t t1, size_t s0, size_t s1) {
    Part p{std::make_unique<RayScene>(), std::make_unique<RayScene>()};
    p.triangles->add_triangles(m.xyz, std::span<const uint32_t>(m.triangles.data() + 3 * t0, 3 * (t1 - t0)));
    p.triangles->commit();
    p.wire->add_segments(m.xyz, std::span<const uint32_t>(m.edges.data() + 2 * s0, 2 * (s1 - s0)),
                         std::span<const float>(m.radius.data() + s0, s1 - s0));
    p.wire->commit();
    return p;
  };
  const Part whole = part(0, triangles, 0, segments);
  // Primitive ranges [0, 1/3), [1/3, 1/3 + 10 segments), ..., the last all segments; one empty part.
  const size_t cuts[][4] = {{0, triangles / 3, 0, 0}, {triangles / 3, triangles, 0, 10}, {triangles, triangles, 10, 10},
                            {triangles, triangles, 10, 45}, {triangles, triangles, 45, segments}};
  std::vector<Part> parts;
  for (const auto& c : cuts) parts.push_back(part(c[0], c[1], c[2], c[3]));
  for (unsigned k : {3u, 1u}) {
    uint64_t sub = 0;  // pixels covered by k × k rays only, over both views
    for (const auto& [eye, target] : {std::pair{std::array<double, 3>{1.6, 1.5, 2.0}, std::array<double, 3>{1.6, 1.6, 0.0}},
                                      std::pair{std::array<double, 3>{-1.0, -0.5, 0.8}, std::array<double, 3>{1.5, 1.5, 0.0}}}) {
      SCOPED_TRACE("supersample " + std::to_string(k));
      core::Camera cam = core::look_at(eye.data(), target.data(), 60, 128);
      cam.supersample = k;
      core::ViewImage a, accumulated, composited;
      const RayScene* w[] = {whole.triangles.get(), whole.wire.get()};
      core::cast_view(w, cam, &a);
      core::clear_view(&composited, 128);
      for (const Part& p : parts) {
        const RayScene* one[] = {p.triangles.get(), p.wire.get()};
        core::cast_view(one, cam, &accumulated, true);
        core::ViewImage alone;
        core::cast_view(one, cam, &alone);
        core::composite_view(&composited, alone);
      }
      uint64_t covered = 0, lines = 0;
      for (uint64_t p = 0; p < a.kind.size(); ++p)
        covered += a.kind[p] != 0, lines += a.kind[p] == uint8_t(core::PrimitiveKind::edge), sub += a.kind[p] && !a.centre[p];
      EXPECT_GT(covered, 1000u);
      EXPECT_GT(lines, 20u);
      for (const core::ViewImage* b : {&accumulated, &composited}) {
        SCOPED_TRACE(b == &accumulated ? "accumulated" : "composited");
        EXPECT_EQ(a.kind, b->kind);
        EXPECT_EQ(a.centre, b->centre);
        EXPECT_EQ(0, std::memcmp(a.depth.data(), b->depth.data(), a.depth.size() * sizeof(float)));
        EXPECT_EQ(0, std::memcmp(a.normal.data(), b->normal.data(), a.normal.size() * sizeof(float)));
      }
    }
    if (k == 3) {
      EXPECT_GT(sub, 20u) << "pixels covered by k × k rays only";
    }
  }
}

// ---------------------------------------------------------------------------------------------------------
// look_at, fibonacci_direction

void expect_orthonormal(const Camera& c) {
  const V3 f = {c.forward[0], c.forward[1], c.forward[2]}, r = {c.right[0], c.right[1], c.right[2]},
           u = {c.up[0], c.up[1], c.up[2]};
  EXPECT_NEAR(norm(f), 1, 1e-12);
  EXPECT_NEAR(norm(r), 1, 1e-12);
  EXPECT_NEAR(norm(u), 1, 1e-12);
  EXPECT_NEAR(dot(f, r), 0, 1e-12);
  EXPECT_NEAR(dot(f, u), 0, 1e-12);
  EXPECT_NEAR(dot(r, u), 0, 1e-12);
  // Right-handed screen: right = forward × up.
  const V3 fu = cross(f, u);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(fu[k], r[k], 1e-12);
}

TEST(LookAt, AxisViewsHaveTheDocumentedUp) {
  const double origin[3] = {0, 0, 0};
  {
    const double eye[3] = {0, 0, 5};  // looking down -z: x and y tie, y wins
    const Camera c = core::look_at(eye, origin, 90, 64);
    expect_orthonormal(c);
    EXPECT_EQ((V3{c.forward[0], c.forward[1], c.forward[2]}), (V3{0, 0, -1}));
    EXPECT_EQ((V3{c.up[0], c.up[1], c.up[2]}), (V3{0, 1, 0}));
    EXPECT_EQ((V3{c.right[0], c.right[1], c.right[2]}), (V3{1, 0, 0}));
    EXPECT_NEAR(c.tan_half_fov, 1.0, 1e-15);
    EXPECT_EQ(c.resolution, 64u);
    EXPECT_EQ((V3{c.eye[0], c.eye[1], c.eye[2]}), (V3{0, 0, 5}));
  }
  {
    const double eye[3] = {5, 0, 0};  // looking down -x: y and z tie, z wins
    const Camera c = core::look_at(eye, origin, 60, 64);
    expect_orthonormal(c);
    EXPECT_EQ((V3{c.forward[0], c.forward[1], c.forward[2]}), (V3{-1, 0, 0}));
    EXPECT_EQ((V3{c.up[0], c.up[1], c.up[2]}), (V3{0, 0, 1}));
    EXPECT_NEAR(c.tan_half_fov, std::tan(M_PI / 6), 1e-15);
  }
}

TEST(LookAt, RandomViewsAreOrthonormalAndLookAtTheTarget) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-10, 10);
  for (int i = 0; i < 200; ++i) {
    const double eye[3] = {u(rng), u(rng), u(rng)}, target[3] = {u(rng), u(rng), u(rng)};
    const Camera c = core::look_at(eye, target, 45, 128);
    expect_orthonormal(c);
    const V3 to = V3{target[0], target[1], target[2]} - V3{eye[0], eye[1], eye[2]};
    const V3 f = {c.forward[0], c.forward[1], c.forward[2]};
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(f[k], to[k] / norm(to), 1e-12);
    // Up leans towards the coordinate axis least aligned with the view (z, then y, then x on ties).
    int axis = 2;
    if (std::fabs(f[1]) < std::fabs(f[axis])) axis = 1;
    if (std::fabs(f[0]) < std::fabs(f[axis])) axis = 0;
    EXPECT_GT(c.up[axis], 0.5) << i;
  }
}

TEST(FibonacciDirection, UnitDistinctAndBalanced) {
  constexpr unsigned K = 32;
  std::vector<V3> d(K);
  V3 mean = {0, 0, 0};
  for (unsigned k = 0; k < K; ++k) {
    core::fibonacci_direction(k, K, d[k].data());
    EXPECT_NEAR(norm(d[k]), 1, 1e-12) << k;
    EXPECT_NEAR(d[k][2], 1 - (2.0 * k + 1) / K, 1e-15) << k;
    mean = mean + d[k] * (1.0 / K);
  }
  double closest = 2;
  for (unsigned i = 0; i < K; ++i)
    for (unsigned j = i + 1; j < K; ++j) closest = std::min(closest, norm(d[i] - d[j]));
  // Near-equal spacing: for 32 points the nearest pair is far from coincident (an equal-area cap per point
  // has angular radius ≈ 2/√32 rad ≈ 0.35).
  EXPECT_GT(closest, 0.3);
  EXPECT_NEAR(mean[2], 0, 1e-15);
  EXPECT_LT(norm(mean), 0.05);
}

// ---------------------------------------------------------------------------------------------------------
// cast_view

// The ray of pixel (x, y) in camera coordinates (right, up, forward), not normalised.
V3 pixel_ray(const Camera& c, unsigned x, unsigned y) {
  const double sx = (2.0 * (x + 0.5) / c.resolution - 1.0) * c.tan_half_fov;
  const double sy = (1.0 - 2.0 * (y + 0.5) / c.resolution) * c.tan_half_fov;
  return {sx, sy, 1};
}

// The same ray in world coordinates, unit.
V3 world_ray(const Camera& c, unsigned x, unsigned y) {
  const V3 r = pixel_ray(c, x, y);
  V3 w = {0, 0, 0};
  for (int k = 0; k < 3; ++k) w[k] = r[0] * c.right[k] + r[1] * c.up[k] + r[2] * c.forward[k];
  return w * (1 / norm(w));
}

ViewImage cast(std::initializer_list<const RayScene*> scenes, const Camera& camera, uint64_t* rays = nullptr) {
  ViewImage image;
  const std::vector<const RayScene*> list(scenes);
  const uint64_t n = core::cast_view(list, camera, &image);
  if (rays) *rays = n;
  return image;
}

// Camera at (0,0,5) looking at the origin, 90° field of view, 63 × 63 pixels (an odd resolution: pixel
// (31, 31) looks straight down the axis). The square [x0, x0+1] × [y0, y0+1] in the plane z = 0, with
// both windings. A pixel is covered iff its centre ray meets the square: at (5 sx, 5 sy, 0).
TEST(CastView, SquareHeadOnCoversExactlyThePixelsWhoseCentresItContains) {
  const double eye[3] = {0, 0, 5}, origin[3] = {0, 0, 0};
  const Camera camera = core::look_at(eye, origin, 90, 63);
  const double x0 = -0.45, y0 = -0.62;
  for (bool flip : {false, true}) {
    Mesh m;
    m.add(x0, y0, 0), m.add(x0 + 1, y0, 0), m.add(x0 + 1, y0 + 1, 0), m.add(x0, y0 + 1, 0);
    m.triangles = flip ? std::vector<uint32_t>{0, 2, 1, 0, 3, 2} : std::vector<uint32_t>{0, 1, 2, 0, 2, 3};
    RayScene scene;
    fill(scene, m);
    uint64_t rays = 0;
    const ViewImage image = cast({&scene}, camera, &rays);
    EXPECT_EQ(rays, 63u * 63u);
    ASSERT_EQ(image.resolution, 63u);
    ASSERT_EQ(image.depth.size(), 63u * 63u);
    ASSERT_EQ(image.normal.size(), 3u * 63 * 63);
    ASSERT_EQ(image.kind.size(), 63u * 63u);
    unsigned covered = 0, expected_covered = 0;
    double margin = 1;
    for (unsigned y = 0; y < 63; ++y) {
      for (unsigned x = 0; x < 63; ++x) {
        const V3 r = pixel_ray(camera, x, y);
        const double hx = 5 * r[0], hy = 5 * r[1];  // right = +x, up = +y
        margin = std::min({margin, std::fabs(hx - x0), std::fabs(hx - x0 - 1), std::fabs(hy - y0), std::fabs(hy - y0 - 1)});
        const bool inside = hx > x0 && hx < x0 + 1 && hy > y0 && hy < y0 + 1;
        const uint64_t p = uint64_t{y} * 63 + x;
        expected_covered += inside;
        covered += image.covered(p);
        ASSERT_EQ(image.covered(p), inside) << "pixel " << x << ", " << y << (flip ? " (flipped)" : "");
        if (inside) {
          EXPECT_EQ(image.kind[p], uint8_t(PrimitiveKind::triangle));
          EXPECT_NEAR(image.depth[p], 5 * norm(r), 2e-6 * 5);
          // The plane's normal, turned towards the camera: +z (dot with forward = -1 < 0).
          EXPECT_NEAR(image.normal[3 * p + 0], 0, 1e-6);
          EXPECT_NEAR(image.normal[3 * p + 1], 0, 1e-6);
          EXPECT_NEAR(image.normal[3 * p + 2], 1, 1e-6);
        } else {
          EXPECT_EQ(image.kind[p], uint8_t(PrimitiveKind::none));
          EXPECT_EQ(image.depth[p], std::numeric_limits<float>::infinity());
          EXPECT_EQ(image.normal[3 * p] == 0 && image.normal[3 * p + 1] == 0 && image.normal[3 * p + 2] == 0, true);
        }
      }
    }
    ASSERT_GT(margin, 1e-3);  // no pixel centre near the square's outline: coverage is unambiguous
    // 10/63 object units per pixel: 6 pixel centres each way fall inside the unit square.
    EXPECT_EQ(expected_covered, 36u);
    EXPECT_EQ(covered, expected_covered);
    EXPECT_EQ(image.depth[31 * 63 + 31], 5.0f);  // the centre pixel, straight down the axis
  }
}

// The same square from behind (eye at z = -5): the normal still faces the camera, now -z.
TEST(CastView, NormalsFaceTheCameraFromEitherSide) {
  Mesh m;
  m.add(-1, -1, 0), m.add(1, -1, 0), m.add(1, 1, 0), m.add(-1, 1, 0);
  m.triangles = {0, 1, 2, 0, 2, 3};
  RayScene scene;
  fill(scene, m);
  const double origin[3] = {0, 0, 0};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (double side : {5.0, -5.0}) {
    for (int i = 0; i < 4; ++i) {
      const double eye[3] = {u(rng), u(rng), side};
      const Camera camera = core::look_at(eye, origin, 40, 32);
      const ViewImage image = cast({&scene}, camera);
      unsigned covered = 0;
      for (uint64_t p = 0; p < 32u * 32u; ++p) {
        if (!image.covered(p)) continue;
        ++covered;
        const V3 n = {image.normal[3 * p], image.normal[3 * p + 1], image.normal[3 * p + 2]};
        EXPECT_NEAR(norm(n), 1, 1e-6);
        EXPECT_LT(dot(n, V3{camera.forward[0], camera.forward[1], camera.forward[2]}), 0);
        EXPECT_NEAR(n[2], side > 0 ? 1 : -1, 1e-6);
      }
      EXPECT_GT(covered, 0u);
    }
  }
}

// A segment along x from -2 to 2 of radius r, seen from directions around its axis (always side on): along
// the image line through the centre, across the segment, the covered run is 2r / pixel_size pixels (± 1).
TEST(CastView, SegmentFromTheSideIsABandTwoRadiiWide) {
  for (float r : {0.2f, 0.07f}) {
    Mesh m;
    m.add(-2, 0, 0), m.add(2, 0, 0);
    m.edges = {0, 1};
    m.radius = {r};
    RayScene scene;
    fill(scene, m);
    const double origin[3] = {0, 0, 0}, distance = 5;
    for (double angle : {0.0, 0.4, 0.9, 1.5707963267948966, 2.2, 3.3, 4.0, 5.5}) {
      const double eye[3] = {0, distance * std::cos(angle), distance * std::sin(angle)};
      const Camera camera = core::look_at(eye, origin, 60, 101);
      const ViewImage image = cast({&scene}, camera);
      // The segment's direction on screen is the x axis projected on right/up.
      const bool horizontal = std::fabs(camera.right[0]) > std::fabs(camera.up[0]);
      ASSERT_GT(std::max(std::fabs(camera.right[0]), std::fabs(camera.up[0])), 1 - 1e-9);
      unsigned run = 0, total = 0;
      for (unsigned i = 0; i < 101; ++i) {
        const uint64_t p = horizontal ? uint64_t{i} * 101 + 50 : 50u * 101 + i;  // across the band
        run += image.covered(p);
        // Through the middle of the segment the ribbon is within r of the axis, at `distance`.
        if (image.covered(p)) {
          EXPECT_NEAR(image.depth[p], distance, r);
        }
      }
      for (uint64_t p = 0; p < 101u * 101u; ++p) {
        if (!image.covered(p)) continue;
        ++total;
        EXPECT_EQ(image.kind[p], uint8_t(PrimitiveKind::edge));
        // The ribbon's normal: perpendicular to the edge (x) and facing the ray, so in the plane of edge
        // and ray. Side on, that is -ray without its x part.
        const unsigned x = static_cast<unsigned>(p % 101), y = static_cast<unsigned>(p / 101);
        const V3 r_cam = pixel_ray(camera, x, y), ray = world_ray(camera, x, y);
        const V3 expected = V3{0, -ray[1], -ray[2]} * (1 / norm(V3{0, ray[1], ray[2]}));
        const V3 n = {image.normal[3 * p], image.normal[3 * p + 1], image.normal[3 * p + 2]};
        EXPECT_NEAR(norm(n), 1, 1e-5);
        EXPECT_NEAR(n[0], 0, 1e-5);
        EXPECT_NEAR(dot(n, expected), 1, 1e-5);
        EXPECT_LT(dot(n, ray), 0);
        // Depth along the unit ray: the ray meets the plane of the axis (at `distance` along the view)
        // after distance · |r_cam|, and the ribbon within r of that.
        EXPECT_NEAR(image.depth[p], distance * norm(r_cam), 1.5 * r);
      }
      const double width = 2 * r / camera.pixel_size(distance);
      EXPECT_NEAR(run, width, 1.0) << "r " << r << " angle " << angle;
      EXPECT_GT(total, 0u);
    }
  }
}

// A disc point of radius r at the origin covers about π (r / pixel)² pixels from any direction.
TEST(CastView, DiscPointCoversItsArea) {
  Mesh m;
  m.add(0, 0, 0);
  m.points = {0};
  m.point_radius = 0.5f;
  RayScene scene;
  fill(scene, m);
  const double origin[3] = {0, 0, 0}, distance = 8;
  for (unsigned k = 0; k < 8; ++k) {
    double dir[3];
    core::fibonacci_direction(k, 8, dir);
    const double eye[3] = {distance * dir[0], distance * dir[1], distance * dir[2]};
    const Camera camera = core::look_at(eye, origin, 30, 128);
    const ViewImage image = cast({&scene}, camera);
    unsigned covered = 0;
    for (uint64_t p = 0; p < 128u * 128u; ++p) {
      if (!image.covered(p)) continue;
      ++covered;
      EXPECT_EQ(image.kind[p], uint8_t(PrimitiveKind::point));
      EXPECT_NEAR(image.depth[p], distance, 0.5);  // within r of the centre's distance
      // The disc faces the ray: its normal is -ray.
      const V3 ray = world_ray(camera, static_cast<unsigned>(p % 128), static_cast<unsigned>(p / 128));
      const V3 n = {image.normal[3 * p], image.normal[3 * p + 1], image.normal[3 * p + 2]};
      EXPECT_NEAR(dot(n, ray), -1, 1e-5);
    }
    const double radius_px = 0.5 / camera.pixel_size(distance);  // ≈ 14.9 pixels
    const double expected = M_PI * radius_px * radius_px;
    EXPECT_NEAR(covered, expected, 0.03 * expected) << "view " << k;
  }
}

// Scene A: the square [-1,1]² at z = 0 (triangles). Scene B: a segment at z = 1, nearer the camera at
// z = 5, across the middle. Where B is in front, B's depth and kind win, in either order of the scenes; an
// empty scene in the list changes nothing.
TEST(CastView, TwoScenesGiveTheNearerHit) {
  Mesh a;
  a.add(-1, -1, 0), a.add(1, -1, 0), a.add(1, 1, 0), a.add(-1, 1, 0);
  a.triangles = {0, 1, 2, 0, 2, 3};
  Mesh b;
  b.add(-3, 0, 1), b.add(3, 0, 1);
  b.edges = {0, 1};
  b.radius = {0.1f};
  RayScene sa, sb, empty;
  fill(sa, a);
  fill(sb, b);
  empty.commit();
  const double eye[3] = {0, 0, 5}, origin[3] = {0, 0, 0};
  const Camera camera = core::look_at(eye, origin, 60, 64);
  uint64_t rays_ab = 0, rays_ba = 0;
  const ViewImage ab = cast({&sa, &sb}, camera, &rays_ab);
  const ViewImage ba = cast({&sb, &empty, &sa}, camera, &rays_ba);
  EXPECT_EQ(rays_ab, 2u * 64 * 64);
  EXPECT_EQ(rays_ba, 2u * 64 * 64);  // the empty scene casts nothing
  const ViewImage only_a = cast({&sa}, camera), only_b = cast({&sb}, camera);
  unsigned from_a = 0, from_b = 0;
  for (uint64_t p = 0; p < 64u * 64u; ++p) {
    const bool hit_b = only_b.covered(p);
    const ViewImage& winner = hit_b ? only_b : only_a;
    for (const ViewImage* both : {&ab, &ba}) {
      ASSERT_EQ(both->kind[p], winner.kind[p]) << p;
      ASSERT_EQ(both->depth[p], winner.depth[p]) << p;
      for (int k = 0; k < 3; ++k) ASSERT_EQ(both->normal[3 * p + k], winner.normal[3 * p + k]) << p;
    }
    if (hit_b) {
      ++from_b;
      EXPECT_EQ(ab.kind[p], uint8_t(PrimitiveKind::edge));
      // The segment's axis is 4 in front along the view axis; along this pixel's ray, further.
      const V3 r = pixel_ray(camera, static_cast<unsigned>(p % 64), static_cast<unsigned>(p / 64));
      EXPECT_NEAR(ab.depth[p], 4 * std::sqrt(1 + r[0] * r[0]), 0.1);
    } else if (only_a.covered(p)) {
      ++from_a;
      EXPECT_EQ(ab.kind[p], uint8_t(PrimitiveKind::triangle));
    }
  }
  EXPECT_GT(from_a, 100u);
  EXPECT_GT(from_b, 20u);
  // B occludes part of A: A's pixels under the segment are replaced.
  unsigned occluded = 0;
  for (uint64_t p = 0; p < 64u * 64u; ++p) occluded += only_a.covered(p) && only_b.covered(p);
  EXPECT_GT(occluded, 10u);
}

// A random scene of triangles, segments and points, cast in an arena of 1 and of 2 threads (and twice in
// each): byte-identical images.
TEST(CastView, ImagesDoNotDependOnThreads) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> u(-1, 1);
  Mesh m;
  for (int t = 0; t < 300; ++t) {
    const uint32_t a = m.add(u(rng), u(rng), u(rng));
    m.add(m.at(a)[0] + 0.3 * u(rng), m.at(a)[1] + 0.3 * u(rng), m.at(a)[2] + 0.3 * u(rng));
    m.add(m.at(a)[0] + 0.3 * u(rng), m.at(a)[1] + 0.3 * u(rng), m.at(a)[2] + 0.3 * u(rng));
    m.triangles.insert(m.triangles.end(), {a, a + 1, a + 2});
  }
  for (int e = 0; e < 100; ++e) {
    m.edges.insert(m.edges.end(), {static_cast<uint32_t>(3 * e), static_cast<uint32_t>(3 * e + 1)});
    m.radius.push_back(0.01f);
  }
  for (uint32_t k = 0; k < 100; ++k) m.points.push_back(3 * k + 2);
  m.point_radius = 0.015f;
  RayScene scene;
  fill(scene, m);
  const double eye[3] = {2.5, 1.5, 2}, origin[3] = {0, 0, 0};
  const Camera camera = core::look_at(eye, origin, 50, 130);  // not a multiple of the 4 × 4 tile
  auto cast_in = [&](int threads) {
    ViewImage image;
    tbb::task_arena arena(threads);
    arena.execute([&] {
      const RayScene* scenes[] = {&scene};
      core::cast_view(scenes, camera, &image);
    });
    return image;
  };
  const ViewImage one = cast_in(1), two = cast_in(2), two_again = cast_in(2), one_again = cast_in(1);
  unsigned kinds[4] = {};
  for (uint8_t k : one.kind) ++kinds[k];
  EXPECT_GT(kinds[1], 1000u);
  EXPECT_GT(kinds[2], 10u);
  EXPECT_GT(kinds[3], 10u);
  EXPECT_GT(kinds[0], 1000u);
  for (const ViewImage* other : {&two, &two_again, &one_again}) {
    ASSERT_EQ(other->depth.size(), one.depth.size());
    EXPECT_EQ(std::memcmp(other->depth.data(), one.depth.data(), one.depth.size() * sizeof(float)), 0);
    EXPECT_EQ(std::memcmp(other->normal.data(), one.normal.data(), one.normal.size() * sizeof(float)), 0);
    EXPECT_EQ(other->kind, one.kind);
  }
}

TEST(CastView, ZeroResolutionAndEmptySceneList) {
  RayScene scene;
  Mesh m;
  m.add(0, 0, 0), m.add(1, 0, 0), m.add(0, 1, 0);
  m.triangles = {0, 1, 2};
  fill(scene, m);
  Camera camera;
  camera.eye[2] = -3;
  camera.resolution = 0;
  ViewImage image;
  image.depth = {1, 2, 3};
  const RayScene* scenes[] = {&scene};
  core::cast_view(scenes, camera, &image);
  EXPECT_EQ(image.resolution, 0u);
  EXPECT_TRUE(image.depth.empty());
  EXPECT_TRUE(image.kind.empty());
  camera.resolution = 8;
  EXPECT_EQ(core::cast_view(std::span<const RayScene* const>(), camera, &image), 0u);
  EXPECT_EQ(image.kind, std::vector<uint8_t>(64, 0));
  EXPECT_EQ(image.depth, std::vector<float>(64, std::numeric_limits<float>::infinity()));
}

}  // namespace
}  // namespace lodstream

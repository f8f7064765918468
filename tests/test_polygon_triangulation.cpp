// core/polygon_triangulation: exact small polygons (concave, collinear, repeated positions, non-planar,
// self-intersecting) and real faces of the furniture and IFC models in ../shared/data. A triangulation is
// checked against the polygon in its own plane: the triangles' areas sum to the polygon's, each triangle's
// centroid is inside the polygon, no triangle edge crosses a polygon edge, and no two triangles overlap
// (intersection area above 1e-9 of the polygon's).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/polygon_triangulation.h"
#include "test_util.h"

namespace lodstream {
namespace {

using core::Triangulation;

struct P2 {
  double x, y;
};

double cross2(P2 a, P2 b, P2 c) { return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x); }

// Even-odd point in polygon.
bool inside(const std::vector<P2>& poly, P2 p) {
  bool in = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const P2 a = poly[i], b = poly[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) in = !in;
  }
  return in;
}

// Segments ab and cd cross at a point interior to both.
bool proper_cross(P2 a, P2 b, P2 c, P2 d, double eps) {
  const double d1 = cross2(a, b, c), d2 = cross2(a, b, d), d3 = cross2(c, d, a), d4 = cross2(c, d, b);
  return ((d1 > eps && d2 < -eps) || (d1 < -eps && d2 > eps)) && ((d3 > eps && d4 < -eps) || (d3 < -eps && d4 > eps));
}

// Area of the intersection of two counter-clockwise triangles: t clipped by the three half-planes of u
// (Sutherland-Hodgman).
double overlap_area(const P2* t, const P2* u) {
  std::vector<P2> poly(t, t + 3), next;
  for (int e = 0; e < 3 && !poly.empty(); ++e) {
    const P2 a = u[e], b = u[(e + 1) % 3];
    next.clear();
    for (size_t i = 0; i < poly.size(); ++i) {
      const P2 p = poly[i], q = poly[(i + 1) % poly.size()];
      const double dp = cross2(a, b, p), dq = cross2(a, b, q);
      if (dp >= 0) next.push_back(p);
      if ((dp >= 0) != (dq >= 0)) {
        const double s = dp / (dp - dq);
        next.push_back({p.x + s * (q.x - p.x), p.y + s * (q.y - p.y)});
      }
    }
    poly.swap(next);
  }
  double area = 0;
  for (size_t i = 0; i < poly.size(); ++i) area += cross2(P2{0, 0}, poly[i], poly[(i + 1) % poly.size()]) / 2;
  return area;
}

// The polygon's corners projected onto its plane, counter-clockwise: by an orthonormal basis of the Newell
// plane (independent of the projection the algorithm uses, equivalent for planar polygons), or, for
// non-planar faces, along the normal's largest axis, the projection the face was triangulated in.
std::vector<P2> plane_coordinates(const std::vector<double>& xyz, bool along_axis) {
  const size_t n = xyz.size() / 3;
  double nm[3] = {0, 0, 0};
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    const double* a = &xyz[3 * i];
    const double* b = &xyz[3 * j];
    nm[0] += (a[1] - b[1]) * (a[2] + b[2]);
    nm[1] += (a[2] - b[2]) * (a[0] + b[0]);
    nm[2] += (a[0] - b[0]) * (a[1] + b[1]);
  }
  const size_t n3 = xyz.size() / 3;
  if (along_axis) {
    int k = 0;
    for (int a = 1; a < 3; ++a)
      if (std::fabs(nm[a]) > std::fabs(nm[k])) k = a;
    const int a = (k + 1) % 3, b = (k + 2) % 3;
    const double mirror = nm[k] > 0 ? 1 : -1;
    std::vector<P2> p(n3);
    for (size_t i = 0; i < n3; ++i) p[i] = {xyz[3 * i + a], mirror * xyz[3 * i + b]};
    return p;
  }
  const double len = std::sqrt(nm[0] * nm[0] + nm[1] * nm[1] + nm[2] * nm[2]);
  for (double& c : nm) c /= len;
  // u: any unit vector orthogonal to the normal; v = n x u.
  double u[3] = {0, 0, 0};
  const int k = std::fabs(nm[0]) < 0.6 ? 0 : 1;
  u[k] = 1;
  const double d = u[0] * nm[0] + u[1] * nm[1] + u[2] * nm[2];
  for (int a = 0; a < 3; ++a) u[a] -= d * nm[a];
  const double ul = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
  for (double& c : u) c /= ul;
  const double v[3] = {nm[1] * u[2] - nm[2] * u[1], nm[2] * u[0] - nm[0] * u[2], nm[0] * u[1] - nm[1] * u[0]};
  std::vector<P2> p(n);
  for (size_t i = 0; i < n; ++i) {
    const double* q = &xyz[3 * i];
    p[i] = {q[0] * u[0] + q[1] * u[1] + q[2] * u[2], q[0] * v[0] + q[1] * v[1] + q[2] * v[2]};
  }
  return p;
}

struct Check {
  double polygon_area = 0, triangle_area = 0;
  int outside = 0, crossing = 0, overlapping = 0, clockwise = 0;
};

Check check(const std::vector<double>& xyz, const std::vector<uint32_t>& tri, bool along_axis = false) {
  const std::vector<P2> p = plane_coordinates(xyz, along_axis);
  const size_t n = p.size();
  double extent = 0;
  for (const P2& q : p)
    for (const P2& r : p) extent = std::max({extent, std::fabs(q.x - r.x), std::fabs(q.y - r.y)});
  const double eps = 1e-9 * extent * extent;
  Check c;
  for (size_t i = 0; i < n; ++i) c.polygon_area += cross2(P2{0, 0}, p[i], p[(i + 1) % n]) / 2;
  // Two triangles overlap when their intersection has more than rounding's area.
  const double overlap_limit = 1e-9 * std::fabs(c.polygon_area);
  const size_t t = tri.size() / 3;
  for (size_t i = 0; i < t; ++i) {
    const P2 a = p[tri[3 * i]], b = p[tri[3 * i + 1]], d = p[tri[3 * i + 2]];
    const double area = cross2(a, b, d) / 2;
    c.triangle_area += std::fabs(area);
    if (area < -eps) ++c.clockwise;
    if (std::fabs(area) <= eps) continue;  // zero-area triangles (collinear corners) have no inside
    if (!inside(p, P2{(a.x + b.x + d.x) / 3, (a.y + b.y + d.y) / 3})) ++c.outside;
    const P2 e[3] = {a, b, d};
    for (int k = 0; k < 3; ++k)
      for (size_t j = 0; j < n; ++j)
        if (proper_cross(e[k], e[(k + 1) % 3], p[j], p[(j + 1) % n], eps)) ++c.crossing;
    for (size_t j = i + 1; j < t; ++j) {
      const P2 f[3] = {p[tri[3 * j]], p[tri[3 * j + 1]], p[tri[3 * j + 2]]};
      if (std::fabs(cross2(f[0], f[1], f[2])) > eps && overlap_area(e, f) > overlap_limit) ++c.overlapping;
    }
  }
  return c;
}

std::vector<double> flat(const std::vector<P2>& p) {
  std::vector<double> xyz;
  for (const P2& q : p) xyz.insert(xyz.end(), {q.x, q.y, 0.0});
  return xyz;
}

// The same polygon in a tilted plane far from the origin: rotated about x by 30 degrees and about z by
// 50 degrees, moved by (1000, -2000, 500).
std::vector<double> tilted(const std::vector<P2>& p) {
  const double a = 30 * M_PI / 180, b = 50 * M_PI / 180;
  std::vector<double> xyz;
  for (const P2& q : p) {
    const double x = q.x, y = q.y * std::cos(a), z = q.y * std::sin(a);
    xyz.insert(xyz.end(), {x * std::cos(b) - y * std::sin(b) + 1000, x * std::sin(b) + y * std::cos(b) - 2000, z + 500});
  }
  return xyz;
}

Triangulation run(const std::vector<double>& xyz, std::vector<uint32_t>* tri) {
  const uint32_t n = static_cast<uint32_t>(xyz.size() / 3);
  tri->assign(3 * (n - 2), UINT32_MAX);
  core::PolygonScratch scratch;
  return core::triangulate_polygon(xyz.data(), n, tri->data(), &scratch);
}

// Triangulates the polygon flat, tilted and reversed (clockwise), and checks each result.
void expect_valid(const std::vector<P2>& poly, Triangulation expected) {
  std::vector<P2> reversed(poly.rbegin(), poly.rend());
  for (const auto& [name, xyz] : {std::pair{"flat", flat(poly)}, std::pair{"tilted", tilted(poly)},
                                  std::pair{"reversed", tilted(reversed)}}) {
    SCOPED_TRACE(name);
    std::vector<uint32_t> tri;
    const Triangulation how = run(xyz, &tri);
    if (std::string(name) != "reversed") {
      EXPECT_EQ(how, expected);
    }
    for (uint32_t k : tri) ASSERT_LT(k, xyz.size() / 3);
    const Check c = check(xyz, tri);
    EXPECT_NEAR(c.triangle_area, std::fabs(c.polygon_area), 1e-9 * std::fabs(c.polygon_area));
    EXPECT_EQ(c.outside, 0);
    EXPECT_EQ(c.crossing, 0);
    EXPECT_EQ(c.overlapping, 0);
    // Same orientation as the ring: no triangle turns against the polygon (the check's plane follows the
    // ring's Newell normal, so the polygon is counter-clockwise in it).
    EXPECT_GT(c.polygon_area, 0);
    EXPECT_EQ(c.clockwise, 0);
  }
}

TEST(PolygonTriangulation, ConvexPolygonsKeepTheFan) {
  for (const std::vector<P2>& poly :
       {std::vector<P2>{{0, 0}, {2, 0}, {2, 1}, {0, 1}}, std::vector<P2>{{0, 0}, {2, 0}, {3, 1}, {1, 3}, {-1, 1}}}) {
    std::vector<uint32_t> tri;
    EXPECT_EQ(run(tilted(poly), &tri), Triangulation::fan);
    std::vector<uint32_t> fan;
    for (uint32_t i = 1; i + 1 < poly.size(); ++i) fan.insert(fan.end(), {0, i, i + 1});
    EXPECT_EQ(tri, fan);
  }
}

TEST(PolygonTriangulation, ConcaveQuadTakesTheInsideDiagonal) {
  // A dart: corner 1 is reflex, so the fan's diagonal 0-2 lies outside.
  const std::vector<P2> dart{{0, 0}, {1, 1}, {2, 0}, {1, 3}};
  std::vector<uint32_t> tri;
  EXPECT_EQ(run(flat(dart), &tri), Triangulation::diagonal);
  EXPECT_EQ(tri, (std::vector<uint32_t>{0, 1, 3, 1, 2, 3}));
  expect_valid(dart, Triangulation::diagonal);
  // Reflex corner 0: the fan's own diagonal is the inside one.
  const std::vector<P2> dart0{{1, 1}, {2, 0}, {1, 3}, {0, 0}};
  EXPECT_EQ(run(flat(dart0), &tri), Triangulation::fan);
}

TEST(PolygonTriangulation, LShapedHexagon) {
  // The L of a slab: the fan from corner 0 = (0,0) would cut across the notch.
  expect_valid({{2, 2}, {1, 2}, {1, 1}, {0, 1}, {0, 0}, {2, 0}}, Triangulation::ear_clipping);
  // Starting at the reflex corner, the fan is inside: kept.
  expect_valid({{1, 1}, {0, 1}, {0, 0}, {2, 0}, {2, 2}, {1, 2}}, Triangulation::fan);
}

TEST(PolygonTriangulation, FanOfAnLShapeLeavesIt) {
  // What the old fan did: the same L, fanned from corner 0, covers area outside the slab.
  const std::vector<double> xyz = flat({{2, 2}, {1, 2}, {1, 1}, {0, 1}, {0, 0}, {2, 0}});
  const std::vector<uint32_t> fan{0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5};
  const Check c = check(xyz, fan);
  EXPECT_NEAR(c.polygon_area, 3.0, 1e-12);
  EXPECT_GT(c.triangle_area, 3.0 + 0.5);
}

TEST(PolygonTriangulation, NotchedOctagon) {
  // A rectangle with a rectangular notch cut into its top side.
  expect_valid({{0, 0}, {4, 0}, {4, 3}, {3, 3}, {3, 1}, {1, 1}, {1, 3}, {0, 3}}, Triangulation::ear_clipping);
  // And one notched from the side of corner 0.
  expect_valid({{0, 3}, {0, 0}, {4, 0}, {4, 3}, {3, 3}, {3, 1}, {1, 1}, {1, 3}}, Triangulation::ear_clipping);
}

TEST(PolygonTriangulation, UShape) {
  expect_valid({{3, 3}, {2, 3}, {2, 1}, {1, 1}, {1, 3}, {0, 3}, {0, 0}, {3, 0}}, Triangulation::ear_clipping);
}

TEST(PolygonTriangulation, CollinearCorners) {
  // An L with extra corners in the middle of its sides, one on each side of the reflex corner.
  expect_valid({{2, 2}, {1.5, 2}, {1, 2}, {1, 1.5}, {1, 1}, {0.5, 1}, {0, 1}, {0, 0}, {1, 0}, {2, 0}, {2, 1}},
               Triangulation::ear_clipping);
  // A convex square with a midpoint: still the fan (a zero-area fan triangle is no area outside).
  expect_valid({{0, 0}, {1, 0}, {2, 0}, {2, 2}, {0, 2}}, Triangulation::fan);
}

TEST(PolygonTriangulation, RepeatedPositionKeyhole) {
  // A square with a square hole, joined by a bridge: corners 0 and 5, 6 and 11 are the same positions
  // (distinct vertices of the file). Area = 16 - 4.
  const std::vector<P2> keyhole{{0, 0}, {4, 0}, {4, 4}, {0, 4}, {0, 0}, {1, 1},
                                {1, 3}, {3, 3}, {3, 1}, {1, 1}};
  std::vector<uint32_t> tri;
  const std::vector<double> xyz = flat(keyhole);
  EXPECT_EQ(run(xyz, &tri), Triangulation::ear_clipping);
  const Check c = check(xyz, tri);
  EXPECT_NEAR(c.polygon_area, 12.0, 1e-12);
  EXPECT_NEAR(c.triangle_area, 12.0, 1e-9);
  EXPECT_EQ(c.overlapping, 0);
  EXPECT_EQ(c.clockwise, 0);
}

TEST(PolygonTriangulation, NonPlanarQuadKeepsTheFan) {
  // A twisted quad (z of two opposite corners raised): convex seen along its Newell normal.
  const std::vector<double> xyz{0, 0, 0, 1, 0, 0.3, 1, 1, 0, 0, 1, 0.3};
  std::vector<uint32_t> tri;
  EXPECT_EQ(run(xyz, &tri), Triangulation::fan);
  EXPECT_EQ(tri, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
  // A non-planar concave quad: the reflex corner 1 decides, as in the plane.
  const std::vector<double> dart{0, 0, 0, 1, 1, 0.2, 2, 0, 0, 1, 3, -0.2};
  EXPECT_EQ(run(dart, &tri), Triangulation::diagonal);
}

TEST(PolygonTriangulation, SelfIntersectingBowTieFallsBackToTheFan) {
  const std::vector<double> bowtie = flat({{0, 0}, {2, 2}, {2, 0}, {0, 2}});
  std::vector<uint32_t> tri;
  EXPECT_EQ(run(bowtie, &tri), Triangulation::fallback);
  EXPECT_EQ(tri, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
  // A self-intersecting hexagon on which ear clipping runs to the end, with triangles whose areas exceed
  // the polygon's: the fan too.
  const std::vector<double> bent = flat({{0, 0}, {3, 0}, {3, 2}, {1, -1}, {1, 3}, {0, 3}});
  EXPECT_EQ(run(bent, &tri), Triangulation::fallback);
  EXPECT_EQ(tri, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5}));
}

TEST(PolygonTriangulation, CollinearRingHasNoPlane) {
  const std::vector<double> line = flat({{0, 0}, {1, 0}, {2, 0}, {3, 0}});
  std::vector<uint32_t> tri;
  EXPECT_EQ(run(line, &tri), Triangulation::fallback);
  EXPECT_EQ(tri, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
}

TEST(PolygonTriangulation, ScaleDoesNotChangeTheResult) {
  const std::vector<P2> u{{3, 3}, {2, 3}, {2, 1}, {1, 1}, {1, 3}, {0, 3}, {0, 0}, {3, 0}};
  std::vector<uint32_t> reference, tri;
  run(flat(u), &reference);
  for (double s : {1e-6, 1e-3, 1e3, 1e7}) {
    std::vector<P2> scaled;
    for (const P2& q : u) scaled.push_back({q.x * s, q.y * s});
    run(flat(scaled), &tri);
    EXPECT_EQ(tri, reference) << s;
  }
}

// Faces of 4+ corners (distinct vertices) of an OBJ file, by a minimal reader of v and f.
struct ObjFaces {
  std::vector<double> positions;
  std::vector<std::vector<uint32_t>> faces;
};

ObjFaces obj_faces(const std::string& path) {
  ObjFaces r;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key == "v") {
      double x, y, z;
      s >> x >> y >> z;
      r.positions.insert(r.positions.end(), {x, y, z});
    } else if (key == "f") {
      std::vector<uint32_t> face;
      std::string token;
      while (s >> token) {
        const long i = std::stol(token.substr(0, token.find('/')));
        face.push_back(static_cast<uint32_t>(i > 0 ? i - 1 : static_cast<long>(r.positions.size() / 3) + i));
      }
      std::vector<uint32_t> sorted = face;
      std::sort(sorted.begin(), sorted.end());
      if (face.size() >= 4 && std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end())
        r.faces.push_back(std::move(face));
    }
  }
  return r;
}

TEST(PolygonTriangulation, RealFacesOfSharedModels) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  // The IFC buildings come tessellated: every face is a triangle, none to check here (the figure is in
  // README). The furniture has n-gons of up to 272 corners, hundreds of them concave.
  uint64_t building_ngons = 0;
  for (const auto& e : std::filesystem::directory_iterator(data + "/buildings"))
    if (e.path().extension() == ".obj") building_ngons += obj_faces(e.path().string()).faces.size();
  std::printf("IFC buildings: %llu faces of 4+ corners\n", static_cast<unsigned long long>(building_ngons));

  uint64_t checked = 0, concave = 0, fallback = 0, bad = 0;
  for (const char* model : {"peterbilt", "antiqueChair", "pedestrianRailing2", "shippingContainer", "cartoon_biplane"}) {
    const ObjFaces m = obj_faces(data + "/furniture-cc0/" + model + "/" + model + ".obj");
    ASSERT_FALSE(m.faces.empty()) << model;
    std::vector<double> xyz;
    std::vector<uint32_t> tri;
    for (const std::vector<uint32_t>& face : m.faces) {
      xyz.clear();
      for (uint32_t v : face) xyz.insert(xyz.end(), &m.positions[3 * v], &m.positions[3 * v + 3]);
      const Triangulation how = run(xyz, &tri);
      if (how == Triangulation::fan) continue;
      if (how == Triangulation::fallback) {
        ++fallback;
        continue;
      }
      ++concave;
      // Real faces are not quite planar: checked in the projection they were triangulated in.
      const Check c = check(xyz, tri, true);
      ++checked;
      const bool ok = std::fabs(c.triangle_area - std::fabs(c.polygon_area)) <= 1e-6 * std::fabs(c.polygon_area) &&
                      c.outside == 0 && c.overlapping == 0;
      if (!ok) {
        ++bad;
        ADD_FAILURE() << model << ": face of " << face.size() << " corners: area " << c.triangle_area << " vs "
                      << c.polygon_area << ", " << c.outside << " outside, " << c.overlapping << " overlapping";
        if (bad > 5) return;
      }
    }
  }
  std::printf("furniture: %llu concave faces checked, %llu fallbacks (self-intersecting or no plane)\n",
              static_cast<unsigned long long>(checked), static_cast<unsigned long long>(fallback));
  EXPECT_GT(concave, 1000u);
}

}  // namespace
}  // namespace lodstream

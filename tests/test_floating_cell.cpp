// Vertex clustering (core/floating_cell.h): hand-placed configurations with exact cell ids, Low & Tan's
// Figure 4 and Plate 5, levels run together or apart, and a brute-force reference on random and lattice
// clouds. In every test the vertex ids are 0, 1, 2, ... in weight order (heaviest first).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <span>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "core/floating_cell.h"
#include "core/hash.h"
#include "core/status.h"
#include "test_util.h"

namespace lodstream {
namespace {

using core::CellChoice;
using core::CellShape;
using core::Clusterer;
using core::ClusterOptions;
using core::Clustering;
using P = std::array<double, 3>;

constexpr ClusterOptions kCubeNearest{Clustering::floating, CellShape::cube, CellChoice::nearest};
constexpr ClusterOptions kCubeHeaviest{Clustering::floating, CellShape::cube, CellChoice::heaviest};
constexpr ClusterOptions kSphereNearest{Clustering::floating, CellShape::sphere, CellChoice::nearest};
constexpr ClusterOptions kSphereHeaviest{Clustering::floating, CellShape::sphere, CellChoice::heaviest};
constexpr ClusterOptions kUniform{Clustering::uniform, CellShape::cube, CellChoice::nearest};
constexpr ClusterOptions kFloatingVariants[] = {kCubeNearest, kCubeHeaviest, kSphereNearest, kSphereHeaviest};

// cells[l][v]: the cell of vertex v (id v, in weight order) in level l.
std::vector<std::vector<uint32_t>> run(Clusterer& clusterer, const std::vector<P>& points) {
  std::vector<std::vector<uint32_t>> cells(clusterer.levels(), std::vector<uint32_t>(points.size()));
  std::vector<uint32_t> out(clusterer.levels());
  for (size_t v = 0; v < points.size(); ++v) {
    clusterer.assign(static_cast<uint32_t>(v), points[v], out);
    for (size_t l = 0; l < out.size(); ++l) cells[l][v] = out[l];
  }
  return cells;
}

std::vector<uint32_t> run1(double size, ClusterOptions options, const std::vector<P>& points) {
  Clusterer clusterer(std::span<const double>(&size, 1), options);
  return run(clusterer, points)[0];
}

std::vector<P> random_cloud(size_t n, uint32_t seed, double lo = 0, double hi = 1) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<P> points(n);
  for (P& p : points) p = {u(rng), u(rng), u(rng)};
  return points;
}

// The definition in floating_cell.h, cell by cell over every cell: O(n · cells). Cell ids are creation
// order. Per-axis differences use fabs(fl(x − cx)) <= h, which equals the exact test whenever the
// differences are exact (the lattice) and differs only with probability ~2^-52 elsewhere (random clouds).
std::vector<uint32_t> brute_force(double size, ClusterOptions options, const std::vector<P>& points) {
  const double h = size / 2;
  std::vector<P> centers;
  std::vector<uint32_t> cells;
  for (const P& p : points) {
    uint32_t best = core::kNoCell;
    double best_d2 = 0;
    for (uint32_t c = 0; c < centers.size(); ++c) {
      const double dx = p[0] - centers[c][0], dy = p[1] - centers[c][1], dz = p[2] - centers[c][2];
      if (std::fabs(dx) > h || std::fabs(dy) > h || std::fabs(dz) > h) continue;
      const double d2 = dx * dx + dy * dy + dz * dz;
      if (options.shape == CellShape::sphere && d2 > h * h) continue;
      if (best == core::kNoCell) {
        best = c, best_d2 = d2;  // lowest id first: heaviest needs nothing more
      } else if (options.choice == CellChoice::nearest && d2 < best_d2) {
        best = c, best_d2 = d2;
      }
    }
    if (best == core::kNoCell) {
      best = static_cast<uint32_t>(centers.size());
      centers.push_back(p);
    }
    cells.push_back(best);
  }
  return cells;
}

// The vertex that created `cell` (its center): the first one assigned to it.
uint32_t center_vertex(const std::vector<uint32_t>& cells, uint32_t cell) {
  return static_cast<uint32_t>(std::find(cells.begin(), cells.end(), cell) - cells.begin());
}

// Most cell centers in one grid square, tallied independently of the clusterer's own counter.
uint32_t max_centers_per_square(const Clusterer& clusterer, size_t level, const std::vector<uint32_t>& cells,
                                const std::vector<P>& points) {
  std::map<std::tuple<int64_t, int64_t, int64_t>, uint32_t> count;
  std::vector<bool> seen(clusterer.cell_count(level), false);
  uint32_t most = 0;
  const double c = clusterer.cell_size(level);
  for (size_t v = 0; v < points.size(); ++v) {
    if (seen[cells[v]]) continue;
    seen[cells[v]] = true;
    const P& q = points[v];
    most = std::max(most, ++count[{core::grid_square(q[0], c), core::grid_square(q[1], c),
                                   core::grid_square(q[2], c)}]);
  }
  return most;
}

TEST(FloatingCell, CubeHandPlaced) {
  // c = 2, so a cube cell reaches 1 from its center on each axis (boundary inside). Seen along z = 0
  // (x to the right), centers marked C:
  //
  //   v7 just beyond (-1,-1,-1)   C0=v0 ---- v6 v3 ---- C1=v2 ---- v5 ---- C2=v4
  //                              x=0      0.75 0.9     1.5      2.5       3
  //   v1 = (1, 1, 1): the corner of cell 0, exactly on its boundary.
  //   v3 is in cells 0 and 1, nearer 1. v5 = (2.5, 0.5, 0) is in cell 1 (exactly at dx = 1) and cell 2,
  //   nearer 2. v6 is exactly as near to cell 0 as to cell 1: the lower id wins in both modes.
  const std::vector<P> points = {
      {0, 0, 0},   {1, 1, 1},   {1.5, 0, 0},    {0.9, 0, 0},
      {3, 0, 0},   {2.5, 0.5, 0}, {0.75, 0, 0}, {-1, -1, std::nextafter(-1.0, -2.0)},
  };
  EXPECT_EQ(run1(2, kCubeNearest, points), (std::vector<uint32_t>{0, 0, 1, 1, 2, 2, 0, 3}));
  EXPECT_EQ(run1(2, kCubeHeaviest, points), (std::vector<uint32_t>{0, 0, 1, 0, 2, 1, 0, 3}));

  Clusterer clusterer(std::vector<double>{2}, kCubeNearest);
  const std::vector<uint32_t> cells = run(clusterer, points)[0];
  ASSERT_EQ(clusterer.cell_count(0), 4u);
  EXPECT_EQ(center_vertex(cells, 0), 0u);
  EXPECT_EQ(center_vertex(cells, 1), 2u);
  EXPECT_EQ(center_vertex(cells, 2), 4u);
  EXPECT_EQ(center_vertex(cells, 3), 7u);
}

TEST(FloatingCell, SphereHandPlaced) {
  // c = 10: balls of radius 5. In the plane z = 0:
  //
  //        y
  //   4 |        v1 (3,4)  C1=v2 (4,4)        v1 is exactly on ball 0's surface (3-4-5): inside.
  //   3 |           v3 (3,3)                  v2 is inside cube 0 but outside ball 0 (√32 > 5): a center.
  //     C0=v0 ----------- x                   v3 is in both balls, nearer ball 1.
  //  -4 | v4 (-3,-4)                          v4: on the surface again, at negative coordinates.
  //   v5 = (0, 0, 5) on the surface; v6 one ulp beyond it: a new cell.
  const double beyond = std::nextafter(5.0, 6.0);
  const std::vector<P> points = {{0, 0, 0},   {3, 4, 0}, {4, 4, 0},     {3, 3, 0},
                                 {-3, -4, 0}, {0, 0, 5}, {0, 0, beyond}};
  EXPECT_EQ(run1(10, kSphereNearest, points), (std::vector<uint32_t>{0, 0, 1, 1, 0, 0, 2}));
  EXPECT_EQ(run1(10, kSphereHeaviest, points), (std::vector<uint32_t>{0, 0, 1, 0, 0, 0, 2}));
  // The cube of side 10 holds all but the last.
  EXPECT_EQ(run1(10, kCubeNearest, points), (std::vector<uint32_t>{0, 0, 0, 0, 0, 0, 1}));
}

TEST(FloatingCell, BoundaryDecidedOnTheExactDifference) {
  // fl(x − cx) can round onto c/2 when the exact difference is just beyond it. c = 2, center at 2^-60:
  // the vertex at 1 is 1 − 2^-60 away (inside, and fl(1 − 2^-60) = 1); the vertex at −1 is 1 + 2^-60 away
  // (outside, although fl(−1 − 2^-60) = −1 as well).
  const double tiny = 0x1p-60;
  ASSERT_EQ(-1.0 - tiny, -1.0);
  const std::vector<P> points = {{tiny, 0, 0}, {1, 0, 0}, {-1, 0, 0}};
  for (const ClusterOptions& o : kFloatingVariants) EXPECT_EQ(run1(2, o, points), (std::vector<uint32_t>{0, 0, 1}));
}

TEST(FloatingCell, Figure4ThinTriangleStaysThin) {
  // Low & Tan's Figure 4, c = 2 (cubes reach 1 from their centers):
  //
  //   V1 ------------------- V3 ---------- V2      V1 = (0, 0, 0) heavier than V2 = (1.6, 0, 0);
  //   |<-------- C1 -------->|                     V3 = (0.95, 0.05, 0) lies in both cells,
  //                  |<-------- C2 -------->|      0.95 from V1 but 0.65 from V2.
  //
  // heaviest puts V3 with V1: the representatives (means) R1 = (V1 + V3)/2 and R2 = V2 then span a wide
  // triangle with the rest of the mesh; nearest puts V3 with V2, keeping the thin triangle thin.
  const std::vector<P> points = {{0, 0, 0}, {1.6, 0, 0}, {0.95, 0.05, 0}};
  EXPECT_EQ(run1(2, kCubeHeaviest, points), (std::vector<uint32_t>{0, 1, 0}));
  EXPECT_EQ(run1(2, kCubeNearest, points), (std::vector<uint32_t>{0, 1, 1}));
  EXPECT_EQ(run1(2, kSphereHeaviest, points), (std::vector<uint32_t>{0, 1, 0}));
  EXPECT_EQ(run1(2, kSphereNearest, points), (std::vector<uint32_t>{0, 1, 1}));
}

TEST(FloatingCell, LevelsTogetherEqualLevelsApart) {
  const std::vector<P> points = random_cloud(20000, 7);
  const std::vector<double> sizes = {0.02, 0.05, 0.1, 0.2, 0.4};
  for (const ClusterOptions& o : {kCubeNearest, kCubeHeaviest, kSphereNearest, kSphereHeaviest, kUniform}) {
    Clusterer together(sizes, o);
    const auto all = run(together, points);
    for (size_t l = 0; l < sizes.size(); ++l) {
      Clusterer alone(std::span<const double>(&sizes[l], 1), o);
      EXPECT_EQ(run(alone, points)[0], all[l]) << "level " << l;
      EXPECT_EQ(alone.cell_count(0), together.cell_count(l));
    }
  }
}

// A's vertices (ids 0 .. nA−1 in A's own weight order) clustered alone and interleaved with B's.
struct Plate5 {
  std::vector<P> a, b;
  std::vector<P> merged;              // the weight order of A ∪ B
  std::vector<uint32_t> merged_of_a;  // position of A's vertex i in `merged`
};

Plate5 make_plate5(double size) {
  Plate5 s;
  s.a = random_cloud(3000, 11);                              // the tree: a unit cube of points
  s.b = random_cloud(3000, 12, -1000 * size, -999 * size);  // the pot, 1000 cell sizes away
  // Interleave by random grades: A keeps its own relative order, as it would in a sort of A ∪ B.
  std::mt19937_64 rng(13);
  std::vector<bool> from_a(s.a.size() + s.b.size(), false);
  std::fill(from_a.begin(), from_a.begin() + static_cast<std::ptrdiff_t>(s.a.size()), true);
  std::shuffle(from_a.begin(), from_a.end(), rng);
  size_t ia = 0, ib = 0;
  for (bool is_a : from_a) {
    if (is_a) {
      s.merged_of_a.push_back(static_cast<uint32_t>(s.merged.size()));
      s.merged.push_back(s.a[ia++]);
    } else {
      s.merged.push_back(s.b[ib++]);
    }
  }
  return s;
}

// For each vertex of A: the position of its cell's center. Equal vectors mean equal cells (centers differ
// between cells of a level) and equal grouping, whatever the ids.
std::vector<P> centers_of_a(const std::vector<P>& points, const std::vector<uint32_t>& cells,
                            const std::vector<uint32_t>& index_of_a) {
  std::vector<P> out;
  for (uint32_t i : index_of_a) out.push_back(points[center_vertex(cells, cells[i])]);
  return out;
}

TEST(FloatingCell, Plate5DistantObjectChangesNothing) {
  const double size = 0.1;
  const Plate5 s = make_plate5(size);
  std::vector<uint32_t> identity(s.a.size());
  std::iota(identity.begin(), identity.end(), 0u);
  for (const ClusterOptions& o : {kCubeNearest, kCubeHeaviest, kSphereNearest, kSphereHeaviest, kUniform}) {
    Clusterer alone(std::span<const double>(&size, 1), o), both(std::span<const double>(&size, 1), o);
    const auto cells_alone = run(alone, s.a)[0];
    const auto cells_both = run(both, s.merged)[0];
    EXPECT_EQ(centers_of_a(s.a, cells_alone, identity), centers_of_a(s.merged, cells_both, s.merged_of_a));
    EXPECT_GT(both.cell_count(0), alone.cell_count(0));  // B did get cells of its own
  }
}

TEST(FloatingCell, Plate5BoundingBoxAnchoredGridWouldChange) {
  // Uniform subdivision with c = 0.25 of the tree A = {x = 0.1, 0.3} (y = z = 0), with and without the pot
  // B at x = −1000.05:
  //   anchored at A's bounding box (min x = 0.1):      (0.1 − 0.1)/0.25 = 0,  (0.3 − 0.1)/0.25 = 0.8
  //                                                     → both in square 0: one cluster;
  //   anchored at A ∪ B's box (min x = −1000.05):      1000.15/0.25 = 4000.6, 1000.35/0.25 = 4001.4
  //                                                     → squares 4000 and 4001: two clusters;
  //   anchored at the origin, with or without B:        0.1/0.25 = 0.4, 0.3/0.25 = 1.2 → squares 0 and 1.
  const double c = 0.25;
  auto square = [&](double x, double anchor) { return static_cast<int64_t>(std::floor((x - anchor) / c)); };
  EXPECT_EQ(square(0.1, 0.1), square(0.3, 0.1));
  EXPECT_NE(square(0.1, -1000.05), square(0.3, -1000.05));

  const std::vector<P> a = {{0.1, 0, 0}, {0.3, 0, 0}};
  const std::vector<P> ab = {{0.1, 0, 0}, {-1000.05, 0, 0}, {0.3, 0, 0}};
  EXPECT_EQ(run1(c, kUniform, a), (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(run1(c, kUniform, ab), (std::vector<uint32_t>{0, 1, 2}));
  Clusterer alone(std::span<const double>(&c, 1), kUniform), both(std::span<const double>(&c, 1), kUniform);
  EXPECT_EQ(center_vertex(run(alone, a)[0], 1), 1u);
  EXPECT_EQ(center_vertex(run(both, ab)[0], 2), 2u);  // the same vertex (A's second) names the same square
}

TEST(FloatingCell, MatchesBruteForceOnRandomCloud) {
  const std::vector<P> points = random_cloud(4000, 21);
  const std::vector<double> sizes = {0.03, 0.1, 0.3};
  for (const ClusterOptions& o : kFloatingVariants) {
    Clusterer clusterer(sizes, o);
    const auto cells = run(clusterer, points);
    for (size_t l = 0; l < sizes.size(); ++l) {
      const auto expected = brute_force(sizes[l], o, points);
      EXPECT_EQ(cells[l], expected) << "shape " << int(o.shape) << " choice " << int(o.choice) << " level " << l;
      EXPECT_EQ(clusterer.cell_count(l), *std::max_element(expected.begin(), expected.end()) + 1);
    }
  }
}

TEST(FloatingCell, MatchesBruteForceOnLattice) {
  // Points of a lattice of spacing 1/8 in [−1, 1]³, shuffled (not by position), with c a multiple of the
  // spacing: every difference is exact, many points lie exactly on cell boundaries and on grid-square
  // boundaries, and many are equally near to two centers.
  std::vector<P> points;
  for (int i = -8; i <= 8; ++i)
    for (int j = -8; j <= 8; ++j)
      for (int k = -8; k <= 8; ++k) points.push_back({i / 8.0, j / 8.0, k / 8.0});
  std::shuffle(points.begin(), points.end(), std::mt19937_64(5));
  const std::vector<double> sizes = {0.25, 0.375, 0.5, 1};
  for (const ClusterOptions& o : kFloatingVariants) {
    Clusterer clusterer(sizes, o);
    const auto cells = run(clusterer, points);
    for (size_t l = 0; l < sizes.size(); ++l)
      EXPECT_EQ(cells[l], brute_force(sizes[l], o, points))
          << "shape " << int(o.shape) << " choice " << int(o.choice) << " level " << l;
  }
}

TEST(FloatingCell, AtMostEightCubesPerSquareOnDenseCloud) {
  const std::vector<P> points = random_cloud(100000, 31);
  const std::vector<double> sizes = {0.01, 0.03, 0.1, 0.3};
  for (const ClusterOptions& o : kFloatingVariants) {
    Clusterer clusterer(sizes, o);
    const auto cells = run(clusterer, points);  // would throw Failure(internal) past the bound
    for (size_t l = 0; l < sizes.size(); ++l) {
      const uint32_t most = max_centers_per_square(clusterer, l, cells[l], points);
      EXPECT_EQ(clusterer.max_cells_per_square(l), most);
      EXPECT_LE(most, o.shape == CellShape::cube ? core::kMaxCubeCellsPerSquare : core::kMaxSphereCellsPerSquare);
      if (o.shape == CellShape::cube) {
        EXPECT_GE(most, 2u);  // the bound is exercised, not vacuous
      }
    }
  }
}

TEST(FloatingCell, SphereSquareCanHoldMoreThanEight) {
  // c = 1 (balls of radius 0.5), all in grid square (0, 0, 0) = [0, 1)³: the 8 corners of [0, 0.99]³ and
  // the 6 face centers (0.495 on the two other axes). Corners are ≥ 0.99 apart, a face center is ≥ 0.70
  // from a corner and from another face center: all more than 0.5 apart, so 14 sphere centers attach to
  // one square — more than the 8 of cubes. As cubes, a face center is within 0.5 of a corner per axis.
  std::vector<P> points;
  for (int i = 0; i < 8; ++i) points.push_back({(i & 1) * 0.99, (i & 2) * 0.495, (i & 4) * 0.2475});
  for (int a = 0; a < 3; ++a)
    for (double side : {0.0, 0.99}) {
      P p = {0.495, 0.495, 0.495};
      p[a] = side;
      points.push_back(p);
    }
  const double c = 1;
  Clusterer sphere(std::span<const double>(&c, 1), kSphereNearest);
  std::vector<uint32_t> ids(14);
  std::iota(ids.begin(), ids.end(), 0u);
  EXPECT_EQ(run(sphere, points)[0], ids);
  EXPECT_EQ(sphere.max_cells_per_square(0), 14u);
  Clusterer cube(std::span<const double>(&c, 1), kCubeNearest);
  run(cube, points);
  EXPECT_EQ(cube.cell_count(0), 8u);
  EXPECT_EQ(cube.max_cells_per_square(0), 8u);  // the cube bound, reached
}

TEST(FloatingCell, GridSquareFloorSemantics) {
  EXPECT_EQ(core::grid_square(0.0, 1), 0);
  EXPECT_EQ(core::grid_square(-0.0, 1), 0);
  EXPECT_EQ(core::grid_square(-1e-300, 1), -1);
  EXPECT_EQ(core::grid_square(0.999, 1), 0);
  EXPECT_EQ(core::grid_square(1, 1), 1);   // a boundary belongs to the square above
  EXPECT_EQ(core::grid_square(-1, 1), -1);
  EXPECT_EQ(core::grid_square(std::nextafter(-1.0, -2.0), 1), -2);
  EXPECT_EQ(core::grid_square(-2.5, 1), -3);
  // 0.5 / 0.1 rounds to 5.0, but the double 0.5 is below 5 × (the double 0.1 = 0.1000000000000000055...):
  // the exact floor is 4. Likewise 1.0 / 0.1.
  ASSERT_EQ(0.5 / 0.1, 5.0);
  EXPECT_EQ(core::grid_square(0.5, 0.1), 4);
  EXPECT_EQ(core::grid_square(1.0, 0.1), 9);
  EXPECT_EQ(core::grid_square(-0.5, 0.1), -5);
  EXPECT_EQ(core::grid_square(0.75, 0.25), 3);
  EXPECT_EQ(core::grid_square(-0.75, 0.25), -3);
}

TEST(FloatingCell, UniformNegativeCoordinatesAndBoundaries) {
  // c = 1, squares [k, k+1): ids in order of first appearance; the first vertex of a square names it.
  const std::vector<P> points = {
      {-0.5, 0, 0},                           // square (−1, 0, 0): cell 0
      {0, 0, 0},                              // (0, 0, 0): cell 1
      {-1, 0.999, 0.5},                       // (−1, 0, 0): cell 0
      {std::nextafter(-1.0, -2.0), 0, 0},     // (−2, 0, 0): cell 2
      {-0.0, -0.0, -0.0},                     // (0, 0, 0): cell 1
      {1, 0, 0},                              // (1, 0, 0): cell 3
      {0.5, -1e-300, 0},                      // (0, −1, 0): cell 4
  };
  const double c = 1;
  Clusterer clusterer(std::span<const double>(&c, 1), kUniform);
  const std::vector<uint32_t> cells = run(clusterer, points)[0];
  EXPECT_EQ(cells, (std::vector<uint32_t>{0, 1, 0, 2, 1, 3, 4}));
  EXPECT_EQ(clusterer.cell_count(0), 5u);
}

TEST(FloatingCell, FloatingNegativeCoordinatesAcrossSquares) {
  // c = 1: cell 0 at (−0.125, −0.125, −0.125) sits in square (−1, −1, −1); (0.375, 0.375, 0.375) is in
  // square (0, 0, 0) yet exactly 0.5 away per axis, so inside (its query block reaches back into square
  // −1). (−0.625, …) is 0.5 away the other way (inside). One ulp beyond 0.375 is a new cell. Decimal
  // values would not do: the doubles 0.4 and −0.1 are 0.50000000000000002776 apart, outside.
  const std::vector<P> points = {{-0.125, -0.125, -0.125},
                                 {0.375, 0.375, 0.375},
                                 {-0.625, -0.625, -0.625},
                                 {std::nextafter(0.375, 1.0), 0.375, 0.375},
                                 {0.4, 0.4, 0.4},
                                 {-0.1, -0.1, -0.1}};
  // The last two: 0.4 joins cell 1 at 0.375 (0.025 away); −0.1 joins cell 0 (0.025 away), not cell 1.
  for (const ClusterOptions& o : {kCubeNearest, kCubeHeaviest})
    EXPECT_EQ(run1(1, o, points), (std::vector<uint32_t>{0, 0, 0, 1, 1, 0}));
  EXPECT_EQ(core::grid_square(-0.125, 1), -1);
  EXPECT_EQ(core::grid_square(0.375, 1), 0);
}

TEST(FloatingCell, MemoryGrowsWithCellsNotVertices) {
  const double c = 1;
  for (const ClusterOptions& o : {kCubeNearest, kSphereHeaviest, kUniform}) {
    Clusterer clusterer(std::span<const double>(&c, 1), o);
    std::vector<uint32_t> cell(1);
    const P first = {0.5, 0.5, 0.5};
    clusterer.assign(0, first, cell);
    const uint64_t after_one = clusterer.memory_bytes();
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(0.35, 0.65);  // all within 0.15 of the first: one cell
    for (uint32_t v = 1; v < 100000; ++v) {
      const P p = {u(rng), u(rng), u(rng)};
      clusterer.assign(v, p, cell);
      ASSERT_EQ(cell[0], 0u);
    }
    EXPECT_EQ(clusterer.cell_count(0), 1u);
    EXPECT_EQ(clusterer.memory_bytes(), after_one);
    // The empty tables (64 sub-tables of 16 wide slots), one page of records, the query scratch.
    EXPECT_LT(clusterer.memory_bytes(), 64 * 1024u);

    // 10000 vertices 2 apart: 10000 cells, each a 32-byte record (floating) or a 32-byte slot at least.
    for (uint32_t v = 0; v < 10000; ++v) {
      const P p = {10.0 + 2.0 * v, 0, 0};
      clusterer.assign(100000 + v, p, cell);
    }
    EXPECT_EQ(clusterer.cell_count(0), 10001u);
    EXPECT_GE(clusterer.memory_bytes(), after_one + 10000 * sizeof(Clusterer::DoubleCell));
    // Records: one per cell, and the page they end on; table: below 3 slots per square (at most 2/3
    // full, doubling), with 64 sub-tables unevenly filled: allow 4.
    EXPECT_LT(clusterer.memory_bytes(), 10001 * (32 + 4 * 32) + 64 * 1024u);
  }
}

TEST(FloatingCell, RejectsBadInput) {
  auto status_of = [](auto&& f) {
    try {
      f();
    } catch (const Failure& e) {
      return e.status();
    }
    return Status::ok;
  };
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{}, {}); }), Status::usage);
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{0.0}, {}); }), Status::usage);
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{-1.0}, {}); }), Status::usage);
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{std::nan("")}, {}); }), Status::usage);
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{0.2, 0.1}, {}); }), Status::usage);
  EXPECT_EQ(status_of([] { Clusterer(std::vector<double>{0.1, 0.1}, {}); }), Status::usage);

  for (const ClusterOptions& o : {kCubeNearest, kUniform}) {
    Clusterer clusterer(std::vector<double>{0.001, 1}, o);
    std::vector<uint32_t> two(2), one(1);
    const P ok = {1, 2, 3};
    EXPECT_EQ(status_of([&] { clusterer.assign(0, ok, one); }), Status::internal);
    const P far = {1e12, 0, 0};  // 2e15 half-cells of 0.001 from the origin
    EXPECT_EQ(status_of([&] { clusterer.assign(0, far, two); }), Status::usage);
    const P nan = {0, std::nan(""), 0};
    EXPECT_EQ(status_of([&] { clusterer.assign(0, nan, two); }), Status::usage);
    const P inf = {0, 0, -std::numeric_limits<double>::infinity()};
    EXPECT_EQ(status_of([&] { clusterer.assign(0, inf, two); }), Status::usage);
    EXPECT_EQ(status_of([&] { clusterer.assign(0, ok, two); }), Status::ok);
  }
}

// Cell centers kept as floats (ClusterOptions::float_positions) give exactly the ids of doubles, when
// every position is a float: on a cloud rounded to float, at sizes where squares hold many cells, in
// every variant, with and without bounds; and a position that is not a float is refused, not rounded.
TEST(FloatingCell, FloatCentersGiveTheSameIds) {
  std::vector<P> points = random_cloud(30000, 9, -2, 2);
  for (P& p : points)
    for (double& x : p) x = static_cast<float>(x);
  const std::vector<double> sizes = {0.02, 0.1, 0.5};
  const double bounds[] = {-2, -2, -2, 2, 2, 2};
  std::vector<ClusterOptions> variants(std::begin(kFloatingVariants), std::end(kFloatingVariants));
  variants.push_back(kUniform);
  for (ClusterOptions o : variants) {
    Clusterer doubles(sizes, o);
    const auto expected = run(doubles, points);
    o.float_positions = true;
    for (bool bounded : {false, true}) {
      Clusterer floats = bounded ? Clusterer(sizes, o, bounds) : Clusterer(sizes, o);
      EXPECT_EQ(run(floats, points), expected) << "bounded " << bounded;
    }
  }
  ClusterOptions o = kCubeNearest;
  o.float_positions = true;
  Clusterer floats(sizes, o);
  std::vector<uint32_t> cells(sizes.size());
  Status status = Status::ok;
  try {
    floats.assign(0, P{0.1, 0, 0}, cells);
  } catch (const Failure& e) {
    status = e.status();
  }
  EXPECT_EQ(status, Status::internal);
}

// The definition of floating_cell.h written out plainly, for real data: a map from grid square to the
// cells whose centers lie in it, and for each vertex every cell of the 27 squares around its own, tested
// exactly as brute_force does (on float positions the differences are exact). Uniform: a map from square
// to the id of its first vertex.
std::vector<uint32_t> reference(double size, ClusterOptions options, const std::vector<P>& points) {
  struct Hash {
    size_t operator()(const std::array<int64_t, 3>& k) const {
      return core::fmix64(static_cast<uint64_t>(k[0]) * 0x9E3779B97F4A7C15ull ^ static_cast<uint64_t>(k[1]) * 0xC2B2AE3D27D4EB4Full ^
                          static_cast<uint64_t>(k[2]));
    }
  };
  std::unordered_map<std::array<int64_t, 3>, std::vector<uint32_t>, Hash> squares;
  std::vector<P> centers;
  std::vector<uint32_t> cells;
  const double h = size / 2;
  for (const P& p : points) {
    const std::array<int64_t, 3> own = {core::grid_square(p[0], size), core::grid_square(p[1], size),
                                        core::grid_square(p[2], size)};
    uint32_t best = core::kNoCell;
    if (options.clustering == Clustering::uniform) {
      auto it = squares.find(own);
      if (it != squares.end()) best = it->second[0];
    } else {
      double best_d2 = 0;
      for (int64_t dx = -1; dx <= 1; ++dx)
        for (int64_t dy = -1; dy <= 1; ++dy)
          for (int64_t dz = -1; dz <= 1; ++dz) {
            auto it = squares.find({own[0] + dx, own[1] + dy, own[2] + dz});
            if (it == squares.end()) continue;
            for (uint32_t c : it->second) {
              const double ex = p[0] - centers[c][0], ey = p[1] - centers[c][1], ez = p[2] - centers[c][2];
              if (std::fabs(ex) > h || std::fabs(ey) > h || std::fabs(ez) > h) continue;
              const double d2 = ex * ex + ey * ey + ez * ez;
              if (options.shape == CellShape::sphere && d2 > h * h) continue;
              const bool better = best == core::kNoCell ||
                                  (options.choice == CellChoice::nearest ? d2 < best_d2 || (d2 == best_d2 && c < best)
                                                                          : c < best);
              if (better) best = c, best_d2 = d2;
            }
          }
    }
    if (best == core::kNoCell) {
      best = static_cast<uint32_t>(centers.size());
      centers.push_back(p);
      squares[own].push_back(best);
    }
    cells.push_back(best);
  }
  return cells;
}

// The compact clusterer as the cluster stage runs it (float centers, the scene's bounds, so that coarse
// levels are dense arrays and fine ones packed hash tables, assign_block in blocks) gives exactly the
// reference's ids on real models: a CAD building and a scan, their vertices in a shuffled order (as weight
// order is spatially random), levels from tens of thousands of cells down to hundreds, in every variant.
TEST(FloatingCell, CompactMatchesReferenceOnRealData) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
  for (const char* model : {"buildings/Office_A_20110811.obj", "scans/nefertiti.obj"}) {
    std::ifstream in(data + "/" + model);
    ASSERT_TRUE(in) << model;
    std::vector<P> points;
    double bounds[6] = {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY};
    for (std::string line; std::getline(in, line);) {
      float x, y, z;
      if (line.rfind("v ", 0) != 0 || std::sscanf(line.c_str() + 2, "%f %f %f", &x, &y, &z) != 3) continue;
      points.push_back({x, y, z});
      for (int a = 0; a < 3; ++a) {
        bounds[a] = std::min(bounds[a], points.back()[a]);
        bounds[3 + a] = std::max(bounds[3 + a], points.back()[a]);
      }
    }
    ASSERT_GT(points.size(), 40000u) << model;
    std::shuffle(points.begin(), points.end(), std::mt19937_64(17));
    const double diag = std::hypot(bounds[3] - bounds[0], bounds[4] - bounds[1], bounds[5] - bounds[2]);
    const std::vector<double> sizes = {diag / 1200, diag / 300, diag / 60};
    std::vector<ClusterOptions> variants(std::begin(kFloatingVariants), std::end(kFloatingVariants));
    variants.push_back(kUniform);
    for (ClusterOptions o : variants) {
      o.float_positions = true;
      Clusterer clusterer(sizes, o, bounds, 1 << 16);  // the coarsest level dense, the others hashed
      std::vector<std::vector<uint32_t>> cells(sizes.size());
      constexpr size_t kBlock = 5000;
      for (size_t first = 0; first < points.size(); first += kBlock) {
        const size_t n = std::min(kBlock, points.size() - first);
        std::vector<uint32_t> ids(n), out(sizes.size() * n);
        std::vector<double> xyz(3 * n);
        for (size_t i = 0; i < n; ++i) {
          ids[i] = static_cast<uint32_t>(first + i);
          std::copy(points[first + i].begin(), points[first + i].end(), &xyz[3 * i]);
        }
        clusterer.assign_block(ids, xyz, out);
        for (size_t l = 0; l < sizes.size(); ++l) cells[l].insert(cells[l].end(), out.begin() + l * n, out.begin() + (l + 1) * n);
      }
      for (size_t l = 0; l < sizes.size(); ++l) {
        const std::vector<uint32_t> expected = reference(sizes[l], o, points);
        EXPECT_EQ(cells[l], expected) << model << " clustering " << int(o.clustering) << " shape " << int(o.shape)
                                      << " choice " << int(o.choice) << " level " << l;
        EXPECT_EQ(clusterer.cell_count(l), *std::max_element(expected.begin(), expected.end()) + 1);
        if (l == 0) {
          EXPECT_GT(clusterer.cell_count(l), 5000u) << model;
        }
      }
    }
  }
}

// assign_block (the pipelined pass the stream stage uses) gives exactly the ids of one assign per vertex,
// with and without bounds (with them, the three coarser levels index their squares directly and the
// finest, whose grid over the bounds is too large, keeps its hash table): for every variant and uniform
// cells, over blocks of uneven sizes (the look-ahead ring wraps, reaches past a block's end, and the tables
// grow in mid-block), on a random cloud and on a lattice of spacing c/4, whose points lie exactly c/2 from
// many centers (the boundary cases the fast scan hands to the exact one).
TEST(FloatingCell, AssignBlockMatchesAssign) {
  std::vector<P> points = random_cloud(20000, 7, -3, 3);
  for (int x = 0; x < 24; ++x)
    for (int y = 0; y < 24; ++y)
      for (int z = 0; z < 6; ++z) points.push_back({x * 0.125 - 1.5, y * 0.125 - 1.5, z * 0.125});
  const double sizes[] = {0.002, 0.5, 1.25, 4};
  constexpr size_t kLevels = 4;
  const double bounds[] = {-3, -3, -3, 3, 3, 3};
  std::vector<ClusterOptions> variants(std::begin(kFloatingVariants), std::end(kFloatingVariants));
  variants.push_back(kUniform);
  for (const ClusterOptions& options : variants) {
    Clusterer one(sizes, options);
    const std::vector<std::vector<uint32_t>> expected = run(one, points);
    for (bool bounded : {false, true}) {
      Clusterer block = bounded ? Clusterer(sizes, options, bounds) : Clusterer(sizes, options);
      const size_t chunks[] = {1, 7, 16, 17, 100, 4096};
      size_t first = 0, k = 0;
      while (first < points.size()) {
        const size_t n = std::min(chunks[k++ % 6], points.size() - first);
        std::vector<uint32_t> ids(n), cells(kLevels * n);
        std::vector<double> xyz(3 * n);
        for (size_t i = 0; i < n; ++i) {
          ids[i] = static_cast<uint32_t>(first + i);
          std::copy(points[first + i].begin(), points[first + i].end(), &xyz[3 * i]);
        }
        block.assign_block(ids, xyz, cells);
        for (size_t l = 0; l < kLevels; ++l)
          for (size_t i = 0; i < n; ++i)
            ASSERT_EQ(cells[l * n + i], expected[l][first + i])
                << "bounded " << bounded << " level " << l << " vertex " << first + i;
        first += n;
      }
      for (size_t l = 0; l < kLevels; ++l) EXPECT_EQ(block.cell_count(l), one.cell_count(l));
    }
  }
  // A position outside the bounds is a caller bug, reported, not an out-of-range write.
  Clusterer bounded(sizes, kCubeNearest, bounds);
  std::vector<uint32_t> cells(kLevels);
  Status status = Status::ok;
  try {
    bounded.assign(0, P{0, 0, 3.5}, cells);
  } catch (const Failure& e) {
    status = e.status();
  }
  EXPECT_EQ(status, Status::internal);
}

}  // namespace
}  // namespace lodstream

// Vertex grading (core/grade.h): exact small cases worked out by hand, the special cases the header
// promises, order independence, and the chunk invariant on a synthetic mesh and on the sample scene.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <numbers>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "core/grade.h"
#include "core/status.h"
#include "reader_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

using core::Grading;
using core::VertexGrade;
constexpr double kPi = std::numbers::pi;

VertexGrade grade(const std::vector<double>& edges, Grading mode = Grading::lowtan) {
  return core::grade_edges(edges, mode);
}

uint64_t bits(double x) {
  return std::bit_cast<uint64_t>(x);
}

void expect_same_bits(const VertexGrade& a, const VertexGrade& b) {
  EXPECT_EQ(bits(a.grade), bits(b.grade));
  EXPECT_EQ(bits(a.theta), bits(b.theta));
  EXPECT_EQ(bits(a.lmax), bits(b.lmax));
}

TEST(GradeKernel, CubeCornerIsCos45) {
  // Three mutually perpendicular unit edges: θ = 90°, Lmax = 1.
  const VertexGrade g = grade({1, 0, 0, 0, 1, 0, 0, 0, 1});
  EXPECT_EQ(g.theta, kPi / 2);  // atan2(1, 0) is exactly fl(π)/2
  EXPECT_EQ(g.lmax, 1.0);
  EXPECT_DOUBLE_EQ(g.grade, std::cos(kPi / 4));
  // Longer edges scale the grade.
  EXPECT_DOUBLE_EQ(grade({3, 0, 0, 0, 1, 0, 0, 0, 1}).grade, 3 * std::cos(kPi / 4));
}

TEST(GradeKernel, FlatGridInteriorIsExactlyZero) {
  // Interior vertex of a square grid of spacing 0.5: 4 neighbours, then 8 (with the diagonals). Opposite
  // edges are exactly opposite, so θ is fl(π) and the grade is exactly 0 (not cos(fl(π)/2) ≈ 6e-17).
  const VertexGrade g4 = grade({0.5, 0, 0, -0.5, 0, 0, 0, 0.5, 0, 0, -0.5, 0});
  EXPECT_EQ(g4.theta, kPi);
  EXPECT_EQ(g4.lmax, 0.5);
  EXPECT_EQ(g4.grade, 0.0);
  const VertexGrade g8 = grade(
      {0.5, 0, 0, -0.5, 0, 0, 0, 0.5, 0, 0, -0.5, 0, 0.5, 0.5, 0, -0.5, -0.5, 0, 0.5, -0.5, 0, -0.5, 0.5, 0});
  EXPECT_EQ(g8.theta, kPi);
  EXPECT_EQ(g8.lmax, 0.5 * std::sqrt(2.0));
  EXPECT_EQ(g8.grade, 0.0);
  // Opposite edges off the axes, of different lengths: parallel edges scale to the same unit-max vector,
  // so they are found exactly opposite too.
  const VertexGrade tilted = grade({0.1, 0.3, 0.7, -0.2, -0.6, -1.4, 0.3, -0.1, 0});
  EXPECT_EQ(tilted.theta, kPi);
  EXPECT_EQ(tilted.grade, 0.0);
  // The same from positions on a grid of spacing 0.1 whose coordinates are not exact binary fractions:
  // the differences differ in their last bits, but the edges stay on the axes, so still exactly π.
  core::GradeScratch scratch;
  const double p[3] = {0.3, 0.7, 5};
  const std::vector<double> q = {0.4, 0.7, 5, 0.2, 0.7, 5, 0.3, 0.8, 5, 0.3, 0.6, 5};
  const VertexGrade gp = core::grade_vertex(p, q, Grading::lowtan, scratch);
  EXPECT_EQ(gp.theta, kPi);
  EXPECT_EQ(gp.grade, 0.0);
  EXPECT_EQ(gp.lmax, std::max({0.4 - 0.3, 0.3 - 0.2, 0.8 - 0.7, 0.7 - 0.6}));
}

TEST(GradeKernel, TiltedFlatVertexIsNearlyZero) {
  // p ± u on a tilted line through p: in floating point (p + u) − p and (p − u) − p are not exactly
  // opposite, so θ is just below π and the grade tiny but not forced to 0 (no snapping is done).
  core::GradeScratch scratch;
  const double p[3] = {0.7, 0.11, 0.13};
  const double u[3] = {0.1, 0.2, 0.3}, w[3] = {-0.3, 0.17, 0.05};
  std::vector<double> q;
  for (int s : {1, -1})
    for (const double* d : {u, w}) q.insert(q.end(), {p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2]});
  const VertexGrade g = core::grade_vertex(p, q, Grading::lowtan, scratch);
  EXPECT_GT(g.theta, kPi - 1e-14);
  EXPECT_LE(g.theta, kPi);
  EXPECT_GE(g.grade, 0.0);
  EXPECT_LT(g.grade, 1e-14 * g.lmax);
}

TEST(GradeKernel, RegularPentagonFanIs144Degrees) {
  // Five neighbours evenly spaced on a circle of radius 2 in a plane: the widest pair is two apart,
  // θ = 4π/5 = 144°, grade = cos 72° · 2.
  std::vector<double> e;
  for (int k = 0; k < 5; ++k)
    e.insert(e.end(), {2 * std::cos(2 * kPi * k / 5), 2 * std::sin(2 * kPi * k / 5), 0});
  const VertexGrade g = grade(e);
  EXPECT_NEAR(g.theta, 4 * kPi / 5, 1e-12);
  EXPECT_NEAR(g.lmax, 2, 1e-15);
  EXPECT_NEAR(g.grade, 2 * std::cos(2 * kPi / 5), 1e-12);
}

TEST(GradeKernel, LmaxIsTheLongestEdgeAndDuplicatesAndZerosAreIgnored) {
  // Lengths 5 (3-4-5), 1, 2; widest pair (1,0,0), (0,2,0) at 90°.
  const std::vector<double> clean = {3, 4, 0, 1, 0, 0, 0, 2, 0};
  const VertexGrade g = grade(clean);
  EXPECT_EQ(g.lmax, 5.0);
  EXPECT_EQ(g.theta, kPi / 2);
  EXPECT_DOUBLE_EQ(g.grade, 5 * std::cos(kPi / 4));
  // A duplicate edge and zero-length ones (including -0) change no bit.
  const std::vector<double> noisy = {0, 0, 0, 1, 0, 0, 3, 4, 0, -0.0, 0, -0.0, 1, 0, 0, 0, 2, 0, 0, 0, 0};
  expect_same_bits(grade(noisy), g);
  expect_same_bits(grade(noisy, Grading::rossignac), grade(clean, Grading::rossignac));
}

TEST(GradeKernel, LineEndAndSpikeHaveThetaZero) {
  // One neighbour: θ = 0, grade = L (cos 0 = 1).
  const VertexGrade end = grade({0, 0, 3});
  EXPECT_EQ(end.theta, 0.0);
  EXPECT_EQ(end.lmax, 3.0);
  EXPECT_EQ(end.grade, 3.0);
  // Several edges in one direction (a spike, or a line whose far vertices are collinear): still θ = 0.
  const VertexGrade spike = grade({1, 1, 1, 2, 2, 2, 0.5, 0.5, 0.5});
  EXPECT_EQ(spike.theta, 0.0);
  EXPECT_EQ(spike.lmax, 2 * std::sqrt(3.0));
  EXPECT_EQ(spike.grade, spike.lmax);
  // Rossignac: θ is clamped to 2^-24, so the grade is L · 2^24 exactly.
  EXPECT_EQ(grade({0, 0, 3}, Grading::rossignac).grade, 3.0 * 16777216.0);
}

TEST(GradeKernel, IsolatedVertexIsZeroInBothModes) {
  for (Grading mode : {Grading::lowtan, Grading::rossignac}) {
    for (const std::vector<double>& edges :
         {std::vector<double>{}, std::vector<double>{0, 0, 0, -0.0, 0, 0}}) {
      const VertexGrade g = grade(edges, mode);
      EXPECT_EQ(g.grade, 0.0);
      EXPECT_EQ(g.theta, 0.0);
      EXPECT_EQ(g.lmax, 0.0);
    }
  }
}

TEST(GradeKernel, RossignacValues) {
  // Cube corner: 1 / (π/2) = 2/π.
  EXPECT_EQ(grade({1, 0, 0, 0, 1, 0, 0, 0, 1}, Grading::rossignac).grade, 2 / kPi);
  // Flat: L / π.
  EXPECT_EQ(grade({0.5, 0, 0, -0.5, 0, 0}, Grading::rossignac).grade, 0.5 / kPi);
  // θ ≈ 1e-10 < 2^-24 is clamped like θ = 0: |(1, 1e-10, 0)| rounds to 1, so the grade is 2^24.
  const VertexGrade tiny = grade({1, 0, 0, 1, 1e-10, 0}, Grading::rossignac);
  EXPECT_NEAR(tiny.theta, 1e-10, 1e-22);
  EXPECT_EQ(tiny.grade, 16777216.0);
  // θ just above the clamp: L / θ, finite, and ordered below the clamped value.
  const VertexGrade small = grade({1, 0, 0, 1, 1e-7, 0}, Grading::rossignac);
  EXPECT_NEAR(small.grade, small.lmax / 1e-7, 1e-3);
  // For the same L the grade does not increase with θ: 0 ≥ tiny ≥ small ≥ cube corner ≥ flat.
  const double line = grade({1, 0, 0}, Grading::rossignac).grade;
  EXPECT_GE(line, tiny.grade);
  EXPECT_GT(tiny.grade, small.grade);
  EXPECT_GT(small.grade, grade({1, 0, 0, 0, 1, 0}, Grading::rossignac).grade);
  EXPECT_GT(grade({1, 0, 0, 0, 1, 0}, Grading::rossignac).grade,
            grade({1, 0, 0, -1, 0, 0}, Grading::rossignac).grade);
}

TEST(GradeKernel, ExtremeEdgeLengthsNeitherOverflowNorUnderflow) {
  // Squaring 1e200 or 1e-200 directly would overflow or flush to 0.
  const VertexGrade big = grade({1e200, 0, 0, 0, 1e200, 0});
  EXPECT_EQ(big.lmax, 1e200);
  EXPECT_EQ(big.theta, kPi / 2);
  EXPECT_DOUBLE_EQ(big.grade, 1e200 * std::cos(kPi / 4));
  const VertexGrade small = grade({1e-200, 0, 0, 0, 0, -1e-200});
  EXPECT_EQ(small.lmax, 1e-200);
  EXPECT_EQ(small.theta, kPi / 2);
  const VertexGrade denormal = grade({4.9e-324, 0, 0});
  EXPECT_EQ(denormal.lmax, 4.9e-324);
  EXPECT_EQ(denormal.grade, 4.9e-324);
}

TEST(GradeKernel, ResultDoesNotDependOnEdgeOrderOrDuplicates) {
  // Sets with many near-ties (regular fans of 3 to 12 edges, whose opposite pairs are only nearly
  // opposite in floating point, and a 3D cross) and random sets; each is shuffled and padded with
  // duplicates and zero edges many times, and must give the same bits every time.
  std::mt19937 rng(20240607);
  std::vector<std::vector<double>> sets;
  for (int n = 3; n <= 12; ++n) {
    std::vector<double> e;
    for (int k = 0; k < n; ++k)
      e.insert(e.end(), {std::cos(2 * kPi * k / n), std::sin(2 * kPi * k / n), 0.25});
    sets.push_back(e);
  }
  sets.push_back({1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1});
  std::uniform_real_distribution<double> coord(-1, 1);
  for (int s = 0; s < 50; ++s) {
    std::vector<double> e;
    const int n = 1 + static_cast<int>(rng() % 14);
    for (int k = 0; k < 3 * n; ++k) e.push_back(coord(rng));
    sets.push_back(e);
  }
  core::GradeScratch scratch;
  for (const auto& set : sets) {
    for (Grading mode : {Grading::lowtan, Grading::rossignac}) {
      const VertexGrade ref = core::grade_edges(set, mode, scratch);
      EXPECT_TRUE(std::isfinite(ref.grade));
      std::vector<std::array<double, 3>> edges;
      for (size_t i = 0; i < set.size(); i += 3) edges.push_back({set[i], set[i + 1], set[i + 2]});
      for (int trial = 0; trial < 20; ++trial) {
        auto shuffled = edges;
        for (int d = 0; d < trial % 4; ++d) shuffled.push_back(edges[rng() % edges.size()]);
        if (trial % 3 == 0) shuffled.push_back({0, 0, 0});
        std::shuffle(shuffled.begin(), shuffled.end(), rng);
        std::vector<double> flat;
        for (const auto& e : shuffled) flat.insert(flat.end(), e.begin(), e.end());
        expect_same_bits(core::grade_edges(flat, mode, scratch), ref);
      }
    }
  }
}

TEST(GradeVertex, NeighbourPositionsMatchTheKernelAndIgnoreTheVertexItself) {
  core::GradeScratch scratch;
  const double p[3] = {1, 2, 3};
  // Neighbours along +x, +y, +z (a cube corner) plus the vertex's own position and a repeat.
  const std::vector<double> q = {2, 2, 3, 1, 3, 3, 1, 2, 3, 1, 2, 4, 2, 2, 3};
  expect_same_bits(core::grade_vertex(p, q, Grading::lowtan, scratch), grade({1, 0, 0, 0, 1, 0, 0, 0, 1}));
}

// Unit cube, vertex i at (i & 1, i >> 1 & 1, i >> 2 & 1), each face split along the diagonal from its
// lowest-numbered corner: diagonals 0-3, 4-7, 0-5, 2-7, 0-6, 1-7, which touch every corner. So every corner
// has its three unit axis edges plus at least one face diagonal of length √2. Axis-axis and axis-diagonal
// (across faces) pairs are at 90°, diagonals are at 45° to their face's axes and 60° to each other, and all
// edges point into the same octant: θ = 90° and Lmax = √2 at every corner, grade = cos 45° · √2 = 1.
const std::vector<double> kCubePositions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0,
                                            0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
const std::vector<uint32_t> kCubeTriangles = {
    0, 3, 1, 0, 2, 3,  // z = 0
    4, 5, 7, 4, 7, 6,  // z = 1
    0, 1, 5, 0, 5, 4,  // y = 0
    2, 7, 3, 2, 6, 7,  // y = 1
    0, 4, 6, 0, 6, 2,  // x = 0
    1, 3, 7, 1, 7, 5,  // x = 1
};

TEST(GradeBatch, TriangulatedCubeGivesEveryCornerTheSameGrade) {
  std::vector<double> g(8), theta(8), lmax(8);
  core::grade_vertices(kCubePositions, kCubeTriangles, {}, 0, 8, Grading::lowtan, g, theta, lmax);
  for (int v = 0; v < 8; ++v) {
    SCOPED_TRACE(v);
    EXPECT_EQ(theta[v], kPi / 2);
    EXPECT_EQ(lmax[v], std::sqrt(2.0));
    EXPECT_NEAR(g[v], 1.0, 1e-15);
    EXPECT_EQ(bits(g[v]), bits(g[0]));
  }
  std::vector<double> r(8);
  core::grade_vertices(kCubePositions, kCubeTriangles, {}, 0, 8, Grading::rossignac, r);
  for (int v = 0; v < 8; ++v) EXPECT_EQ(r[v], std::sqrt(2.0) / (kPi / 2));
}

TEST(GradeBatch, Tetrahedra) {
  const std::vector<uint32_t> tris = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  // Corner tetrahedron: vertex 0 is a cube corner (θ = 90°, Lmax 1); vertex 1 has edges (-1,0,0),
  // (-1,1,0), (-1,0,1) at 45°, 45° and 60°: θ = 60°, Lmax = √2, grade = cos 30° · √2 = √6 / 2. Same for
  // vertices 2 and 3 by symmetry.
  const std::vector<double> corner = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::vector<double> g(4), theta(4), lmax(4);
  core::grade_vertices(corner, tris, {}, 0, 4, Grading::lowtan, g, theta, lmax);
  EXPECT_EQ(theta[0], kPi / 2);
  EXPECT_EQ(lmax[0], 1.0);
  EXPECT_DOUBLE_EQ(g[0], std::cos(kPi / 4));
  for (int v = 1; v < 4; ++v) {
    SCOPED_TRACE(v);
    EXPECT_NEAR(theta[v], kPi / 3, 1e-12);
    EXPECT_EQ(lmax[v], std::sqrt(2.0));
    EXPECT_NEAR(g[v], std::sqrt(6.0) / 2, 1e-12);
  }
  // Regular tetrahedron of edge 2√2: θ = 60° everywhere, grade = cos 30° · 2√2 = √6.
  const std::vector<double> regular = {1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1};
  core::grade_vertices(regular, tris, {}, 0, 4, Grading::lowtan, g, theta, lmax);
  for (int v = 0; v < 4; ++v) {
    SCOPED_TRACE(v);
    EXPECT_NEAR(theta[v], kPi / 3, 1e-12);
    EXPECT_EQ(lmax[v], 2 * std::sqrt(2.0));
    EXPECT_NEAR(g[v], std::sqrt(6.0), 1e-12);
  }
}

TEST(GradeBatch, SegmentsDegenerateTrianglesAndALocalRange) {
  // Local range starts at vertex 1000. A polyline 1000-1001-1002-1003 through (0,0,0), (1,0,0), (3,0,0),
  // (3,0,2); vertex 1004 is isolated. Degenerate triangles add no edge or only an existing one.
  const std::vector<double> pos = {0, 0, 0, 1, 0, 0, 3, 0, 0, 3, 0, 2, 9, 9, 9};
  const std::vector<uint32_t> segs = {1000, 1001, 1001, 1002, 1002, 1003};
  const std::vector<uint32_t> tris = {1003, 1003, 1003, 1000, 1000, 1001};
  std::vector<double> g(5), theta(5), lmax(5);
  core::grade_vertices(pos, tris, segs, 1000, 5, Grading::lowtan, g, theta, lmax);
  const std::vector<double> want_theta = {0, kPi, kPi / 2, 0, 0}, want_lmax = {1, 2, 2, 2, 0};
  EXPECT_EQ(theta, want_theta);
  EXPECT_EQ(lmax, want_lmax);
  EXPECT_EQ(g[0], 1.0);  // line end: grade = L
  EXPECT_EQ(g[1], 0.0);  // straight through: θ = π
  EXPECT_DOUBLE_EQ(g[2], 2 * std::cos(kPi / 4));
  EXPECT_EQ(g[3], 2.0);
  EXPECT_EQ(g[4], 0.0);  // isolated
  // θ and Lmax are optional; the grades do not change without them.
  std::vector<double> g2(5);
  core::grade_vertices(pos, tris, segs, 1000, 5, Grading::lowtan, g2);
  EXPECT_EQ(g2, g);
}

TEST(GradeBatch, AdjacencyListsAreSortedAndDistinct) {
  // Square 0-1-2-3 as two triangles sharing the side 0-2, plus a segment repeating side 2-3.
  core::Adjacency adj;
  core::build_adjacency(std::vector<uint32_t>{10, 11, 12, 10, 12, 13}, std::vector<uint32_t>{13, 12}, 10, 5,
                        adj);
  auto list = [&](uint32_t v) {
    auto s = adj.of(v);
    return std::vector<uint32_t>(s.begin(), s.end());
  };
  EXPECT_EQ(list(0), (std::vector<uint32_t>{1, 2, 3}));
  EXPECT_EQ(list(1), (std::vector<uint32_t>{0, 2}));
  EXPECT_EQ(list(2), (std::vector<uint32_t>{0, 1, 3}));
  EXPECT_EQ(list(3), (std::vector<uint32_t>{0, 2}));
  EXPECT_TRUE(list(4).empty());
  EXPECT_EQ(adj.neighbours.size(), 10u);
}

TEST(GradeBatch, BadInputThrows) {
  std::vector<double> g(3);
  const std::vector<double> pos(9, 0.0);
  // Vertex 3 and vertex 4 are outside [1, 4) and [0, 3); a wrapped id below first_vertex is caught too.
  EXPECT_THROW(core::grade_vertices(pos, std::vector<uint32_t>{0, 1, 3}, {}, 0, 3, Grading::lowtan, g),
               Failure);
  EXPECT_THROW(core::grade_vertices(pos, std::vector<uint32_t>{0, 1, 2}, {}, 1, 3, Grading::lowtan, g),
               Failure);
  EXPECT_THROW(core::grade_vertices(pos, {}, std::vector<uint32_t>{4, 1}, 0, 3, Grading::lowtan, g), Failure);
  try {
    core::grade_vertices(pos, std::vector<uint32_t>{0, 1, 2, 2, 1, 7}, {}, 0, 3, Grading::lowtan, g);
    ADD_FAILURE() << "no throw";
  } catch (const Failure& e) {
    EXPECT_EQ(e.status(), Status::internal);
    EXPECT_NE(std::string(e.what()).find("triangle 1 (2 1 7)"), std::string::npos) << e.what();
  }
  std::vector<double> short_out(2);
  EXPECT_THROW(
      core::grade_vertices(pos, std::vector<uint32_t>{0, 1, 2}, {}, 0, 3, Grading::lowtan, short_out),
      Failure);
  EXPECT_THROW(core::grade_vertices(pos, std::vector<uint32_t>{0, 1, 2}, {}, 0, 4, Grading::lowtan, g),
               Failure);
}

// Grades the mesh as stage 2 would with two chunks: the triangles [0, cut) and [cut, end) (segments all in
// the second chunk) are graded separately; a vertex with neighbours in both chunks is a seam vertex and is
// graded from the union of the neighbour positions both chunks saw (concatenated: unsorted, with repeats).
std::vector<double> grade_in_two_chunks(const std::vector<double>& pos, const std::vector<uint32_t>& tris,
                                        const std::vector<uint32_t>& segs, size_t cut, Grading mode) {
  const uint32_t n = static_cast<uint32_t>(pos.size() / 3);
  const std::span<const uint32_t> all(tris);
  core::Adjacency a, b;
  core::GradeScratch scratch;
  core::build_adjacency(all.first(3 * cut), {}, 0, n, a);
  core::build_adjacency(all.subspan(3 * cut), segs, 0, n, b);
  std::vector<double> ga(n), gb(n), out(n);
  core::grade_vertices(a, pos, mode, scratch, ga);
  core::grade_vertices(b, pos, mode, scratch, gb);
  std::vector<double> seam;
  for (uint32_t v = 0; v < n; ++v) {
    const auto na = a.of(v), nb = b.of(v);
    if (na.empty() || nb.empty()) {
      out[v] = na.empty() ? gb[v] : ga[v];
      continue;
    }
    seam.clear();
    for (auto list : {nb, na})
      for (uint32_t u : list) seam.insert(seam.end(), {pos[3 * u], pos[3 * u + 1], pos[3 * u + 2]});
    out[v] = core::grade_vertex(std::span<const double, 3>(pos.data() + 3 * v, 3), seam, mode, scratch).grade;
  }
  return out;
}

void expect_chunk_invariant(const std::vector<double>& pos, const std::vector<uint32_t>& tris,
                            const std::vector<uint32_t>& segs, Grading mode,
                            size_t* seam_vertices = nullptr) {
  const uint32_t n = static_cast<uint32_t>(pos.size() / 3);
  std::vector<double> whole(n);
  core::grade_vertices(pos, tris, segs, 0, n, mode, whole);
  for (size_t cut : {tris.size() / 6, tris.size() / 3 / 3, tris.size() / 3 - 1}) {
    const std::vector<double> split = grade_in_two_chunks(pos, tris, segs, cut, mode);
    size_t differ = 0;
    for (uint32_t v = 0; v < n; ++v) differ += bits(split[v]) != bits(whole[v]);
    EXPECT_EQ(differ, 0u) << "cut at triangle " << cut;
  }
  if (seam_vertices) {
    core::Adjacency a, b;
    core::build_adjacency(std::span<const uint32_t>(tris).first(tris.size() / 2 / 3 * 3), {}, 0, n, a);
    core::build_adjacency(std::span<const uint32_t>(tris).subspan(tris.size() / 2 / 3 * 3), segs, 0, n, b);
    *seam_vertices = 0;
    for (uint32_t v = 0; v < n; ++v) *seam_vertices += !a.of(v).empty() && !b.of(v).empty();
  }
}

TEST(GradeChunks, TwoChunksPlusSeamMergeEqualTheWholeMeshBitForBit) {
  // A 30 × 30 height field: a flat region (exactly opposite edges), a bumpy region, and a ridge, with
  // alternating quad diagonals; plus a polyline along one border.
  const int n = 30;
  std::vector<double> pos;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = 0.1 * i, y = 0.1 * j;
      const double z = i < 10 ? 0.0 : i < 20 ? 0.05 * std::sin(3 * x) * std::cos(5 * y) : 0.3 * (i == 25);
      pos.insert(pos.end(), {x, y, z});
    }
  std::vector<uint32_t> tris, segs;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      if ((i + j) % 2)
        tris.insert(tris.end(), {a, b, d, a, d, c});
      else
        tris.insert(tris.end(), {a, b, c, b, d, c});
    }
  for (int i = 0; i + 1 < n; ++i) segs.insert(segs.end(), {uint32_t(i), uint32_t(i + 1)});
  size_t seam = 0;
  expect_chunk_invariant(pos, tris, segs, Grading::lowtan, &seam);
  EXPECT_GE(seam, size_t{n});  // the split really crosses the mesh
  expect_chunk_invariant(pos, tris, segs, Grading::rossignac);
}

TEST(GradeSample, SampleRoomGradesAreFiniteAndChunkInvariant) {
  const std::string path = test::source_dir() + "/tests/data/sample-room.ply";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "sample scene not present";
  const test::ReadAll r = test::read_all(path, 1 << 20);
  const uint64_t n = r.vertex_count();
  ASSERT_GT(n, 0u);
  ASSERT_LT(n, uint64_t{1} << 32);
  std::vector<uint32_t> tris(r.triangles.size()), segs(r.lines.size());
  for (size_t i = 0; i < tris.size(); ++i) {
    ASSERT_GE(r.triangles[i], 0);
    ASSERT_LT(static_cast<uint64_t>(r.triangles[i]), n);
    tris[i] = static_cast<uint32_t>(r.triangles[i]);
  }
  for (size_t i = 0; i < segs.size(); ++i) segs[i] = static_cast<uint32_t>(r.lines[i]);
  std::vector<double> g(n), theta(n), lmax(n);
  core::grade_vertices(r.positions, tris, segs, 0, static_cast<uint32_t>(n), Grading::lowtan, g, theta, lmax);
  size_t bad = 0, graded = 0;
  for (uint64_t v = 0; v < n; ++v) {
    bad += !(std::isfinite(g[v]) && g[v] >= 0 && g[v] <= lmax[v] && theta[v] >= 0 && theta[v] <= kPi);
    graded += g[v] > 0;
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(graded, n / 2);
  size_t seam = 0;
  expect_chunk_invariant(r.positions, tris, segs, Grading::lowtan, &seam);
  EXPECT_GT(seam, 0u);
}

}  // namespace
}  // namespace lodstream

// Floating cells over part of a scene (core/floating_cell_region.h): every settled status and cell is
// the whole-scene Clusterer's, on clouds (random, on a lattice with ties at c/2, and in clumps) cut by
// many boxes, for every shape and choice; a hand-made chain that a halo settles only when it is wide
// enough; and the whole scene as one box settles everything.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <vector>

#include "core/floating_cell.h"
#include "core/floating_cell_region.h"
#include "core/status.h"
#include "clouds.h"

namespace lodstream {
namespace {

using core::CellChoice;
using core::CellShape;
using core::ClusterOptions;
using core::Clustering;
using core::RegionClusterer;
using core::RegionStatus;
using P = std::array<double, 3>;
constexpr double kInf = std::numeric_limits<double>::infinity();

constexpr ClusterOptions kVariants[] = {
    {Clustering::floating, CellShape::cube, CellChoice::nearest},
    {Clustering::floating, CellShape::cube, CellChoice::heaviest},
    {Clustering::floating, CellShape::sphere, CellChoice::nearest},
    {Clustering::floating, CellShape::sphere, CellChoice::heaviest},
};

// The whole-scene pass: per vertex (in weight order) the index of its cell's center vertex.
std::vector<uint32_t> whole_scene_centers(const std::vector<P>& pts, double c, ClusterOptions o) {
  static_assert(sizeof(P) == 3 * sizeof(double));
  return core::whole_scene_centers(std::span<const double>(pts.data()->data(), 3 * pts.size()), c, o);
}

struct Tally {
  uint64_t held = 0, settled_status = 0, settled_cells = 0;
};

// Runs a RegionClusterer over the vertices in `box`, each tagged by its whole-scene index, and checks each
// settled decision against `whole`; a second one runs them through assign_block, in blocks of random
// sizes, and must decide exactly as the first.
Tally check_box(const std::vector<P>& pts, const std::vector<uint32_t>& whole, double c, ClusterOptions o,
                const std::array<double, 6>& box, uint32_t max_open = 16, uint64_t* crowded = nullptr) {
  RegionClusterer rc(c, o, box, max_open), blocks(c, o, box, max_open);
  std::vector<uint32_t> tags;
  std::vector<double> xyz;
  std::vector<core::RegionDecision> decisions;
  Tally t;
  for (uint32_t i = 0; i < pts.size(); ++i) {
    const P& p = pts[i];
    bool in = true;
    for (int a = 0; a < 3; ++a) in &= p[a] >= box[a] && p[a] < box[3 + a];
    if (!in) continue;
    tags.push_back(i);
    xyz.insert(xyz.end(), p.begin(), p.end());
    const core::RegionDecision d = rc.assign(i, p);
    decisions.push_back(d);
    ++t.held;
    if (d.status != RegionStatus::unsettled) {
      ++t.settled_status;
      EXPECT_EQ(d.status == RegionStatus::center, whole[i] == i) << "vertex " << i;
    }
    if (d.cell_settled) {
      ++t.settled_cells;
      EXPECT_NE(d.status, RegionStatus::unsettled);
      EXPECT_EQ(d.center, whole[i]) << "vertex " << i;
    }
  }
  EXPECT_EQ(t.held - t.settled_status, rc.unsettled());
  std::mt19937 rng(static_cast<uint32_t>(tags.size()));
  std::vector<core::RegionDecision> out(tags.size());
  for (size_t first = 0; first < tags.size();) {
    const size_t n = std::min<size_t>(tags.size() - first, 1 + rng() % 100);
    blocks.assign_block(std::span<const uint32_t>(&tags[first], n), std::span<const double>(&xyz[3 * first], 3 * n),
                        std::span<core::RegionDecision>(&out[first], n));
    first += n;
  }
  for (size_t k = 0; k < tags.size(); ++k) {
    EXPECT_EQ(out[k].status, decisions[k].status) << "vertex " << tags[k];
    EXPECT_EQ(out[k].cell_settled, decisions[k].cell_settled) << "vertex " << tags[k];
    EXPECT_EQ(out[k].center, decisions[k].center) << "vertex " << tags[k];
  }
  EXPECT_EQ(blocks.crowded_squares(), rc.crowded_squares());
  if (crowded) *crowded += rc.crowded_squares();
  return t;
}

std::vector<P> cloud(std::mt19937_64& rng, int kind, size_t n) { return test::cloud(rng, kind, n); }

TEST(FloatingCellRegion, SettledDecisionsAreTheWholeScenePass) {
  std::mt19937_64 rng(19);
  std::uniform_real_distribution<double> u(-1.0, 11.0);
  uint64_t settled = 0, held = 0;
  for (int kind = 0; kind < 3; ++kind) {
    const std::vector<P> pts = cloud(rng, kind, 6000);
    for (const ClusterOptions& o : kVariants) {
      for (double c : {0.5, 1.0, 2.0}) {
        const std::vector<uint32_t> whole = whole_scene_centers(pts, c, o);
        for (int b = 0; b < 6; ++b) {
          std::array<double, 6> box;
          for (int a = 0; a < 3; ++a) {
            double x = u(rng), y = u(rng);
            if (x > y) std::swap(x, y);
            if (rng() % 4 == 0) x = -kInf;
            box[a] = x, box[3 + a] = y;
          }
          const Tally t = check_box(pts, whole, c, o, box);
          settled += t.settled_status, held += t.held;
        }
      }
    }
  }
  // Not a vacuous check: most held vertices are settled.
  EXPECT_GT(held, 10000u);
  EXPECT_GT(settled, held / 4);
}

// Crowded squares (floating_cell_region.h): with one unsettled entry a square before its box takes over,
// boxes are made everywhere doubt is, and every settled decision is still the whole-scene pass's; the
// box only adds doubt, and not much of it where the doubt is thin.
TEST(FloatingCellRegion, CrowdedSquaresBecomeBoxesAndStaySound) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1.0, 11.0);
  uint64_t crowded = 0, settled_exact = 0, settled_boxed = 0;
  for (int kind = 0; kind < 3; ++kind) {
    const std::vector<P> pts = cloud(rng, kind, 6000);
    for (const ClusterOptions& o : kVariants) {
      const std::vector<uint32_t> whole = whole_scene_centers(pts, 1.0, o);
      for (int b = 0; b < 4; ++b) {
        std::array<double, 6> box;
        for (int a = 0; a < 3; ++a) {
          double x = u(rng), y = u(rng);
          if (x > y) std::swap(x, y);
          box[a] = x, box[3 + a] = y;
        }
        settled_exact += check_box(pts, whole, 1.0, o, box, UINT32_MAX).settled_status;
        settled_boxed += check_box(pts, whole, 1.0, o, box, 1, &crowded).settled_status;
      }
    }
  }
  EXPECT_GT(crowded, 100u) << "no square was crowded";
  EXPECT_LE(settled_boxed, settled_exact);
  EXPECT_GT(settled_boxed, settled_exact / 2);
}

TEST(FloatingCellRegion, TheWholeSceneAsOneBoxSettlesEverything) {
  std::mt19937_64 rng(7);
  const std::vector<P> pts = cloud(rng, 2, 5000);
  for (const ClusterOptions& o : kVariants) {
    const std::vector<uint32_t> whole = whole_scene_centers(pts, 1.0, o);
    const Tally t = check_box(pts, whole, 1.0, o, {-kInf, -kInf, -kInf, kInf, kInf, kInf});
    EXPECT_EQ(t.settled_status, pts.size());
    EXPECT_EQ(t.settled_cells, pts.size());
  }
}

// A chain along x, 0.4 apart, heaviest first, c = 1 (c/2 = 0.5): 0 starts a cell, 0.4 joins it, 0.8
// starts one, 1.2 joins it, and so on. A task that does not hold x = 0 cannot tell whether 0.4 starts a
// cell, and the doubt runs down the whole chain; holding x = 0 settles it.
TEST(FloatingCellRegion, ADoubtRunsDownAChainUntilTheHaloHoldsItsHead) {
  std::vector<P> pts;
  for (int i = 0; i < 10; ++i) pts.push_back({0.4 * i, 0.0, 0.0});
  const ClusterOptions o = kVariants[0];
  const std::vector<uint32_t> whole = whole_scene_centers(pts, 1.0, o);
  // The task's region is x >= 2; its box starts at 0.2 (a halo of 1.8 that misses the head).
  Tally t = check_box(pts, whole, 1.0, o, {0.2, -kInf, -kInf, kInf, kInf, kInf});
  EXPECT_EQ(t.held, 9u);
  EXPECT_EQ(t.settled_status, 0u);
  // A halo reaching x = -0.6 holds the head: everything is settled.
  t = check_box(pts, whole, 1.0, o, {-0.6, -kInf, -kInf, kInf, kInf, kInf});
  EXPECT_EQ(t.settled_status, 10u);
  EXPECT_EQ(t.settled_cells, 10u);
  // Holding the head, but with it within c/2 of the box's edge: it is exposed, and the chain with it.
  t = check_box(pts, whole, 1.0, o, {-0.4, -kInf, -kInf, kInf, kInf, kInf});
  EXPECT_EQ(t.settled_status, 0u);
}

// Tags name the vertices in weight order: one that does not exceed the last is a caller's bug.
TEST(FloatingCellRegion, TagsMustIncrease) {
  RegionClusterer rc(1.0, kVariants[0], std::array<double, 6>{-kInf, -kInf, -kInf, kInf, kInf, kInf});
  const P p{0, 0, 0}, q{5, 5, 5};
  EXPECT_EQ(rc.assign(7, p).center, 7u);
  EXPECT_THROW(rc.assign(7, q), Failure);
  EXPECT_THROW(rc.assign(3, q), Failure);
  EXPECT_EQ(rc.assign(8, q).center, 8u);
}

}  // namespace
}  // namespace lodstream

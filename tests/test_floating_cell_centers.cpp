// The centers of a floating-cell level (core/floating_cell_centers.h): CenterPass finds exactly the
// whole-scene Clusterer's centers, with and without its covered voxels, on clouds (random, on a lattice whose
// points and cell sides fall on voxel boundaries, in clumps, and dense on planes, where most vertices are
// skipped), for every shape and choice, in blocks of random sizes; and a range of the weight order
// clustered on its own, after the centers before it, gets the whole pass's cells.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "core/floating_cell.h"
#include "core/floating_cell_centers.h"
#include "core/floating_cell_region.h"
#include "core/status.h"
#include "clouds.h"

namespace lodstream {
namespace {

using core::CellChoice;
using core::CellShape;
using core::CenterPass;
using core::ClusterOptions;
using core::Clustering;
using P = std::array<double, 3>;

constexpr ClusterOptions kVariants[] = {
    {Clustering::floating, CellShape::cube, CellChoice::nearest},
    {Clustering::floating, CellShape::cube, CellChoice::heaviest},
    {Clustering::floating, CellShape::sphere, CellChoice::nearest},
    {Clustering::floating, CellShape::sphere, CellChoice::heaviest},
};

std::vector<P> cloud(std::mt19937_64& rng, int kind, size_t n) { return test::cloud(rng, kind, n); }

std::array<double, 6> bounds_of(const std::vector<P>& pts) {
  std::array<double, 6> b = {pts[0][0], pts[0][1], pts[0][2], pts[0][0], pts[0][1], pts[0][2]};
  for (const P& p : pts)
    for (int a = 0; a < 3; ++a) b[a] = std::min(b[a], p[a]), b[3 + a] = std::max(b[3 + a], p[a]);
  return b;
}

// CenterPass over pts in blocks of random sizes: per vertex, 1 when it starts a cell.
// wide: bounds 10⁴ times the cloud's, so that no bitmap over them fits and the voxels go in bricks.
std::vector<uint8_t> centers_of(const std::vector<P>& pts, double c, ClusterOptions o, uint64_t bitmap_bytes, std::mt19937_64& rng,
                                uint64_t* skipped, double* voxel, bool wide = false, bool* sparse = nullptr) {
  std::array<double, 6> b = bounds_of(pts);
  if (wide)
    for (int a = 0; a < 3; ++a) b[a] -= 1e5, b[3 + a] += 1e5;
  CenterPass pass(c, o, b, bitmap_bytes);
  if (sparse) *sparse = pass.sparse();
  std::vector<uint8_t> out(pts.size());
  for (size_t at = 0; at < pts.size();) {
    const size_t n = std::min<size_t>(1 + rng() % 700, pts.size() - at);
    pass.visit_block(std::span<const double>(pts[at].data(), 3 * n), std::span<uint8_t>(&out[at], n));
    at += n;
  }
  *skipped = pass.skipped();
  *voxel = pass.voxel();
  uint64_t centers = 0;
  for (uint8_t x : out) centers += x;
  EXPECT_EQ(centers, pass.centers());
  return out;
}

// The budgets: none, too small for any voxels, a bitmap at c/4 for the coarser cells and bricks at their
// budget for the finer, an ample bitmap, and (kWide) bricks over bounds too wide for a bitmap.
constexpr uint64_t kWide = 1;

TEST(FloatingCellCenters, CentersAreTheWholeScenePassWithAndWithoutCoveredVoxels) {
  std::mt19937_64 rng(7);
  uint64_t skipped_total = 0, checked = 0;
  for (int kind = 0; kind < 4; ++kind) {
    const std::vector<P> pts = cloud(rng, kind, kind == 3 ? 40000 : 6000);
    const std::span<const double> xyz(pts.data()->data(), 3 * pts.size());
    for (const ClusterOptions& o : kVariants)
      for (double c : {0.5, 1.0, 2.0}) {
        const std::vector<uint32_t> whole = core::whole_scene_centers(xyz, c, o);
        for (uint64_t bytes : {uint64_t{0}, uint64_t{64}, uint64_t{1} << 12, uint64_t{1} << 22, kWide}) {
          uint64_t skipped = 0;
          double voxel = 0;
          bool sparse = false;
          const bool wide = bytes == kWide;
          const std::vector<uint8_t> centers = centers_of(pts, c, o, wide ? uint64_t{1} << 22 : bytes, rng, &skipped, &voxel, wide, &sparse);
          if (wide) {
            EXPECT_TRUE(sparse) << "no bitmap over the wide bounds fits";
          }
          if (bytes == uint64_t{1} << 22) {
            EXPECT_FALSE(sparse);
          }
          for (size_t i = 0; i < pts.size(); ++i)
            ASSERT_EQ(centers[i] != 0, whole[i] == i) << "kind " << kind << " c " << c << " bitmap " << bytes << " vertex " << i;
          if (voxel == 0) {
            EXPECT_EQ(skipped, 0u);
          } else {
            EXPECT_LE(voxel, c / 4);
            EXPECT_EQ(voxel, std::ldexp(1.0, std::ilogb(voxel)));  // a power of two
          }
          if (bytes == 0) {
            EXPECT_EQ(voxel, 0.0);
          }
          if (bytes == uint64_t{1} << 22) {
            EXPECT_LE(voxel, c / 8);  // room for fine voxels here
          }
          if (kind == 3 && bytes == uint64_t{1} << 22) {
            EXPECT_GT(skipped, pts.size() / 3) << "c " << c;  // 40 % at c = 0.5
          }
          if (kind == 3 && wide) {
            EXPECT_GT(skipped, pts.size() / 8) << "c " << c;  // 16 % at c = 0.5: bricks' voxels are c/4
          }
          skipped_total += skipped;
          ++checked;
        }
      }
  }
  EXPECT_GT(skipped_total, 0u);
  EXPECT_EQ(checked, 4u * 4u * 3u * 5u);
}

// A range [lo, hi) of the weight order clustered alone: a Clusterer given the centers before lo, then the
// range, decides the range's vertices as the whole pass does (what a share of a level split by records does).
TEST(FloatingCellCenters, ARangeAfterTheCentersBeforeItIsTheWholePass) {
  std::mt19937_64 rng(11);
  for (int kind = 0; kind < 4; ++kind) {
    const std::vector<P> pts = cloud(rng, kind, 5000);
    const std::span<const double> xyz(pts.data()->data(), 3 * pts.size());
    for (const ClusterOptions& o : kVariants) {
      const double c = 1.0;
      const std::vector<uint32_t> whole = core::whole_scene_centers(xyz, c, o);
      const std::array<double, 6> b = bounds_of(pts);
      for (size_t lo : {size_t{0}, size_t{1}, size_t{1234}, size_t{4999}}) {
        const size_t hi = std::min<size_t>(pts.size(), lo + 1700);
        core::Clusterer range(std::span<const double>(&c, 1), o, b);
        std::vector<uint32_t> center_of_cell;
        uint32_t cell = 0;
        for (size_t i = 0; i < lo; ++i)
          if (whole[i] == i) {
            range.assign(static_cast<uint32_t>(i), std::span<const double, 3>(pts[i].data(), 3), std::span<uint32_t>(&cell, 1));
            ASSERT_EQ(cell, center_of_cell.size());  // every center starts its cell
            center_of_cell.push_back(static_cast<uint32_t>(i));
          }
        for (size_t i = lo; i < hi; ++i) {
          range.assign(static_cast<uint32_t>(i), std::span<const double, 3>(pts[i].data(), 3), std::span<uint32_t>(&cell, 1));
          if (cell == center_of_cell.size()) center_of_cell.push_back(static_cast<uint32_t>(i));
          ASSERT_EQ(center_of_cell[cell], whole[i]) << "kind " << kind << " vertex " << i;
        }
      }
    }
  }
}

TEST(FloatingCellCenters, RefusesUniformCells) {
  const std::array<double, 6> b = {0, 0, 0, 1, 1, 1};
  EXPECT_THROW(CenterPass(1.0, ClusterOptions{Clustering::uniform}, b, 1024), Failure);
}

}  // namespace
}  // namespace lodstream

// Exact squared Euclidean distance transform (core/distance_transform.h): small cases drawn out, degenerate
// sizes (empty, 1 × 1, 1 × N, N × 1), empty and full masks, both targets, bad arguments, and exact equality
// with a brute-force minimum over all target pixels on random images of many sizes and densities.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "core/distance_transform.h"
#include "core/status.h"

namespace lodstream {
namespace {

using core::EdtTarget;
using core::kEdtNoTarget;

std::vector<uint32_t> edt(const std::vector<uint8_t>& mask, int w, int h, EdtTarget target = EdtTarget::nonzero) {
  std::vector<uint32_t> out(mask.size(), 12345);
  core::squared_edt(mask, w, h, out, target);
  return out;
}

std::vector<uint32_t> brute_force(const std::vector<uint8_t>& mask, int w, int h, EdtTarget target) {
  std::vector<uint32_t> out(mask.size(), kEdtNoTarget);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      uint32_t best = kEdtNoTarget;
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          const bool set = mask[static_cast<size_t>(v) * w + u] != 0;
          if (set != (target == EdtTarget::nonzero)) continue;
          best = std::min(best, static_cast<uint32_t>((x - u) * (x - u) + (y - v) * (y - v)));
        }
      }
      out[static_cast<size_t>(y) * w + x] = best;
    }
  }
  return out;
}

// . . . . .
// . . . . .
// . . # . .      single pixel at (2, 2) of a 5 × 4 image
// . . . . .
TEST(DistanceTransform, SinglePixel) {
  const int w = 5, h = 4;
  std::vector<uint8_t> mask(w * h, 0);
  mask[2 * w + 2] = 1;
  const std::vector<uint32_t> expected = {
      8, 5, 4, 5, 8,  //
      5, 2, 1, 2, 5,  //
      4, 1, 0, 1, 4,  //
      5, 2, 1, 2, 5,  //
  };
  EXPECT_EQ(edt(mask, w, h), expected);
}

// # . . . . . #   two sites in one row: the envelope switches halfway (x = 3 is 9 from both)
TEST(DistanceTransform, TwoSitesInARow) {
  const std::vector<uint8_t> mask = {1, 0, 0, 0, 0, 0, 1};
  const std::vector<uint32_t> expected = {0, 1, 4, 9, 4, 1, 0};
  EXPECT_EQ(edt(mask, 7, 1), expected);
  EXPECT_EQ(edt(mask, 1, 7), expected);  // the same as a column
}

TEST(DistanceTransform, EmptyAndFullMasks) {
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 1}, std::pair{1, 4}, std::pair{6, 5}}) {
    const std::vector<uint8_t> none(static_cast<size_t>(w * h), 0);
    const std::vector<uint8_t> all(static_cast<size_t>(w * h), 255);
    EXPECT_EQ(edt(none, w, h), std::vector<uint32_t>(none.size(), kEdtNoTarget)) << w << "x" << h;
    EXPECT_EQ(edt(all, w, h), std::vector<uint32_t>(all.size(), 0u)) << w << "x" << h;
    EXPECT_EQ(edt(none, w, h, EdtTarget::zero), std::vector<uint32_t>(none.size(), 0u)) << w << "x" << h;
    EXPECT_EQ(edt(all, w, h, EdtTarget::zero), std::vector<uint32_t>(all.size(), kEdtNoTarget)) << w << "x" << h;
  }
}

TEST(DistanceTransform, ZeroSizedImage) {
  std::vector<uint8_t> mask;
  std::vector<uint32_t> out;
  EXPECT_NO_THROW(core::squared_edt(mask, 0, 0, out));
  EXPECT_NO_THROW(core::squared_edt(mask, 0, 7, out));
  EXPECT_NO_THROW(core::squared_edt(mask, 9, 0, out));
}

TEST(DistanceTransform, BadArguments) {
  std::vector<uint8_t> mask(6, 0);
  std::vector<uint32_t> out(6);
  std::vector<uint32_t> short_out(5);
  EXPECT_THROW(core::squared_edt(mask, 2, 2, out), Failure);  // mask size is not 2 × 2
  EXPECT_THROW(core::squared_edt(mask, 3, 2, short_out), Failure);
  EXPECT_THROW(core::squared_edt(mask, -1, -6, out), Failure);
  std::vector<uint8_t> wide(core::kEdtMaxSide + 1, 0);
  std::vector<uint32_t> wide_out(wide.size());
  EXPECT_THROW(core::squared_edt(wide, core::kEdtMaxSide + 1, 1, wide_out), Failure);
}

// The largest distances: one target in a corner of a long thin image, exact at the far end.
TEST(DistanceTransform, FarCorner) {
  const int w = 3000, h = 2;
  std::vector<uint8_t> mask(static_cast<size_t>(w) * h, 0);
  mask[0] = 1;
  const std::vector<uint32_t> out = edt(mask, w, h);
  EXPECT_EQ(out[static_cast<size_t>(w) * h - 1], 2999u * 2999u + 1u);
  EXPECT_EQ(out[w - 1], 2999u * 2999u);
}

TEST(DistanceTransform, MatchesBruteForceOnRandomImages) {
  std::mt19937 rng(20240611);
  const std::vector<std::pair<int, int>> sizes = {{1, 1},  {1, 2},  {2, 1},  {1, 17}, {23, 1}, {2, 2},
                                                  {3, 5},  {7, 4},  {8, 8},  {16, 9}, {9, 16}, {31, 30},
                                                  {40, 3}, {3, 40}, {33, 47}};
  const std::vector<double> densities = {0.0, 0.003, 0.02, 0.1, 0.5, 0.9, 1.0};
  int cases = 0;
  for (const auto& [w, h] : sizes) {
    for (const double density : densities) {
      for (int rep = 0; rep < 3; ++rep) {
        std::bernoulli_distribution set(density);
        std::vector<uint8_t> mask(static_cast<size_t>(w) * h);
        for (uint8_t& m : mask) m = set(rng) ? static_cast<uint8_t>(1 + rng() % 255) : 0;
        for (const EdtTarget target : {EdtTarget::nonzero, EdtTarget::zero}) {
          ASSERT_EQ(edt(mask, w, h, target), brute_force(mask, w, h, target))
              << w << "x" << h << " density " << density << " rep " << rep;
          ++cases;
        }
      }
    }
  }
  EXPECT_EQ(cases, 15 * 7 * 3 * 2);
}

// Sparse sites on a larger image, where the row envelopes hold many parabolas with far-apart heights.
TEST(DistanceTransform, MatchesBruteForceSparseLarge) {
  std::mt19937 rng(7);
  const int w = 97, h = 61;
  for (int sites : {1, 2, 5, 30}) {
    std::vector<uint8_t> mask(static_cast<size_t>(w) * h, 0);
    for (int i = 0; i < sites; ++i) mask[rng() % mask.size()] = 1;
    ASSERT_EQ(edt(mask, w, h), brute_force(mask, w, h, EdtTarget::nonzero)) << sites << " sites";
  }
}

}  // namespace
}  // namespace lodstream

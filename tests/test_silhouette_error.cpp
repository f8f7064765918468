// Silhouette error (core/silhouette_error.h): hand-made masks with exact expectations (a shifted square, an
// isolated extra pixel, identical masks, the image border bounding every distance), nearest-rank
// percentiles on known distributions, summing views in any order, and a brute-force reference of the
// per-pixel definition on random masks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <ostream>
#include <random>
#include <vector>

#include "core/silhouette_error.h"
#include "core/status.h"

namespace lodstream {
namespace core {
void PrintTo(const SquaredDistanceCount& h, std::ostream* os) { *os << "{" << h.squared << ", " << h.count << "}"; }
}  // namespace core

namespace {

using core::SilhouetteCounts;
using core::SquaredDistanceCount;

struct Image {
  int w, h;
  std::vector<uint8_t> pixels;
  Image(int width, int height) : w(width), h(height), pixels(static_cast<size_t>(width) * height, 0) {}
  void set(int x, int y) { pixels[static_cast<size_t>(y) * w + x] = 1; }
  void fill(int x0, int y0, int x1, int y1) {  // [x0, x1) × [y0, y1)
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) set(x, y);
  }
};

struct Result {
  SilhouetteCounts counts;
  std::vector<float> distances;
};

Result compare(const Image& original, const Image& lod) {
  Result r;
  core::SilhouetteScratch scratch;
  r.distances.assign(original.pixels.size(), -1.0f);
  core::compare_silhouettes(original.pixels, lod.pixels, original.w, original.h, scratch, r.counts, r.distances);
  return r;
}

std::vector<SquaredDistanceCount> histogram(std::initializer_list<std::pair<uint32_t, uint64_t>> entries) {
  std::vector<SquaredDistanceCount> h;
  for (const auto& [squared, count] : entries) h.push_back({squared, count});
  return h;
}

// O = the square [5, 15)², L = the same square 3 pixels to the right, in a 30 × 30 image.
// L \ O is columns 15..17: 1, 2, 3 pixels from O's right edge (10 pixels each).
// O \ L is columns 5..7, measured to the nearest pixel outside O, which may be above or below:
//   column 5: 1 (10 pixels); column 6: 1 at rows 5 and 14, else 2; column 7: 1, 2 near the ends, else 3.
TEST(SilhouetteError, SquareShiftedByThree) {
  Image o(30, 30), l(30, 30);
  o.fill(5, 5, 15, 15);
  l.fill(8, 5, 18, 15);
  const Result r = compare(o, l);
  EXPECT_EQ(r.counts.mismatched, 60u);
  EXPECT_EQ(r.counts.covered_either, 130u);
  EXPECT_EQ(r.counts.covered_both, 70u);
  EXPECT_EQ(r.counts.histogram, histogram({{1, 24}, {4, 20}, {9, 16}}));

  const core::SilhouetteStats s = core::silhouette_stats(r.counts);
  EXPECT_EQ(s.max, 3.0);
  EXPECT_EQ(s.p95, 3.0);  // rank 57 of 60
  EXPECT_DOUBLE_EQ(s.mean, (24 * 1 + 20 * 2 + 16 * 3) / 60.0);
  EXPECT_DOUBLE_EQ(s.mismatch_fraction, 60.0 / 130.0);

  // Heat map: 0 where coverage agrees, the distance elsewhere.
  EXPECT_EQ(r.distances[0], 0.0f);
  EXPECT_EQ(r.distances[10 * 30 + 10], 0.0f);  // covered by both
  EXPECT_EQ(r.distances[10 * 30 + 15], 1.0f);
  EXPECT_EQ(r.distances[10 * 30 + 17], 3.0f);
  EXPECT_EQ(r.distances[10 * 30 + 7], 3.0f);
  EXPECT_EQ(r.distances[5 * 30 + 7], 1.0f);
  EXPECT_EQ(r.distances[6 * 30 + 7], 2.0f);
  EXPECT_EQ(r.distances[10 * 30 + 18], 0.0f);
}

TEST(SilhouetteError, IdenticalMasks) {
  Image o(20, 12);
  o.fill(3, 2, 17, 9);
  o.set(0, 11);
  const Result r = compare(o, o);
  EXPECT_EQ(r.counts.mismatched, 0u);
  EXPECT_EQ(r.counts.covered_either, 14u * 7u + 1u);
  EXPECT_EQ(r.counts.covered_both, 14u * 7u + 1u);
  EXPECT_TRUE(r.counts.histogram.empty());
  EXPECT_EQ(r.distances, std::vector<float>(o.pixels.size(), 0.0f));
  const core::SilhouetteStats s = core::silhouette_stats(r.counts);
  EXPECT_EQ(s.max, 0.0);
  EXPECT_EQ(s.p95, 0.0);
  EXPECT_EQ(s.mean, 0.0);
  EXPECT_EQ(s.mismatch_fraction, 0.0);
}

TEST(SilhouetteError, NothingCovered) {
  const Image o(8, 8);
  const Result r = compare(o, o);
  EXPECT_EQ(r.counts.covered_either, 0u);
  EXPECT_EQ(core::silhouette_stats(r.counts).mismatch_fraction, 0.0);
}

// An extra pixel at (22, 23), 3 right of and 4 below the square's corner (19, 19): 5 pixels away.
TEST(SilhouetteError, IsolatedPixelAtDistanceFive) {
  Image o(32, 32);
  o.fill(10, 10, 20, 20);
  Image l = o;
  l.set(22, 23);
  const Result r = compare(o, l);
  EXPECT_EQ(r.counts.mismatched, 1u);
  EXPECT_EQ(r.counts.histogram, histogram({{25, 1}}));
  const core::SilhouetteStats s = core::silhouette_stats(r.counts);
  EXPECT_EQ(s.max, 5.0);
  EXPECT_EQ(s.p95, 5.0);
  EXPECT_EQ(s.mean, 5.0);
  EXPECT_DOUBLE_EQ(s.mismatch_fraction, 1.0 / 101.0);
  EXPECT_EQ(r.distances[23 * 32 + 22], 5.0f);
}

// A hole in the LOD is measured to the original's outline, not to the hole's edge: a 1-pixel hole in the
// middle of a 9 × 9 square is 5 pixels from the nearest uncovered pixel.
TEST(SilhouetteError, HoleMeasuredToOriginalOutline) {
  Image o(11, 11);
  o.fill(1, 1, 10, 10);
  Image l = o;
  l.pixels[5 * 11 + 5] = 0;
  const Result r = compare(o, l);
  EXPECT_EQ(r.counts.histogram, histogram({{25, 1}}));
  EXPECT_EQ(r.counts.covered_both, 80u);
}

// The original's coverage beyond the border is unknown, so the border bounds every distance: a pinhole in a
// view the original fills is as far as its nearest outside pixel, not the image diagonal.
TEST(SilhouetteError, BorderBoundsTheDistance) {
  Image full(6, 4);
  full.fill(0, 0, 6, 4);
  Image holed = full;
  holed.pixels[0] = 0;              // corner: 1 from outside
  holed.pixels[1 * 6 + 2] = 0;      // (2, 1): 2 from the top edge
  EXPECT_EQ(compare(full, holed).counts.histogram, histogram({{1, 1}, {4, 1}}));
  const Image empty(6, 4);
  Image speck(6, 4);
  speck.set(2, 2);                  // min(3, 3, 4, 2) = 2
  speck.set(3, 2);                  // min(4, 3, 3, 2) = 2
  const Result r = compare(empty, speck);
  EXPECT_EQ(r.counts.histogram, histogram({{4, 2}}));
  EXPECT_EQ(r.distances[2 * 6 + 2], 2.0f);
  // Inside a large image, the outline in view is nearer than the border and wins.
  Image o(40, 40), l(40, 40);
  o.fill(10, 10, 30, 30);
  l = o;
  l.set(33, 20);                    // 4 from O, 7 from the border
  EXPECT_EQ(compare(o, l).counts.histogram, histogram({{16, 1}}));
}

TEST(SilhouetteError, BadArguments) {
  core::SilhouetteScratch scratch;
  SilhouetteCounts out;
  const std::vector<uint8_t> a(12, 0), b(11, 0);
  std::vector<float> short_image(11);
  EXPECT_THROW(core::compare_silhouettes(a, b, 4, 3, scratch, out), Failure);
  EXPECT_THROW(core::compare_silhouettes(a, a, 4, 3, scratch, out, short_image), Failure);
  EXPECT_THROW(core::compare_silhouettes(a, a, 5, 3, scratch, out), Failure);
  EXPECT_NO_THROW(core::compare_silhouettes(a, a, 4, 3, scratch, out));
  EXPECT_THROW(core::squared_distance_percentile(out, 0), Failure);
  EXPECT_THROW(core::squared_distance_percentile(out, 101), Failure);
}

// Nearest rank: the value at position ceil(p / 100 × N) in increasing order.
TEST(SilhouetteError, PercentileNearestRank) {
  SilhouetteCounts c;
  c.histogram = histogram({{1, 90}, {4, 5}, {9, 4}, {16, 1}});  // 100 pixels
  c.mismatched = 100;
  EXPECT_EQ(core::squared_distance_percentile(c, 95), 4u);  // rank 95: the last 4
  EXPECT_EQ(core::squared_distance_percentile(c, 90), 1u);
  EXPECT_EQ(core::squared_distance_percentile(c, 91), 4u);
  EXPECT_EQ(core::squared_distance_percentile(c, 96), 9u);
  EXPECT_EQ(core::squared_distance_percentile(c, 100), 16u);
  EXPECT_EQ(core::squared_distance_percentile(c, 1), 1u);
  EXPECT_EQ(core::silhouette_stats(c).p95, 2.0);

  c.histogram = histogram({{1, 90}, {4, 5}, {9, 6}});  // 101 pixels: rank ceil(95.95) = 96
  c.mismatched = 101;
  EXPECT_EQ(core::squared_distance_percentile(c, 95), 9u);

  c.histogram = histogram({{2, 19}, {8, 1}});  // 20 pixels: rank 19 exactly
  c.mismatched = 20;
  EXPECT_EQ(core::squared_distance_percentile(c, 95), 2u);
  EXPECT_DOUBLE_EQ(core::silhouette_stats(c).p95, std::sqrt(2.0));

  // Counts near 2^63 do not overflow the rank.
  const uint64_t big = uint64_t{1} << 62;
  c.histogram = histogram({{1, big}, {4, big / 10}});
  c.mismatched = big + big / 10;
  EXPECT_EQ(core::squared_distance_percentile(c, 90), 1u);
  EXPECT_EQ(core::squared_distance_percentile(c, 95), 4u);

  EXPECT_EQ(core::squared_distance_percentile(SilhouetteCounts{}, 95), 0u);
}

TEST(SilhouetteError, SumOfViewsInAnyOrder) {
  std::mt19937 rng(3);
  std::vector<SilhouetteCounts> views;
  core::SilhouetteScratch scratch;
  for (int v = 0; v < 6; ++v) {
    Image o(17, 13), l(17, 13);
    for (auto& p : o.pixels) p = rng() % 3 == 0;
    for (auto& p : l.pixels) p = rng() % 3 == 0;
    SilhouetteCounts c;
    core::compare_silhouettes(o.pixels, l.pixels, 17, 13, scratch, c);
    views.push_back(c);
  }
  views.push_back(SilhouetteCounts{});  // a view with nothing in it
  SilhouetteCounts forward, backward;
  for (const auto& v : views) core::add_silhouette_counts(forward, v);
  for (auto it = views.rbegin(); it != views.rend(); ++it) core::add_silhouette_counts(backward, *it);
  EXPECT_EQ(forward.histogram, backward.histogram);
  EXPECT_EQ(forward.mismatched, backward.mismatched);

  std::map<uint32_t, uint64_t> expected;
  uint64_t mismatched = 0, either = 0, both = 0;
  for (const auto& v : views) {
    mismatched += v.mismatched;
    either += v.covered_either;
    both += v.covered_both;
    for (const auto& h : v.histogram) expected[h.squared] += h.count;
  }
  std::vector<SquaredDistanceCount> expected_histogram;
  for (const auto& [squared, count] : expected) expected_histogram.push_back({squared, count});
  EXPECT_EQ(forward.histogram, expected_histogram);
  EXPECT_EQ(forward.mismatched, mismatched);
  EXPECT_EQ(forward.covered_either, either);
  EXPECT_EQ(forward.covered_both, both);
  const core::SilhouetteStats a = core::silhouette_stats(forward), b = core::silhouette_stats(backward);
  EXPECT_EQ(a.mean, b.mean);
  EXPECT_EQ(a.p95, b.p95);
  EXPECT_EQ(a.max, b.max);
}

// The definition, pixel by pixel, with a full scan for the nearest pixel.
std::vector<uint32_t> brute_force(const Image& o, const Image& l) {
  std::vector<uint32_t> out(o.pixels.size(), 0);
  for (int y = 0; y < o.h; ++y) {
    for (int x = 0; x < o.w; ++x) {
      const bool in_o = o.pixels[static_cast<size_t>(y) * o.w + x] != 0;
      const bool in_l = l.pixels[static_cast<size_t>(y) * o.w + x] != 0;
      if (in_o == in_l) continue;
      // L \ O: nearest pixel of O; O \ L: nearest pixel not in O.
      uint32_t best = std::numeric_limits<uint32_t>::max();
      for (int v = 0; v < o.h; ++v) {
        for (int u = 0; u < o.w; ++u) {
          if ((o.pixels[static_cast<size_t>(v) * o.w + u] != 0) == in_o) continue;
          best = std::min(best, static_cast<uint32_t>((x - u) * (x - u) + (y - v) * (y - v)));
        }
      }
      const uint32_t border = static_cast<uint32_t>(std::min(std::min(x + 1, y + 1), std::min(o.w - x, o.h - y)));
      out[static_cast<size_t>(y) * o.w + x] = std::min(best, border * border);
    }
  }
  return out;
}

TEST(SilhouetteError, MatchesBruteForceOnRandomMasks) {
  std::mt19937 rng(11);
  core::SilhouetteScratch scratch;  // reused across sizes on purpose
  int cases = 0;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {1, 9}, {12, 1}, {5, 5}, {24, 17}, {40, 40}}) {
    for (int rep = 0; rep < 8; ++rep) {
      Image o(w, h), l(w, h);
      // Blobby shapes: a random rectangle each, then noise of varying strength.
      o.fill(static_cast<int>(rng() % w), static_cast<int>(rng() % h), w, h);
      l.fill(0, 0, static_cast<int>(rng() % (w + 1)), static_cast<int>(rng() % (h + 1)));
      const unsigned noise = 1 + rng() % 20;
      for (auto& p : o.pixels)
        if (rng() % 100 < noise) p ^= 1;
      for (auto& p : l.pixels)
        if (rng() % 100 < noise) p ^= 1;

      SilhouetteCounts c;
      std::vector<float> distances(o.pixels.size());
      core::compare_silhouettes(o.pixels, l.pixels, w, h, scratch, c, distances);
      const std::vector<uint32_t> expected = brute_force(o, l);

      std::map<uint32_t, uint64_t> expected_counts;
      uint64_t either = 0, both = 0, mismatched = 0;
      for (size_t i = 0; i < o.pixels.size(); ++i) {
        either += o.pixels[i] || l.pixels[i];
        both += o.pixels[i] && l.pixels[i];
        if (o.pixels[i] != l.pixels[i]) {
          ++mismatched;
          ++expected_counts[expected[i]];
        }
        ASSERT_EQ(distances[i], static_cast<float>(std::sqrt(static_cast<double>(expected[i])))) << i;
      }
      std::vector<SquaredDistanceCount> expected_histogram;
      for (const auto& [squared, count] : expected_counts) expected_histogram.push_back({squared, count});
      ASSERT_EQ(c.histogram, expected_histogram) << w << "x" << h << " rep " << rep;
      ASSERT_EQ(c.mismatched, mismatched);
      ASSERT_EQ(c.covered_either, either);
      ASSERT_EQ(c.covered_both, both);

      // p95 and max against a sorted list of every distance.
      std::vector<uint32_t> all;
      for (const auto& [squared, count] : expected_counts) all.insert(all.end(), count, squared);
      const core::SilhouetteStats s = core::silhouette_stats(c);
      if (!all.empty()) {
        const size_t rank = (all.size() * 95 + 99) / 100;
        EXPECT_EQ(s.p95, std::sqrt(static_cast<double>(all[rank - 1])));
        EXPECT_EQ(s.max, std::sqrt(static_cast<double>(all.back())));
      }
      ++cases;
    }
  }
  EXPECT_EQ(cases, 48);
}

}  // namespace
}  // namespace lodstream

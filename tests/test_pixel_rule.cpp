// The report's pixel rule (core/view_cast.h), on scenes with a known answer. Camera at (0, 0, 5) looking at
// the origin with a 90° field of view and H = 64 pixels: pixel column x sees the plane z = 0 at
// X = 5 (2u / H − 1) for u in [x, x + 1), so a pixel is 10/64 = 0.15625 units wide there, and the k × k rays
// of column x meet it at u = x + (i + ½) / k.
// - a thin pole (a rectangle of triangles) between two pixel centres: missed with one ray a pixel, covered
//   in exactly its column with k = 4 (wider than 1/4 pixel), missed again when narrower than the rays'
//   spacing and between them;
// - the same pole as a thick edge of its width: the same pixels, pixel for pixel (the symmetry the rule is
//   for);
// - a point drawn one pixel wide (one_pixel_radii): at any position, covered, in at most two pixels, its
//   own or a neighbour; a line drawn one pixel wide: one pixel or two in every row it crosses;
// - centre hits win: a pixel whose centre sees the far plane keeps the far depth though a k × k ray sees a
//   nearer pole; a pixel whose centre misses takes the nearest of its k × k hits;
// - chunks: a grid with duplicated triangles and a pole traced in parts gives the image of the whole, with
//   k = 3 (k × k rays bounded by earlier chunks' hits);
// - thin features (core/silhouette_error.h): a one-pixel line and a block, half the line kept.
#include <gtest/gtest.h>

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
#include "core/silhouette_error.h"
#include "core/view_cast.h"

namespace lodstream {
namespace {

using core::Camera;
using core::PrimitiveKind;
using core::RayScene;
using core::ViewImage;

constexpr unsigned kH = 64;
constexpr double kPixel = 10.0 / kH;  // object units per pixel at z = 0

Camera head_on(unsigned k) {
  const double eye[3] = {0, 0, 5}, origin[3] = {0, 0, 0};
  Camera c = core::look_at(eye, origin, 90, kH);
  c.supersample = k;
  return c;
}

// Object x at z = 0 of image coordinate u (pixels from the left edge).
double x_of(double u) { return 5 * (2 * u / kH - 1); }

ViewImage cast(const std::vector<const RayScene*>& scenes, const Camera& camera) {
  ViewImage image;
  core::cast_view(scenes, camera, &image);
  return image;
}

// A rectangle [x0, x1] × [y0, y1] at height z, as two triangles.
std::unique_ptr<RayScene> rectangle(double x0, double x1, double y0, double y1, double z) {
  const std::vector<float> xyz = {float(x0), float(y0), float(z), float(x1), float(y0), float(z),
                                  float(x1), float(y1), float(z), float(x0), float(y1), float(z)};
  const std::vector<uint32_t> tri = {0, 1, 2, 0, 2, 3};
  auto s = std::make_unique<RayScene>();
  s->add_triangles(xyz, tri);
  s->commit();
  return s;
}

// Covered pixels of column x in rows [y0, y1).
unsigned column_count(const ViewImage& v, unsigned x, unsigned y0 = 0, unsigned y1 = kH) {
  unsigned n = 0;
  for (unsigned y = y0; y < y1; ++y) n += v.covered(uint64_t{y} * kH + x);
  return n;
}

// A pole 0.3 pixels wide, its middle at u = 40.75: between the centres of columns 40 and 41 (40.5, 41.5),
// over the sub-ray u = 40.875 of k = 4 (40.625 and 40.875 are the nearest: [40.6, 40.9] holds both).
TEST(PixelRule, ThinPoleIsMissedByOneRayAndCoveredInItsColumnByFour) {
  const double u0 = 40.6, u1 = 40.9;
  const auto pole = rectangle(x_of(u0), x_of(u1), -2, 2, 0);
  const ViewImage one = cast({pole.get()}, head_on(1));
  for (unsigned x = 0; x < kH; ++x) EXPECT_EQ(column_count(one, x), 0u) << "column " << x;
  const ViewImage four = cast({pole.get()}, head_on(4));
  // y in [-2, 2] is v in [19.2, 44.8] (y = 5 (1 - 2v/H)): rows 19 to 44 have a ray row inside.
  EXPECT_EQ(column_count(four, 40), 26u);
  for (unsigned x = 0; x < kH; ++x)
    if (x != 40) {
      EXPECT_EQ(column_count(four, x), 0u) << "column " << x;
    }
  // Its pixels: kind, the depth of the nearest of its rays on the pole (u = 40.625, v = 32.125), normal
  // facing the camera.
  const uint64_t p = uint64_t{32} * kH + 40;
  EXPECT_EQ(four.kind[p], uint8_t(PrimitiveKind::triangle));
  EXPECT_EQ(four.centre[p], 0);
  EXPECT_NEAR(four.depth[p], std::sqrt(25 + std::pow(x_of(40.625), 2) + std::pow(x_of(32.125), 2)), 1e-4);
  EXPECT_NEAR(four.normal[3 * p + 2], 1.0, 1e-6);
}

// Narrower than the rays' spacing and between two of them: nothing, whatever k.
TEST(PixelRule, PoleBetweenTheRaysIsMissed) {
  const auto pole = rectangle(x_of(40.65), x_of(40.85), -2, 2, 0);  // between 40.625 and 40.875
  const ViewImage four = cast({pole.get()}, head_on(4));
  for (unsigned x = 0; x < kH; ++x) EXPECT_EQ(column_count(four, x), 0u);
}

// A pole as a thick edge of its width (radius = width / 2), along its axis, seen head-on near the image's
// centre: the same covered pixels over the pole's length, for k = 1 to 5. (A flat curve faces the ray, so
// off the axis its footprint on the plane is 1 / cos θ wider: at most 0.4 % here, within the margin below.)
TEST(PixelRule, ThickEdgeOfAPolesWidthCoversThePolesPixels) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> at(29.0, 33.0), width(0.05, 1.6);
  for (int trial = 0; trial < 12; ++trial) {
    const double u0 = at(rng), w = width(rng);
    const double x0 = x_of(u0), x1 = x_of(u0 + w), xm = (x0 + x1) / 2;
    const auto pole = rectangle(x0, x1, -3, 3, 0);
    const std::vector<float> xyz = {float(xm), -3.0f, 0.0f, float(xm), 3.0f, 0.0f};
    const std::vector<uint32_t> ends = {0, 1};
    const std::vector<float> radius = {float((x1 - x0) / 2)};
    RayScene edge;
    edge.add_segments(xyz, ends, radius);
    edge.commit();
    for (unsigned k = 1; k <= 5; ++k) {
      const ViewImage a = cast({pole.get()}, head_on(k)), b = cast({&edge}, head_on(k));
      // Skip a rule whose ray falls within float rounding of a side: coverage is then a coin toss.
      bool near_side = false;
      for (unsigned x = 0; x < kH; ++x)
        for (unsigned i = 0; i <= k; ++i) {
          const double u = i == k ? x + 0.5 : x + (i + 0.5) / k;
          near_side |= std::fabs(u - u0) < 0.005 || std::fabs(u - u0 - w) < 0.005;
        }
      if (near_side) continue;
      for (unsigned y = 16; y < kH - 16; ++y)  // away from the ends (rows 13 to 51; a ribbon's end is rounded)
        for (unsigned x = 0; x < kH; ++x)
          ASSERT_EQ(a.covered(uint64_t{y} * kH + x), b.covered(uint64_t{y} * kH + x))
              << "trial " << trial << " k " << k << " pixel " << x << ", " << y << " width " << w;
      unsigned expected = 0;  // columns whose rays (centre, or any of k) fall in [u0, u0 + w]
      for (unsigned x = 0; x < kH; ++x) {
        bool hit = x + 0.5 > u0 && x + 0.5 < u0 + w;
        for (unsigned i = 0; i < k; ++i) hit |= x + (i + 0.5) / k > u0 && x + (i + 0.5) / k < u0 + w;
        expected += hit;
        EXPECT_EQ(column_count(a, x, 16, kH - 16) > 0, hit) << "k " << k << " column " << x;
      }
      if (w >= 1.0 / k) {
        EXPECT_GE(expected, 1u);  // wider than the rays' spacing: never missed
      }
    }
  }
}

// A point drawn one pixel wide, anywhere: covered in one pixel or two (its own or a neighbour), for
// k = 1 to 5. A line drawn one pixel wide, at any angle: one or two pixels in every row it crosses.
TEST(PixelRule, PointsAndLinesDrawnOnePixelWide) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> at(10.0, 54.0), angle(0.0, 0.35);
  for (unsigned k = 1; k <= 5; ++k) {
    const core::OnePixelRadii r = core::one_pixel_radii(kPixel, k);
    for (int trial = 0; trial < 40; ++trial) {
      const double u = at(rng), v = at(rng);
      const std::vector<float> xyz = {float(x_of(u)), float(-x_of(v)), 0.0f};
      const std::vector<uint32_t> ids = {0};
      RayScene point;
      point.add_points(xyz, ids, r.point);
      point.commit();
      const ViewImage img = cast({&point}, head_on(k));
      unsigned covered = 0;
      for (unsigned y = 0; y < kH; ++y)
        for (unsigned x = 0; x < kH; ++x) {
          if (!img.covered(uint64_t{y} * kH + x)) continue;
          ++covered;
          EXPECT_LE(std::fabs(x + 0.5 - u), 1.5);
          EXPECT_LE(std::fabs(y + 0.5 - v), 1.5);
          EXPECT_EQ(img.kind[uint64_t{y} * kH + x], uint8_t(PrimitiveKind::point));
        }
      EXPECT_GE(covered, 1u) << "k " << k << " point at " << u << ", " << v;
      EXPECT_LE(covered, 4u) << "k " << k << " point at " << u << ", " << v;
    }
    for (int trial = 0; trial < 6; ++trial) {
      // From (u, 8) downwards at `a` from the vertical (up to 20°), 48 rows long.
      const double u = 20 + at(rng) / 2, a = angle(rng) * (trial % 2 ? 1 : -1);  // stays inside the image
      const double u1 = u + 48 * std::tan(a);
      const std::vector<float> xyz = {float(x_of(u)), float(-x_of(8)), 0.0f, float(x_of(u1)), float(-x_of(56)), 0.0f};
      const std::vector<uint32_t> ends = {0, 1};
      const std::vector<float> radius = {r.line};
      RayScene line;
      line.add_segments(xyz, ends, radius);
      line.commit();
      const ViewImage img = cast({&line}, head_on(k));
      for (unsigned y = 9; y < 55; ++y) {
        unsigned row = 0;
        for (unsigned x = 0; x < kH; ++x) row += img.covered(uint64_t{y} * kH + x);
        EXPECT_GE(row, 1u) << "k " << k << " row " << y;
        EXPECT_LE(row, 3u) << "k " << k << " row " << y;
      }
    }
  }
}

// A wide far plane (z = 0) and a pole nearer the camera (z = 1) between pixel centres: pixels whose centre
// sees the plane keep the plane's depth; the pole's own pixels are centre hits of the plane too. With the
// plane cut away under the pole's column, that column's centre rays miss and it takes the pole's depth.
TEST(PixelRule, CentreHitWinsAndOtherwiseTheNearestOfTheRays) {
  const double u0 = 40.6, u1 = 40.9;
  const auto pole = rectangle(0.8 * x_of(u0), 0.8 * x_of(u1), -2, 2, 1);  // at z = 1, scaled to project there
  const auto plane = rectangle(-10, 10, -10, 10, 0);
  const ViewImage both = cast({plane.get(), pole.get()}, head_on(4));
  const uint64_t p = uint64_t{32} * kH + 40;
  EXPECT_TRUE(both.centre[p]);
  EXPECT_GT(both.depth[p], 5.0f);  // the plane, 5 along the axis and a little more off it
  // Two planes with a gap around column 40: its centres miss; the k × k rays see the pole (depth ~4).
  const auto left = rectangle(-10, x_of(40.05), -10, 10, 0), right = rectangle(x_of(40.95), 10, -10, 10, 0);
  const ViewImage gap = cast({left.get(), right.get(), pole.get()}, head_on(4));
  EXPECT_FALSE(gap.centre[p]);
  EXPECT_EQ(gap.kind[p], uint8_t(PrimitiveKind::triangle));
  // The nearest of its rays on the pole: u = 40.625 (of 40.625 and 40.875), v = 32.125.
  const double hx = 0.8 * x_of(40.625), hy = 0.8 * -x_of(32.125);
  EXPECT_NEAR(gap.depth[p], std::sqrt(hx * hx + hy * hy + 16), 1e-4);
}

// A wavy grid with every triangle twice, and thin poles, traced whole and in 3 parts, k = 3: the same bits.
TEST(PixelRule, ChunksGiveTheWholeImageWithSeveralRaysAPixel) {
  std::vector<float> xyz;
  std::vector<uint32_t> tri;
  const int n = 24;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      xyz.insert(xyz.end(), {float(-3 + 6.0 * i / n), float(-3 + 6.0 * j / n), float(0.2 * std::sin(i * 0.7) * std::cos(j * 0.5))});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      if ((i * 7 + j * 3) % 5 == 0) continue;  // holes, so some centres miss
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      tri.insert(tri.end(), {a, b, d, a, d, c});
    }
  const size_t base = tri.size();
  for (size_t t = 0; t < base; t += 3) tri.insert(tri.end(), {tri[t + 1], tri[t + 2], tri[t]});
  for (int pole = 0; pole < 20; ++pole) {  // 0.02 wide: about a seventh of a pixel
    const uint32_t v = static_cast<uint32_t>(xyz.size() / 3);
    const float x = -2.5f + 0.25f * pole, z = 0.5f;
    xyz.insert(xyz.end(), {x, -2, z, x + 0.02f, -2, z, x + 0.02f, 2, z, x, 2, z});
    tri.insert(tri.end(), {v, v + 1, v + 2, v, v + 2, v + 3});
  }
  RayScene whole;
  whole.add_triangles(xyz, tri);
  whole.commit();
  std::vector<std::unique_ptr<RayScene>> parts;
  const size_t count = tri.size() / 3, per = (count + 2) / 3;
  for (size_t first = 0; first < count; first += per) {
    const size_t end = std::min(count, first + per);
    parts.push_back(std::make_unique<RayScene>());
    parts.back()->add_triangles(xyz, std::span<const uint32_t>(tri.data() + 3 * first, 3 * (end - first)));
    parts.back()->commit();
  }
  for (const std::array<double, 3>& eye : {std::array<double, 3>{0.3, 0.2, 4.0}, std::array<double, 3>{-3.5, -2.0, 2.5}}) {
    const double target[3] = {0, 0, 0};
    Camera cam = core::look_at(eye.data(), target, 60, 96);
    cam.supersample = 3;
    ViewImage a, b;
    const RayScene* w[] = {&whole};
    core::cast_view(w, cam, &a);
    for (const auto& p : parts) {
      const RayScene* one[] = {p.get()};
      core::cast_view(one, cam, &b, true);
    }
    uint64_t sub = 0;
    for (size_t p = 0; p < a.kind.size(); ++p) sub += a.kind[p] != 0 && !a.centre[p];
    EXPECT_GT(sub, 50u);  // pixels covered only by k × k rays (the poles, the holes' borders)
    EXPECT_EQ(a.kind, b.kind);
    EXPECT_EQ(a.centre, b.centre);
    EXPECT_EQ(0, std::memcmp(a.depth.data(), b.depth.data(), a.depth.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(a.normal.data(), b.normal.data(), a.normal.size() * sizeof(float)));
  }
}

// O: a one-pixel line (10 pixels) and a 3 × 3 block; L covers the block and the line's first 4 pixels.
// Thin: the line's 10 pixels (no 2 × 2 block of O holds them); the block's 9 are thick. Kept: 4.
TEST(PixelRule, ThinFeatureShare) {
  const int w = 20, h = 12;
  std::vector<uint8_t> o(w * h, 0), l(w * h, 0);
  for (int x = 2; x < 12; ++x) o[2 * w + x] = 1;
  for (int y = 6; y < 9; ++y)
    for (int x = 6; x < 9; ++x) o[y * w + x] = l[y * w + x] = 1;
  for (int x = 2; x < 6; ++x) l[2 * w + x] = 1;
  core::SilhouetteScratch scratch;
  core::SilhouetteCounts counts;
  core::compare_silhouettes(o, l, w, h, scratch, counts);
  EXPECT_EQ(counts.thin, 10u);
  EXPECT_EQ(counts.thin_kept, 4u);
  core::SilhouetteCounts total;
  core::add_silhouette_counts(total, counts);
  core::add_silhouette_counts(total, counts);
  const core::SilhouetteStats s = core::silhouette_stats(total);
  EXPECT_EQ(s.thin, 20u);
  EXPECT_EQ(s.thin_kept, 8u);
  EXPECT_DOUBLE_EQ(s.thin_kept_fraction, 0.4);
  // Identical masks keep everything; no thin pixel at all counts as all kept.
  core::compare_silhouettes(o, o, w, h, scratch, counts);
  EXPECT_EQ(counts.thin_kept, counts.thin);
  std::vector<uint8_t> block(w * h, 0);
  for (int y = 1; y < 5; ++y)
    for (int x = 1; x < 5; ++x) block[y * w + x] = 1;
  core::compare_silhouettes(block, l, w, h, scratch, counts);
  EXPECT_EQ(counts.thin, 0u);
  EXPECT_DOUBLE_EQ(core::silhouette_stats(counts).thin_kept_fraction, 1.0);
}

}  // namespace
}  // namespace lodstream

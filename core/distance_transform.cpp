// Exact squared Euclidean distance transform. This work is based on:
// Pedro F. Felzenszwalb and Daniel P. Huttenlocher. Distance Transforms of Sampled Functions. Theory of
// Computing 8, 2012, §3 (Algorithm 1, the 1-D transform by the lower envelope of parabolas) and §5
// (separability: columns, then rows).
//
// Pass 1 (columns): the sampled function is 0 on target pixels and ∞ elsewhere, so the lower envelope of
// its parabolas is simply the parabola of the nearest target in the column; two row-major sweeps (down,
// then up) find it while reading the image in memory order.
// Pass 2 (rows): Algorithm 1 on each row of the column result, skipping infinite samples (they add no
// parabola). The breakpoints z between envelope parabolas are rationals kept as exact integer fractions,
// so every comparison is exact and so is every output, (q − v)² + f(v).
#include "core/distance_transform.h"

#include <algorithm>
#include <string>
#include <vector>

#include "core/status.h"

namespace lodstream::core {
namespace {

// z = num / den with den > 0. |num| < 2^32 and den <= 2^16 for kEdtMaxSide, so cross products fit in 63 bits.
struct Breakpoint {
  int64_t num;
  int64_t den;
};

// d[q] = min over p with f[p] finite of (q − p)² + f[p], or kEdtNoTarget when every f[p] is infinite
// (kEdtNoTarget). v and z are scratch of n entries each.
//
// invariant: after site q is added, v[0..k] are the sites whose parabolas form the lower envelope of the
// sites <= q, left to right, parabola i lowest on [z[i], z[i+1]], with z[1] < z[2] < ... < z[k] (z[0] is −∞
// and z[k+1] is +∞, neither stored).
void envelope_1d(const uint32_t* f, int n, uint32_t* d, int* v, Breakpoint* z) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kEdtNoTarget) continue;
    const int64_t hq = int64_t{f[q]} + int64_t{q} * q;
    Breakpoint s{0, 1};
    while (k >= 0) {
      const int p = v[k];
      // Where the parabolas of p and q meet: s = ((f[q] + q²) − (f[p] + p²)) / (2(q − p)).
      s = {hq - (int64_t{f[p]} + int64_t{p} * p), 2 * int64_t{q - p}};
      // Parabola k is hidden when q's is already lower at k's left end z[k].
      if (k > 0 && s.num * z[k].den <= z[k].num * s.den) {
        --k;
        continue;
      }
      break;
    }
    ++k;
    v[k] = q;
    z[k] = s;  // for k == 0 this is the −∞ boundary and never read
  }
  if (k < 0) {
    std::fill(d, d + n, kEdtNoTarget);
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (j < k && z[j + 1].num < int64_t{q} * z[j + 1].den) ++j;  // z[j + 1] < q
    const int64_t dq = q - v[j];
    d[q] = static_cast<uint32_t>(dq * dq + f[v[j]]);
  }
}

}  // namespace

void squared_edt(std::span<const uint8_t> mask, int width, int height, std::span<uint32_t> out,
                 EdtTarget target) {
  if (width < 0 || height < 0 || width > kEdtMaxSide || height > kEdtMaxSide) {
    fail(Status::internal, "squared_edt: image size " + std::to_string(width) + " x " + std::to_string(height) +
                               " out of range");
  }
  const size_t w = static_cast<size_t>(width);
  const size_t h = static_cast<size_t>(height);
  if (mask.size() != w * h || out.size() != w * h) {
    fail(Status::internal, "squared_edt: mask or output size is not width x height");
  }
  if (w == 0 || h == 0) return;
  const uint8_t want_nonzero = target == EdtTarget::nonzero ? 1 : 0;
  auto is_target = [&](size_t i) { return static_cast<uint8_t>(mask[i] != 0) == want_nonzero; };

  // Pass 1: out = squared distance to the nearest target in the same column, or kEdtNoTarget.
  std::vector<int> nearest(w);
  std::fill(nearest.begin(), nearest.end(), -1);  // row of the last target seen in each column
  for (size_t y = 0; y < h; ++y) {
    const size_t row = y * w;
    for (size_t x = 0; x < w; ++x) {
      if (is_target(row + x)) nearest[x] = static_cast<int>(y);
      const int64_t dy = static_cast<int64_t>(y) - nearest[x];
      out[row + x] = nearest[x] < 0 ? kEdtNoTarget : static_cast<uint32_t>(dy * dy);
    }
  }
  std::fill(nearest.begin(), nearest.end(), -1);
  for (size_t y = h; y-- > 0;) {
    const size_t row = y * w;
    for (size_t x = 0; x < w; ++x) {
      if (is_target(row + x)) nearest[x] = static_cast<int>(y);
      if (nearest[x] < 0) continue;
      const int64_t dy = nearest[x] - static_cast<int64_t>(y);
      out[row + x] = std::min(out[row + x], static_cast<uint32_t>(dy * dy));
    }
  }

  // Pass 2: the 1-D transform of each row of the column result.
  std::vector<uint32_t> f(w);
  std::vector<int> v(w);
  std::vector<Breakpoint> z(w);
  for (size_t y = 0; y < h; ++y) {
    uint32_t* row = out.data() + y * w;
    std::copy(row, row + w, f.begin());
    envelope_1d(f.data(), width, row, v.data(), z.data());
  }
}

}  // namespace lodstream::core

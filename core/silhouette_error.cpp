// Silhouette error by distance transforms. This work is based on:
// Susana Mata, Luis Pastor and Angel Rodríguez. Silhouette detection for adaptive polygonal mesh
// simplification using distance transforms. GRAPP 2006 (distance to the projected contour, per pixel)
// Pedro F. Felzenszwalb and Daniel P. Huttenlocher. Distance Transforms of Sampled Functions. 2012
//
// One view: a counting scan, then each of the two transforms of the original's coverage only when some
// pixel needs it, then the squared distances of the mismatched pixels are sorted and run-length encoded
// into the histogram. Everything after the transforms is integer arithmetic.
#include "core/silhouette_error.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/status.h"

namespace lodstream::core {

void compare_silhouettes(std::span<const uint8_t> original, std::span<const uint8_t> lod, int width, int height,
                         SilhouetteScratch& scratch, SilhouetteCounts& out, std::span<float> distance_image) {
  if (width < 0 || height < 0 || width > kEdtMaxSide || height > kEdtMaxSide) {
    fail(Status::internal, "compare_silhouettes: image size " + std::to_string(width) + " x " +
                               std::to_string(height) + " out of range");
  }
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
  if (original.size() != n || lod.size() != n || (!distance_image.empty() && distance_image.size() != n)) {
    fail(Status::internal, "compare_silhouettes: mask or distance image size is not width x height");
  }

  out.mismatched = 0;
  out.covered_either = 0;
  out.covered_both = 0;
  out.histogram.clear();
  uint64_t lod_only = 0;
  uint64_t original_only = 0;
  for (size_t i = 0; i < n; ++i) {
    const bool o = original[i] != 0;
    const bool l = lod[i] != 0;
    out.covered_either += o || l;
    out.covered_both += o && l;
    lod_only += l && !o;
    original_only += o && !l;
  }
  out.mismatched = lod_only + original_only;
  out.thin = 0;
  out.thin_kept = 0;
  // A pixel is thick when one of the (up to) four 2 × 2 blocks around it lies wholly in O.
  const auto block = [&](int x, int y) {  // the block whose top left pixel is (x, y)
    if (x < 0 || y < 0 || x + 1 >= width || y + 1 >= height) return false;
    const size_t i = static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
    return original[i] && original[i + 1] && original[i + width] && original[i + width + 1];
  };
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t i = static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
      if (!original[i] || block(x, y) || block(x - 1, y) || block(x, y - 1) || block(x - 1, y - 1)) continue;
      ++out.thin;
      out.thin_kept += lod[i] != 0;
    }
  if (!distance_image.empty()) std::fill(distance_image.begin(), distance_image.end(), 0.0f);
  if (out.mismatched == 0) return;

  scratch.squared.resize(n);
  scratch.mismatched.clear();
  auto collect = [&](EdtTarget target, bool lod_side) {
    squared_edt(original, width, height, scratch.squared, target);
    for (size_t i = 0; i < n; ++i) {
      const bool o = original[i] != 0;
      const bool l = lod[i] != 0;
      if (o == l || l != lod_side) continue;
      // The nearest pixel center outside the image bounds every distance (see the header).
      const uint32_t x = static_cast<uint32_t>(i % static_cast<size_t>(width)), y = static_cast<uint32_t>(i / static_cast<size_t>(width));
      const uint32_t border = std::min(std::min(x + 1, y + 1), std::min(static_cast<uint32_t>(width) - x, static_cast<uint32_t>(height) - y));
      const uint32_t d2 = std::min(scratch.squared[i], border * border);
      scratch.mismatched.push_back(d2);
      if (!distance_image.empty()) distance_image[i] = static_cast<float>(std::sqrt(static_cast<double>(d2)));
    }
  };
  // L \ O: distance to the nearest covered pixel of the original; O \ L: to the nearest uncovered one.
  if (lod_only > 0) collect(EdtTarget::nonzero, true);
  if (original_only > 0) collect(EdtTarget::zero, false);

  std::sort(scratch.mismatched.begin(), scratch.mismatched.end());
  for (const uint32_t d2 : scratch.mismatched) {
    if (out.histogram.empty() || out.histogram.back().squared != d2) out.histogram.push_back({d2, 0});
    ++out.histogram.back().count;
  }
}

void add_silhouette_counts(SilhouetteCounts& total, const SilhouetteCounts& view) {
  total.mismatched += view.mismatched;
  total.covered_either += view.covered_either;
  total.covered_both += view.covered_both;
  total.thin += view.thin;
  total.thin_kept += view.thin_kept;
  if (view.histogram.empty()) return;
  std::vector<SquaredDistanceCount> merged;
  merged.reserve(total.histogram.size() + view.histogram.size());
  size_t a = 0;
  size_t b = 0;
  while (a < total.histogram.size() || b < view.histogram.size()) {
    SquaredDistanceCount next;
    if (b == view.histogram.size() ||
        (a < total.histogram.size() && total.histogram[a].squared < view.histogram[b].squared)) {
      next = total.histogram[a++];
    } else if (a == total.histogram.size() || view.histogram[b].squared < total.histogram[a].squared) {
      next = view.histogram[b++];
    } else {
      next = {total.histogram[a].squared, total.histogram[a].count + view.histogram[b].count};
      ++a;
      ++b;
    }
    merged.push_back(next);
  }
  total.histogram.swap(merged);
}

uint32_t squared_distance_percentile(const SilhouetteCounts& counts, int percent) {
  if (percent < 1 || percent > 100) {
    fail(Status::internal, "squared_distance_percentile: percent " + std::to_string(percent) + " out of range");
  }
  uint64_t total = 0;
  for (const SquaredDistanceCount& h : counts.histogram) total += h.count;
  if (total == 0) return 0;
  // rank = ceil(percent × total / 100), split so that nothing overflows.
  const uint64_t p = static_cast<uint64_t>(percent);
  const uint64_t rank = total / 100 * p + (total % 100 * p + 99) / 100;
  uint64_t seen = 0;
  for (const SquaredDistanceCount& h : counts.histogram) {
    seen += h.count;
    if (seen >= rank) return h.squared;
  }
  return counts.histogram.back().squared;  // not reached: rank <= total
}

SilhouetteStats silhouette_stats(const SilhouetteCounts& counts) {
  SilhouetteStats s;
  s.mismatched = counts.mismatched;
  s.covered_either = counts.covered_either;
  s.covered_both = counts.covered_both;
  s.thin = counts.thin;
  s.thin_kept = counts.thin_kept;
  s.thin_kept_fraction = counts.thin == 0 ? 1.0 : static_cast<double>(counts.thin_kept) / static_cast<double>(counts.thin);
  s.mismatch_fraction = counts.covered_either == 0 ? 0.0
                                                   : static_cast<double>(counts.mismatched) /
                                                         static_cast<double>(counts.covered_either);
  if (counts.histogram.empty()) return s;
  s.max = std::sqrt(static_cast<double>(counts.histogram.back().squared));
  s.p95 = std::sqrt(static_cast<double>(squared_distance_percentile(counts, 95)));
  double sum = 0;
  uint64_t total = 0;
  for (const SquaredDistanceCount& h : counts.histogram) {
    sum += static_cast<double>(h.count) * std::sqrt(static_cast<double>(h.squared));
    total += h.count;
  }
  s.mean = sum / static_cast<double>(total);
  return s;
}

}  // namespace lodstream::core

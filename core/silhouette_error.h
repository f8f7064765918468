// Silhouette error of a level of detail in one view, and over many views (DESIGN.md, "Error report"): shown
// at its switching distance, how many pixels did the outline move?
//
// Susana Mata, Luis Pastor and Angel Rodríguez. Silhouette detection for adaptive polygonal mesh
// simplification using distance transforms. GRAPP 2006: the distance transform of a view's coverage image
// gives every pixel its distance to the projected contour. Here both transforms are of the ORIGINAL's
// coverage O (core/distance_transform.h, exact), and the LOD's coverage L is measured against them:
//
//   pixel in L, not in O   distance to the nearest pixel of O       (the LOD spills over the outline)
//   pixel in O, not in L   distance to the nearest pixel not in O   (the LOD leaves a gap or a hole)
//   coverage agrees        no distance (0 in the heat map)
//
// Distances are between pixel centers, in pixels. What the original covers beyond the image's border is
// unknown (the outline may run just outside it), so a distance is at most the distance to the nearest
// pixel center outside the image, min(x + 1, y + 1, width − x, height − y): a lower bound wherever the
// border is nearer than anything in view. (Without that bound, a pinhole in a view the original fills
// would count as the image diagonal.)
//
// Thin features: a pixel of O that no 2 × 2 block of O's pixels contains belongs to a part of the original
// at most about one pixel wide (a pole, a railing, a wire) or small (a lamp), or to a one-pixel sliver of a
// larger part. The share of those pixels that L covers too says whether the level keeps the features that
// a one-ray-a-pixel comparison would count as silhouette errors far from any outline.
//
// Exactness: every distance is kept as its squared value, an integer dx² + dy² (< 2^31), in a histogram keyed
// by that value; counts are exact integers. So max and p95 are exact (the square root of an exact integer),
// and summing views (add_silhouette_counts) gives the same histogram in any order. The mean is a double sum
// over the histogram in increasing order, hence deterministic too.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/distance_transform.h"

namespace lodstream::core {

struct SquaredDistanceCount {
  uint32_t squared = 0;  // squared distance in pixels²
  uint64_t count = 0;    // mismatched pixels at that distance (> 0)
  bool operator==(const SquaredDistanceCount&) const = default;
};

// Counts of one view, or summed over views.
struct SilhouetteCounts {
  uint64_t mismatched = 0;      // pixels covered by exactly one of O and L
  uint64_t covered_either = 0;  // pixels covered by O or L
  uint64_t covered_both = 0;    // pixels covered by O and L
  uint64_t thin = 0;            // pixels of O in no 2 × 2 block of O's pixels
  uint64_t thin_kept = 0;       // of those, pixels covered by L
  // Distances of the mismatched pixels: increasing `squared`, each value once; counts sum to `mismatched`.
  std::vector<SquaredDistanceCount> histogram;
};

// Buffers reused across calls of compare_silhouettes (4 bytes per pixel, plus 4 per mismatched pixel).
struct SilhouetteScratch {
  std::vector<uint32_t> squared;
  std::vector<uint32_t> mismatched;
};

// Compares the coverage masks of one view: original and lod hold width × height bytes each, row-major,
// nonzero = covered; 0 <= width, height <= kEdtMaxSide. Fills `out` (its histogram is reused). When
// distance_image is not empty it must hold width × height floats and receives the distance in pixels at
// every mismatched pixel and 0 elsewhere (a heat map). Wrong sizes: Failure(Status::internal).
void compare_silhouettes(std::span<const uint8_t> original, std::span<const uint8_t> lod, int width, int height,
                         SilhouetteScratch& scratch, SilhouetteCounts& out, std::span<float> distance_image = {});

// Adds the counts and histogram of `view` to `total`.
void add_silhouette_counts(SilhouetteCounts& total, const SilhouetteCounts& view);

// The squared distance of nearest rank ceil(percent / 100 × mismatched) among the mismatched pixels (in
// increasing order), for 1 <= percent <= 100 (else Failure(Status::internal)); 0 when nothing is mismatched.
uint32_t squared_distance_percentile(const SilhouetteCounts& counts, int percent);

// The report's numbers; distances in pixels.
struct SilhouetteStats {
  uint64_t mismatched = 0;
  uint64_t covered_either = 0;
  uint64_t covered_both = 0;
  uint64_t thin = 0, thin_kept = 0;
  double thin_kept_fraction = 1; // thin_kept / thin, 1 when the original has no thin pixel
  double max = 0;                // largest distance (0 when nothing is mismatched)
  double p95 = 0;                // nearest-rank 95th percentile of the distances
  double mean = 0;               // mean distance over the mismatched pixels
  double mismatch_fraction = 0;  // mismatched / covered_either, 0 when nothing is covered
};

SilhouetteStats silhouette_stats(const SilhouetteCounts& counts);

}  // namespace lodstream::core

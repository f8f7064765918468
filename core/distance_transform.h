// Exact Euclidean distance transform of a binary image, for the silhouette error of `lodstream report`
// (core/silhouette_error.h): for every pixel, the squared distance to the nearest target pixel.
//
// Pedro F. Felzenszwalb and Daniel P. Huttenlocher. Distance Transforms of Sampled Functions. Theory of
// Computing 8, 2012. The squared Euclidean transform is separable: first a 1-D transform of every column,
// then the 1-D transform of every row applied to the column result (§3, lower envelope of parabolas).
//
// Units and conventions: distances are between pixel centers, in pixels; pixel (x, y) is mask[y * width + x]
// (row-major, no padding). Only pixels inside the image count: nothing is assumed beyond its border. The
// results are exact: every value is dx² + dy² for integers dx, dy, computed in integer arithmetic.
//
// Cost: O(width × height) time; scratch memory O(width + height), allocated once per call.
#pragma once

#include <cstdint>
#include <limits>
#include <span>

namespace lodstream::core {

// The value of every pixel when the image has no target pixel at all (larger than any real result).
inline constexpr uint32_t kEdtNoTarget = std::numeric_limits<uint32_t>::max();

// Largest width or height accepted: squared distances stay below 2 × 32767² < 2^31.
inline constexpr int kEdtMaxSide = 32768;

// Which pixels distances are measured to.
enum class EdtTarget {
  nonzero,  // pixels whose mask byte is not 0
  zero,     // pixels whose mask byte is 0 (the transform of the complement)
};

// out[y * width + x] = min over target pixels (u, v) of (x − u)² + (y − v)²: 0 on target pixels,
// kEdtNoTarget everywhere when there is no target pixel. mask and out hold width × height entries each;
// 0 <= width, height <= kEdtMaxSide (an empty image is allowed). Otherwise Failure(Status::internal).
void squared_edt(std::span<const uint8_t> mask, int width, int height, std::span<uint32_t> out,
                 EdtTarget target = EdtTarget::nonzero);

}  // namespace lodstream::core

// Silhouette labels (Mata et al. 2006, §3); see silhouette_labels.h.
#include "core/silhouette_labels.h"

#include <algorithm>
#include <cmath>

#include "core/distance_transform.h"
#include "core/status.h"

namespace lodstream::core {

Camera label_camera(unsigned k, unsigned count, const double center[3], double radius, double fov_degrees,
                    unsigned resolution) {
  double dir[3];
  fibonacci_direction(k, count, dir);
  const double distance = std::max(radius, 1e-30) / std::sin(fov_degrees * M_PI / 360.0);
  const double eye[3] = {center[0] + dir[0] * distance, center[1] + dir[1] * distance, center[2] + dir[2] * distance};
  return look_at(eye, center, fov_degrees, resolution);
}

void outline_distances(std::span<const uint8_t> coverage, unsigned resolution, std::span<uint32_t> out) {
  const uint64_t pixels = uint64_t{resolution} * resolution;
  if (coverage.size() != pixels || out.size() != pixels || resolution > unsigned(kEdtMaxSide))
    fail(Status::internal, "outline_distances: image sizes do not match");
  const int h = static_cast<int>(resolution);
  squared_edt(coverage, h, h, out, EdtTarget::zero);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < h; ++x) {
      uint32_t& d = out[uint64_t(y) * resolution + x];
      const uint32_t border = static_cast<uint32_t>(std::min({x + 1, y + 1, h - x, h - y}));
      d = std::min(d, border * border);
    }
}

namespace {

template <class T>
void lower(const Camera& cam, std::span<const uint32_t> squared, std::span<const T> xyz, std::span<float> labels) {
  const uint64_t h = cam.resolution;
  if (squared.size() != h * h || xyz.size() != 3 * labels.size())
    fail(Status::internal, "lower_labels: sizes do not match");
  const double scale = h / (2 * cam.tan_half_fov);
  for (size_t i = 0; i < labels.size(); ++i) {
    const double v[3] = {double(xyz[3 * i]) - cam.eye[0], double(xyz[3 * i + 1]) - cam.eye[1],
                         double(xyz[3 * i + 2]) - cam.eye[2]};
    const double z = v[0] * cam.forward[0] + v[1] * cam.forward[1] + v[2] * cam.forward[2];
    if (!(z > 0)) continue;
    const double sx = (v[0] * cam.right[0] + v[1] * cam.right[1] + v[2] * cam.right[2]) / z;
    const double sy = (v[0] * cam.up[0] + v[1] * cam.up[1] + v[2] * cam.up[2]) / z;
    // view_cast's pixel x has its center at sx = (2(x + 0.5)/h − 1)·tan: the inverse, floored.
    const double fx = std::floor(sx * scale + 0.5 * double(h)), fy = std::floor(0.5 * double(h) - sy * scale);
    if (!(fx >= 0 && fx < double(h) && fy >= 0 && fy < double(h))) continue;
    const uint32_t d2 = squared[uint64_t(fy) * h + uint64_t(fx)];
    const float label = static_cast<float>(std::sqrt(double(d2)) * cam.pixel_size(z));
    labels[i] = std::min(labels[i], label);
  }
}

}  // namespace

void lower_labels(const Camera& camera, std::span<const uint32_t> squared, std::span<const float> xyz,
                  std::span<float> labels) {
  lower(camera, squared, xyz, labels);
}
void lower_labels(const Camera& camera, std::span<const uint32_t> squared, std::span<const double> xyz,
                  std::span<float> labels) {
  lower(camera, squared, xyz, labels);
}

}  // namespace lodstream::core

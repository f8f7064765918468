// Point clouds in weight order for the floating-cell tests (test_floating_cell_region.cpp,
// test_floating_cell_centers.cpp).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <random>
#include <vector>

namespace lodstream::test {

// kind 0: uniform in [0, 10)³; 1: a lattice of step 1/4 (many points exactly c/2 apart for c = 0.5, 1, 2,
// and on the power-of-two voxel boundaries of core/floating_cell_centers.h); 2: 12 Gaussian clumps;
// 3: dense on three planes of each axis (x, y or z = 2, 5 or 8), as a building's walls.
inline std::vector<std::array<double, 3>> cloud(std::mt19937_64& rng, int kind, size_t n) {
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::normal_distribution<double> g(0.0, 0.4);
  std::vector<std::array<double, 3>> pts(n);
  std::vector<std::array<double, 3>> clumps(12);
  for (auto& q : clumps) q = {u(rng), u(rng), u(rng)};
  for (auto& p : pts) {
    if (kind == 0) {
      p = {u(rng), u(rng), u(rng)};
    } else if (kind == 1) {
      for (double& x : p) x = 0.25 * std::floor(4 * u(rng));
    } else if (kind == 2) {
      const auto& q = clumps[rng() % clumps.size()];
      p = {q[0] + g(rng), q[1] + g(rng), q[2] + g(rng)};
    } else {
      const int axis = static_cast<int>(rng() % 3);
      for (int a = 0; a < 3; ++a) p[a] = a == axis ? 2.0 + 3.0 * static_cast<double>(rng() % 3) : u(rng);
    }
  }
  return pts;  // the order is the weight order
}

}  // namespace lodstream::test

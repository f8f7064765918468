// Octree regions of a level (see core/octree_regions.h).
#include "core/octree_regions.h"

#include <algorithm>
#include <cmath>

#include "core/status.h"

namespace lodstream::core {

namespace {

// Spreads the low 20 bits of v to every third bit.
uint64_t spread(uint64_t v) {
  uint64_t x = v & 0xFFFFF;
  x = (x | x << 32) & 0x001F00000000FFFFull;
  x = (x | x << 16) & 0x001F0000FF0000FFull;
  x = (x | x << 8) & 0x100F00F00F00F00Full;
  x = (x | x << 4) & 0x10C30C30C30C30C3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

uint64_t morton(uint64_t x, uint64_t y, uint64_t z) { return spread(x) | spread(y) << 1 | spread(z) << 2; }

// Codes in [first, first + span) among sorted codes.
uint64_t count_in(std::span<const uint64_t> sorted, uint64_t first, uint64_t span) {
  const auto a = std::lower_bound(sorted.begin(), sorted.end(), first);
  const auto b = std::lower_bound(a, sorted.end(), first + span);
  return static_cast<uint64_t>(b - a);
}

// Appends `key` to `out`, split (depth first, children in Morton order) while it holds more than max_cells,
// or more than side.min_cells above side.min_depth.
// invariant: the regions appended are disjoint, in region order, and tile `key` (empty children are kept,
// so that a cut tiles the whole cube and a finer level's cells, wherever they are, fall in the coarser cut).
void split(std::span<const uint64_t> sorted, const RegionKey& key, uint64_t cells, uint64_t max_cells, const SideBound& side,
           std::vector<RegionKey>& out) {
  if ((cells <= max_cells && (cells <= side.min_cells || key.depth >= side.min_depth)) || key.depth >= kMaxRegionDepth) {
    out.push_back(key);
    return;
  }
  for (uint32_t child = 0; child < 8; ++child) {
    const RegionKey c{static_cast<uint8_t>(key.depth + 1), key.x * 2 + (child & 1), key.y * 2 + (child >> 1 & 1),
                      key.z * 2 + (child >> 2 & 1)};
    split(sorted, c, count_in(sorted, region_code(c), region_span(c)), max_cells, side, out);
  }
}

}  // namespace

SceneCube scene_cube(const double* lo, const double* hi) {
  SceneCube c;
  if (!(lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2])) return c;
  double side = 0;
  for (int k = 0; k < 3; ++k) side = std::max(side, hi[k] - lo[k]);
  side = std::max(side * (1 + std::ldexp(1.0, -20)), 1e-30);
  for (int k = 0; k < 3; ++k) c.min[k] = (lo[k] + hi[k]) / 2 - side / 2;
  c.side = side;
  return c;
}

uint64_t region_code(const RegionKey& key) {
  return morton(key.x, key.y, key.z) << (3 * (kMaxRegionDepth - key.depth));
}

uint64_t region_span(const RegionKey& key) { return uint64_t{1} << (3 * (kMaxRegionDepth - key.depth)); }

bool region_before(const RegionKey& a, const RegionKey& b) {
  const uint64_t ca = region_code(a), cb = region_code(b);
  return ca != cb ? ca < cb : a.depth < b.depth;
}

RegionKey region_parent(const RegionKey& key) {
  if (key.depth == 0) return key;
  return {static_cast<uint8_t>(key.depth - 1), key.x >> 1, key.y >> 1, key.z >> 1};
}

RegionKey point_node(const SceneCube& cube, const double* p, unsigned depth) {
  const double n = std::ldexp(1.0, static_cast<int>(depth));
  uint32_t q[3];
  for (int k = 0; k < 3; ++k) {
    const double f = std::floor((p[k] - cube.min[k]) / cube.side * n);
    q[k] = !(f > 0) ? 0 : f >= n - 1 ? static_cast<uint32_t>(n - 1) : static_cast<uint32_t>(f);
  }
  return {static_cast<uint8_t>(depth), q[0], q[1], q[2]};
}

uint64_t point_code(const SceneCube& cube, const double* p) { return region_code(point_node(cube, p, kMaxRegionDepth)); }

void region_box(const SceneCube& cube, const RegionKey& key, double* lo, double* hi) {
  const double size = std::ldexp(cube.side, -static_cast<int>(key.depth));
  const uint32_t q[3] = {key.x, key.y, key.z};
  for (int k = 0; k < 3; ++k) {
    lo[k] = cube.min[k] + size * q[k];
    hi[k] = cube.min[k] + size * (q[k] + 1.0);
  }
}

std::vector<RegionKey> cut_regions(std::span<const uint64_t> sorted_codes, std::span<const RegionKey> coarser,
                                   uint64_t max_cells, const SideBound& side) {
  if (max_cells == 0) fail(Status::internal, "cut_regions: max_cells must be positive");
  std::vector<RegionKey> out;
  if (coarser.empty()) {
    split(sorted_codes, RegionKey{}, sorted_codes.size(), max_cells, side, out);
    return out;
  }
  uint64_t held = 0;
  for (const RegionKey& r : coarser) {
    const uint64_t n = count_in(sorted_codes, region_code(r), region_span(r));
    held += n;
    split(sorted_codes, r, n, max_cells, side, out);
  }
  if (held != sorted_codes.size()) fail(Status::internal, "cut_regions: the coarser cut does not hold every cell");
  return out;
}

uint32_t region_of_code(std::span<const RegionKey> regions, uint64_t code) {
  // The last region whose first code is <= code (regions are disjoint and in code order).
  size_t lo = 0, hi = regions.size();
  while (hi - lo > 1) {
    const size_t mid = (lo + hi) / 2;
    (region_code(regions[mid]) <= code ? lo : hi) = mid;
  }
  return static_cast<uint32_t>(lo);
}

}  // namespace lodstream::core

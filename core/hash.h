// Integer mixing for the open-addressing hash tables (clustering grid, census).
#pragma once

#include <cstdint>

namespace lodstream::core {

// MurmurHash3's 64-bit finaliser (Austin Appleby, public domain): every input bit affects every output
// bit, so keys that differ only in a few low bits (neighbouring grid squares, close coordinates) spread
// over the whole table.
inline uint64_t fmix64(uint64_t k) {
  k ^= k >> 33;
  k *= 0xFF51AFD7ED558CCDull;
  k ^= k >> 33;
  k *= 0xC4CEB9FE1A85EC53ull;
  k ^= k >> 33;
  return k;
}

// The hash of grid square xyz (core/floating_cell.cpp, core/floating_cell_region.cpp): fmix64 of a linear
// mix of the coordinates. The mix is a sum of per-axis terms, so that a query's 8 squares share the 6
// products of their 2 coordinates per axis; it leaves neighbouring squares in neighbouring low bits, which
// fmix64 then spreads.
inline constexpr uint64_t kAxisMul[3] = {0x9E3779B97F4A7C15ull, 0xC2B2AE3D27D4EB4Full, 0x165667B19E3779F9ull};

inline uint64_t axis_term(int64_t x, int axis) { return static_cast<uint64_t>(x) * kAxisMul[axis]; }

inline uint64_t hash_square(int64_t x, int64_t y, int64_t z) {
  return fmix64(axis_term(x, 0) + axis_term(y, 1) + axis_term(z, 2));
}

}  // namespace lodstream::core

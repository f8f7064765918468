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

}  // namespace lodstream::core

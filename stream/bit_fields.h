// Bit fields packed into 64-bit words in the machine's byte order, low bits first: the files of the cells by
// vertex (stream/vertex_cells.h) and of the pairs by vertex range (stream/vertex_pairs.h).
#pragma once

#include <cstdint>
#include <cstring>

namespace lodstream::stream {

// The `bits` bits (1 to 63) at bit `bit` of the words at `data` (any alignment), of which the bytes up to
// the end of the word holding the field's last bit are readable.
inline uint64_t read_bits(const char* data, uint64_t bit, unsigned bits) {
  const uint64_t s = bit % 64;
  uint64_t w;
  std::memcpy(&w, data + bit / 64 * 8, 8);
  uint64_t x = w >> s;
  if (s + bits > 64) std::memcpy(&w, data + bit / 64 * 8 + 8, 8), x |= w << (64 - s);
  return x & ((uint64_t{1} << bits) - 1);
}

// ORs `value` (below 2^bits, bits 1 to 64) into the `bits` bits at bit `bit` of `words`, whose field is
// zero: the writing counterpart of read_bits, for words filled once.
inline void or_bits(uint64_t* words, uint64_t bit, uint64_t value, unsigned bits) {
  const uint64_t s = bit % 64;
  words[bit / 64] |= value << s;
  if (s + bits > 64) words[bit / 64 + 1] |= value >> (64 - s);
}

}  // namespace lodstream::stream

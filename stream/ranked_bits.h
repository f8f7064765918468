// A bit per item with rank: the set bits below an item, from a count per 64-bit word and a popcount.
// Used for the clustering shares' selected vertices (cluster_shares.cpp) and the centers of a split
// level's cells (cluster_merge.cpp: a cell's id is the rank of its center).
#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstdint>
#include <vector>

namespace lodstream::stream {

// `before` is filled by count() once every bit is set (until then it is a plain bit set: 8 bytes a 64 items;
// with the counts, 12).
struct RankedBits {
  std::vector<uint64_t> bits;
  std::vector<uint32_t> before;
  explicit RankedBits(uint64_t n = 0) : bits((n + 63) / 64, 0) {}
  void set(uint64_t i) { bits[i >> 6] |= uint64_t{1} << (i & 63); }
  // set() from several threads at once (before count()): a bit only ever goes from 0 to 1, so the result does
  // not depend on their order.
  void set_shared(uint64_t i) {
    const uint64_t m = uint64_t{1} << (i & 63);
    std::atomic_ref<uint64_t> w(bits[i >> 6]);
    if (!(w.load(std::memory_order_relaxed) & m)) w.fetch_or(m, std::memory_order_relaxed);
  }
  bool has(uint64_t i) const { return (bits[i >> 6] >> (i & 63)) & 1; }
  // The set bits (after count()).
  uint64_t ones() const { return bits.empty() ? 0 : before.back() + static_cast<uint64_t>(std::popcount(bits.back())); }
  void count() {
    before.resize(bits.size());
    uint32_t n = 0;
    for (size_t w = 0; w < bits.size(); ++w) before[w] = n, n += static_cast<uint32_t>(std::popcount(bits[w]));
  }
  uint32_t rank(uint64_t i) const {
    return before[i >> 6] + static_cast<uint32_t>(std::popcount(bits[i >> 6] & ((uint64_t{1} << (i & 63)) - 1)));
  }
  // A hint that has(i) and rank(i) come soon: their word and count are fetched (at random, a cache miss).
  void prefetch(uint64_t i) const {
    __builtin_prefetch(&bits[i >> 6]);
    __builtin_prefetch(&before[i >> 6]);
  }
  // The position of set bit k (k < ones(), after count()).
  uint64_t select(uint64_t k) const {
    const size_t w = static_cast<size_t>(std::upper_bound(before.begin(), before.end(), k) - before.begin()) - 1;
    uint64_t b = bits[w];
    for (uint64_t r = k - before[w]; r > 0; --r) b &= b - 1;
    return 64 * w + static_cast<uint64_t>(std::countr_zero(b));
  }
  // Calls f(i) for each set bit i, in order.
  template <class F>
  void for_each(F&& f) const {
    for (size_t w = 0; w < bits.size(); ++w)
      for (uint64_t b = bits[w]; b; b &= b - 1) f(64 * uint64_t{w} + static_cast<uint64_t>(std::countr_zero(b)));
  }
  uint64_t bytes() const { return bits.capacity() * 8 + before.capacity() * 4; }
};

}  // namespace lodstream::stream

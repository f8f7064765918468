// Open-addressing hash map from N uint32 words to a uint32 value, for the emit stage's dedupe tables.
// Linear probing, at most half full, grows by doubling; a key whose word 0 is UINT32_MAX is reserved as the
// empty marker (cell ids never reach it). clear() keeps the capacity, so a per-thread map reused block
// after block allocates only while it grows. Values = false makes it a set (no value array; insert returns
// value 0 and find returns 0 for a present key), a quarter less memory for the triangle table.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <vector>

#include "core/hash.h"

namespace lodstream::stream {

template <int N, bool Values = true>
class FlatMap {
 public:
  using Key = std::array<uint32_t, N>;
  static constexpr uint32_t empty = UINT32_MAX;

  // Returns {value, inserted}: the stored value, or `value` stored now if the key was absent.
  std::pair<uint32_t, bool> insert(const Key& k, uint32_t value) {
    if (2 * (size_ + 1) > keys_.size()) grow();
    for (uint64_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i][0] == empty) {
        keys_[i] = k;
        if constexpr (Values) values_[i] = value;
        ++size_;
        return {value, true};
      }
      if (same(keys_[i], k)) return {value_at(i), false};
    }
  }
  // The value of k, or `empty` if absent.
  uint32_t find(const Key& k) const {
    if (keys_.empty()) return empty;
    for (uint64_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i][0] == empty) return empty;
      if (same(keys_[i], k)) return value_at(i);
    }
  }
  uint64_t size() const { return size_; }
  void clear() {
    if (size_ == 0) return;
    for (Key& k : keys_) k[0] = empty;
    size_ = 0;
  }

 private:
  uint32_t value_at(uint64_t i) const {
    if constexpr (Values) return values_[i];
    return 0;
  }
  // Word by word: std::array's == becomes a call to memcmp, a tenth of the emit stage's time.
  static bool same(const Key& a, const Key& b) {
    bool equal = true;
    for (int i = 0; i < N; ++i) equal &= a[i] == b[i];
    return equal;
  }
  static uint64_t hash(const Key& k) {
    uint64_t h = 0;
    for (int i = 0; i < N; ++i) h = core::fmix64(h ^ (k[i] + 0x9E3779B97F4A7C15ull * static_cast<uint64_t>(i + 1)));
    return h;
  }
  void grow() {
    std::vector<Key> old_keys = std::move(keys_);
    std::vector<uint32_t> old_values = std::move(values_);
    const uint64_t slots = std::max<uint64_t>(64, 2 * old_keys.size());
    keys_.assign(slots, Key{});
    for (Key& k : keys_) k[0] = empty;
    if constexpr (Values) values_.assign(slots, 0);
    mask_ = slots - 1;
    size_ = 0;
    for (uint64_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i][0] != empty) insert(old_keys[i], Values ? old_values[i] : 0);
  }

  std::vector<Key> keys_;
  std::vector<uint32_t> values_;
  uint64_t mask_ = 0, size_ = 0;
};

}  // namespace lodstream::stream

#include "stream/distinct_count.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <atomic>
#include <memory>
#include <vector>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/hash.h"
#include "core/status.h"
#include "io/mapped_file.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

namespace {

// W words of coordinate bits. All-ones in word 0 is a NaN pattern, which no stored coordinate has
// (ingest rejects non-finite input), so it marks an empty table slot.
template <int W>
struct Key {
  uint64_t w[W];
  bool operator==(const Key&) const = default;
};
constexpr uint64_t empty_word = ~uint64_t{0};

using core::fmix64;

template <int W>
inline uint64_t hash(const Key<W>& k) {
  uint64_t h = 0x9E3779B97F4A7C15ULL;
  for (int i = 0; i < W; ++i) h = fmix64(h ^ k.w[i]) + 0x9E3779B97F4A7C15ULL * static_cast<uint64_t>(i + 1);
  return h;
}

inline uint32_t bits(float v) { return std::bit_cast<uint32_t>(v == 0 ? 0.0f : v); }
inline uint64_t bits(double v) { return std::bit_cast<uint64_t>(v == 0 ? 0.0 : v); }

inline Key<2> make_key(const float* p) {
  return {{uint64_t{bits(p[0])} << 32 | bits(p[1]), uint64_t{bits(p[2])}}};
}
inline Key<3> make_key(const double* p) { return {{bits(p[0]), bits(p[1]), bits(p[2])}}; }

// Open addressing with linear probing, sized for `keys` at load <= 1/2; counts keys on first insertion
// and keeps the value given with a key's first insertion.
template <int W>
class Table {
 public:
  void reset(uint64_t keys) {
    const uint64_t slots = std::bit_ceil(std::max<uint64_t>(2 * keys, 16));
    if (slots > capacity_) {
      slots_ = std::make_unique_for_overwrite<Key<W>[]>(slots);
      values_ = std::make_unique_for_overwrite<uint32_t[]>(slots);
      capacity_ = slots;
    }
    mask_ = slots - 1;
    for (uint64_t i = 0; i < slots; ++i) slots_[i].w[0] = empty_word;
    count_ = 0;
  }
  // Returns the value stored with the key: `value` if it is new.
  uint32_t insert(const Key<W>& k, uint64_t h, uint32_t value) {
    for (uint64_t i = h & mask_;; i = (i + 1) & mask_) {
      Key<W>& s = slots_[i];
      if (s.w[0] == empty_word) {
        s = k;
        values_[i] = value;
        ++count_;
        return value;
      }
      if (s == k) return values_[i];
    }
  }
  uint64_t count() const { return count_; }

 private:
  std::unique_ptr<Key<W>[]> slots_;
  std::unique_ptr<uint32_t[]> values_;
  uint64_t capacity_ = 0, mask_ = 0, count_ = 0;
};

// 256 buckets by the top 8 bits of the hash; a bucket's table indexes by the low bits.
constexpr int bucket_bits = 8;
constexpr uint64_t buckets = uint64_t{1} << bucket_bits;

// Counts distinct keys; when `canonical` is given (count entries), also writes for every vertex the
// smallest vertex id with the same key.
template <class T, int W>
uint64_t count_keys(const std::string& path, uint64_t count, uint64_t memory_bytes, Progress& progress,
                    const char* stage, uint32_t* canonical) {
  io::MappedFile file(path);
  const uint64_t stride = 3 * sizeof(T);
  if (file.size() != count * stride) fail(Status::io_error, path + ": size does not match store.json");
  // Mapped pages count as resident: small windows. The file is read in fixed slices of kSlice vertices
  // (a constant, not the thread count), in parallel; within a bucket, keys are placed slice by slice, so
  // they stay in file order, which the canonical ids rely on.
  constexpr uint64_t kSlice = uint64_t{1} << 20;
  const uint64_t step = stride * 65536;
  const uint64_t slices = (count + kSlice - 1) / kSlice;
  auto scan_slice = [&](uint64_t slice, auto&& visit) {
    const uint64_t end = std::min(count, (slice + 1) * kSlice) * stride;
    for (uint64_t at = slice * kSlice * stride; at < end; at += step) {
      progress.check();
      const io::Window w = file.map(at, std::min(at + step, end));
      const T* xyz = reinterpret_cast<const T*>(w.data());
      const uint64_t first = at / stride;
      for (uint64_t i = 0, n = w.size() / stride; i < n; ++i) {
        const Key<W> k = make_key(xyz + 3 * i);
        visit(k, hash(k), static_cast<uint32_t>(first + i));
      }
    }
  };

  // Pass 1: the exact size of every bucket, per slice.
  std::vector<uint64_t> slice_size(slices * buckets, 0);
  tbb::parallel_for(uint64_t{0}, slices, [&](uint64_t sl) {
    uint64_t* sz = &slice_size[sl * buckets];
    scan_slice(sl, [&](const Key<W>&, uint64_t h, uint32_t) { ++sz[h >> (64 - bucket_bits)]; });
  });
  std::vector<uint64_t> size(buckets, 0);
  for (uint64_t sl = 0; sl < slices; ++sl)
    for (uint64_t b = 0; b < buckets; ++b) size[b] += slice_size[sl * buckets + b];
  progress.report(stage, 0.2);

  // Then, for as many consecutive buckets as the budget holds at a time (keys plus one table per
  // thread, each at most 4 slots per key of the largest bucket): scatter their keys into one array at
  // bucket offsets, and count each bucket's distinct keys in its own small table, in parallel.
  const unsigned threads = static_cast<unsigned>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const uint64_t largest = *std::max_element(size.begin(), size.end());
  const uint64_t per_key = sizeof(Key<W>) + (canonical ? sizeof(uint32_t) : 0);
  const uint64_t tables = threads * 4 * largest * per_key;
  const uint64_t key_budget = std::max<uint64_t>(memory_bytes > tables + threads * step ? memory_bytes - tables - threads * step : 0,
                                                 largest * per_key);
  uint64_t distinct = 0;
  for (uint64_t first = 0; first < buckets;) {
    uint64_t last = first, bytes = 0;
    while (last < buckets && (last == first || bytes + size[last] * per_key <= key_budget))
      bytes += size[last++] * per_key;
    std::vector<uint64_t> offset(buckets + 1, 0);
    for (uint64_t b = first; b < last; ++b) offset[b + 1] = offset[b] + size[b];
    // Where each slice's keys of each bucket start: after the earlier slices' keys of that bucket.
    std::vector<uint64_t> fill(slices * buckets, 0);
    for (uint64_t b = first; b < last; ++b)
      for (uint64_t sl = 0, at = offset[b]; sl < slices; ++sl) {
        fill[sl * buckets + b] = at;
        at += slice_size[sl * buckets + b];
      }
    auto keys = std::make_unique_for_overwrite<Key<W>[]>(std::max<uint64_t>(offset[last], 1));
    std::unique_ptr<uint32_t[]> ids;
    if (canonical) ids = std::make_unique_for_overwrite<uint32_t[]>(std::max<uint64_t>(offset[last], 1));
    tbb::parallel_for(uint64_t{0}, slices, [&](uint64_t sl) {
      uint64_t* at = &fill[sl * buckets];
      scan_slice(sl, [&](const Key<W>& k, uint64_t h, uint32_t id) {
        const uint64_t b = h >> (64 - bucket_bits);
        if (b >= first && b < last) {
          if (canonical) ids[at[b]] = id;
          keys[at[b]++] = k;
        }
      });
    });
    std::atomic<uint64_t> found{0};
    tbb::enumerable_thread_specific<Table<W>> table;
    tbb::parallel_for(first, last, [&](uint64_t b) {
      Table<W>& t = table.local();
      t.reset(size[b]);
      // Ids within a bucket come in file order, so a key's first id is its smallest.
      if (canonical) {
        for (uint64_t i = offset[b]; i < offset[b + 1]; ++i) canonical[ids[i]] = t.insert(keys[i], hash(keys[i]), ids[i]);
      } else {
        for (uint64_t i = offset[b]; i < offset[b + 1]; ++i) t.insert(keys[i], hash(keys[i]), 0);
      }
      found += t.count();
    });
    distinct += found;
    first = last;
    progress.report(stage, 0.2 + 0.8 * static_cast<double>(first) / static_cast<double>(buckets));
  }
  return distinct;
}

}  // namespace

uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress) {
  if (count == 0) return 0;
  return single_precision ? count_keys<float, 2>(path, count, memory_bytes, progress, "census", nullptr)
                          : count_keys<double, 3>(path, count, memory_bytes, progress, "census", nullptr);
}

uint64_t weld_positions(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                        Progress& progress, std::span<uint32_t> canonical) {
  if (canonical.size() != count) fail(Status::internal, "weld_positions: canonical has the wrong size");
  if (count == 0) return 0;
  return single_precision ? count_keys<float, 2>(path, count, memory_bytes, progress, "weld", canonical.data())
                          : count_keys<double, 3>(path, count, memory_bytes, progress, "weld", canonical.data());
}

}  // namespace lodstream::stream

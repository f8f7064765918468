#include "stream/distinct_count.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <atomic>
#include <memory>
#include <vector>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

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

inline uint64_t fmix64(uint64_t k) {  // MurmurHash3's finaliser
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdULL;
  k ^= k >> 33;
  k *= 0xc4ceb9fe1a85ec53ULL;
  k ^= k >> 33;
  return k;
}

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

// Open addressing with linear probing; counts keys on first insertion. Sized for the expected number
// of keys at load <= 1/2, it doubles only if more arrive (then briefly holding old and new tables).
template <int W>
class Table {
 public:
  explicit Table(uint64_t expected_keys) { allocate(std::bit_ceil(std::max<uint64_t>(2 * expected_keys, 1 << 12))); }
  void insert(const Key<W>& k) {
    if (2 * (count_ + 1) > mask_ + 1) grow();
    if (place(k)) ++count_;
  }
  uint64_t count() const { return count_; }

 private:
  void allocate(uint64_t slots) {
    mask_ = slots - 1;
    slots_ = std::make_unique_for_overwrite<Key<W>[]>(slots);
    for (uint64_t i = 0; i < slots; ++i) slots_[i].w[0] = empty_word;
  }
  bool place(const Key<W>& k) {
    for (uint64_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      Key<W>& s = slots_[i];
      if (s.w[0] == empty_word) {
        s = k;
        return true;
      }
      if (s == k) return false;
    }
  }
  void grow() {
    std::unique_ptr<Key<W>[]> old = std::move(slots_);
    const uint64_t old_slots = mask_ + 1;
    allocate(2 * old_slots);
    for (uint64_t i = 0; i < old_slots; ++i)
      if (old[i].w[0] != empty_word) place(old[i]);
  }
  uint64_t mask_ = 0;
  std::unique_ptr<Key<W>[]> slots_;
  uint64_t count_ = 0;
};

template <class T, int W>
uint64_t count_keys(const std::string& path, uint64_t count, uint64_t memory_bytes, unsigned threads,
                    Progress& progress) {
  io::MappedFile file(path);
  const uint64_t stride = 3 * sizeof(T);
  if (file.size() != count * stride) fail(Status::io_error, path + ": size does not match store.json");
  // Mapped pages count as resident: small windows, and their bytes come out of the tables' budget.
  const uint64_t step = stride * 65536;
  const uint64_t windows = step * std::max(threads, 1u);
  memory_bytes = memory_bytes > 2 * windows ? memory_bytes - windows : memory_bytes / 2;

  // Partition p holds the keys whose hash falls in the p-th of P equal ranges (the table indexes by the
  // low bits). Each partition is one read-only pass over the column; partitions run in parallel, each
  // with memory_bytes / threads. Under uniform hashing a partition has at most count / P distinct keys.
  // bit_ceil(2 n) slots is at most 4 n.
  const uint64_t per_key = 4 * sizeof(Key<W>);
  const uint64_t per_table = std::max<uint64_t>(memory_bytes / std::max(threads, 1u), 1 << 20);
  const uint64_t partitions = std::max<uint64_t>(1, (count * per_key + per_table - 1) / per_table);
  std::vector<uint64_t> distinct(partitions, 0);
  std::atomic<uint64_t> done{0};
  tbb::parallel_for(uint64_t{0}, partitions, [&](uint64_t p) {
    Table<W> table(count / partitions + count / partitions / 8);
    for (uint64_t at = 0; at < file.size(); at += step) {
      progress.check();
      const io::Window w = file.map(at, at + step);
      const T* xyz = reinterpret_cast<const T*>(w.data());
      for (uint64_t i = 0, n = w.size() / stride; i < n; ++i) {
        const Key<W> k = make_key(xyz + 3 * i);
        if (partitions == 1 || static_cast<uint64_t>((static_cast<unsigned __int128>(hash(k)) * partitions) >> 64) == p)
          table.insert(k);
      }
      progress.report("census", static_cast<double>(done += w.size()) / static_cast<double>(file.size() * partitions));
    }
    distinct[p] = table.count();
  });
  uint64_t total = 0;
  for (uint64_t d : distinct) total += d;
  return total;
}

}  // namespace

uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress) {
  if (count == 0) return 0;
  const unsigned threads = static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
  return single_precision ? count_keys<float, 2>(path, count, memory_bytes, threads, progress)
                          : count_keys<double, 3>(path, count, memory_bytes, threads, progress);
}

}  // namespace lodstream::stream

#include "stream/distinct_count.h"

#include <fcntl.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/hash.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/external_sort.h"
#include "stream/weld_file.h"

namespace lodstream::stream {

namespace {

// A position's coordinate bits: three 32-bit words (floats) or three 64-bit words (doubles). All-ones in
// word 0 is a NaN pattern, which no stored coordinate has (ingest rejects non-finite input), so it marks
// an empty table slot.
template <class U>
struct Key {
  using Word = U;
  Word w[3];
  bool operator==(const Key&) const = default;
};
using FloatKey = Key<uint32_t>;
using DoubleKey = Key<uint64_t>;
template <class U>
constexpr U kEmpty = std::numeric_limits<U>::max();

using core::fmix64;

inline uint64_t mix(uint64_t h, uint64_t word, uint64_t i) { return fmix64(h ^ word) + 0x9E3779B97F4A7C15ULL * (i + 1); }
inline uint64_t hash(const FloatKey& k) {
  return mix(mix(0x9E3779B97F4A7C15ULL, uint64_t{k.w[0]} << 32 | k.w[1], 0), k.w[2], 1);
}
inline uint64_t hash(const DoubleKey& k) {
  uint64_t h = 0x9E3779B97F4A7C15ULL;
  for (uint64_t i = 0; i < 3; ++i) h = mix(h, k.w[i], i);
  return h;
}

inline uint32_t bits(float v) { return std::bit_cast<uint32_t>(v == 0 ? 0.0f : v); }
inline uint64_t bits(double v) { return std::bit_cast<uint64_t>(v == 0 ? 0.0 : v); }
inline FloatKey make_key(const float* p) { return {{bits(p[0]), bits(p[1]), bits(p[2])}}; }
inline DoubleKey make_key(const double* p) { return {{bits(p[0]), bits(p[1]), bits(p[2])}}; }

// Open addressing with linear probing at load <= 1/2: sized for `keys` distinct keys, and doubled (its
// keys placed again) when more come, so that it grows with the distinct keys, never with their copies.
// Counts keys on first insertion and keeps the value given with a key's first insertion.
template <class K>
class Table {
 public:
  void reset(uint64_t keys) {
    allocate(std::bit_ceil(std::max<uint64_t>(2 * keys, 16)));
    count_ = 0;
  }
  // Returns the value stored with the key: `value` if it is new. `h` is hash(k).
  uint32_t insert(const K& k, uint64_t h, uint32_t value) {
    for (uint64_t i = h & mask_;; i = (i + 1) & mask_) {
      K& s = slots_[i];
      if (s.w[0] == kEmpty<typename K::Word>) {
        s = k;
        values_[i] = value;
        if (2 * ++count_ > mask_ + 1) grow();
        return value;
      }
      if (s == k) return values_[i];
    }
  }
  uint64_t count() const { return count_; }

 private:
  void allocate(uint64_t slots) {
    if (slots > capacity_) {
      slots_ = std::make_unique_for_overwrite<K[]>(slots);
      values_ = std::make_unique_for_overwrite<uint32_t[]>(slots);
      capacity_ = slots;
    }
    mask_ = slots - 1;
    for (uint64_t i = 0; i < slots; ++i) slots_[i].w[0] = kEmpty<typename K::Word>;
  }
  void grow() {
    const uint64_t old = mask_ + 1;
    std::unique_ptr<K[]> keys = std::move(slots_);
    std::unique_ptr<uint32_t[]> values = std::move(values_);
    capacity_ = 0;
    allocate(2 * old);
    for (uint64_t j = 0; j < old; ++j) {
      if (keys[j].w[0] == kEmpty<typename K::Word>) continue;
      uint64_t i = hash(keys[j]) & mask_;
      while (slots_[i].w[0] != kEmpty<typename K::Word>) i = (i + 1) & mask_;
      slots_[i] = keys[j];
      values_[i] = values[j];
    }
  }
  std::unique_ptr<K[]> slots_;
  std::unique_ptr<uint32_t[]> values_;
  uint64_t capacity_ = 0, mask_ = 0, count_ = 0;
};

// 256 buckets by the top 8 bits of the hash; sub-buckets of about kSubKeys keys by the bits below.
constexpr int bucket_bits = 8;
constexpr uint64_t buckets = uint64_t{1} << bucket_bits;
constexpr uint64_t kSubKeys = 8192;
// Sub-buckets of a bucket of n keys: 2^sub_bits(n) of them.
inline int sub_bits(uint64_t n) { return n > kSubKeys ? static_cast<int>(std::bit_width((n - 1) / kSubKeys)) : 0; }
// What a thread holds besides the batch (dedupe_bucket's copies, sub-bucket numbers and pairs) per key of
// the largest bucket, and its table (a sub-bucket of up to twice kSubKeys keys, at load 1/2, rounded up).
template <class K>
constexpr uint64_t kScratchPerKey = sizeof(K) + 4 + 4 + 8;
template <class K>
constexpr uint64_t kTableBytes = 8 * kSubKeys * (sizeof(K) + 4);

// A bucket's keys on their way from the scan to the batch (count_keys).
constexpr uint32_t kStaged = 16;
template <class K>
struct Staged {
  K keys[kStaged];
  uint32_t ids[kStaged];
  uint32_t n = 0;
};

// Welded vertices, as (id << 32 | canonical id), in any order.
using PairSink = std::function<void(std::span<const uint64_t>)>;

template <class K>
struct Scratch {
  Table<K> table;
  std::vector<K> keys;
  std::vector<uint32_t> ids, sub;
  std::vector<uint64_t> start, fill, pairs;
};

// Inserts keys[i] with ids[i] (file order) into a fresh table; with `weld`, appends every key's pair that
// an earlier id already holds. Returns the distinct keys.
template <class K>
uint64_t insert_run(std::span<const K> keys, const uint32_t* ids, Scratch<K>& s, bool weld) {
  // A sub-bucket far over kSubKeys keys holds copies of a few positions (its keys' hashes are spread
  // otherwise): its table starts small and grows with the distinct keys, not with the copies.
  s.table.reset(keys.size() <= 2 * kSubKeys ? keys.size() : kSubKeys / 8);
  if (weld) {
    for (size_t i = 0; i < keys.size(); ++i) {
      const uint32_t c = s.table.insert(keys[i], hash(keys[i]), ids[i]);
      if (c != ids[i]) s.pairs.push_back(uint64_t{ids[i]} << 32 | c);
    }
  } else {
    for (size_t i = 0; i < keys.size(); ++i) s.table.insert(keys[i], hash(keys[i]), 0);
  }
  return s.table.count();
}

// One bucket's distinct keys (and with `ids`, its pairs in s.pairs). Invariant: every sub-bucket gets its
// keys in the order the bucket holds them (file order), since the counting sort is stable.
template <class K>
uint64_t dedupe_bucket(std::span<const K> keys, const uint32_t* ids, Scratch<K>& s) {
  s.pairs.clear();
  const uint64_t n = keys.size();
  const int sb = sub_bits(n);
  if (sb == 0) return insert_run(keys, ids, s, ids != nullptr);
  const uint64_t subs = uint64_t{1} << sb;
  const int shift = 64 - bucket_bits - sb;
  s.start.assign(subs + 1, 0);
  s.sub.resize(n);
  for (uint64_t i = 0; i < n; ++i) {
    s.sub[i] = static_cast<uint32_t>((hash(keys[i]) >> shift) & (subs - 1));
    ++s.start[s.sub[i] + 1];
  }
  for (uint64_t j = 0; j < subs; ++j) s.start[j + 1] += s.start[j];
  s.keys.resize(n);
  if (ids) s.ids.resize(n);
  s.fill.assign(s.start.begin(), s.start.end() - 1);
  for (uint64_t i = 0; i < n; ++i) {
    const uint64_t to = s.fill[s.sub[i]]++;
    s.keys[to] = keys[i];
    if (ids) s.ids[to] = ids[i];
  }
  uint64_t distinct = 0;
  for (uint64_t j = 0; j < subs; ++j) {
    const uint64_t first = s.start[j], end = s.start[j + 1];
    distinct += insert_run(std::span<const K>(s.keys.data() + first, end - first), ids ? s.ids.data() + first : nullptr, s,
                           ids != nullptr);
  }
  return distinct;
}

// Counts the distinct keys of buckets [first_bucket, end_bucket); with `sink`, also hands it every welded
// vertex's pair.
// `known_sizes`, when it holds them, gives pass 1's sizes (weld units share them: sizes_file); else they
// are counted and, when it is given, kept there.
template <class T, class K>
uint64_t count_keys(const std::string& path, uint64_t count, uint64_t memory_bytes, Progress& progress,
                    const char* stage, const PairSink* sink, uint64_t first_bucket = 0, uint64_t end_bucket = buckets,
                    std::vector<uint64_t>* known_sizes = nullptr) {
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
        const K k = make_key(xyz + 3 * i);
        visit(k, hash(k), static_cast<uint32_t>(first + i));
      }
    }
  };

  // Pass 1: the exact size of every bucket, per slice.
  std::vector<uint64_t> slice_size(slices * buckets, 0);
  if (known_sizes && known_sizes->size() == slice_size.size()) {
    slice_size = *known_sizes;
  } else {
    tbb::parallel_for(uint64_t{0}, slices, [&](uint64_t sl) {
      uint64_t* sz = &slice_size[sl * buckets];
      scan_slice(sl, [&](const K&, uint64_t h, uint32_t) { ++sz[h >> (64 - bucket_bits)]; });
    });
    if (known_sizes) *known_sizes = slice_size;
  }
  std::vector<uint64_t> size(buckets, 0);
  for (uint64_t sl = 0; sl < slices; ++sl)
    for (uint64_t b = 0; b < buckets; ++b) size[b] += slice_size[sl * buckets + b];
  progress.report(stage, 0.2);

  // Then, for as many consecutive buckets as the budget holds at a time (keys and ids, beside each
  // thread's scratch and table and its window of the file): scatter their keys into one array at bucket
  // offsets, and count each bucket's distinct keys, buckets in parallel.
  const uint64_t threads = static_cast<uint64_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const uint64_t largest = *std::max_element(size.begin() + first_bucket, size.begin() + end_bucket);
  const uint64_t per_key = sizeof(K) + (sink ? sizeof(uint32_t) : 0);
  const uint64_t per_thread = largest * kScratchPerKey<K> + kTableBytes<K> + step;
  const uint64_t key_budget = std::max<uint64_t>(memory_bytes > threads * per_thread ? memory_bytes - threads * per_thread : 0,
                                                 std::max<uint64_t>(largest, 1) * per_key);
  uint64_t distinct = 0;
  // The batch's keys and ids, allocated for the largest batch so far and reused: fresh pages for every
  // batch would be faulted in again.
  uint64_t capacity = 0;
  std::unique_ptr<K[]> keys;
  std::unique_ptr<uint32_t[]> ids;
  std::vector<uint64_t> bounce(sink ? 1 << 16 : 0);  // pairs, 8-byte aligned for the sink
  tbb::enumerable_thread_specific<Scratch<K>> scratch;
  for (uint64_t first = first_bucket; first < end_bucket;) {
    // As few batches as the budget allows, of about equal sizes (a last batch of a few keys would cost a
    // whole scan of the column).
    uint64_t rest = 0;
    for (uint64_t b = first; b < end_bucket; ++b) rest += size[b] * per_key;
    const uint64_t batches_left = std::max<uint64_t>((rest + key_budget - 1) / key_budget, 1);
    const uint64_t limit = std::min(key_budget, rest / batches_left + largest * per_key);
    uint64_t last = first, bytes = 0;
    while (last < end_bucket && (last == first || bytes + size[last] * per_key <= limit))
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
    if (offset[last] > capacity) {
      capacity = offset[last];
      keys.reset(), ids.reset();
      keys = std::make_unique_for_overwrite<K[]>(capacity);
      if (sink) ids = std::make_unique_for_overwrite<uint32_t[]>(capacity);
    }
    tbb::parallel_for(uint64_t{0}, slices, [&](uint64_t sl) {
      // Keys are staged a few at a time per bucket and copied out together (software write combining:
      // a bucket's destination is then written in whole cache lines).
      std::vector<Staged<K>> staged(last - first + 1);  // and one for the keys of other batches
      uint64_t* const at = &fill[sl * buckets];
      K* const to_keys = keys.get();
      uint32_t* const to_ids = ids.get();
      const uint64_t lo = first, span = last - first;
      auto flush = [&](uint64_t i) {
        Staged<K>& st = staged[i];
        if (st.n == 0) return;
        if (i == last - first) {
          st.n = 0;
          return;
        }
        const uint64_t to = at[lo + i];
        std::memcpy(to_keys + to, st.keys, st.n * sizeof(K));
        if (to_ids) std::memcpy(to_ids + to, st.ids, st.n * sizeof(uint32_t));
        at[lo + i] += st.n;
        st.n = 0;
      };
      // Without a branch on the bucket (taken at random, it was mispredicted for about one key in three):
      // the keys of other batches go to a last staging area that is never copied out.
      scan_slice(sl, [&staged, &flush, lo, span](const K& k, uint64_t h, uint32_t id) {
        const uint64_t raw = (h >> (64 - bucket_bits)) - lo;
        const uint64_t i = raw < span ? raw : span;
        Staged<K>& st = staged[i];
        st.keys[st.n] = k;
        st.ids[st.n] = id;
        if (++st.n == kStaged) flush(i);
      });
      for (uint64_t i = 0; i < span; ++i) flush(i);
    });
    // Each bucket's pairs go where its keys were (8 bytes a pair, fewer pairs than keys), and to the sink
    // after the batch, in bucket order, with every thread free for the sink's sort.
    std::atomic<uint64_t> found{0};
    std::vector<uint64_t> pairs(buckets, 0);
    tbb::parallel_for(first, last, [&](uint64_t b) {
      Scratch<K>& s = scratch.local();
      found += dedupe_bucket(std::span<const K>(keys.get() + offset[b], size[b]), sink ? ids.get() + offset[b] : nullptr, s);
      pairs[b] = s.pairs.size();
      if (!s.pairs.empty()) std::memcpy(keys.get() + offset[b], s.pairs.data(), s.pairs.size() * sizeof(uint64_t));
    });
    for (uint64_t b = first; b < last; ++b) {
      const char* from = reinterpret_cast<const char*>(keys.get() + offset[b]);
      for (uint64_t done = 0; done < pairs[b];) {
        const uint64_t n = std::min<uint64_t>(pairs[b] - done, bounce.size());
        std::memcpy(bounce.data(), from + done * sizeof(uint64_t), n * sizeof(uint64_t));
        (*sink)(std::span<const uint64_t>(bounce.data(), n));
        done += n;
      }
    }
    distinct += found;
    first = last;
    progress.report(stage, 0.2 + 0.8 * static_cast<double>(first - first_bucket) / static_cast<double>(end_bucket - first_bucket));
  }
  return distinct;
}

// Bytes of one key in a batch and in a thread's scratch.
uint64_t key_bytes(bool single_precision) { return single_precision ? sizeof(FloatKey) : sizeof(DoubleKey); }

}  // namespace

uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress) {
  if (count == 0) return 0;
  return single_precision ? count_keys<float, FloatKey>(path, count, memory_bytes, progress, "census", nullptr)
                          : count_keys<double, DoubleKey>(path, count, memory_bytes, progress, "census", nullptr);
}

uint64_t weld_memory_floor(uint64_t count, bool single_precision) {
  const uint64_t threads = static_cast<uint64_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const uint64_t bucket = 2 * count / buckets + 1;
  const uint64_t key = key_bytes(single_precision);
  return weld_detail::words(count) * 12 + (4 << 20) + bucket * (key + 4) +
         threads * (bucket * (key + 16) + 8 * kSubKeys * (key + 4) + key * 65536);
}

namespace {

using PairSorter = ExternalSorter<uint64_t, std::less<uint64_t>>;

// The weld's share of the budget for sorting its pairs: an eighth, at least 4 MiB, at most all pairs.
uint64_t pair_sort_bytes(uint64_t memory_bytes, uint64_t count) {
  return std::clamp<uint64_t>(memory_bytes / 8, 4 << 20, std::max<uint64_t>(8 * count, 4 << 20));
}

void check_floor(uint64_t count, bool single_precision, uint64_t memory_bytes) {
  const uint64_t floor = weld_memory_floor(count, single_precision);
  if (memory_bytes < floor)
    fail(Status::usage, "welding " + std::to_string(count) + " stored vertices needs at least " + std::to_string(floor >> 20) +
                            " MiB, more than --memory allows (" + std::to_string(memory_bytes >> 20) + " MiB for the stage): raise --memory");
}

// The weld of buckets [first_bucket, end_bucket), its welded vertices' pairs to `sink`; `held` bytes of
// the budget are taken already. Returns the buckets' distinct positions.
uint64_t weld_buckets(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes, uint64_t held,
                      Progress& progress, uint64_t first_bucket, uint64_t end_bucket, const PairSink& sink,
                      std::vector<uint64_t>* known_sizes = nullptr) {
  const uint64_t rest = memory_bytes - std::min(memory_bytes, held);
  return single_precision
             ? count_keys<float, FloatKey>(path, count, rest, progress, "weld", &sink, first_bucket, end_bucket, known_sizes)
             : count_keys<double, DoubleKey>(path, count, rest, progress, "weld", &sink, first_bucket, end_bucket, known_sizes);
}

// The bucket sizes per slice that weld units share: a header (vertices, the positions file's bytes and
// mtime in ns) and the sizes. Read only when the header matches the column and every slice's sizes add up
// to its vertices; else empty.
std::vector<uint64_t> read_sizes_file(const std::string& sizes_path, const io::MappedFile& column, uint64_t count) {
  constexpr uint64_t kSlice = uint64_t{1} << 20;  // count_keys'
  const uint64_t slices = (count + kSlice - 1) / kSlice;
  std::error_code ec;
  if (sizes_path.empty() || std::filesystem::file_size(sizes_path, ec) != 24 + 8 * slices * buckets || ec) return {};
  const std::string bytes = io::read_small_file(sizes_path);
  uint64_t header[3];
  std::memcpy(header, bytes.data(), sizeof header);
  if (header[0] != count || header[1] != column.size() || header[2] != static_cast<uint64_t>(column.mtime_ns())) return {};
  std::vector<uint64_t> sizes(slices * buckets);
  std::memcpy(sizes.data(), bytes.data() + 24, 8 * sizes.size());
  for (uint64_t sl = 0; sl < slices; ++sl) {
    uint64_t sum = 0;
    for (uint64_t b = 0; b < buckets; ++b) sum += sizes[sl * buckets + b];
    if (sum != std::min(count, (sl + 1) * kSlice) - sl * kSlice) return {};
  }
  return sizes;
}

void write_sizes_file(const std::string& sizes_path, const io::MappedFile& column, uint64_t count, const std::vector<uint64_t>& sizes) {
  std::string bytes(24 + 8 * sizes.size(), '\0');
  const uint64_t header[3] = {count, column.size(), static_cast<uint64_t>(column.mtime_ns())};
  std::memcpy(bytes.data(), header, sizeof header);
  std::memcpy(bytes.data() + 24, sizes.data(), 8 * sizes.size());
  io::write_file_atomic(sizes_path, bytes, io::Sync::none, io::Writers::several);  // units may count them at once
}

void set_bit(std::vector<uint64_t>& bits, uint64_t pair) { bits[pair >> 38] |= uint64_t{1} << ((pair >> 32) % 64); }

}  // namespace

uint64_t weld_positions(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                        const WorkDir& work, Progress& progress, const std::string& weld_path) {
  if (count == 0) return 0;
  check_floor(count, single_precision, memory_bytes);
  // Held throughout: the map's bits (and, when it is written, its ranks: 4 bytes a word). The welded
  // vertices' canonical ids go straight to their places in an array of a u32 a vertex where that takes at
  // most half the budget (the sort costs more than the array's pages), else through an external sort.
  std::vector<uint64_t> bits(weld_detail::words(count), 0);
  uint64_t welded = 0, distinct = 0;
  auto check = [&] {
    if (distinct + welded != count)
      fail(Status::internal, path + ": the weld found " + std::to_string(distinct) + " positions and " +
                                 std::to_string(welded) + " welded vertices among " + std::to_string(count));
  };
  if (4 * count <= memory_bytes / 2) {
    const auto canonical = std::make_unique_for_overwrite<uint32_t[]>(count);  // read only where a bit is set
    const PairSink sink = [&](std::span<const uint64_t> pairs) {
      for (uint64_t p : pairs) set_bit(bits, p), canonical[p >> 32] = static_cast<uint32_t>(p);
      welded += pairs.size();
    };
    distinct = weld_buckets(path, count, single_precision, memory_bytes, bits.size() * 12 + 4 * count, progress, 0, buckets, sink);
    check();
    if (welded == 0) return distinct;
    WeldFileWriter out(weld_path, count, bits);
    for (uint64_t w = 0; w < bits.size(); ++w)
      for (uint64_t b = bits[w]; b; b &= b - 1) out.add(canonical[64 * w + static_cast<uint64_t>(std::countr_zero(b))]);
    out.commit();
    return distinct;
  }
  const uint64_t sort_bytes = pair_sort_bytes(memory_bytes, count);
  PairSorter sorter(work, "weld", sort_bytes);
  const PairSink sink = [&](std::span<const uint64_t> pairs) {
    for (uint64_t p : pairs) set_bit(bits, p);
    sorter.push(pairs);
    welded += pairs.size();
  };
  distinct = weld_buckets(path, count, single_precision, memory_bytes, bits.size() * 12 + sort_bytes, progress, 0, buckets, sink);
  check();
  if (welded == 0) return distinct;
  // The pairs in id order: the welded vertices' canonical ids as the map lists them.
  WeldFileWriter out(weld_path, count, bits);
  sorter.merge([&](uint64_t p) { out.add(static_cast<uint32_t>(p)); });
  out.commit();
  return distinct;
}

std::pair<unsigned, unsigned> weld_unit_buckets(unsigned unit, unsigned units) {
  return {static_cast<unsigned>(buckets * unit / units), static_cast<unsigned>(buckets * (unit + 1) / units)};
}

WeldUnitResult weld_unit(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                         const WorkDir& work, Progress& progress, unsigned unit, unsigned units, const std::string& run_path,
                         const std::string& sizes_path) {
  if (units == 0 || units > kMaxWeldUnits || unit >= units) fail(Status::internal, "weld_unit: unit out of range");
  WeldUnitResult r;
  io::FileWriter out(run_path, 4 << 20);
  if (count > 0) {
    check_floor(count, single_precision, memory_bytes);
    const uint64_t sort_bytes = pair_sort_bytes(memory_bytes, count);
    PairSorter sorter(work, "weld-unit", sort_bytes);
    const auto [first, end] = weld_unit_buckets(unit, units);
    const PairSink sink = [&](std::span<const uint64_t> pairs) {
      sorter.push(pairs);
      r.welded += pairs.size();
    };
    // The bucket sizes: another unit's, or counted here and left for the others.
    const io::MappedFile column(path);
    std::vector<uint64_t> sizes = read_sizes_file(sizes_path, column, count);
    const bool counted = sizes.empty();
    r.distinct = weld_buckets(path, count, single_precision, memory_bytes, sort_bytes, progress, first, end, sink, &sizes);
    if (counted && !sizes_path.empty()) write_sizes_file(sizes_path, column, count, sizes);
    std::vector<uint64_t> block;
    block.reserve(1 << 16);
    sorter.merge([&](uint64_t p) {
      block.push_back(p);
      if (block.size() == block.capacity()) out.write_array(std::span<const uint64_t>(block)), block.clear();
    });
    out.write_array(std::span<const uint64_t>(block));
  }
  out.commit();
  return r;
}

void start_weld_map(const std::string& path, uint64_t count, uint64_t welded) {
  const io::OffsetFile file(path, O_WRONLY | O_CREAT | O_TRUNC);
  const uint64_t header[2] = {count, welded};
  file.write(header, sizeof header, 0);
  file.resize(weld_detail::targets_offset(count) + 4 * welded);  // the ranks' padding reads as zeros
}

std::pair<uint64_t, uint64_t> weld_map_unit_words(uint64_t count, unsigned unit, unsigned units) {
  const uint64_t words = weld_detail::words(count);
  return {words * unit / units, words * (unit + 1) / units};
}

void write_weld_map_unit(const std::vector<std::pair<std::string, uint64_t>>& runs, uint64_t count, uint64_t memory_bytes,
                         const WorkDir& work, const std::string& path, unsigned unit, unsigned units) {
  const auto [w0, w1] = weld_map_unit_words(count, unit, units);
  const uint64_t v0 = 64 * w0, v1 = std::min(count, 64 * w1);
  // Each run is sorted by id: the unit's pairs are one stretch of it, found by binary search; the pairs
  // before the stretches are the welded vertices before the unit's (its ranks' and canonical ids' offset).
  std::vector<uint64_t> bits(w1 - w0, 0);
  PairSorter sorter(work, fmt::format("weld-map-{}", unit), pair_sort_bytes(memory_bytes, v1 - v0));
  uint64_t before = 0, held = 0;
  std::vector<uint64_t> window(1 << 20);
  for (const auto& [run, pairs] : runs) {
    const io::OffsetFile file(run, O_RDONLY);
    std::error_code ec;
    if (std::filesystem::file_size(run, ec) != 8 * pairs || ec)
      fail(Status::io_error, run + ": does not hold " + std::to_string(pairs) + " welded vertices (weld unit)");
    auto first_at_least = [&](uint64_t v) { return file.partition_point<uint64_t>(pairs, [&](uint64_t p) { return (p >> 32) < v; }); };
    const uint64_t lo = first_at_least(v0), hi = first_at_least(v1);
    if (v1 == count && hi != pairs) fail(Status::io_error, run + ": not a weld unit's run (an id past the store's vertices)");
    before += lo, held += hi - lo;
    for (uint64_t at = lo; at < hi; at += window.size()) {
      const uint64_t n = std::min<uint64_t>(window.size(), hi - at);
      file.read(window.data(), 8 * n, 8 * at);
      for (uint64_t i = 0; i < n; ++i) {
        const uint64_t v = window[i] >> 32;
        if (v < v0 || v >= v1 || static_cast<uint32_t>(window[i]) >= v || (i && window[i - 1] >> 32 >= v))
          fail(Status::io_error, run + ": not a weld unit's run");
        bits[v / 64 - w0] |= uint64_t{1} << (v % 64);
      }
    }
    if (hi > lo) sorter.add_sorted_run(run, hi - lo, lo);
  }
  // The unit's words of the map: bits, ranks (the welded vertices before each word), canonical ids.
  const io::OffsetFile out(path, O_WRONLY);
  out.write(bits.data(), 8 * bits.size(), 16 + 8 * w0);
  std::vector<uint32_t> ranks(bits.size());
  for (uint64_t i = 0, r = before; i < bits.size(); ++i) ranks[i] = static_cast<uint32_t>(r), r += static_cast<uint64_t>(std::popcount(bits[i]));
  out.write(ranks.data(), 4 * ranks.size(), weld_detail::ranks_offset(count) + 4 * w0);
  std::vector<uint64_t>().swap(bits);
  std::vector<uint32_t>().swap(ranks);
  std::vector<uint32_t> targets;
  targets.reserve(1 << 16);
  uint64_t written = 0;
  auto flush = [&] {
    out.write(targets.data(), 4 * targets.size(), weld_detail::targets_offset(count) + 4 * (before + written));
    written += targets.size();
    targets.clear();
  };
  sorter.merge([&](uint64_t p) {
    targets.push_back(static_cast<uint32_t>(p));
    if (targets.size() == targets.capacity()) flush();
  });
  flush();
  if (written != held) fail(Status::internal, path + ": weld map unit " + std::to_string(unit) + " lost canonical ids");
}

void write_weld_map(const std::vector<std::pair<std::string, uint64_t>>& runs, uint64_t count, uint64_t memory_bytes,
                    const WorkDir& work, const std::string& weld_path) {
  uint64_t welded = 0;
  for (const auto& run : runs) welded += run.second;
  const std::string partial = weld_path + ".partial";
  try {
    start_weld_map(partial, count, welded);
    write_weld_map_unit(runs, count, memory_bytes, work, partial, 0, 1);
  } catch (...) {
    std::error_code ec;
    std::filesystem::remove(partial, ec);  // no partial map left behind
    throw;
  }
  std::filesystem::rename(partial, weld_path);
}

}  // namespace lodstream::stream

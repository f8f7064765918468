// Vertex clustering (pipeline stage 4). This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2 and §4
// Jarek Rossignac and Paul Borrel. Multi-resolution 3D approximations for rendering complex scenes. 1993
//
// A pass guarantees: a vertex joins a cell exactly when it is inside it (the exact tests of
// floating_cell.h), it starts a cell exactly when it is inside none, and the choice among several cells
// depends only on distances and ids — never on the hash table's layout — so the ids are a function of the
// vertex order and positions alone.
//
// The square of a coordinate is computed from its half-square index floor(x / (c/2)): the square is that
// index >> 1 and its low bit tells which half the coordinate lies in, i.e. which neighbour square along
// that axis can hold a center within c/2. One division per axis serves both.
//
// Speed: a query reads 8 table slots and their runs per level, mostly cache misses in the fine levels.
// assign therefore works in passes over all levels — prefetch every slot, then read the slots and prefetch
// the runs, then test the candidates — so that the misses of all levels overlap, and assign_block runs
// the same passes as a pipeline over vertices a few places apart, so that the misses of successive
// vertices overlap too; runs keep a square's candidates in one or two cache lines; the large arrays sit on
// huge pages (HugePageAllocator), so the random reads do not also miss the TLB; slots are packed to 16
// bytes where the bounds allow, and coarse levels index a dense array instead of hashing; the candidate
// test is branch-free. None of this affects the result.
//
// Memory: a cell record holds only its center (float where every position is a float: the same value, so
// the same comparisons) and its id; the pool grows by mremap, without a second copy; the hash table is 64
// sub-tables, so a growth step rehashes 1/64 of it while the rest stays put, and each is up to 2/3 full
// (the fill trades memory for time: on a 9.4 M-triangle city, perf counted the clustering functions at
// +22 % over main's half-full single table with 3/4, +13 % with 5/8; most of it in probes for absent squares).
#include "core/floating_cell.h"
#include "core/hash.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <new>
#if __has_include(<sys/mman.h>)
#include <sys/mman.h>
#endif
#include <string>
#include <type_traits>

#include "core/status.h"

namespace lodstream::core {
namespace {

using FloatCell = Clusterer::FloatCell;
using DoubleCell = Clusterer::DoubleCell;
using Slot = Clusterer::Slot;
using PackedSlot = Clusterer::PackedSlot;

static_assert(sizeof(FloatCell) == 16 && sizeof(DoubleCell) == 32 && sizeof(Slot) == 32 && sizeof(PackedSlot) == 16,
              "records sized for whole numbers per cache line");

constexpr size_t kInitialSlots = 16;  // per sub-table
constexpr int kSubShift = 64 - 6;     // the sub-table of a hash: its top Clusterer::kSubTableBits bits

// Squares hash by hash_square (core/hash.h).

// The two kinds of hash-table slot, with their keys: a Slot keys a square by its three coordinates; a
// PackedSlot, used where the bounds allow, by one word (21 bits per axis, relative to the level's first
// square), so it takes 16 bytes instead of 32 and a cache line holds four.
struct WideKey {
  int64_t xyz[3];
};
inline bool matches(const Slot& s, const WideKey& k) {
  return s.square[0] == k.xyz[0] && s.square[1] == k.xyz[1] && s.square[2] == k.xyz[2];
}
inline bool matches(const PackedSlot& s, uint64_t k) { return s.key == k; }
inline void set_key(Slot& s, const WideKey& k) { s.square[0] = k.xyz[0], s.square[1] = k.xyz[1], s.square[2] = k.xyz[2]; }
inline void set_key(PackedSlot& s, uint64_t k) { s.key = k; }
inline uint64_t key_hash(const WideKey& k) { return hash_square(k.xyz[0], k.xyz[1], k.xyz[2]); }
inline uint64_t key_hash(uint64_t k) { return fmix64(k); }
inline uint64_t slot_hash(const Slot& s) { return hash_square(s.square[0], s.square[1], s.square[2]); }
inline uint64_t slot_hash(const PackedSlot& s) { return fmix64(s.key); }

// The slot of `key`, or nullptr if absent; `i` is its hash & mask.
template <class S, class K>
inline const S* find(const S* table, uint64_t mask, uint64_t i, const K& key) {
  for (;; i = (i + 1) & mask) {
    const S& s = table[i];
    if (s.count == 0) return nullptr;  // the table is never full, so every probe ends
    if (matches(s, key)) return &s;
  }
}

// The slot of `key` (hash h) in `table`, inserting an empty-listed one (count 0 → 1 is the caller's) if
// absent; doubles the key's sub-table first when an insert would make it more than 2/3 full.
template <class S, class K>
S& find_or_insert(Clusterer::Table<S>& table, uint64_t h, const K& key) {
  const size_t t = h >> kSubShift;
  std::vector<S, HugePageAllocator<S>>& sub = table.sub[t];
  uint64_t mask = sub.size() - 1;
  uint64_t i = h & mask;
  for (;; i = (i + 1) & mask) {
    S& s = sub[i];
    if (s.count == 0) break;
    if (matches(s, key)) return s;
  }
  if (3 * (table.used[t] + 1) > 2 * sub.size()) {
    std::vector<S, HugePageAllocator<S>> grown(2 * sub.size(), S{});
    const uint64_t grown_mask = grown.size() - 1;
    for (const S& s : sub) {
      if (s.count == 0) continue;
      uint64_t j = slot_hash(s) & grown_mask;
      while (grown[j].count != 0) j = (j + 1) & grown_mask;
      grown[j] = s;
    }
    sub.swap(grown);
    mask = grown_mask;
    i = h & mask;
    while (sub[i].count != 0) i = (i + 1) & mask;
  }
  ++table.used[t];
  S& s = sub[i];
  set_key(s, key);
  s.run = kNoCell;
  return s;
}

// The slot of `key` (hash h) in a table, or nullptr if absent.
template <class S, class K>
inline const S* find_in(const Clusterer::Table<S>& table, uint64_t h, const K& key) {
  const auto& sub = table.sub[h >> kSubShift];
  const uint64_t mask = sub.size() - 1;
  return find(sub.data(), mask, h & mask, key);
}

template <class S>
inline const S* home_slot(const Clusterer::Table<S>& table, uint64_t h) {
  const auto& sub = table.sub[h >> kSubShift];
  return &sub[h & (sub.size() - 1)];
}

template <class S>
void init_table(Clusterer::Table<S>& table) {
  table.sub.resize(size_t{1} << Clusterer::kSubTableBits);
  for (auto& sub : table.sub) sub.assign(kInitialSlots, S{});
  table.used.assign(table.sub.size(), 0);
}

template <class S>
uint64_t table_bytes(const Clusterer::Table<S>& table, uint64_t* largest) {
  uint64_t bytes = 0;
  for (const auto& sub : table.sub) {
    bytes += sub.capacity() * sizeof(S);
    *largest = std::max<uint64_t>(*largest, sub.capacity() * sizeof(S));
  }
  return bytes + table.used.capacity() * sizeof(uint64_t) + table.sub.capacity() * sizeof(table.sub[0]);
}

// The candidate test of assign_floating, over the runs of the query block. Squares and runs come in no
// particular id order: distances and ids alone decide (nearest: smallest fl(d²), ties by lowest id;
// heaviest: lowest id).
//
// scan_fast is branch-free: in a coarse level a query meets dozens of candidates, accepted or rejected
// about at random, which branches would mispredict half the time. It decides |d| <= h per axis on the
// rounded difference, which is exact except where that difference rounds onto h itself; it then sets
// `boundary` and the caller redoes the scan with scan_exact, whose `within` decides those cases exactly.
template <bool kNearest, bool kSphere, class Cell>
uint32_t scan_fast(const Cell* pool, const Clusterer::Query& q, const double* p, double h, double half_sq,
                   bool& boundary) {
  uint32_t best = kNoCell;
  double best_key = std::numeric_limits<double>::infinity();
  bool on_h = false;
  for (int i = 0; i < 8; ++i) {
    const Cell* run = pool + q.run[i];
    for (uint32_t j = 0; j < q.count[i]; ++j) {
      double key;
      const bool inside = fast_inside<kNearest, kSphere>(p, static_cast<double>(run[j].position[0]), static_cast<double>(run[j].position[1]),
                                                         static_cast<double>(run[j].position[2]), h, half_sq, on_h, key);
      const uint32_t c = run[j].id;
      const bool better = inside & ((key < best_key) | ((key == best_key) & (c < best)));
      best = better ? c : best;
      best_key = better ? key : best_key;
    }
  }
  boundary = on_h;
  return best;
}

template <class Cell>
uint32_t scan_exact(const Cell* pool, const Clusterer::Query& q, const double* p, double h, double half_sq,
                    bool sphere, bool nearest) {
  const CellShape shape = sphere ? CellShape::sphere : CellShape::cube;
  uint32_t best = kNoCell;
  double best_d2 = 0;
  for (int i = 0; i < 8; ++i) {
    const Cell* run = pool + q.run[i];
    for (uint32_t j = 0; j < q.count[i]; ++j) {
      const double cp[3] = {static_cast<double>(run[j].position[0]), static_cast<double>(run[j].position[1]),
                            static_cast<double>(run[j].position[2])};
      const uint32_t c = run[j].id;
      double d2;
      if (!floating_cell_contains(p, cp, h, half_sq, shape, d2)) continue;
      const bool better = best == kNoCell || (nearest ? (d2 < best_d2 || (d2 == best_d2 && c < best)) : c < best);
      if (better) best = c, best_d2 = d2;
    }
  }
  return best;
}

[[gnu::cold, gnu::noinline]] void outside_bounds() {
  fail(Status::internal, "clustering: a position lies outside the bounds given to the clusterer");
}

inline void check_inside(const int64_t* first, const int64_t* dims, const int64_t own[3]) {
  for (int a = 0; a < 3; ++a)
    if (own[a] <= first[a] || own[a] >= first[a] + dims[a] - 1) outside_bounds();
}

constexpr size_t kHugePage = size_t{2} << 20;

// The first and last cache line of a run of `count` records of `bytes` each at record `run`.
inline void prefetch_run(const std::byte* pool, size_t bytes, uint32_t run, uint32_t count) {
  const std::byte* first = pool + static_cast<size_t>(run) * bytes;
  __builtin_prefetch(first);
  __builtin_prefetch(first + static_cast<size_t>(count) * bytes - 1);
}

}  // namespace

template <class T>
T* HugePageAllocator<T>::allocate(size_t n) {
  if (n > SIZE_MAX / sizeof(T)) throw std::bad_alloc();
  const size_t bytes = n * sizeof(T);
  if (bytes < kHugePage) return static_cast<T*>(::operator new(bytes));
  const size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* p = std::aligned_alloc(kHugePage, rounded);
  if (p == nullptr) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
  madvise(p, rounded, MADV_HUGEPAGE);  // a hint: failure only costs speed
#endif
  return static_cast<T*>(p);
}

template <class T>
void HugePageAllocator<T>::deallocate(T* p, size_t n) {
  if (n * sizeof(T) < kHugePage)
    ::operator delete(p);
  else
    std::free(p);
}

template struct HugePageAllocator<Clusterer::Slot>;
template struct HugePageAllocator<Clusterer::DenseSquare>;
template struct HugePageAllocator<Clusterer::PackedSlot>;

GrowableBuffer::GrowableBuffer(GrowableBuffer&& o) noexcept : data_(o.data_), size_(o.size_), capacity_(o.capacity_) {
  o.data_ = nullptr, o.size_ = o.capacity_ = 0;
}

GrowableBuffer& GrowableBuffer::operator=(GrowableBuffer&& o) noexcept {
  if (this != &o) {
    this->~GrowableBuffer();
    data_ = o.data_, size_ = o.size_, capacity_ = o.capacity_;
    o.data_ = nullptr, o.size_ = o.capacity_ = 0;
  }
  return *this;
}

#if defined(__linux__) && defined(MREMAP_MAYMOVE)
GrowableBuffer::~GrowableBuffer() {
  if (data_) munmap(data_, capacity_);
}

void GrowableBuffer::resize(size_t bytes) {
  if (bytes <= capacity_) {
    size_ = std::max(size_, bytes);
    return;
  }
  size_t capacity = std::max<size_t>(capacity_ ? capacity_ : 64 << 10, 64 << 10);
  while (capacity < bytes) capacity *= 2;
  // Anonymous pages are zero and not resident until written; mremap moves the page tables, not the data.
  void* p = data_ ? mremap(data_, capacity_, capacity, MREMAP_MAYMOVE)
                  : mmap(nullptr, capacity, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
  if (capacity >= kHugePage) madvise(p, capacity, MADV_HUGEPAGE);  // a hint: failure only costs speed
#endif
  data_ = static_cast<std::byte*>(p);
  capacity_ = capacity;
  size_ = bytes;
}
#else
GrowableBuffer::~GrowableBuffer() { std::free(data_); }

void GrowableBuffer::resize(size_t bytes) {
  if (bytes <= capacity_) {
    size_ = std::max(size_, bytes);
    return;
  }
  size_t capacity = std::max<size_t>(capacity_, 64 << 10);
  while (capacity < bytes) capacity *= 2;
  void* p = std::realloc(data_, capacity);
  if (p == nullptr) throw std::bad_alloc();
  std::memset(static_cast<std::byte*>(p) + capacity_, 0, capacity - capacity_);
  data_ = static_cast<std::byte*>(p);
  capacity_ = capacity;
  size_ = bytes;
}
#endif

uint64_t GrowableBuffer::resident_bytes() const {
  const uint64_t page = capacity_ >= kHugePage ? kHugePage : 4096;
  return (size_ + page - 1) / page * page;
}


void coordinate_out_of_range(double x, double size) {
  fail(Status::usage, "clustering: coordinate " + std::to_string(x) + " is too far from the origin (or not finite) "
                      "for cell size " + std::to_string(size) + " (at most 2^49 half-cells per axis)");
}

int64_t grid_square(double x, double size) {
  if (!(size >= kMinCellSize && size <= kMaxCellSize))
    fail(Status::usage, "clustering: cell size " + std::to_string(size) + " out of range");
  return half_index(x, size / 2, size) >> 1;
}

Clusterer::Clusterer(std::span<const double> cell_sizes, ClusterOptions options, std::span<const double> bounds,
                     uint64_t max_dense_squares, std::span<const double> fine_sizes)
    : options_(options) {
  max_dense_squares = std::min(max_dense_squares, kMaxDenseSquares);
  if (cell_sizes.empty()) fail(Status::usage, "clustering: no level (no cell size)");
  if (!bounds.empty() && bounds.size() != 6) fail(Status::internal, "clustering: bounds need 6 values");
  if (!fine_sizes.empty() && fine_sizes.size() != cell_sizes.size())
    fail(Status::internal, "clustering: fine_sizes needs one size (or 0) per level");
  if (cell_sizes.size() > kMaxFineLevels && !fine_sizes.empty())
    fail(Status::usage, "clustering: fine cells take at most " + std::to_string(kMaxFineLevels) + " levels");
  // Internal grids: the levels' own first, then one fine grid per level that has one, in level order.
  external_ = cell_sizes.size();
  std::vector<double> sizes(cell_sizes.begin(), cell_sizes.end());
  fine_of_.assign(external_, kNoCell);
  for (size_t l = 0; l < fine_sizes.size(); ++l) {
    if (fine_sizes[l] == 0) continue;
    if (!(fine_sizes[l] >= kMinCellSize && fine_sizes[l] < cell_sizes[l]))
      fail(Status::usage, "clustering: a fine cell size must be positive and below its level's cell size");
    fine_of_[l] = static_cast<uint32_t>(sizes.size());
    sizes.push_back(fine_sizes[l]);
  }
  levels_.resize(sizes.size());
  for (size_t l = 0; l < sizes.size(); ++l) {
    const double c = sizes[l];
    if (!(c >= kMinCellSize && c <= kMaxCellSize))
      fail(Status::usage, "clustering: cell size " + std::to_string(c) + " out of range");
    if (l > 0 && l < external_ && !(c > sizes[l - 1]))
      fail(Status::usage, "clustering: cell sizes must be strictly increasing");
    Level& level = levels_[l];
    level.size = c;
    level.half = c / 2;  // exact: c is normal
    level.half_sq = level.half * level.half;
    uint64_t squares = bounds.empty() ? kMaxDenseSquares + 1 : 1;
    for (int a = 0; a < 3 && !bounds.empty(); ++a) {
      level.first[a] = grid_square(bounds[a], c) - 1;
      level.dims[a] = grid_square(bounds[3 + a], c) + 2 - level.first[a];
      squares = level.dims[a] > 0 && static_cast<uint64_t>(level.dims[a]) <= kMaxDenseSquares
                    ? squares * static_cast<uint64_t>(level.dims[a])
                    : kMaxDenseSquares + 1;
      if (squares > kMaxDenseSquares) squares = kMaxDenseSquares + 1;
    }
    bool packable = !bounds.empty();
    for (int a = 0; a < 3; ++a) packable &= level.dims[a] > 0 && level.dims[a] < (int64_t{1} << 21);
    if (squares <= max_dense_squares)
      level.dense.assign(squares, DenseSquare{kNoCell, 0});
    else if (packable)
      init_table(level.packed);
    else
      init_table(level.table);
  }
  // A fine grid numbers its cells from its level's counter, so that the level's ids stay 0, 1, 2, ... in
  // order of creation over both grids.
  for (size_t l = 0; l < levels_.size(); ++l) levels_[l].next_id = &levels_[l].cells;
  for (size_t l = 0; l < external_; ++l)
    if (fine_of_[l] != kNoCell) levels_[fine_of_[l]].next_id = &levels_[l].cells;
  if (options_.clustering == Clustering::floating) {
    queries_.resize(external_);
    ring_.resize(kQueryRing * external_);
  }
}

double Clusterer::fine_cell_size(size_t level) const {
  return fine_of_[level] == kNoCell ? 0 : levels_[fine_of_[level]].size;
}

uint32_t Clusterer::max_cells_per_square(size_t level) const {
  const uint32_t own = levels_[level].max_per_square;
  return fine_of_[level] == kNoCell ? own : std::max(own, levels_[fine_of_[level]].max_per_square);
}

void Clusterer::assign(uint32_t vertex_id, std::span<const double, 3> position, std::span<uint32_t> cells,
                       uint32_t fine_mask) {
  if (cells.size() != external_) fail(Status::internal, "Clusterer::assign: cells.size() != levels()");
  const double p[3] = {position[0], position[1], position[2]};
  if (options_.clustering == Clustering::floating) {
    // Three passes over the levels, each issuing independent memory accesses for all of them: the table
    // slots, then the list heads, then the lists. Levels do not interact, so the order changes nothing.
    for (size_t l = 0; l < external_; ++l) query_floating(grid(l, fine_mask), p, queries_[l]);
    for (size_t l = 0; l < external_; ++l) find_runs(grid(l, fine_mask), queries_[l]);
    for (size_t l = 0; l < external_; ++l) cells[l] = assign_floating(grid(l, fine_mask), p, queries_[l]);
  } else {
    for (size_t l = 0; l < external_; ++l) cells[l] = assign_uniform(grid(l, fine_mask), p);
  }
  static_cast<void>(vertex_id);  // the order is the caller's; no vertex id is kept
}

void Clusterer::assign_block(std::span<const uint32_t> ids, std::span<const double> positions,
                             std::span<uint32_t> cells, std::span<const uint32_t> fine_masks) {
  const size_t n = ids.size(), nl = external_;
  if (positions.size() != 3 * n || cells.size() != nl * n || (!fine_masks.empty() && fine_masks.size() != n))
    fail(Status::internal, "Clusterer::assign_block: positions, cells or fine masks do not match the ids");
  const double* xyz = positions.data();
  auto mask = [&](size_t i) { return fine_masks.empty() ? 0u : fine_masks[i]; };
  if (options_.clustering == Clustering::uniform) {
    constexpr size_t kAhead = 8;
    for (size_t i = 0; i < n; ++i) {
      if (i + kAhead < n)
        for (size_t l = 0; l < nl; ++l) prefetch_uniform(grid(l, mask(i + kAhead)), xyz + 3 * (i + kAhead));
      for (size_t l = 0; l < nl; ++l) cells[l * n + i] = assign_uniform(grid(l, mask(i)), xyz + 3 * i);
    }
    return;
  }
  // A software pipeline over the vertices. Vertex i + kSlotsAhead gets its query (squares, slot indices)
  // and its table slots fetched; vertex i + kRunsAhead has its slots read and its cell runs fetched; vertex
  // i is assigned, as assign does, from slots and runs that are by then mostly in cache. The queries are
  // exact (they depend on the position alone); what the later stages read ahead may be stale by the time
  // the vertex is assigned, so the assignment itself re-reads everything.
  constexpr size_t kSlotsAhead = 16, kRunsAhead = 8;
  static_assert(kRunsAhead < kSlotsAhead && kSlotsAhead < kQueryRing);
  auto ring = [&](size_t i) { return &ring_[(i % kQueryRing) * nl]; };
  auto query = [&](size_t i) {
    Query* q = ring(i);
    for (size_t l = 0; l < nl; ++l) query_floating(grid(l, mask(i)), xyz + 3 * i, q[l]);
  };
  for (size_t i = 0; i < std::min(n, kSlotsAhead); ++i) query(i);
  for (size_t i = 0; i < n; ++i) {
    if (i + kSlotsAhead < n) query(i + kSlotsAhead);
    if (i + kRunsAhead < n) {
      const Query* q = ring(i + kRunsAhead);
      for (size_t l = 0; l < nl; ++l) prefetch_runs(grid(l, mask(i + kRunsAhead)), q[l]);
    }
    Query* q = ring(i);
    const uint32_t m = mask(i);
    for (size_t l = 0; l < nl; ++l) find_runs(grid(l, m), q[l]);
    for (size_t l = 0; l < nl; ++l) cells[l * n + i] = assign_floating(grid(l, m), xyz + 3 * i, q[l]);
  }
}

void Clusterer::prefetch_runs(const Level& level, const Query& q) const {
  const std::byte* pool = level.pool.data();
  const size_t bytes = cell_bytes();
  if (!level.dense.empty()) {
    for (int i = 0; i < 8; ++i) {
      const DenseSquare& d = level.dense[q.slot[i]];
      if (d.count) prefetch_run(pool, bytes, d.run, d.count);
    }
    return;
  }
  if (!level.packed.sub.empty()) {
    for (int i = 0; i < 8; ++i)
      if (const PackedSlot* s = find_in(level.packed, q.slot[i], q.key[i])) prefetch_run(pool, bytes, s->run, s->count);
    return;
  }
  for (int i = 0; i < 8; ++i)
    if (const Slot* s = find_in(level.table, q.slot[i], WideKey{{q.square[i][0], q.square[i][1], q.square[i][2]}}))
      prefetch_run(pool, bytes, s->run, s->count);
}

void Clusterer::prefetch_uniform(const Level& level, const double* p) const {
  if (!level.dense.empty()) return;  // small enough to stay in cache
  int64_t square[3];
  for (int a = 0; a < 3; ++a) square[a] = half_index(p[a], level.half, level.size) >> 1;
  if (!level.packed.sub.empty()) {  // only a hint: a square outside the bounds fetches some slot, harmlessly
    __builtin_prefetch(home_slot(level.packed, fmix64(pack(level, square))));
    return;
  }
  __builtin_prefetch(home_slot(level.table, hash_square(square[0], square[1], square[2])));
}

uint64_t Clusterer::pack(const Level& level, const int64_t square[3]) {
  return static_cast<uint64_t>(square[0] - level.first[0]) | static_cast<uint64_t>(square[1] - level.first[1]) << 21 |
         static_cast<uint64_t>(square[2] - level.first[2]) << 42;
}

// The run and count fields of `square`, which is inserted (count 0) if absent.
void Clusterer::square_fields(Level& level, const int64_t square[3], uint32_t*& run, uint32_t*& count) {
  if (!level.dense.empty()) {
    check_inside(level.first, level.dims, square);
    DenseSquare& d = level.dense[dense_index(level, square)];
    run = &d.run, count = &d.count;
  } else if (!level.packed.sub.empty()) {
    check_inside(level.first, level.dims, square);
    const uint64_t key = pack(level, square);
    PackedSlot& slot = find_or_insert(level.packed, fmix64(key), key);
    run = &slot.run, count = &slot.count;
  } else {
    const WideKey key{{square[0], square[1], square[2]}};
    Slot& slot = find_or_insert(level.table, key_hash(key), key);
    run = &slot.run, count = &slot.count;
  }
}

// The index of `square` in a dense level's array. The vertex's own square must lie inside the bounds'
// squares (then its query block lies in the array, which has one more square on each side).
uint64_t Clusterer::dense_index(const Level& level, const int64_t square[3]) {
  const uint64_t x = static_cast<uint64_t>(square[0] - level.first[0]);
  const uint64_t y = static_cast<uint64_t>(square[1] - level.first[1]);
  const uint64_t z = static_cast<uint64_t>(square[2] - level.first[2]);
  return x + static_cast<uint64_t>(level.dims[0]) * (y + static_cast<uint64_t>(level.dims[1]) * z);
}

// Square i of a query's 2×2×2 block (bit a of i selects the neighbour along axis a), stored in q.square[i].
inline const int64_t* block_square(Clusterer::Query& q, const int64_t other[3], int i) {
  int64_t* sq = q.square[i];
  sq[0] = (i & 1) ? other[0] : q.own[0];
  sq[1] = (i & 2) ? other[1] : q.own[1];
  sq[2] = (i & 4) ? other[2] : q.own[2];
  return sq;
}

void Clusterer::query_floating(const Level& level, const double* p, Query& q) const {
  const double h = level.half;
  int64_t other[3];
  uint64_t term[3][2];  // axis_term of own (0) and other (1)
  for (int a = 0; a < 3; ++a) {
    const int64_t k = half_index(p[a], h, level.size);
    q.own[a] = k >> 1;  // arithmetic shift: floor division by 2 at negative indices too
    // A center within c/2 of p lies in p's square or in the neighbour on the side of p's half.
    other[a] = q.own[a] + ((k & 1) ? 1 : -1);
    term[a][0] = axis_term(q.own[a], a);
    term[a][1] = axis_term(other[a], a);
  }
  if (!level.dense.empty()) {
    check_inside(level.first, level.dims, q.own);
    for (int i = 0; i < 8; ++i) {
      q.slot[i] = dense_index(level, block_square(q, other, i));
    }
    return;
  }
  if (!level.packed.sub.empty()) {
    check_inside(level.first, level.dims, q.own);
    for (int i = 0; i < 8; ++i) {
      q.key[i] = pack(level, block_square(q, other, i));
      q.slot[i] = fmix64(q.key[i]);
      // Four slots share a cache line: the probe for an absent square runs on to the next empty slot,
      // which may be in the next line (no branch: a mispredicted one costs more than a redundant fetch).
      const auto& sub = level.packed.sub[q.slot[i] >> kSubShift];
      const uint64_t mask = sub.size() - 1;
      __builtin_prefetch(&sub[q.slot[i] & mask]);
      __builtin_prefetch(&sub[(q.slot[i] + 3) & mask]);
    }
    return;
  }
  for (int i = 0; i < 8; ++i) {
    block_square(q, other, i);
    q.slot[i] = fmix64(term[0][i & 1] + term[1][(i >> 1) & 1] + term[2][(i >> 2) & 1]);
    // The probe for an absent square (most of them in the fine levels) runs on to the next empty slot,
    // often on the next cache line: fetch that too.
    const auto& sub = level.table.sub[q.slot[i] >> kSubShift];
    const uint64_t mask = sub.size() - 1;
    __builtin_prefetch(&sub[q.slot[i] & mask]);
    __builtin_prefetch(&sub[(q.slot[i] + 2) & mask]);
  }
}

void Clusterer::find_runs(const Level& level, Query& q) const {
  if (!level.dense.empty()) {
    for (int i = 0; i < 8; ++i) {
      const DenseSquare& d = level.dense[q.slot[i]];
      q.run[i] = d.run;
      q.count[i] = d.count;
    }
    return;
  }
  const std::byte* pool = level.pool.data();
  const size_t bytes = cell_bytes();
  auto take = [&](int i, const auto* s) {
    q.run[i] = s ? s->run : 0;
    q.count[i] = s ? s->count : 0;
    if (s) prefetch_run(pool, bytes, s->run, s->count);
  };
  if (!level.packed.sub.empty()) {
    for (int i = 0; i < 8; ++i) take(i, find_in(level.packed, q.slot[i], q.key[i]));
  } else {
    for (int i = 0; i < 8; ++i)
      take(i, find_in(level.table, q.slot[i], WideKey{{q.square[i][0], q.square[i][1], q.square[i][2]}}));
  }
}

namespace {

template <class Cell>
uint32_t scan(const Cell* pool, const Clusterer::Query& q, const double* p, double h, double half_sq, bool sphere,
              bool nearest) {
  bool boundary = false;
  uint32_t best = nearest ? (sphere ? scan_fast<true, true>(pool, q, p, h, half_sq, boundary)
                                    : scan_fast<true, false>(pool, q, p, h, half_sq, boundary))
                          : (sphere ? scan_fast<false, true>(pool, q, p, h, half_sq, boundary)
                                    : scan_fast<false, false>(pool, q, p, h, half_sq, boundary));
  if (boundary) best = scan_exact(pool, q, p, h, half_sq, sphere, nearest);
  return best;
}

}  // namespace

uint32_t Clusterer::assign_floating(Level& level, const double* p, const Query& q) {
  const bool sphere = options_.shape == CellShape::sphere;
  const bool nearest = options_.choice == CellChoice::nearest;
  const uint32_t best =
      options_.float_positions
          ? scan(reinterpret_cast<const FloatCell*>(level.pool.data()), q, p, level.half, level.half_sq, sphere, nearest)
          : scan(reinterpret_cast<const DoubleCell*>(level.pool.data()), q, p, level.half, level.half_sq, sphere, nearest);
  if (best != kNoCell) return best;
  return start_cell(level, p, q.own);
}

// p lies in no cell: it starts one, attached to its own square.
uint32_t Clusterer::start_cell(Level& level, const double* p, const int64_t square[3]) {
  uint32_t* run;
  uint32_t* count;
  square_fields(level, square, run, count);
  const uint32_t id = options_.float_positions ? add_cell<FloatCell>(level, *run, *count, p)
                                               : add_cell<DoubleCell>(level, *run, *count, p);
  // invariant: count <= kMaxCubeCellsPerSquare (cubes) or kMaxSphereCellsPerSquare (spheres); see the
  // header for the proof. It rests on the exact square and inside tests above, so a violation is a bug.
  const uint32_t bound = options_.shape == CellShape::sphere ? kMaxSphereCellsPerSquare : kMaxCubeCellsPerSquare;
  if (*count > bound)
    fail(Status::internal, "clustering: " + std::to_string(*count) + " cells attached to one grid square (bound " +
                               std::to_string(bound) + ")");
  if (*count > level.max_per_square) level.max_per_square = *count;
  return id;
}

uint32_t Clusterer::assign_uniform(Level& level, const double* p) {
  int64_t square[3];
  for (int a = 0; a < 3; ++a) square[a] = half_index(p[a], level.half, level.size) >> 1;
  uint32_t* run;
  uint32_t* count;
  square_fields(level, square, run, count);
  if (*count == 0) {
    // The first vertex to reach a square is its heaviest: it names the cell and numbers it. A square holds
    // one cell and nothing reads its center, so the slot keeps the id itself, and no record.
    if (*level.next_id == kNoCell) fail(Status::internal, "clustering: more than 2^32 - 1 cells in one level");
    *run = (*level.next_id)++;
    *count = 1;
    level.max_per_square = 1;
  }
  return *run;
}

// Appends a new cell centred on p to a square's run (its `slot_run`, `slot_count` fields; count += 1),
// moving the run to one twice as large first if it is full, and returns the cell's id.
template <class Cell>
uint32_t Clusterer::add_cell(Level& level, uint32_t& slot_run, uint32_t& slot_count, const double* p) {
  // Cell ids share uint32 with vertex ids and kNoCell is reserved; a pass creates at most one cell per
  // vertex, so reaching it means the caller fed more than 2^32 − 1 vertices.
  if (*level.next_id == kNoCell) fail(Status::internal, "clustering: more than 2^32 - 1 cells in one level");
  using Position = std::remove_extent_t<decltype(Cell::position)>;
  const Position c[3] = {static_cast<Position>(p[0]), static_cast<Position>(p[1]), static_cast<Position>(p[2])};
  if (!(c[0] == p[0] && c[1] == p[1] && c[2] == p[2]))
    fail(Status::internal, "clustering: a position is not exactly a float, but the clusterer keeps floats");
  const uint32_t n = slot_count;
  // A run's capacity is the power of two >= its count (1 for a new square), so it is full exactly when the
  // count is 0 or a power of two.
  if ((n & (n - 1)) == 0) {
    const uint32_t capacity = n == 0 ? 1 : 2 * n;
    const int k = std::countr_zero(capacity);
    if (k >= kRunClasses) fail(Status::internal, "clustering: too many cells attached to one grid square");
    uint32_t run = level.free_run[k];
    if (run != kNoCell) {
      level.free_run[k] = reinterpret_cast<Cell*>(level.pool.data())[run].id;
    } else {
      if (uint64_t{level.records} + capacity > kNoCell) fail(Status::internal, "clustering: cell pool too large");
      run = level.records;
      level.records += capacity;
      level.pool.resize(static_cast<size_t>(level.records) * sizeof(Cell));
    }
    Cell* pool = reinterpret_cast<Cell*>(level.pool.data());
    if (n > 0) {
      std::copy(pool + slot_run, pool + slot_run + n, pool + run);
      const int old_k = std::countr_zero(n);
      pool[slot_run].id = level.free_run[old_k];
      level.free_run[old_k] = slot_run;
    }
    slot_run = run;
  }
  const uint32_t id = (*level.next_id)++;
  Cell& cell = reinterpret_cast<Cell*>(level.pool.data())[slot_run + n];
  std::copy(c, c + 3, cell.position);
  cell.id = id;
  slot_count = n + 1;
  return id;
}

uint64_t Clusterer::memory_bytes() const {
  uint64_t bytes = sizeof(*this) + levels_.capacity() * sizeof(Level), largest = 0;
  for (const Level& level : levels_)
    bytes += level.pool.resident_bytes() + table_bytes(level.table, &largest) + table_bytes(level.packed, &largest) +
             level.dense.capacity() * sizeof(DenseSquare);
  return bytes + (queries_.capacity() + ring_.capacity()) * sizeof(Query);
}

uint64_t Clusterer::growth_bytes() const {
  uint64_t largest = 0;
  for (const Level& level : levels_) {
    table_bytes(level.table, &largest);
    table_bytes(level.packed, &largest);
  }
  return 2 * largest + levels_.size() * kHugePage;
}

}  // namespace lodstream::core

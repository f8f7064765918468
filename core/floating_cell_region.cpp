// Floating cells over part of a scene, three-valued. This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2
// See floating_cell_region.h for the rule and the proof of its invariant.
#include "core/floating_cell_region.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <iterator>
#include <limits>

#include "core/hash.h"
#include "core/status.h"

namespace lodstream::core {

namespace {

constexpr size_t kInitialSlots = 64;

inline bool same_square(const int64_t* a, const int64_t* b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

}  // namespace

RegionClusterer::RegionClusterer(double cell_size, ClusterOptions options, std::span<const double, 6> held, uint32_t max_open)
    : half_(cell_size / 2), half_sq_(half_ * half_), options_(options), max_open_(std::max<uint32_t>(max_open, 1)) {
  if (options.clustering != Clustering::floating)
    fail(Status::internal, "RegionClusterer: floating cells only (uniform cells need no halo)");
  if (!(cell_size >= kMinCellSize && cell_size <= kMaxCellSize))
    fail(Status::usage, "clustering: cell size " + std::to_string(cell_size) + " out of range");
  for (int a = 0; a < 3; ++a) lo_[a] = held[a], hi_[a] = held[3 + a];
  std::fill(std::begin(free_), std::end(free_), kNone);
  ring_.resize(kQueryRing);
}

bool RegionClusterer::exposed(const double* p) const {
  for (int a = 0; a < 3; ++a)
    if (p[a] - lo_[a] <= half_ || hi_[a] - p[a] <= half_) return true;
  return false;
}

bool RegionClusterer::box_holds(const double* lo, const double* hi, const double* p) const {
  for (int a = 0; a < 3; ++a)
    if (!(lo[a] - p[a] <= half_ && p[a] - hi[a] <= half_)) return false;
  return true;
}

// A cell that holds p has its center within c/2 of p: in p's square or, per axis, the neighbour on the
// side of the half p lies in (floating_cell.h). The hashes are taken here; the slots they name are read
// when the vertex is decided, from the table as it is then (it may have grown since).
void RegionClusterer::query(const double* p, Query& q) const {
  int64_t side[3];
  uint64_t term[3][2];
  for (int a = 0; a < 3; ++a) {
    const int64_t h = half_index(p[a], half_, 2 * half_);  // floor(p / (c/2)), exact
    q.own[a] = h >> 1;
    side[a] = q.own[a] + ((h & 1) ? 1 : -1);
    term[a][0] = axis_term(q.own[a], a);
    term[a][1] = axis_term(side[a], a);
  }
  const size_t mask = slots_.size() - 1;
  for (int i = 0; i < 8; ++i) {
    int64_t* sq = q.square[i];
    sq[0] = (i & 1) ? side[0] : q.own[0], sq[1] = (i & 2) ? side[1] : q.own[1], sq[2] = (i & 4) ? side[2] : q.own[2];
    q.hash[i] = fmix64(term[0][i & 1] + term[1][(i >> 1) & 1] + term[2][(i >> 2) & 1]);
    if (!slots_.empty()) __builtin_prefetch(&slots_[q.hash[i] & mask]);
  }
}

const RegionClusterer::Slot* RegionClusterer::find(const int64_t* square, uint64_t hash) const {
  if (slots_.empty()) return nullptr;
  const size_t mask = slots_.size() - 1;
  for (size_t i = hash & mask;; i = (i + 1) & mask) {  // at most half full: every probe ends
    const Slot& s = slots_[i];
    if (s.count == 0) return nullptr;
    if (same_square(s.square, square)) return &s;
  }
}

void RegionClusterer::prefetch_runs(const Query& q) const {
  const std::byte* base = pool_.data();
  for (int i = 0; i < 8; ++i)
    if (const Slot* s = find(q.square[i], q.hash[i])) {  // every cache line of the run (two records a line)
      const std::byte* first = base + size_t{s->run} * sizeof(Record);
      const std::byte* last = first + size_t{s->count} * sizeof(Record) - 1;
      for (const std::byte* line = first; line <= last; line += 64) __builtin_prefetch(line);
      __builtin_prefetch(last);
    }
}

RegionClusterer::Slot& RegionClusterer::slot(const int64_t* square, uint64_t hash) {
  if (2 * (occupied_ + 1) > slots_.size()) {  // grow: at most half full
    decltype(slots_) old(std::max(kInitialSlots, 2 * slots_.size()), Slot{{0, 0, 0}, 0, 0});
    old.swap(slots_);
    const size_t mask = slots_.size() - 1;
    for (const Slot& s : old) {
      if (s.count == 0) continue;
      size_t i = hash_square(s.square[0], s.square[1], s.square[2]) & mask;
      while (slots_[i].count != 0) i = (i + 1) & mask;
      slots_[i] = s;
    }
  }
  const size_t mask = slots_.size() - 1;
  size_t i = hash & mask;
  while (slots_[i].count != 0 && !same_square(slots_[i].square, square)) i = (i + 1) & mask;
  Slot& s = slots_[i];
  if (s.count == 0) s = Slot{{square[0], square[1], square[2]}, kNone, 0}, ++occupied_;
  return s;
}

uint32_t RegionClusterer::take_run(uint32_t capacity) {
  const int k = std::countr_zero(capacity);
  uint32_t run = free_[k];
  if (run != kNone) {
    free_[k] = pool()[run].tag;
    return run;
  }
  if (uint64_t{records_} + capacity >= kNone) fail(Status::internal, "RegionClusterer: more than 2^32 - 1 records");
  run = records_;
  records_ += capacity;
  pool_.resize(size_t{records_} * sizeof(Record));
  return run;
}

// invariant: a run of `count` records has capacity std::bit_ceil(count).
void RegionClusterer::free_run(uint32_t run, uint32_t count) {
  const int k = std::countr_zero(std::bit_ceil(count));
  pool()[run].tag = free_[k];
  free_[k] = run;
}

void RegionClusterer::add(const int64_t* square, uint64_t hash, const Record& r) {
  Slot& s = slot(square, hash);
  Record* run = pool() + (s.count ? s.run : 0);
  if (r.kind == Record::kOpen) {
    uint32_t open = 0, box = kNone;
    for (uint32_t j = 0; j < s.count; ++j) {
      open += run[j].kind == Record::kOpen;
      if (run[j].kind == Record::kBoxLo) box = j;
    }
    if (box != kNone) {  // a crowded square: its box widens
      for (int a = 0; a < 3; ++a)
        run[box].position[a] = std::min(run[box].position[a], r.position[a]),
        run[box + 1].position[a] = std::max(run[box + 1].position[a], r.position[a]);
      return;
    }
    if (open == max_open_) {
      // Crowded: the square's unsettled records and r become its box (two records, its corners, kept
      // together); the run keeps its settled centers.
      scratch_.clear();
      Record lo{{r.position[0], r.position[1], r.position[2]}, 0, Record::kBoxLo}, hi{lo};
      hi.kind = Record::kBoxHi;
      for (uint32_t j = 0; j < s.count; ++j) {
        if (run[j].kind != Record::kOpen) {
          scratch_.push_back(run[j]);
          continue;
        }
        for (int a = 0; a < 3; ++a)
          lo.position[a] = std::min(lo.position[a], run[j].position[a]), hi.position[a] = std::max(hi.position[a], run[j].position[a]);
      }
      scratch_.push_back(lo);
      scratch_.push_back(hi);
      free_run(s.run, s.count);
      s.run = take_run(std::bit_ceil(static_cast<uint32_t>(scratch_.size())));
      std::copy(scratch_.begin(), scratch_.end(), pool() + s.run);
      s.count = static_cast<uint32_t>(scratch_.size());
      ++crowded_;
      return;
    }
  }
  // A run is full exactly when its count is 0 or a power of two (its capacity is the power of two at or
  // above its count): then it moves to one twice as large.
  const uint32_t n = s.count;
  if ((n & (n - 1)) == 0) {
    if (n == (uint32_t{1} << (kRunClasses - 1))) fail(Status::internal, "RegionClusterer: too many records in one square");
    const uint32_t run_to = take_run(n == 0 ? 1 : 2 * n);
    if (n > 0) {
      std::copy(pool() + s.run, pool() + s.run + n, pool() + run_to);
      free_run(s.run, n);
    }
    s.run = run_to;
  }
  pool()[s.run + n] = r;
  s.count = n + 1;
}

namespace {

// What holds p among a query's runs: the best settled center, the best unsettled vertex (each by the
// choice's order: nearest, ties by the lower tag; or the lower tag), and whether a crowded square's box
// holds p.
struct Holders {
  uint32_t settled = kNoCell, open = kNoCell;
  double settled_d2 = 0, open_d2 = 0;  // their fl(d²) (nearest choice only)
  bool crowded = false;
};

// The order of the choice (floating_cell.h): whether candidate a (its fl(d²), a_d2) comes before b, which
// may be none (kNoCell): nearest, ties by the lower tag; or the lower tag.
inline bool precedes(bool nearest, uint32_t a, double a_d2, uint32_t b, double b_d2) {
  if (b == kNoCell) return true;
  return nearest ? (a_d2 < b_d2 || (a_d2 == b_d2 && a < b)) : a < b;
}

template <class Record>
struct Runs {
  const Record* first[8];
  uint32_t count[8];
};

// The candidate test, branch-free as Clusterer's scan_fast is (in a coarse level a vertex meets dozens of
// candidates, accepted or rejected about at random, which branches would mispredict half the time). It
// decides |d| <= h per axis on the rounded difference, exact except where that difference rounds onto h
// itself: it then sets `boundary`, and the caller redoes the scan with scan_exact. A box's corners are
// the rare records, behind a branch that is nearly always predicted.
template <bool kNearest, bool kSphere, class Record, class BoxHolds>
Holders scan_fast(const Runs<Record>& runs, const double* p, double h, double half_sq, BoxHolds box_holds,
                  bool& boundary) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  uint32_t st = kNoCell, ot = kNoCell;
  double sk = kInf, ok = kInf;
  bool on_h = false, crowded = false;
  for (int i = 0; i < 8; ++i) {
    const Record* run = runs.first[i];
    for (uint32_t j = 0; j < runs.count[i]; ++j) {
      const Record& e = run[j];
      if (e.kind >= Record::kBoxLo) [[unlikely]] {
        if (e.kind == Record::kBoxLo) crowded = crowded || box_holds(e.position, run[j + 1].position, p);
        continue;
      }
      double key;
      const bool inside = fast_inside<kNearest, kSphere>(p, e.position[0], e.position[1], e.position[2], h, half_sq, on_h, key);
      const bool settled = e.kind == Record::kSettled;
      const bool s_better = inside & settled & ((key < sk) | ((key == sk) & (e.tag < st)));
      const bool o_better = inside & !settled & ((key < ok) | ((key == ok) & (e.tag < ot)));
      st = s_better ? e.tag : st;
      sk = s_better ? key : sk;
      ot = o_better ? e.tag : ot;
      ok = o_better ? key : ok;
    }
  }
  boundary = on_h;
  Holders w;
  w.settled = st, w.open = ot, w.crowded = crowded;
  w.settled_d2 = st == kNoCell ? 0 : sk, w.open_d2 = ot == kNoCell ? 0 : ok;
  return w;
}

// The same with floating_cell_contains, exact on the boundary.
template <class Record, class BoxHolds>
Holders scan_exact(const Runs<Record>& runs, const double* p, double h, double half_sq, ClusterOptions options,
                   BoxHolds box_holds) {
  const bool nearest = options.choice == CellChoice::nearest;
  Holders w;
  for (int i = 0; i < 8; ++i) {
    const Record* run = runs.first[i];
    for (uint32_t j = 0; j < runs.count[i]; ++j) {
      const Record& e = run[j];
      if (e.kind >= Record::kBoxLo) {
        if (e.kind == Record::kBoxLo) w.crowded = w.crowded || box_holds(e.position, run[j + 1].position, p);
        continue;
      }
      double d2;
      if (!floating_cell_contains(p, e.position, h, half_sq, options.shape, d2)) continue;
      if (!nearest) d2 = 0;
      if (e.kind == Record::kSettled) {
        if (precedes(nearest, e.tag, d2, w.settled, w.settled_d2)) w.settled = e.tag, w.settled_d2 = d2;
      } else if (precedes(nearest, e.tag, d2, w.open, w.open_d2)) {
        w.open = e.tag, w.open_d2 = d2;
      }
    }
  }
  return w;
}

}  // namespace

RegionDecision RegionClusterer::decide(uint32_t tag, const double* p, const Query& q) {
  if (tag < last_tag_) fail(Status::internal, "RegionClusterer: tags must be strictly increasing");
  last_tag_ = uint64_t{tag} + 1;
  const bool nearest = options_.choice == CellChoice::nearest, sphere = options_.shape == CellShape::sphere;
  Runs<Record> runs;
  for (int i = 0; i < 8; ++i) {
    const Slot* s = find(q.square[i], q.hash[i]);
    runs.first[i] = s ? pool() + s->run : nullptr;
    runs.count[i] = s ? s->count : 0;
  }
  auto box = [this](const double* lo, const double* hi, const double* x) { return box_holds(lo, hi, x); };
  bool boundary = false;
  Holders w = nearest ? (sphere ? scan_fast<true, true>(runs, p, half_, half_sq_, box, boundary)
                                : scan_fast<true, false>(runs, p, half_, half_sq_, box, boundary))
                      : (sphere ? scan_fast<false, true>(runs, p, half_, half_sq_, box, boundary)
                                : scan_fast<false, false>(runs, p, half_, half_sq_, box, boundary));
  if (boundary) w = scan_exact(runs, p, half_, half_sq_, options_, box);

  // A vertex the task does not hold, or a crowded square's unsettled vertex, may hold p.
  const bool outside_may_hold = exposed(p) || w.crowded;
  RegionDecision d;
  if (w.settled != kNoCell) {
    // invariant: a settled center's cell holds p, so p starts no cell in the whole-scene pass.
    d.status = RegionStatus::member;
    d.cell_settled = !outside_may_hold && (w.open == kNoCell || !precedes(nearest, w.open, w.open_d2, w.settled, w.settled_d2));
    if (d.cell_settled) d.center = w.settled;
    return d;
  }
  const bool is_center = !outside_may_hold && w.open == kNoCell;
  d.status = is_center ? RegionStatus::center : RegionStatus::unsettled;
  d.cell_settled = is_center;
  if (is_center) d.center = tag;
  if (!is_center) ++unsettled_;
  // The own square is block square 0.
  add(q.own, q.hash[0], Record{{p[0], p[1], p[2]}, tag, is_center ? Record::kSettled : Record::kOpen});
  return d;
}

RegionDecision RegionClusterer::assign(uint32_t tag, std::span<const double, 3> position) {
  Query& q = ring_[0];
  query(position.data(), q);
  return decide(tag, position.data(), q);
}

// A software pipeline over the vertices, as in Clusterer::assign_block: vertex i + kSlotsAhead gets its
// query (squares, hashes) and its slots fetched; vertex i + kRunsAhead has its slots read and its runs
// fetched; vertex i is decided from slots and runs that are by then mostly in cache. What the later
// stages read ahead may be stale by then (the table may have grown, a square gained records), so the
// decision reads everything again; only the query, which depends on the position alone, is kept.
void RegionClusterer::assign_block(std::span<const uint32_t> tags, std::span<const double> positions,
                                   std::span<RegionDecision> decisions) {
  const size_t n = tags.size();
  if (positions.size() != 3 * n || decisions.size() != n)
    fail(Status::internal, "RegionClusterer::assign_block: positions or decisions do not match the tags");
  static_assert(kRunsAhead < kSlotsAhead && kSlotsAhead < kQueryRing);
  const double* xyz = positions.data();
  auto ring = [&](size_t i) -> Query& { return ring_[i % kQueryRing]; };
  for (size_t i = 0; i < std::min(n, kSlotsAhead); ++i) query(xyz + 3 * i, ring(i));
  for (size_t i = 0; i < n; ++i) {
    if (i + kSlotsAhead < n) query(xyz + 3 * (i + kSlotsAhead), ring(i + kSlotsAhead));
    if (i + kRunsAhead < n) prefetch_runs(ring(i + kRunsAhead));
    decisions[i] = decide(tags[i], xyz + 3 * i, ring(i));
  }
}

std::vector<uint32_t> whole_scene_centers(std::span<const double> positions, double cell_size, ClusterOptions options) {
  const double sizes[] = {cell_size};
  Clusterer clusterer(sizes, options);
  const size_t n = positions.size() / 3;
  std::vector<uint32_t> center_of_cell, out(n);
  for (size_t i = 0; i < n; ++i) {
    uint32_t cell;
    clusterer.assign(static_cast<uint32_t>(i), std::span<const double, 3>(&positions[3 * i], 3),
                     std::span<uint32_t>(&cell, 1));
    if (cell == center_of_cell.size()) center_of_cell.push_back(static_cast<uint32_t>(i));  // i created the cell
    out[i] = center_of_cell[cell];
  }
  return out;
}

}  // namespace lodstream::core

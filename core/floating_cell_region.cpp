// Floating cells over part of a scene, three-valued. This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2
// See floating_cell_region.h for the rule and the proof of its invariant.
#include "core/floating_cell_region.h"

#include <algorithm>
#include <cmath>

#include "core/hash.h"
#include "core/status.h"

namespace lodstream::core {

size_t RegionClusterer::home(const int64_t* square) const {
  return hash_square(square[0], square[1], square[2]) & (slots_.size() - 1);
}

size_t RegionClusterer::probe(const int64_t* square, size_t from) const {
  const size_t mask = slots_.size() - 1;
  size_t i = from;
  while (slots_[i].used() &&
         !(slots_[i].square[0] == square[0] && slots_[i].square[1] == square[1] && slots_[i].square[2] == square[2]))
    i = (i + 1) & mask;
  return i;
}

RegionClusterer::Slot& RegionClusterer::slot(const int64_t* square) {
  if (2 * (occupied_ + 1) > slots_.size()) {  // grow: at most half full
    std::vector<Slot> old(std::max<size_t>(64, 2 * slots_.size()), Slot{{0, 0, 0}, kNone, 0, kNone});
    old.swap(slots_);
    for (const Slot& s : old)
      if (s.used()) slots_[probe(s.square)] = s;
  }
  Slot& s = slots_[probe(square)];
  if (!s.used()) s = Slot{{square[0], square[1], square[2]}, kNone, 0, kNone}, ++occupied_;
  return s;
}

void RegionClusterer::add(const int64_t* square, const Entry& e) {
  Slot& s = slot(square);
  if (!e.settled && s.box != kNone) {  // a crowded square: its box widens
    boxes_[s.box].take(e.position);
    return;
  }
  if (!e.settled && s.open == max_open_) {
    // Crowded: the square's unsettled entries and e become its box; the list keeps its settled centers.
    Box b{{e.position[0], e.position[1], e.position[2]}, {e.position[0], e.position[1], e.position[2]}};
    uint32_t* link = &s.head;
    while (*link != kNone) {
      Entry& x = entries_[*link];
      if (x.settled) {
        link = &x.next;
        continue;
      }
      b.take(x.position);
      *link = x.next;  // unlinked (its record stays unused in entries_)
    }
    s.open = 0;
    s.box = static_cast<uint32_t>(boxes_.size());
    boxes_.push_back(b);
    return;
  }
  if (entries_.size() >= kNone) fail(Status::internal, "RegionClusterer: more than 2^32 - 1 entries");
  entries_.push_back(e);
  entries_.back().next = s.head;
  s.head = static_cast<uint32_t>(entries_.size() - 1);
  s.open += !e.settled;
}

bool RegionClusterer::box_holds(const Box& b, const double* p) const {
  for (int a = 0; a < 3; ++a)
    if (!(b.lo[a] - p[a] <= half_ && p[a] - b.hi[a] <= half_)) return false;
  return true;
}

RegionClusterer::RegionClusterer(double cell_size, ClusterOptions options, std::span<const double, 6> held, uint32_t max_open)
    : half_(cell_size / 2), half_sq_(half_ * half_), options_(options), max_open_(std::max<uint32_t>(max_open, 1)) {
  if (options.clustering != Clustering::floating)
    fail(Status::internal, "RegionClusterer: floating cells only (uniform cells need no halo)");
  if (!(cell_size >= kMinCellSize && cell_size <= kMaxCellSize))
    fail(Status::usage, "clustering: cell size " + std::to_string(cell_size) + " out of range");
  for (int a = 0; a < 3; ++a) lo_[a] = held[a], hi_[a] = held[3 + a];
}

bool RegionClusterer::exposed(const double* p) const {
  for (int a = 0; a < 3; ++a)
    if (p[a] - lo_[a] <= half_ || hi_[a] - p[a] <= half_) return true;
  return false;
}

RegionDecision RegionClusterer::assign(std::span<const double, 3> position) {
  const double* p = position.data();
  const uint32_t index = next_++;
  const bool nearest = options_.choice == CellChoice::nearest;
  // The order of the choice (floating_cell.h): nearest, ties by the earlier center; or the earlier center.
  auto better = [&](uint32_t a, double a_d2, uint32_t b, double b_d2) {
    if (b == kNoCell) return true;
    return nearest ? (a_d2 < b_d2 || (a_d2 == b_d2 && a < b)) : a < b;
  };

  // A cell that holds p has its center within c/2 of p: in p's square or, per axis, the neighbour on the
  // side of the half p lies in (floating_cell.h).
  int64_t own[3], side[3];
  for (int a = 0; a < 3; ++a) {
    const int64_t h = grid_square(p[a], half_);  // floor(p / (c/2)), exact
    own[a] = h >> 1;
    side[a] = own[a] + ((h & 1) ? 1 : -1);
  }
  uint32_t settled = kNoCell, open = kNoCell;  // the best settled center, the best unsettled vertex holding p
  double settled_d2 = 0, open_d2 = 0;
  bool crowded = false;  // a crowded square's box holds p: an unsettled vertex of unknown rank may
  // The 8 squares' slots, then their first entries, are fetched before any is read, so that their cache
  // misses overlap (the probes do not depend on each other).
  const Slot* slots[8] = {};
  if (!slots_.empty()) {
    int64_t squares[8][3];
    size_t from[8];
    for (int i = 0; i < 8; ++i) {
      squares[i][0] = (i & 1) ? side[0] : own[0], squares[i][1] = (i & 2) ? side[1] : own[1], squares[i][2] = (i & 4) ? side[2] : own[2];
      from[i] = home(squares[i]);
      __builtin_prefetch(&slots_[from[i]]);
    }
    for (int i = 0; i < 8; ++i) {
      const Slot& s = slots_[probe(squares[i], from[i])];
      if (!s.used()) continue;
      slots[i] = &s;
      if (s.head != kNone) __builtin_prefetch(&entries_[s.head]);
    }
  }
  for (const Slot* slot : slots) {
    if (!slot) continue;
    if (slot->box != kNone && !crowded) crowded = box_holds(boxes_[slot->box], p);
    for (uint32_t k = slot->head; k != kNone; k = entries_[k].next) {
      const Entry& e = entries_[k];
      double d2;
      if (!floating_cell_contains(p, e.position, half_, half_sq_, options_.shape, d2)) continue;
      if (e.settled) {
        if (better(e.index, d2, settled, settled_d2)) settled = e.index, settled_d2 = d2;
      } else if (better(e.index, d2, open, open_d2)) {
        open = e.index, open_d2 = d2;
      }
    }
  }

  // A vertex the task does not hold, or a crowded square's unsettled vertex, may hold p.
  const bool outside_may_hold = exposed(p) || crowded;
  RegionDecision d;
  if (settled != kNoCell) {
    // invariant: a settled center's cell holds p, so p starts no cell in the whole-scene pass.
    d.status = RegionStatus::member;
    d.cell_settled = !outside_may_hold && (open == kNoCell || !better(open, open_d2, settled, settled_d2));
    if (d.cell_settled) d.center = settled;
    return d;
  }
  const bool is_center = !outside_may_hold && open == kNoCell;
  d.status = is_center ? RegionStatus::center : RegionStatus::unsettled;
  d.cell_settled = is_center;
  if (is_center) d.center = index;
  if (!is_center) ++unsettled_;
  add(own, Entry{{p[0], p[1], p[2]}, index, kNone, is_center});
  return d;
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

// Floating cells over part of a scene: which vertices' clustering a task can settle from the vertices it
// holds (issue 19, clustering by region with a halo).
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.2 (floating cells, the nearest
// variant of §3.2.3), as core/floating_cell.h runs it over the whole scene: vertices in weight order, a
// vertex inside no earlier cell starts one, a vertex inside some joins the nearest (or heaviest). The pass
// is sequential: a vertex's cell depends on the heavier centers within c/2 of it, whose own status depends
// on the heavier centers within c/2 of them, and so on. A task that holds only the vertices inside a box
// (its region and a halo around it) runs the same pass over them, in the same order, three-valued:
//   center    — a center in the whole-scene pass, for certain;
//   member    — not a center, for certain: it lies inside the cell of a settled center;
//   unsettled — it lies inside no settled cell but inside the cell of an unsettled vertex (which may or may
//               not be a center), or it lies within c/2 of the box's outside, where a heavier vertex the
//               task does not hold may have started a cell that holds it.
// A member's cell (the center it joins) is settled when no unsettled vertex's cell holds it and it is not
// within c/2 of the outside: its candidates are then exactly the settled centers holding it.
//
// Invariant (by induction over the weight order; the tests compare with Clusterer on clouds and meshes
// cut by many boxes): every settled status is the whole-scene pass's, and every settled cell is the
// whole-scene pass's cell, named by its center's index in the task's order.
// Proof. v is a whole-scene center iff no heavier whole-scene center's cell holds v. The heavier vertices
// whose cell could hold v lie within c/2 of it: held ones (settled correctly, or unsettled, by the
// induction) and, only when v is within c/2 of the outside, ones the task does not hold. If a settled
// center's cell holds v, v is a member. If v is not near the outside and no settled center's or unsettled
// vertex's cell holds v, no whole-scene center's cell holds v, and v is a center. Otherwise v is left
// unsettled. A member's whole-scene cell is the best of the whole-scene centers holding it; when neither
// an unsettled vertex nor the outside can hold it, those are exactly the settled centers holding it.
//
// "Within c/2 of the outside" is tested conservatively: the task holds every vertex p with
// lo[a] <= p[a] < hi[a] on every axis a (infinite bounds allowed), and v counts as exposed when
// fl(v[a] − lo[a]) <= c/2 or fl(hi[a] − v[a]) <= c/2 on some axis (rounding is monotone, so every truly
// exposed vertex is caught).
//
// Crowded squares. Unsettled vertices, unlike centers, may crowd a square (near the edge of what the task
// holds, every vertex no settled cell holds is one), and every later vertex near it would test them all.
// Once a square holds `max_open` unsettled entries, they are replaced by their bounding box: a vertex
// within c/2 of the box (per axis, fl(lo − p) <= c/2 and fl(p − hi) <= c/2) counts as held by an
// unsettled vertex of unknown rank. Every vertex an unsettled vertex's cell holds is within c/2 of it on
// every axis (spheres lie inside cubes), hence within c/2 of the box (rounding is monotone and c/2 is
// exact), so the box only adds doubt: the invariant holds as proved, with "unsettled vertex's cell"
// read as "a crowded square's box, or an unsettled vertex's cell". Later unsettled vertices of that
// square widen its box instead of being stored.
//
// One grid of one cell size: a level with a fine grid (Mata et al.'s labels) is two such grids, each over
// the vertices its mask sends it. Memory: one entry (its position, index and list link, 40 bytes) per
// center and per unsettled vertex, and a 32-byte slot per occupied grid square in a table at most half
// full; members keep nothing.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/floating_cell.h"

namespace lodstream::core {

enum class RegionStatus : uint8_t { center, member, unsettled };

struct RegionDecision {
  RegionStatus status = RegionStatus::unsettled;
  bool cell_settled = false;  // a center's cell is itself; a member's, when it is settled
  uint32_t center = kNoCell;  // with cell_settled: the index (in assign order) of the cell's center vertex
};

class RegionClusterer {
 public:
  // held: {lo x, lo y, lo z, hi x, hi y, hi z}, the box whose vertices the caller holds and will assign
  // (lo <= p < hi per axis; ±infinity where the task holds everything on that side). Floating cells only:
  // options.clustering must be floating (uniform cells need no halo: a vertex's cell is its square).
  // max_open: the unsettled entries a square keeps before they become its box (see "Crowded squares").
  RegionClusterer(double cell_size, ClusterOptions options, std::span<const double, 6> held, uint32_t max_open = 16);

  // The next held vertex in weight order (the whole-scene pass's order restricted to the box); its index
  // is the number of calls before it.
  RegionDecision assign(std::span<const double, 3> position);

  uint64_t unsettled() const { return unsettled_; }
  // Bytes held now (the table's and the entries' capacity), and what the next growth step may briefly add
  // (the table doubles while its old copy is held; the entries' vector doubles).
  uint64_t memory_bytes() const {
    return slots_.capacity() * sizeof(Slot) + entries_.capacity() * sizeof(Entry) + boxes_.capacity() * sizeof(Box);
  }
  uint64_t growth_bytes() const {
    return 2 * slots_.capacity() * sizeof(Slot) + entries_.capacity() * sizeof(Entry) + boxes_.capacity() * sizeof(Box);
  }
  uint64_t crowded_squares() const { return boxes_.size(); }

 private:
  // A square's entries are a list through `entries_`, newest first (the choice is a total order on
  // (distance, index), so the order they are read in does not matter).
  struct Entry {
    double position[3];
    uint32_t index;
    uint32_t next;  // the square's next entry, or kNone
    bool settled;   // a settled center; else an unsettled vertex
  };
  // A slot of the open-addressing table of occupied squares (linear probing, at most half full).
  struct Slot {
    int64_t square[3];
    uint32_t head;  // the square's newest entry, or kNone for an empty slot
    uint32_t open;  // unsettled entries in the list
    uint32_t box;   // a crowded square's box in boxes_ (its unsettled entries are then off the list), or kNone
    // A crowded square may have no entry left, but it keeps its box.
    bool used() const { return head != kNone || box != kNone; }
  };
  struct Box {
    double lo[3], hi[3];
    void take(const double* p) {
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    }
  };
  static constexpr uint32_t kNone = UINT32_MAX;

  bool exposed(const double* p) const;
  size_t home(const int64_t* square) const;   // where the square's probe starts (slots_ not empty)
  size_t probe(const int64_t* square, size_t from) const;  // the square's slot, or the empty one where it would go
  size_t probe(const int64_t* square) const { return probe(square, home(square)); }
  Slot& slot(const int64_t* square);  // the square's slot, made empty if new
  void add(const int64_t* square, const Entry& e);
  bool box_holds(const Box& b, const double* p) const;

  double half_, half_sq_;
  ClusterOptions options_;
  double lo_[3], hi_[3];
  std::vector<Slot> slots_;
  uint64_t occupied_ = 0;
  std::vector<Entry> entries_;
  std::vector<Box> boxes_;
  uint32_t max_open_;
  uint32_t next_ = 0;
  uint64_t unsettled_ = 0;
};

// The whole-scene pass in RegionClusterer's terms, the reference its decisions are checked against: for
// vertex i of `positions` (xyz, in weight order), the index of its cell's center vertex (i for a center).
std::vector<uint32_t> whole_scene_centers(std::span<const double> positions, double cell_size, ClusterOptions options);

}  // namespace lodstream::core

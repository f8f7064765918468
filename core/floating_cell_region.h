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
// whole-scene pass's cell, named by its center's tag.
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
// Records (issue 19, session 25): as in Clusterer, a square's entries are one run of records in a pool
// (power-of-two capacities, runs moved to one twice as large when full, freed runs reused by size), so
// that a query reads each of its 8 squares from one or two cache lines instead of following a list
// through entries in creation order; a crowded square's box is two records of its run (its low and high
// corner). assign_block runs the vertices through a software pipeline (squares and slots fetched for the
// vertex 16 places ahead, runs for the one 8 places ahead), as Clusterer::assign_block does.
//
// Tags: the caller names each vertex by a tag (its record in the weight index, say), strictly increasing
// in the order of the calls, and a settled cell is reported by its center's tag. The choice orders
// centers by tag, which is their weight order (ties in the nearest choice go to the lower tag, the
// heavier center).
//
// One grid of one cell size: a level with a fine grid (Mata et al.'s labels) is two such grids, each over
// the vertices its mask sends it. Memory: one record (32 bytes) per center and per unsettled vertex and
// two per crowded square, in runs at least half full, and a 32-byte slot per occupied grid square in a
// table at most half full; members keep nothing.
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
  uint32_t center = kNoCell;  // with cell_settled: the tag of the cell's center vertex
};

class RegionClusterer {
 public:
  // held: {lo x, lo y, lo z, hi x, hi y, hi z}, the box whose vertices the caller holds and will assign
  // (lo <= p < hi per axis; ±infinity where the task holds everything on that side). Floating cells only:
  // options.clustering must be floating (uniform cells need no halo: a vertex's cell is its square).
  // max_open: the unsettled entries a square keeps before they become its box (see "Crowded squares").
  RegionClusterer(double cell_size, ClusterOptions options, std::span<const double, 6> held, uint32_t max_open = 16);

  // The next held vertex in weight order (the whole-scene pass's order restricted to the box), named by
  // `tag`, greater than every tag before it (else Failure(Status::internal)).
  RegionDecision assign(uint32_t tag, std::span<const double, 3> position);
  // The same for n = tags.size() consecutive held vertices: vertex i has tag tags[i] and position
  // positions[3i .. 3i + 3), and its decision goes to decisions[i]. Exactly the decisions of n calls of
  // assign; faster, because the squares of the vertices a few places ahead are fetched meanwhile (a fetch
  // is only a hint: the decision itself reads everything again).
  void assign_block(std::span<const uint32_t> tags, std::span<const double> positions, std::span<RegionDecision> decisions);

  uint64_t unsettled() const { return unsettled_; }
  // Bytes held now (the table's capacity and the pool's resident pages), and what the next growth step
  // may briefly add (the table doubles while its old copy is held; the pool grows in place by mremap and
  // touches at most one more huge page, counted as its whole size to stay on the safe side).
  uint64_t memory_bytes() const { return slots_.capacity() * sizeof(Slot) + pool_.resident_bytes(); }
  uint64_t growth_bytes() const { return 2 * slots_.capacity() * sizeof(Slot) + pool_.resident_bytes(); }
  uint64_t crowded_squares() const { return crowded_; }

 private:
  // A record of a square's run: a settled center, an unsettled vertex, or one corner of a crowded square's
  // box. The choice is a total order on (distance, tag), so the order of a run does not matter. In the
  // first record of a free run, tag is the next free run of its size.
  struct Record {
    enum Kind : uint32_t { kSettled, kOpen, kBoxLo, kBoxHi };
    double position[3];
    uint32_t tag;
    Kind kind;
  };
  static_assert(sizeof(Record) == 32, "two records a cache line");
  // A slot of the open-addressing table of occupied squares (linear probing, at most half full): Clusterer's
  // wide slot, the square's run (its first record in the pool) and its count of records (0: an empty slot).
  using Slot = Clusterer::Slot;
  // A vertex's 2×2×2 block of squares and their hashes, computed ahead of its decision.
  struct Query {
    int64_t own[3];
    int64_t square[8][3];
    uint64_t hash[8];
  };
  static constexpr uint32_t kNone = UINT32_MAX;
  static constexpr int kRunClasses = 32;  // capacities 2^0 .. 2^31
  static constexpr size_t kQueryRing = 32, kSlotsAhead = 16, kRunsAhead = 8;

  void query(const double* p, Query& q) const;
  const Slot* find(const int64_t* square, uint64_t hash) const;  // nullptr if absent
  void prefetch_runs(const Query& q) const;
  RegionDecision decide(uint32_t tag, const double* p, const Query& q);
  Slot& slot(const int64_t* square, uint64_t hash);  // the square's slot, inserted (count 0) if absent
  void add(const int64_t* square, uint64_t hash, const Record& r);
  uint32_t take_run(uint32_t capacity);  // a free run of that capacity (a power of two)
  void free_run(uint32_t run, uint32_t count);
  Record* pool() const { return reinterpret_cast<Record*>(pool_.data()); }
  bool exposed(const double* p) const;
  bool box_holds(const double* lo, const double* hi, const double* p) const;

  double half_, half_sq_;
  ClusterOptions options_;
  double lo_[3], hi_[3];
  std::vector<Slot, HugePageAllocator<Slot>> slots_;  // huge pages: a probe costs a cache miss, not also a page walk
  uint64_t occupied_ = 0;
  GrowableBuffer pool_;
  uint32_t records_ = 0;
  uint32_t free_[kRunClasses];
  uint32_t max_open_;
  uint64_t last_tag_ = 0;  // one past the last tag
  uint64_t unsettled_ = 0, crowded_ = 0;
  std::vector<Query> ring_;
  std::vector<Record> scratch_;  // a crowded square's new run
};

// The whole-scene pass in RegionClusterer's terms, the reference its decisions are checked against: for
// vertex i of `positions` (xyz, in weight order), the index of its cell's center vertex (i for a center).
std::vector<uint32_t> whole_scene_centers(std::span<const double> positions, double cell_size, ClusterOptions options);

}  // namespace lodstream::core

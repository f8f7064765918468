// Vertex clustering, pipeline stage 4: one pass over the vertices in weight order assigns every vertex to a
// cell in every level at once.
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.2 and §4:
//   floating cells — visit vertices in non-increasing weight; a vertex inside no existing cell becomes the
//   center of a new cell (a cube of side c, or a ball); a later vertex inside one or more cells joins one of
//   them: the heaviest center (the original method) or the nearest center (the §3.2.3 variant, which keeps
//   the thin triangle of their Figure 4 thin). Cells are found through a uniform grid of squares of side c.
// Rossignac & Borrel, "Multi-resolution 3D approximations for rendering complex scenes", 1993 (Low & Tan's
// reference [13]), kept as the baseline:
//   uniform subdivision — a vertex's cell is the grid square of side c holding it. Unlike the paper, the
//   grid is anchored at the origin, not at the bounding box, so adding a distant object changes nothing.
//
// Units: positions and cell sizes in scene units, double precision. Cell ids are per level, 0, 1, 2, ... in
// order of creation; since the vertex order is fixed (non-increasing grade, ties by vertex id), so are the
// ids, whatever the chunking, the thread count or the memory budget of the caller.
//
// Definitions (every comparison is exact unless stated; "d" is the vertex minus the center):
// - Grid square of a coordinate x for size c: floor(x / c) as int64, evaluated exactly (the rounded
//   quotient is corrected when it lands on an integer), so a square is the half-open [k·c, (k+1)·c) of the
//   real line: a point exactly on a square boundary belongs to the square above it, at negative
//   coordinates too.
// - Cube cell: closed. Inside when max(|dx|, |dy|, |dz|) <= c/2, with |d| <= c/2 decided on the exact
//   difference (a point exactly c/2 away on an axis is inside).
// - Sphere cell: the closed ball of diameter c (radius c/2), so it fits in the cube cell of the same c.
//   Inside when the cube test holds and fl(dx² + dy² + dz²) <= fl((c/2)²): the surface is decided up to
//   rounding of the sum of squares (exact for exactly representable sums, e.g. a 3-4-5 triangle).
// - Nearest: the containing cell with the smallest fl(dx² + dy² + dz²), ties by lowest id. Heaviest: the
//   containing cell with the lowest id (its center came first in weight order).
//
// Invariants (where they hold: Clusterer::assign in floating_cell.cpp):
// - A cell's center lies in no earlier cell, so any two cube centers are more than c/2 apart on some axis,
//   and any two sphere centers more than c/2 apart. Hence a vertex's candidate cells are attached to the
//   2×2×2 block of squares nearest it (its own square and, per axis, the neighbour on the side of the half
//   it lies in).
// - At most kMaxCubeCellsPerSquare = 8 cube cells attach to one square (split the square into 8 half-open
//   sub-cubes of side c/2: two centers in one would be within c/2 on every axis). For spheres the bound is
//   larger: at least 14 fit (8 near the corners and 6 near the face centers; the tests build it) and at
//   most kMaxSphereCellsPerSquare = 48 (split the square into 3×4×4 boxes of c/3 × c/4 × c/4, whose
//   diagonal √(1/9 + 1/16 + 1/16)·c ≈ 0.486·c is below c/2). A square stores its cells together, as one run
//   of records in a per-level pool whose capacity is the power of two at or above its count (a full run
//   moves to one twice as large; freed runs are reused by size), so no fixed per-square capacity is
//   reserved; assign checks the bound and throws
//   Failure(Status::internal) if it is ever exceeded (a bug, never bad input).
// - Memory grows with the number of cells, not of vertices, and a cell keeps only what later queries read:
//   its center and its id. Per level (floating): one pool record per cell (16 bytes with float_positions,
//   else 32; runs are at least half full and freed runs are reused; the pool grows in place, by mremap,
//   so a growth step never holds two copies) and one hash-table slot per occupied square (16 bytes packed,
//   32 wide), in 64 sub-tables by the hash's top bits, each at most 2/3 full, so that a growth step
//   rehashes 1/64 of the table at a time — or, for a coarse level given bounds, a dense array of 8 bytes per
//   square of the bounds (at most kMaxDenseSquares). Uniform cells need no record: the square's slot holds
//   the id. The center vertex and position of a cell are not kept: they are the vertex that created it,
//   which the caller sees (its cell id equals cell_count() before the call). Nothing per vertex is kept.
//
// Cells of two sizes in one level (Mata et al., GRAPP 2006, §3.4: a smaller error allowed near the
// outline; core/silhouette_labels.h gives the labels): a level may have a fine grid of size f < c beside
// its own. The caller says, per vertex and level, which grid the vertex uses (a bit of its fine mask), and
// the vertex is assigned exactly as above but within that grid only: it joins or starts a cell of that
// grid, and never sees the other grid's cells. Both grids number their cells from the level's one counter.
// Invariants with fine grids (the proofs above hold grid by grid, since each grid sees only its vertices,
// in weight order, and one size):
// - No lost vertex: every vertex gets one cell id per level, below cell_count(level) — the id of a cell
//   of the grid it was sent to, which exists in that grid only.
// - Deterministic ids: a level's ids are 0, 1, 2, ... in order of creation over both grids; creation
//   depends on the vertex order, the positions and the masks only.
// - Per-square bound: a square of either grid holds at most kMaxCubeCellsPerSquare (cubes) or
//   kMaxSphereCellsPerSquare (spheres) cells, since every center of a grid lies in no earlier cell of
//   that grid; cells of the two grids may overlap, and are never in one square's run together.
// - Memory: a cell is a record of one grid only, so the bytes per cell do not change; a fine grid adds its
//   own index (table or dense array), chosen like a level's.
//
// Limits (Failure(Status::usage) from the constructor or assign, as the stream stage should have checked
// them against the scene's bounding box first): cell sizes finite, in [kMinCellSize, kMaxCellSize] and
// strictly increasing; every coordinate within kMaxSquaresPerAxis · c/2 of the origin for every level c
// (about 5.6e14 half-squares: a 1 km scene at 1 nm cells). NaN and infinities fail the same check.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace lodstream::core {

enum class Clustering {
  floating,  // Low & Tan §3.2: cells centred on the heaviest vertices
  uniform,   // Rossignac & Borrel: the grid square of side c, grid anchored at the origin
};

enum class CellShape {
  cube,    // axis-aligned cube of side c centred on the center vertex
  sphere,  // ball of diameter c centred on the center vertex
};

enum class CellChoice {
  nearest,   // Low & Tan §3.2.3: the cell whose center is nearest (ties: lowest id); the default
  heaviest,  // Low & Tan §3.2 original: the cell whose center came first (lowest id)
};

struct ClusterOptions {
  Clustering clustering = Clustering::floating;
  CellShape shape = CellShape::cube;       // floating only
  CellChoice choice = CellChoice::nearest;  // floating only
  // Every position assigned is exactly a float (the caller's guarantee, e.g. a single-precision store;
  // checked when a cell is created: Failure(Status::internal) otherwise). Cell centers are then kept as
  // floats, 16 bytes a record instead of 32; every comparison sees the same values, so the ids are the same.
  bool float_positions = false;
};

inline constexpr uint32_t kNoCell = UINT32_MAX;
inline constexpr uint32_t kMaxCubeCellsPerSquare = 8;
inline constexpr uint32_t kMaxSphereCellsPerSquare = 48;
// Coordinates satisfy |x| < kMaxSquaresPerAxis · (c/2): below 2^53, so that every half-square index and
// its neighbours are exact in a double, with room to spare.
inline constexpr double kMaxSquaresPerAxis = 0x1p49;
// Cell sizes keep c/2 and (c/2)² normal and 3 · (c/2)² finite.
inline constexpr double kMinCellSize = 0x1p-480;
inline constexpr double kMaxCellSize = 0x1p480;

[[noreturn]] void coordinate_out_of_range(double x, double size);  // Failure(Status::usage)

// floor(x / h) exactly, for |x / h| < kMaxSquaresPerAxis, h = size / 2 (else coordinate_out_of_range):
// the half-square of x, inline for the clusterers' queries. The rounded quotient can only be wrong when
// the exact one lies just below an integer and rounds onto it (a non-integer rounded quotient has the
// same floor, since integers of this size are doubles); then x − q·h, evaluated with one rounding by fma,
// is negative, and its sign is exact. The fma is a library call on targets without the instruction, but
// it runs only for quotients that are exact integers (points on a half-square boundary).
inline int64_t half_index(double x, double h, double size) {
  const double r = x / h;
  if (!(std::fabs(r) < kMaxSquaresPerAxis)) coordinate_out_of_range(x, size);
  double q = std::floor(r);
  if (q == r && std::fma(-q, h, x) < 0) q -= 1;
  return static_cast<int64_t>(q);
}

// floor(x / size) as int64, exact (see "Grid square" above). Same limits as the Clusterer: size within
// [kMinCellSize, kMaxCellSize] and |x| < kMaxSquaresPerAxis · size / 2; otherwise throws
// Failure(Status::usage).
int64_t grid_square(double x, double size);

// The exact inside test of a floating cell (the definitions above) of half size `half` = c/2 and
// `half_sq` = fl((c/2)²) centred on `center`, as Clusterer decides it; d2 receives fl(dx² + dy² + dz²),
// the key of the nearest choice. For callers that must reach the same decisions as a Clusterer
// (core/floating_cell_region.h).
// |x − cx| <= h on the exact difference, given d = fl(x − cx). Rounding is monotone and h is a double, so
// |d| < h and |d| > h already decide; only |d| == h needs the rounding error, which TwoSum gives exactly.
// This matters beyond the boundary points themselves: the 2×2×2 query relies on every accepted center
// being truly within h per axis.
inline bool exactly_within(double x, double cx, double d, double h) {
  const double a = std::fabs(d);
  if (a != h) return a < h;
  const double b = -cx;
  const double bv = d - x;
  const double err = (x - (d - bv)) + (b - bv);  // exact: (x − cx) − d
  return d > 0 ? err <= 0 : err >= 0;
}

// Inline: every query of every pass runs it on each candidate.
inline bool floating_cell_contains(const double* p, const double* center, double half, double half_sq, CellShape shape,
                                   double& d2) {
  const double dx = p[0] - center[0], dy = p[1] - center[1], dz = p[2] - center[2];
  d2 = dx * dx + dy * dy + dz * dz;
  const double m = std::max(std::max(std::fabs(dx), std::fabs(dy)), std::fabs(dz));
  if (m > half) return false;
  if (m == half && !(exactly_within(p[0], center[0], dx, half) && exactly_within(p[1], center[1], dy, half) &&
                     exactly_within(p[2], center[2], dz, half)))
    return false;
  return shape != CellShape::sphere || d2 <= half_sq;
}

// The branch-free candidate test of the clusterers' fast scans (Clusterer's in floating_cell.cpp, the region
// clusterer's in floating_cell_region.cpp): whether p lies inside the cell centred on c, judged on the
// rounded differences, which is exact unless some |d| rounds onto h itself (then `on_h` is set, and the
// caller redoes its scan with floating_cell_contains); `key` receives the choice's key, fl(d²) for the
// nearest choice and 0 for the heaviest.
template <bool kNearest, bool kSphere>
inline bool fast_inside(const double* p, double cx, double cy, double cz, double h, double half_sq, bool& on_h,
                        double& key) {
  const double dx = p[0] - cx, dy = p[1] - cy, dz = p[2] - cz;
  const double m = std::max(std::max(std::fabs(dx), std::fabs(dy)), std::fabs(dz));
  const double d2 = dx * dx + dy * dy + dz * dz;
  on_h |= m == h;
  bool inside = m < h;
  if constexpr (kSphere) inside &= d2 <= half_sq;
  key = kNearest ? d2 : 0.0;
  return inside;
}

// One clustering pass, all levels at once. Not thread-safe (one pass is inherently sequential: each
// vertex's cell depends on every heavier vertex). Levels are independent, though: a Clusterer per level
// (one cell size each), run on separate threads over the same vertex order, gives the same ids.
// Allocator for the per-level arrays, which are read at random: large blocks are 2 MiB aligned and marked
// for transparent huge pages (where the OS offers them: madvise), so that a random probe into a table of
// tens of MiB costs a cache miss but not also a page walk. Small blocks come from operator new as usual.
template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) {}
  T* allocate(size_t n);
  void deallocate(T* p, size_t n);
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const { return true; }
};

// A byte buffer that grows without a copy: anonymous memory enlarged by mremap (Linux; elsewhere realloc),
// marked for transparent huge pages like HugePageAllocator's blocks. Only the pages written are resident,
// and a growth step never holds the old and the new block at once. New bytes are zero.
class GrowableBuffer {
 public:
  GrowableBuffer() = default;
  GrowableBuffer(GrowableBuffer&& o) noexcept;
  GrowableBuffer& operator=(GrowableBuffer&& o) noexcept;
  GrowableBuffer(const GrowableBuffer&) = delete;
  GrowableBuffer& operator=(const GrowableBuffer&) = delete;
  ~GrowableBuffer();
  std::byte* data() const { return data_; }
  size_t size() const { return size_; }
  void resize(size_t bytes);  // larger only; capacity doubles (address space, not memory)
  uint64_t resident_bytes() const;  // the bytes in use, rounded up to whole (huge) pages

 private:
  std::byte* data_ = nullptr;
  size_t size_ = 0, capacity_ = 0;
};

class Clusterer {
 public:
  // cell_sizes: c_0 < c_1 < ..., one level each, at least one. Copied.
  // bounds: empty, or {min x, min y, min z, max x, max y, max z} of every position that will be assigned.
  // With bounds, a level whose grid over them has at most kMaxDenseSquares squares indexes its squares
  // directly (a dense array) instead of hashing them: the coarse levels, which meet every vertex but hold
  // few cells, then skip the hash and the probes. A finer level within 2^21 squares per axis keys its hash
  // table by one packed word (16-byte slots instead of 32). The ids are the same either way; a position
  // outside the bounds is then a caller bug: Failure(Status::internal). max_dense_squares (at most
  // kMaxDenseSquares) lowers the dense arrays' limit, for a caller whose memory is tight: a dense array
  // takes 8 bytes per square of the bounds, occupied or not, a hashed level 16 or 32 per occupied square.
  // fine_sizes: empty, or one value per level: 0 (no fine grid) or the fine grid's cell size, in
  // [kMinCellSize, cell_sizes[l]) (else Failure(Status::usage)); the fine grids need at most
  // kMaxFineLevels levels, one bit each in a fine mask.
  Clusterer(std::span<const double> cell_sizes, ClusterOptions options = {}, std::span<const double> bounds = {},
            uint64_t max_dense_squares = kMaxDenseSquares, std::span<const double> fine_sizes = {});
  static constexpr uint64_t kMaxDenseSquares = uint64_t{1} << 21;  // 16 MiB of squares at 8 bytes
  static constexpr size_t kMaxFineLevels = 32;

  // Assigns the next vertex in weight order (non-increasing grade, ties by vertex id: the caller's
  // guarantee; the clusterer cannot check it) at `position` (xyz) in every level, and writes its cell id in
  // level l to cells[l]. cells.size() must equal levels() (else Failure(Status::internal)). A vertex that
  // starts a cell becomes its center vertex. Cost per level: O(1) hash probes (8 for floating cells, 1 for
  // uniform) and the cells attached to the probed squares (at most 64 cubes; about 10 in a dense random cloud).
  // Allocates only when a level's pool, index or hash table grows (doubling).
  // fine_mask: bit l set sends the vertex to level l's fine grid (ignored for a level without one).
  void assign(uint32_t vertex_id, std::span<const double, 3> position, std::span<uint32_t> cells, uint32_t fine_mask = 0);

  // The same for n = ids.size() consecutive vertices in weight order: vertex i has id ids[i] and position
  // positions[3i .. 3i + 3), and its cell in level l is written to cells[l · n + i] (level-major, so that
  // cells.size() must be levels() · n; else Failure(Status::internal)). Exactly the ids that n calls of
  // assign would give; faster, because the table slots and cell runs of the vertices a few places ahead
  // are fetched while the current one is assigned (a later vertex's squares do not depend on earlier
  // vertices, and a fetch is only a hint, so a stale one costs time, never a wrong answer).
  // fine_masks: empty (every vertex in the levels' own grids) or vertex i's fine mask at fine_masks[i].
  void assign_block(std::span<const uint32_t> ids, std::span<const double> positions, std::span<uint32_t> cells,
                    std::span<const uint32_t> fine_masks = {});

  size_t levels() const { return external_; }
  double cell_size(size_t level) const { return levels_[level].size; }
  double fine_cell_size(size_t level) const;  // 0 when the level has no fine grid
  const ClusterOptions& options() const { return options_; }
  // Cells so far. A vertex whose cell id in a level equals that level's count before its assignment
  // created the cell (floating: it is the center; uniform: the first, i.e. heaviest, vertex in the square).
  uint32_t cell_count(size_t level) const { return levels_[level].cells; }
  // Most cells attached to one grid square so far in a level (uniform: 1 once a vertex was assigned).
  // With a fine grid: the larger of the two grids' figures.
  uint32_t max_cells_per_square(size_t level) const;
  // Bytes held now (the hash tables' and dense arrays' capacity, the pools' resident pages, the object),
  // for the stream stage's budget; a growth step briefly holds more (growth_bytes).
  uint64_t memory_bytes() const;
  // What the next growth step may briefly add to memory_bytes(): a hash sub-table doubles while its old
  // copy is still held (twice the largest sub-table), and a pool touches one more huge page per level.
  uint64_t growth_bytes() const;

  // Exposed for tests and the documentation above. A square's cells are stored together, as one run of
  // records in a per-level pool, so that the candidate test reads them from one or two cache lines instead
  // of following a list through records in creation order. In the first record of a free run, id is the
  // next free run of its size.
  struct FloatCell {  // float_positions: 16 bytes
    float position[3];
    uint32_t id;
  };
  struct DoubleCell {  // 32 bytes
    double position[3];
    uint32_t id;
    uint32_t unused;
  };
  struct Slot {
    int64_t square[3];
    uint32_t run;    // index in the pool of the square's first cell
    uint32_t count;  // cells attached (the first `count` records of the run); 0 marks an empty slot
  };
  struct PackedSlot {  // a Slot whose square is packed into one word (Clusterer::pack)
    uint64_t key;
    uint32_t run;
    uint32_t count;
  };
  // A hash table split into 2^kSubTableBits sub-tables by the top bits of the hash; each has a power-of-two
  // size, linear probing on the hash's low bits, and is at most 2/3 full.
  static constexpr int kSubTableBits = 6;
  template <class S>
  struct Table {
    std::vector<std::vector<S, HugePageAllocator<S>>> sub;
    std::vector<uint64_t> used;  // occupied slots per sub-table
  };
  struct DenseSquare {  // a square of a dense level: the fields of Slot without the key
    uint32_t run;
    uint32_t count;
  };
  // One level's 2×2×2 query block for a vertex (floating only): computed ahead of the assignment (for
  // every level, and in assign_block for vertices a few places ahead) so that the hash slots and runs are
  // fetched before any is read, and their cache misses overlap instead of following one another.
  struct Query {
    int64_t own[3];       // p's square
    int64_t square[8][3]; // the block: bit a of the index selects the neighbour along axis a
    uint64_t slot[8];     // each square's hash (its sub-table and slot are taken when read, so a table
                          // that grew since the query was made is still read right); dense: its index
    uint64_t key[8];      // packed levels: each square's packed key
    uint32_t run[8];      // each square's run in the pool
    uint32_t count[8];    // and its cell count (0: square absent)
  };

 private:
  // Runs have power-of-two capacities 2^k, k < kRunClasses (64 >= kMaxSphereCellsPerSquare); a run that
  // fills moves to one twice as large and its old place joins the free list of its size.
  static constexpr int kRunClasses = 7;
  struct Level {
    double size = 0;
    double half = 0;     // c/2, exact
    double half_sq = 0;  // fl((c/2)²)
    GrowableBuffer pool;  // floating: FloatCell or DoubleCell records, runs, one per occupied square, and free runs
    uint32_t records = 0;  // records in pool
    uint32_t cells = 0;
    uint32_t* next_id = nullptr;  // the counter ids are drawn from: its own `cells`, or its level's for a fine grid
    // The squares' index, one of three kinds: a dense array (dense non-empty), a hash table of packed
    // slots (packed.sub non-empty), or of wide slots (table.sub non-empty).
    Table<Slot> table;
    Table<PackedSlot> packed;
    uint32_t max_per_square = 0;
    uint32_t free_run[kRunClasses] = {kNoCell, kNoCell, kNoCell, kNoCell, kNoCell, kNoCell, kNoCell};
    // Levels with bounds: squares first[a] .. first[a] + dims[a] − 1 per axis, which is the bounds'
    // squares with one more on each side (a query block reaches one square past the vertex's). A dense
    // level stores them x fastest; a packed level keys them by (x − first) | (y − first) << 21 |
    // (z − first) << 42, which needs dims below 2^21 per axis.
    std::vector<DenseSquare, HugePageAllocator<DenseSquare>> dense;
    int64_t first[3] = {0, 0, 0};
    int64_t dims[3] = {0, 0, 0};
  };

  void query_floating(const Level& level, const double* p, Query& q) const;
  void find_runs(const Level& level, Query& q) const;
  void prefetch_runs(const Level& level, const Query& q) const;
  void prefetch_uniform(const Level& level, const double* p) const;
  uint32_t assign_floating(Level& level, const double* p, const Query& q);
  uint32_t assign_uniform(Level& level, const double* p);
  template <class C>
  static uint32_t add_cell(Level& level, uint32_t& run, uint32_t& count, const double* p);
  static uint64_t dense_index(const Level& level, const int64_t square[3]);
  static uint64_t pack(const Level& level, const int64_t square[3]);
  static void square_fields(Level& level, const int64_t square[3], uint32_t*& run, uint32_t*& count);
  uint32_t start_cell(Level& level, const double* p, const int64_t square[3]);
  size_t cell_bytes() const { return options_.float_positions ? sizeof(FloatCell) : sizeof(DoubleCell); }

  // The grid of level l that a vertex with this fine mask uses.
  Level& grid(size_t l, uint32_t fine_mask) {
    return fine_of_[l] != kNoCell && (fine_mask >> l & 1) ? levels_[fine_of_[l]] : levels_[l];
  }

  ClusterOptions options_;
  std::vector<Level> levels_;  // the levels' own grids (external_ of them), then the fine grids
  size_t external_ = 0;
  std::vector<uint32_t> fine_of_;  // per level: its fine grid's index in levels_, or kNoCell
  // Scratch for assign (one per level) and assign_block (kQueryRing per level, level-major), sized once.
  static constexpr size_t kQueryRing = 32;
  std::vector<Query> queries_;
  std::vector<Query> ring_;
};

}  // namespace lodstream::core

// Stage 5: emit a group of levels in one pass over the input. See emit_stage.h for the rules.
#include "stream/emit_stage.h"

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>
#include <tbb/task_arena.h>

#include "core/normals.h"
#include "core/quadric.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_stage.h"
#include "stream/emit_regions.h"
#include "stream/external_sort.h"
#include "stream/flat_map.h"
#include "stream/position_gather.h"
#include "stream/store_access.h"
#include "stream/task_file.h"
#include "stream/vertex_cells.h"
#include "stream/weld_file.h"

namespace lodstream::stream {

namespace {

// Fixed block size: sums are formed per block and merged in block order, so it must not depend on the
// memory plan or the thread count.
constexpr uint64_t kEmitBlock = 1 << 16;

struct EdgeSums {
  double a[3] = {0, 0, 0}, b[3] = {0, 0, 0};  // corner positions in the edge's lower cell (a), higher (b)
  uint64_t na = 0, nb = 0;
};
struct Distances {
  double a = 0, b = 0;
};

struct Block {
  int kind = 0;  // 0 triangles, 1 segments, 2 points
  uint64_t first = 0, count = 0;
};

// One bit per input triangle (kind 0) or segment (kind 1) of a level that collapsed to an edge or a point,
// so that passes B and C visit only those. Held for the blocks of kEmitBlock primitives the group visits, a
// block's words found through an offset a block (UINT32_MAX: not visited, none of its bits set), so that a
// task holds a bit a primitive of its share of the input, not of the whole input.
struct CollapsedBits {
  static constexpr uint64_t kBlockWords = kEmitBlock / 64;
  std::vector<uint32_t> first_word;  // per block of the kind: its first word in `words`, or UINT32_MAX
  std::vector<uint64_t> words;
  // Words for the blocks of kind `kind` among `visited` (of a column of `count` primitives), all zero.
  void assign(uint64_t count, const std::vector<Block>& visited, int kind) {
    first_word.assign((count + kEmitBlock - 1) / kEmitBlock, UINT32_MAX);
    uint64_t n = 0;
    for (const Block& b : visited) {
      if (b.kind != kind || b.count == 0) continue;
      for (uint64_t i = b.first / kEmitBlock; i <= (b.first + b.count - 1) / kEmitBlock; ++i)
        if (first_word[i] == UINT32_MAX) first_word[i] = static_cast<uint32_t>(n), n += kBlockWords;
    }
    if (n > UINT32_MAX) fail(Status::internal, "emit: more than 2^32 words of collapsed bits");
    words.assign(n, 0);
  }
  // Where the word of primitives [64 w, 64 w + 64) is in `words`, or kNotHeld when their block is not
  // visited. A block's words are consecutive.
  static constexpr uint64_t kNotHeld = UINT64_MAX;
  uint64_t at(uint64_t w) const {
    const uint32_t f = w / kBlockWords < first_word.size() ? first_word[w / kBlockWords] : UINT32_MAX;
    return f == UINT32_MAX ? kNotHeld : f + w % kBlockWords;
  }
  uint64_t* word(uint64_t w) {
    const uint64_t i = at(w);
    return i == kNotHeld ? nullptr : &words[i];
  }
  const uint64_t* word(uint64_t w) const {
    const uint64_t i = at(w);
    return i == kNotHeld ? nullptr : &words[i];
  }
  // Where block b's words are (a visited block: within one block of kEmitBlock primitives, at a multiple
  // of 64).
  uint64_t block_at(const Block& b) const {
    const uint64_t i = at(b.first / 64);
    if (i == kNotHeld) fail(Status::internal, "emit: a block's collapsed bits are not held");
    return i;
  }
};

struct BlockOut {
  std::vector<std::array<uint32_t, 3>> triangles;  // input winding
  std::vector<std::array<uint32_t, 2>> edges;      // lower cell first
  std::vector<uint32_t> points;
  // With materials: per triangle, edge and point above, the material of the input primitive that made it.
  std::vector<uint32_t> triangle_materials, edge_materials, point_materials;
  std::vector<uint32_t> quadric_cells;
  std::vector<core::Quadric> quadrics;
  // A unit of pass A only (EmitOptions::classify_unit): per edge and point above, which of the block's
  // sixteen sub-blocks of kBoundsBlock primitives hold a triangle or segment that collapsed to it (bit k:
  // sub-block k), so that the task reading the unit visits in pass B only the sub-blocks that hold one
  // that collapsed to a kept edge or point.
  std::vector<uint16_t> edge_masks, point_masks;
  // Pass B: the block's distinct corners of kept edges (and points), as corner_key()s.
  std::vector<uint64_t> corners;
  void clear() {
    triangles.clear(), edges.clear(), points.clear(), edge_masks.clear(), point_masks.clear();
    triangle_materials.clear(), edge_materials.clear(), point_materials.clear();
    quadric_cells.clear(), quadrics.clear(), corners.clear();
  }
};

struct Scratch {
  FlatMap<3, false> triangles;
  FlatMap<2> edges;
  FlatMap<1> points;  // a point's index in BlockOut::points
  FlatMap<1> cells;  // pass A: a cell's quadric slot
  FlatMap<2, false> corners;  // pass B: {kept edge, canonical vertex} pairs seen in the block
  // Pass A: the last point and the last quadric cell of the block. Neighbouring triangles mostly fall in
  // the same cell at coarse levels; these skip the hash table then (same result: the cell is in it).
  uint32_t last_point = UINT32_MAX, last_point_index = 0, last_cell = UINT32_MAX, last_slot = 0;
  void clear() {
    triangles.clear(), edges.clear(), points.clear(), cells.clear(), corners.clear();
    last_point = last_cell = UINT32_MAX;
  }
};

// The whole input's blocks (emit_block_count): kind by kind, each in store order.
std::vector<Block> whole_blocks(const uint64_t* column_count) {
  std::vector<Block> blocks;
  for (int kind = 0; kind < 3; ++kind)
    for (uint64_t first = 0; first < column_count[kind]; first += kEmitBlock)
      blocks.push_back({kind, first, std::min(kEmitBlock, column_count[kind] - first)});
  return blocks;
}

// A unit's file of one level's pass A outputs (EmitOptions::classify_unit; written and read as the other
// files the processes of a sharded run hand one another, stream/task_file.h): the magic, then per block its
// kind, first primitive and count, its BlockOut's triangles, edges, points (each with its materials when
// the store has them, and the edges' and points' sub-block masks) and quadric sums, and the level's
// collapsed bits of its primitives (whole words: a block starts at a multiple of 64); then an end header
// {kEndOfBlocks, the count of blocks, 0}.
constexpr char kClassifiedMagic[8] = {'L', 'O', 'D', 'C', 'L', 'S', 'A', '3'};
constexpr uint64_t kEndOfBlocks = UINT64_MAX;

// A block's header and outputs, as ClassifiedReader reads them.
void write_block_out(io::FileWriter& f, const Block& b, const BlockOut& o, const CollapsedBits* collapsed) {
  put(f, static_cast<uint64_t>(b.kind)), put(f, b.first), put(f, b.count);
  put_array(f, o.triangles), put_array(f, o.triangle_materials);
  put_array(f, o.edges), put_array(f, o.edge_materials), put_array(f, o.edge_masks);
  put_array(f, o.points), put_array(f, o.point_materials), put_array(f, o.point_masks);
  put_array(f, o.quadric_cells), put_array(f, o.quadrics);
  if (b.kind < 2) f.write(collapsed[b.kind].words.data() + collapsed[b.kind].block_at(b), (b.count + 63) / 64 * sizeof(uint64_t));
}

// Reads a unit's file block by block; Failure(io_error) naming the file where it is missing, of another
// version, cut short or damaged.
class ClassifiedReader : TaskFileReader {
 public:
  explicit ClassifiedReader(const std::string& path) : TaskFileReader(path, kClassifiedMagic, "a unit of pass A") {}
  // The next block's header; false at the end header (its count of blocks checked).
  bool next(Block& b, uint64_t blocks_so_far) {
    uint64_t head[3];
    read(head, sizeof head);
    if (head[0] == kEndOfBlocks) {
      if (head[1] != blocks_so_far) fail(Status::io_error, path_ + ": its count of blocks does not match");
      return false;
    }
    b = {static_cast<int>(head[0]), head[1], head[2]};
    return true;
  }
  // A block's outputs (after its header) into `o`, its collapsed bits into `collapsed` (per kind, the
  // level's words of every primitive; none: passed over).
  void block_out(const Block& b, BlockOut& o, CollapsedBits* collapsed) {
    values(o.triangles), values(o.triangle_materials);
    values(o.edges), values(o.edge_materials), values(o.edge_masks);
    values(o.points), values(o.point_materials), values(o.point_masks);
    values(o.quadric_cells), values(o.quadrics);
    if (b.kind == 2) return;
    const uint64_t bytes = (b.count + 63) / 64 * sizeof(uint64_t);
    if (collapsed) read(collapsed[b.kind].words.data() + collapsed[b.kind].block_at(b), bytes);
    else if (std::fseek(f_, static_cast<long>(bytes), SEEK_CUR) != 0) fail(Status::io_error, path_ + ": " + what_ + " is cut short");
  }

 private:
  // A block holds at most three cells' quadrics a primitive, and fewer outputs of each kind than primitives.
  template <class T>
  void values(std::vector<T>& v) {
    uint64_t n;
    read(&n, sizeof n);
    if (n > 3 * kEmitBlock) fail(Status::io_error, path_ + ": " + what_ + " is damaged");
    v.resize(n);
    read(v.data(), n * sizeof(T));
  }
};

void add(double* sum, const double* p) {
  sum[0] += p[0], sum[1] += p[1], sum[2] += p[2];
}

double distance_to_line(const double* x, const double* a, const double* b) {
  const double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double v[3] = {x[0] - a[0], x[1] - a[1], x[2] - a[2]};
  const double len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  if (!(len2 > 0)) return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const double c[3] = {v[1] * d[2] - v[2] * d[1], v[2] * d[0] - v[0] * d[2], v[0] * d[1] - v[1] * d[0]};
  return std::sqrt((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) / len2);
}

// The material of each primitive of a kind, from the store's object runs (stream/scene_store.h): a cursor
// that moves forward through the runs as a block's primitives are visited in order. Every kept triangle,
// edge and point takes the material of the input primitive it was first made from, in store order (the one
// whose cells the dedupe kept), so the rule is deterministic and needs no vote.
class MaterialCursor {
 public:
  MaterialCursor(std::span<const ObjectRun> runs, uint64_t first) : runs_(runs) {
    at_ = static_cast<size_t>(std::upper_bound(runs.begin(), runs.end(), first,
                                               [](uint64_t p, const ObjectRun& r) { return p < r.first; }) -
                              runs.begin());
    at_ = at_ > 0 ? at_ - 1 : 0;
  }
  uint32_t operator()(uint64_t primitive) {
    while (at_ + 1 < runs_.size() && runs_[at_ + 1].first <= primitive) ++at_;
    return runs_.empty() ? 0 : runs_[at_].material;
  }

 private:
  std::span<const ObjectRun> runs_;
  size_t at_ = 0;
};

// Vertex colours of the cells (stores with colours only), weighted the way the representative is: center
// takes its center vertex's colour (the cell's first vertex in weight order), mean the grade-weighted mean
// of its vertices' colours (the plain mean when every grade is 0), quadric the plain mean. Sums are formed
// serially in weight order, so they do not depend on the threads.
// The integer sums are exact (a cell has fewer than 2^32 vertices); the grade-weighted sums, for the mean
// representative only, are kept apart (CellWeighted) so that the other representatives hold 40 bytes a cell.
struct CellColor {
  uint64_t sum[4] = {0, 0, 0, 0};
  uint32_t count = 0;
  uint8_t first[4] = {0, 0, 0, 0};
};
struct CellWeighted {
  double weighted[4] = {0, 0, 0, 0}, weight = 0;
};

uint8_t color_byte(double v) { return v <= 0 ? 0 : v >= 255 ? 255 : static_cast<uint8_t>(std::lround(v)); }

void cell_rgba(const CellColor& c, const CellWeighted* w, Representative r, uint8_t* out) {
  for (int k = 0; k < 4; ++k) {
    if (r == Representative::center) out[k] = c.first[k];
    else if (r == Representative::mean && w && w->weight > 0) out[k] = color_byte(w->weighted[k] / w->weight);
    else out[k] = color_byte(c.count > 0 ? static_cast<double>(c.sum[k]) / c.count : 255);
  }
}

// A level's cell colours: a bit per cell for those an output vertex of the level (or of the batch) can use,
// with its rank, and RGBA per such cell, by rank.
struct LevelColors {
  RankedBits cells;
  std::vector<uint8_t> rgba;
  const uint8_t* of(uint32_t cell) const { return &rgba[4 * uint64_t{cells.rank(cell)}]; }
};

// The group's cluster maps, packed: per stored vertex one record of `bits` bits (at most 64), at bit
// v * bits of a plain word array, holding each level's cell in its own field. A field of b bits holds the
// cells 0 .. 2^b - 2 and all ones for "no cell", so a level of C cells needs bit_width(C) bits. Packing
// several levels into one record lets one pass over the triangles serve them all (one record fetch per
// corner instead of one map per level), and packing to the bit keeps a lone level at 22 bits per vertex
// on a 2.5M-cell level instead of 32.
class PackedMap {
 public:
  // Every record all ones: no vertex has a cell yet.
  void reset(std::vector<uint64_t>& words, uint64_t vertices, unsigned bits) {
    words_ = &words, bits_ = bits;
    mask_ = bits == 64 ? ~uint64_t{0} : (uint64_t{1} << bits) - 1;
    const uint64_t n = (vertices * bits + 63) / 64 + 1;  // + 1: get() may read one word past
    // A larger map than the previous group's: free that one first, so that the two are never held
    // together (the memory model counts one map).
    if (words.capacity() < n) std::vector<uint64_t>().swap(words);
    words.assign(n, ~uint64_t{0});
  }
  // The map `words` already holds, at `bits` bits a record.
  void attach(std::vector<uint64_t>& words, unsigned bits) {
    words_ = &words, bits_ = bits;
    mask_ = bits == 64 ? ~uint64_t{0} : (uint64_t{1} << bits) - 1;
  }
  uint64_t get(uint64_t v) const {
    const uint64_t bit = v * bits_, s = bit % 64;
    const uint64_t* w = words_->data() + bit / 64;
    uint64_t x = w[0] >> s;
    if (s + bits_ > 64) x |= w[1] << (64 - s);
    return x & mask_;
  }
  void set(uint64_t v, uint64_t record) {
    const uint64_t bit = v * bits_, s = bit % 64;
    uint64_t* w = words_->data() + bit / 64;
    w[0] = (w[0] & ~(mask_ << s)) | (record << s);
    if (s + bits_ > 64) w[1] = (w[1] & ~(mask_ >> (64 - s))) | (record >> (64 - s));
  }

 private:
  std::vector<uint64_t>* words_ = nullptr;
  unsigned bits_ = 0;
  uint64_t mask_ = 0;
};

// What a lone level's packed map is made of: its cluster map and the weld, named with their sizes and
// modification times, the order, and the counts.
// `by_file`: the map is read from the level's cells by vertex (vertex_cells.h) instead.
std::string packed_map_key(const std::string& prefix, const std::string& canonical_path, const EmitLevel& level,
                           uint64_t vertices, uint64_t records, bool by_file = false) {
  std::string key = std::to_string(level.level) + " " + std::to_string(level.cells) + " " + std::to_string(vertices) + " " +
                    std::to_string(records);
  for (const std::string& path : {by_file ? vertex_cells_path(prefix, level.level) : cells_path(prefix, level.level),
                                  order_path(prefix), canonical_path}) {
    struct stat st {};
    if (!path.empty() && ::stat(path.c_str(), &st) != 0) return {};
    key += " " + path + " " + std::to_string(st.st_ino) + " " + std::to_string(st.st_size) + " " +
           std::to_string(st.st_mtim.tv_sec) + "." + std::to_string(st.st_mtim.tv_nsec);
  }
  return key;
}

// One level of a group: its field in the packed map and what it accumulates.
struct LevelState {
  EmitLevel in;
  // Batched levels (find_halos): a bit per cell of the level for the batch's own cells (those of its
  // regions) and one for its halo (the others that share an input primitive with one of its own). What a
  // batch holds beyond these few bits a cell grows with the batch, not with the level.
  RankedBits own, halo;
  uint64_t quadric_base = 0;  // representatives_only: the first cell of the range summed
  // The level sums quadrics in pass A (quadric representatives, unless it is batched and reads them).
  bool sums_quadrics = false;
  // A batched level that sums them (EmitOptions::own_representatives): its own and halo cells (`touched`)
  // have their quadrics first, by rank, then those of its ring (`ring`: the cells beyond the halo that
  // corners of its triangles fall in, pass Q), by rank.
  bool ranks_quadrics = false;
  RankedBits touched, ring;
  unsigned shift = 0;
  uint64_t mask = 0;  // field mask after the shift; all ones is "no cell"
  // Pass A.
  FlatMap<3, false> g_triangles;
  FlatMap<2> g_edges;
  FlatMap<1, false> g_points;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<std::array<uint32_t, 2>> edges;
  std::vector<uint32_t> points;
  std::vector<uint32_t> triangle_materials, edge_materials, point_materials;  // with materials, as BlockOut's
  std::vector<core::Quadric> quadrics;
  // Elimination: per cell a bit when a kept triangle uses it, and one when a kept edge does.
  RankedBits by_triangle, by_kept_edge;
  // The input triangles and segments that collapsed to an edge or a point (passes B and C visit only those).
  CollapsedBits collapsed[2];
  // Elimination, passes B and C.
  std::vector<std::array<uint32_t, 2>> kept_edges;  // in edge order; k_edges finds them by cells
  FlatMap<2> k_edges;
  std::vector<uint32_t> kept_points;
  std::vector<uint32_t> kept_edge_materials, kept_point_materials;
  std::vector<EdgeSums> kept_sums;
  uint64_t first_target = 0;  // the group's id of its first kept edge (corner_key)
  std::vector<std::array<double, 3>> pa, pb;
  std::vector<Distances> distances;
  EmitCounts counts;
};

bool owned(const LevelState& L, uint64_t c) { return !L.in.batched || L.own.has(c); }
// A cell the batch visits: its own or its halo's.
bool in_batch(const LevelState& L, uint64_t c) { return L.own.has(c) || L.halo.has(c); }
// A cell a kept triangle or edge uses.
bool used(const LevelState& L, uint64_t c) { return L.by_triangle.has(c) || L.by_kept_edge.has(c); }

// Where cell c's quadric is in L.quadrics (past its end: the cell has none).
uint64_t quadric_index(const LevelState& L, uint32_t c) {
  if (!L.ranks_quadrics) return c - L.quadric_base;
  if (L.touched.has(c)) return L.touched.rank(c);
  return L.ring.bits.empty() || !L.ring.has(c) ? UINT64_MAX : L.touched.ones() + L.ring.rank(c);
}

// A cell of the batch's own regions (the others of a batched level are its halo, its ring, or none of its).
bool in_batch_regions(const LevelState& L, uint64_t c) {
  const uint32_t r = L.in.regions->of(c);
  return r >= L.in.first_region && r < L.in.end_region;
}

// Adds triangle quadric q to cell c's sum in the block (passes A and Q): a block's sums are formed in store
// order, and merged in block order (merge_quadrics), so a cell's quadric does not depend on the threads.
void add_quadric(BlockOut& o, Scratch& s, uint32_t c, const core::Quadric& q) {
  if (c == s.last_cell) {
    o.quadrics[s.last_slot].add(q);
    return;
  }
  const auto [slot, fresh] = s.cells.insert({c}, static_cast<uint32_t>(o.quadrics.size()));
  if (fresh) o.quadric_cells.push_back(c), o.quadrics.push_back(q);
  else o.quadrics[slot].add(q);
  s.last_cell = c, s.last_slot = slot;
}

void merge_quadrics(LevelState& L, const BlockOut& o) {
  for (size_t i = 0; i < o.quadric_cells.size(); ++i) L.quadrics[quadric_index(L, o.quadric_cells[i])].add(o.quadrics[i]);
}

// A point's size (core/mesh.h) is measured as an edge's thickness is: kept point p joins passes B and C as
// the edge {c, c} with id E + p, after the E kept edges. Every corner of a primitive that collapsed to it
// falls in its cell, hence in A; pass B collects its distinct corners (by canonical id, as an edge's), pass C
// measures their distances to their mean P_A (P_B is set to P_A), and the size is 2·D_A, the diameter of what
// the point replaces. A cell reached only by input points has no corners
// (size 0: drawn one pixel wide). A kept point's cell is used by no kept edge or triangle, so every
// primitive with a corner in it collapsed to it, and a batch owning the cell visits them all.
void index_kept_points(LevelState& L) {
  const uint32_t first = static_cast<uint32_t>(L.kept_edges.size());
  for (size_t p = 0; p < L.kept_points.size(); ++p)
    L.k_edges.insert({L.kept_points[p], L.kept_points[p]}, first + static_cast<uint32_t>(p));
}

// The cell whose corners go to A: a kept edge's lower cell, a kept point's cell.
uint32_t lower_cell(const LevelState& L, uint32_t e) {
  return e < L.kept_edges.size() ? L.kept_edges[e][0] : L.kept_points[e - L.kept_edges.size()];
}

std::vector<float> kept_point_sizes(const LevelState& L) {
  const size_t first = L.kept_edges.size();
  std::vector<float> size(L.kept_points.size());
  for (size_t p = 0; p < size.size(); ++p) {
    const EdgeSums& s = L.kept_sums[first + p];
    size[p] = s.na ? static_cast<float>(2 * L.distances[first + p].a / static_cast<double>(s.na)) : 0.0f;
  }
  return size;
}
bool visited(const LevelState& L, const uint32_t* c, size_t arity) {
  if (!L.in.batched) return true;
  for (size_t k = 0; k < arity; ++k)
    if (in_batch(L, c[k])) return true;
  return false;
}

}  // namespace

// The halo of every batched level of the group: marks every cell that shares an input triangle or segment
// with a cell of the batch (L.own) and is not its own. Halo bits only go from 0 to 1 during the pass, and a
// primitive's test reads the own bits only, so the result does not depend on the threads.
template <class RunBlocks, class RecordOf, class CellOf>
void find_halos(std::vector<LevelState>& levels, RunBlocks& run_blocks, RecordOf& record_of, CellOf& cell) {
  bool any = false;
  for (LevelState& L : levels) {
    if (!L.in.batched) continue;
    L.own = RankedBits(L.in.cells), L.halo = RankedBits(L.in.cells);
    uint64_t owned_cells = 0;
    for (uint64_t c = 0; c < L.in.cells; ++c)
      if (in_batch_regions(L, c)) L.own.set(c), ++owned_cells;
    // A routed batch: its halo was found while routing (the same rule, over the whole input).
    if (L.in.routes && L.in.routes->halo.size() == L.in.cells) {
      const uint8_t bit = static_cast<uint8_t>(1u << L.in.route_bit);
      for (uint64_t c = 0; c < L.in.cells; ++c)
        if (!L.own.has(c) && (L.in.routes->halo[c] & bit)) L.halo.set(c);
      continue;
    }
    // A batch of every cell (a sharded task's wide level, stream/shard.h) has no halo: no pass for it.
    if (owned_cells == L.in.cells) continue;
    any = true;
  }
  if (!any) return;
  run_blocks(
      "emit", true,
      [&](const Block& b, std::span<const uint32_t> ids, BlockOut*, Scratch*) {
        const size_t arity = static_cast<size_t>(3 - b.kind);
        for (size_t i = 0; i < ids.size(); i += arity) {
          uint64_t r[3];
          for (size_t k = 0; k < arity; ++k) r[k] = record_of(ids[i + k]);
          for (LevelState& L : levels) {
            if (!L.in.batched) continue;
            uint32_t c[3];
            bool touches = false;
            for (size_t k = 0; k < arity; ++k) c[k] = cell(L, r[k]), touches = touches || L.own.has(c[k]);
            if (!touches) continue;
            for (size_t k = 0; k < arity; ++k)
              if (!L.own.has(c[k])) L.halo.set_shared(c[k]);
          }
        }
      },
      [](BlockOut*) {});
}

// The cells a batch of a level needs, numbered in order of first use: triangle corners, then the ends of
// its kept edges, its kept points, and its cells that only other batches' kept edges use.
// A bit per cell of the level and a slot per numbered cell (by rank): a batch's slots grow with the batch.
struct CellSlots {
  RankedBits numbered;                 // per cell of the level: it has a slot
  std::vector<uint32_t> slot_by_rank;  // per numbered cell, by rank
  std::vector<uint32_t> cell;          // per slot
  size_t triangle_slots = 0;
  std::vector<uint32_t> triangles;  // 3 slots per triangle of L.triangles
  std::vector<double> rep;          // xyz per slot
  uint32_t slot_of(uint64_t c) const { return numbered.has(c) ? slot_by_rank[numbered.rank(c)] : UINT32_MAX; }
};

void number_cells(const LevelState& L, CellSlots& s) {
  // The cells that take a slot: the corners of the triangles, the ends of the kept edges, the kept points,
  // and the own cells that a kept edge uses.
  s.numbered = RankedBits(L.in.cells);
  for (const auto& t : L.triangles)
    for (uint32_t c : t) s.numbered.set(c);
  for (const auto& e : L.kept_edges) s.numbered.set(e[0]), s.numbered.set(e[1]);
  for (uint32_t c : L.kept_points) s.numbered.set(c);
  L.by_kept_edge.for_each([&](uint64_t c) {
    if (owned(L, c)) s.numbered.set(c);
  });
  s.numbered.count();
  // Their slots, in order of first use.
  s.slot_by_rank.assign(s.numbered.ones(), UINT32_MAX);
  auto use = [&](uint64_t c) {
    uint32_t& slot = s.slot_by_rank[s.numbered.rank(c)];
    if (slot == UINT32_MAX) slot = static_cast<uint32_t>(s.cell.size()), s.cell.push_back(static_cast<uint32_t>(c));
    return slot;
  };
  s.triangles.reserve(3 * L.triangles.size());
  for (const auto& t : L.triangles)
    for (uint32_t c : t) s.triangles.push_back(use(c));
  s.triangle_slots = s.cell.size();
  for (const auto& e : L.kept_edges) use(e[0]), use(e[1]);
  for (uint32_t c : L.kept_points) use(c);
  L.by_kept_edge.for_each([&](uint64_t c) {
    if (owned(L, c)) use(c);
  });
}

// The representatives of the slots: read from the level's representatives file (batched levels, so that a
// cell's representative is the same in every batch that needs it), or formed from the cell table and the
// quadrics summed in pass A. Windows of cells in cell order, in parallel (each representative depends on its
// cell alone, so the bytes do not depend on the threads).
void load_representatives(const LevelState& L, const std::string& prefix, const core::ClusterOptions& cluster,
                          const EmitOptions& options, bool single_precision, CellSlots& s) {
  s.rep.resize(3 * s.cell.size());
  const uint64_t cells = L.in.cells;
  constexpr size_t record = 3 * sizeof(double);
  std::unique_ptr<io::MappedFile> reps;
  std::unique_ptr<CellInfoReader> table;
  const bool from_file = L.in.batched && !options.own_representatives;
  if (from_file) {
    reps = std::make_unique<io::MappedFile>(representatives_path(prefix, L.in.level));
    if (reps->size() != cells * record) fail(Status::io_error, reps->path() + ": size does not match");
  } else {
    table = std::make_unique<CellInfoReader>(cell_info_path(prefix, L.in.level), cells,
                                             cell_info_kind(options.representative), single_precision);
  }
  constexpr uint64_t window_cells = 1 << 16;
  tbb::parallel_for(uint64_t{0}, (cells + window_cells - 1) / window_cells, [&](uint64_t window) {
    const uint64_t first = window * window_cells, end = std::min(cells, first + window_cells);
    io::Window w;
    for (uint64_t c = first; c < end; ++c) {
      const uint32_t slot = s.slot_of(c);
      if (slot == UINT32_MAX) continue;
      if (from_file) {
        if (!w.data()) w = reps->map(first * record, end * record);
        std::memcpy(&s.rep[3 * slot], w.data() + (c - first) * record, record);
        continue;
      }
      if (!w.data()) w = table->map(first, end);
      const CellInfo ci = table->get(w, c - first);
      const uint64_t q = L.sums_quadrics ? quadric_index(L, static_cast<uint32_t>(c)) : 0;
      if (L.sums_quadrics && q >= L.quadrics.size()) fail(Status::internal, "emit: a cell the batch needs has no quadric");
      cell_representative(ci, L.sums_quadrics ? &L.quadrics[q] : nullptr, options.representative, cluster, L.in.cell_size,
                          &s.rep[3 * slot]);
    }
  });
}

// The batch's output vertices: the triangle corners split by normal (core/normals.h), then one vertex with a
// zero normal for each cell that only edges and points use. A cell's triangles are all in the batch when the
// cell is owned or in the halo, so its vertices (and their order, the variants) are the level's.
struct BatchVertices {
  std::vector<uint32_t> slot, variant;  // per vertex
  std::vector<float> normals;           // xyz per vertex
  std::vector<uint32_t> triangles;      // 3 vertices per triangle of L.triangles
  std::vector<uint32_t> end_vertex;     // per slot: the vertex an edge or point end at its cell uses
};

void make_vertices(const CellSlots& s, const EmitOptions& options, BatchVertices& v) {
  core::CreaseNormals normals;
  core::crease_normals(std::span<const double>(s.rep.data(), 3 * s.triangle_slots), s.triangles,
                       options.normals ? options.crease_degrees : 180.0, normals);
  v.slot = std::move(normals.vertex);
  v.normals = std::move(normals.normals);
  v.triangles = std::move(normals.triangles);
  std::vector<uint32_t> next(s.cell.size(), 0);
  v.end_vertex.assign(s.cell.size(), UINT32_MAX);
  v.variant.resize(v.slot.size());
  for (size_t i = 0; i < v.slot.size(); ++i) {
    v.variant[i] = next[v.slot[i]]++;
    if (v.end_vertex[v.slot[i]] == UINT32_MAX) v.end_vertex[v.slot[i]] = static_cast<uint32_t>(i);
  }
  for (size_t slot = s.triangle_slots; slot < s.cell.size(); ++slot) {
    v.end_vertex[slot] = static_cast<uint32_t>(v.slot.size());
    v.slot.push_back(static_cast<uint32_t>(slot));
    v.variant.push_back(0);
    v.normals.insert(v.normals.end(), {0.0f, 0.0f, 0.0f});
  }
}

// Ids 0 .. n - 1 grouped by region (region(i) < regions, or UINT32_MAX for none), in id order within each.
struct Buckets {
  std::vector<uint32_t> start, ids;
  std::span<const uint32_t> of(uint32_t r) const { return {ids.data() + start[r], ids.data() + start[r + 1]}; }
};
template <class Region>
Buckets bucket(size_t n, uint32_t regions, Region&& region) {
  Buckets b;
  b.start.assign(regions + 2, 0);
  for (size_t i = 0; i < n; ++i)
    if (const uint32_t r = region(i); r != UINT32_MAX) ++b.start[r + 2];
  for (uint32_t r = 0; r < regions; ++r) b.start[r + 2] += b.start[r + 1];
  b.ids.resize(b.start[regions + 1]);
  for (size_t i = 0; i < n; ++i)
    if (const uint32_t r = region(i); r != UINT32_MAX) b.ids[b.start[r + 1]++] = static_cast<uint32_t>(i);
  return b;
}

// Classify .. thickness done: the batch's regions' parts, each handed to `sink` in region order. A triangle
// is owned with its lowest cell, an edge with its lower one; only the batch's own edges and
// points were kept.
// With `colors`, every vertex takes its cell's colour; with `materials` (the store's table), every
// primitive its material (LevelState's *_materials).
template <class Sink>
void build_parts(LevelState& L, const std::vector<float>& thickness, const std::vector<float>& point_size,
                 const LevelColors* colors, const std::vector<core::Material>* materials, const std::string& prefix,
                 const core::ClusterOptions& cluster, const EmitOptions& options, bool single_precision, Sink&& sink) {
  CellSlots s;
  number_cells(L, s);
  load_representatives(L, prefix, cluster, options, single_precision, s);
  std::vector<core::Quadric>().swap(L.quadrics);
  L.ranks_quadrics = false, L.touched = RankedBits(), L.ring = RankedBits();
  BatchVertices v;
  make_vertices(s, options, v);
  std::vector<uint32_t>().swap(s.triangles);

  const uint32_t first = L.in.first_region, regions = L.in.end_region - first;
  auto region = [&](uint32_t c) { return owned(L, c) ? L.in.regions->of(c) - first : UINT32_MAX; };
  const Buckets triangles = bucket(L.triangles.size(), regions, [&](size_t t) {
    const auto& c = L.triangles[t];
    return region(std::min({c[0], c[1], c[2]}));
  });
  const Buckets edges = bucket(L.kept_edges.size(), regions, [&](size_t e) { return region(L.kept_edges[e][0]); });
  const Buckets points = bucket(L.kept_points.size(), regions, [&](size_t p) { return region(L.kept_points[p]); });
  Buckets own = bucket(v.slot.size(), regions, [&](size_t i) { return region(s.cell[v.slot[i]]); });
  auto key = [&](uint32_t i) { return uint64_t{s.cell[v.slot[i]]} << 32 | v.variant[i]; };
  for (uint32_t r = 0; r < regions; ++r)
    std::sort(own.ids.begin() + own.start[r], own.ids.begin() + own.start[r + 1],
              [&](uint32_t a, uint32_t b) { return key(a) < key(b); });

  std::vector<uint32_t> local(v.slot.size(), UINT32_MAX);
  std::vector<uint32_t> numbered;  // the vertices `local` numbers for the current part
  for (uint32_t r = 0; r < regions; ++r) {
    RegionPart part;
    part.region = first + r;
    core::LodMesh& mesh = part.mesh;
    auto position = [&](uint32_t i, std::vector<float>& out) {
      for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(s.rep[3 * v.slot[i] + k]));
    };
    auto add = [&](uint32_t i) {
      if (local[i] == UINT32_MAX) {
        local[i] = static_cast<uint32_t>(part.vertex_key.size());
        numbered.push_back(i);
        part.vertex_key.push_back(key(i));
        position(i, mesh.positions);
        mesh.normals.insert(mesh.normals.end(), &v.normals[3 * uint64_t{i}], &v.normals[3 * uint64_t{i}] + 3);
        if (colors) mesh.colors.insert(mesh.colors.end(), colors->of(s.cell[v.slot[i]]), colors->of(s.cell[v.slot[i]]) + 4);
      }
      return local[i];
    };
    for (uint32_t t : triangles.of(r)) {
      for (int k = 0; k < 3; ++k) mesh.triangles.push_back(add(v.triangles[3 * uint64_t{t} + k]));
      if (materials) mesh.triangle_materials.push_back(L.triangle_materials[t]);
    }
    for (uint32_t e : edges.of(r)) {
      for (uint32_t c : L.kept_edges[e]) mesh.edges.push_back(add(v.end_vertex[s.slot_of(c)]));
      mesh.thickness.push_back(thickness[e]);
      if (materials) mesh.edge_materials.push_back(L.kept_edge_materials[e]);
    }
    for (uint32_t p : points.of(r)) {
      mesh.points.push_back(add(v.end_vertex[s.slot_of(L.kept_points[p])]));
      mesh.point_size.push_back(point_size[p]);
      if (materials) mesh.point_materials.push_back(L.kept_point_materials[p]);
    }
    if (materials) mesh.materials = *materials;
    for (uint32_t i : own.of(r)) {
      part.owned_key.push_back(key(i));
      position(i, part.owned_positions);
      part.owned_normals.insert(part.owned_normals.end(), &v.normals[3 * uint64_t{i}], &v.normals[3 * uint64_t{i}] + 3);
      if (colors) part.owned_colors.insert(part.owned_colors.end(), colors->of(s.cell[v.slot[i]]), colors->of(s.cell[v.slot[i]]) + 4);
    }
    L.counts.triangles += mesh.triangle_count();
    L.counts.edges += mesh.edge_count();
    L.counts.points += mesh.point_count();
    for (uint32_t i : numbered) local[i] = UINT32_MAX;
    numbered.clear();
    sink(part);
  }
}

unsigned emit_bits(uint64_t cells) { return vertex_cell_bits(cells); }

uint64_t emit_level_bytes(uint64_t cells, uint64_t primitives, const EmitOptions& options) {
  // Measured on the 48M-triangle city scene at its finest level (2.56M cells, 5.4M output triangles): the
  // dedupe tables (half-full open addressing, doubled while they grow), the output arrays and the
  // per-thread block tables peak at about 240 bytes per cell during pass A; the quadrics add 80. Measured
  // on the 193M-triangle city with three coarse levels in one group (60K cells): each level also holds
  // about 25 MB whatever its cells, its share of the block outputs and per-thread tables of the blocks in
  // flight (two sets of 4 per thread, 16 here): 24 bytes per primitive in flight.
  // With materials, a material id per output primitive during pass A (about 3 a cell, 4 bytes each).
  // Vertex colours add nothing at the peak: their pass (sum_cell_colors: a bit and a half a cell, 44 bytes
  // a used cell, 84 with the mean) runs after elimination has freed pass A's dedupe tables, and what it keeps
  // (8 bytes a used cell) goes with the level's parts. Measured: the 48.6 M city with colours at --memory 1G emits
  // its finest level whole, as without, within the cap (README, "Materials and colours").
  const bool quadric = options.representative == Representative::quadric && !options.count_only;
  return cells * (240 + (quadric ? sizeof(core::Quadric) : 0) + (options.materials && !options.count_only ? 12 : 0)) +
         24 * std::min(primitives, 16 * kEmitBlock);
}

uint64_t emit_corner_bytes(uint64_t budget) { return std::clamp<uint64_t>(budget / 24, 1 << 20, 40 << 20); }

uint64_t emit_map_bytes(uint64_t vertices, unsigned bits) { return (vertices * bits + 63) / 64 * 8 + 8; }

void check_emit_budget(std::span<const uint64_t> cells, size_t first, uint64_t vertices, uint64_t primitives,
                       uint64_t budget, uint64_t resident, const EmitOptions& options) {
  const uint64_t need =
      resident + emit_map_bytes(vertices, emit_bits(cells[first])) + emit_level_bytes(cells[first], primitives, options) +
      emit_corner_bytes(budget);
  if (need <= budget) return;
  fail(Status::usage, "emitting level " + std::to_string(first) + " (" + std::to_string(cells[first]) +
                          " cells) needs about " + std::to_string(need >> 20) + " MiB, more than --memory allows (" +
                          std::to_string(budget >> 20) + " MiB for the stage" +
                          (resident ? ", what is already held included" : "") +
                          "): raise --memory, or make the level coarser (--cell-sizes, --target-triangles)");
}

size_t emit_group_end(std::span<const uint64_t> cells, size_t first, uint64_t vertices, uint64_t primitives, uint64_t budget,
                      uint64_t resident, const EmitOptions& options) {
  unsigned bits = emit_bits(cells[first]);
  uint64_t work = emit_level_bytes(cells[first], primitives, options) + emit_corner_bytes(budget);
  size_t end = first + 1;
  while (end < cells.size()) {
    const unsigned b = bits + emit_bits(cells[end]);
    const uint64_t w = work + emit_level_bytes(cells[end], primitives, options);
    if (b > 64 || resident + emit_map_bytes(vertices, b) + w > budget) break;
    bits = b, work = w, ++end;
  }
  return end;
}

EmitLevelPlan plan_emit_level(size_t level, uint64_t cells, uint64_t largest_region, uint64_t vertices,
                              uint64_t primitives, uint64_t budget, const EmitOptions& options, bool* fits) {
  EmitLevelPlan plan;
  const uint64_t map = emit_map_bytes(vertices, emit_bits(cells));
  const uint64_t tables = kLevelBytesPerCell * cells;
  if (map + tables + emit_level_bytes(cells, primitives, options) + emit_corner_bytes(budget) <= budget) {
    plan.batch_cells = cells;
    return plan;
  }
  plan.batched = true;
  // A batch holds pass A's tables for its cells and its halo (counted as half its cells again), without
  // quadrics (its representatives are read from the file), plus the block outputs in flight.
  EmitOptions no_quadric = options;
  no_quadric.representative = Representative::center;
  const uint64_t per_cell = emit_level_bytes(1, 0, no_quadric) * 3 / 2;
  const uint64_t in_flight = emit_level_bytes(0, primitives, no_quadric) + emit_corner_bytes(budget);
  // The routes of the batches (route_batches: a byte per 64 primitives and a byte a cell) are held beside
  // each of them.
  const uint64_t routes = primitives / 64 + 3 + cells;
  const uint64_t need = map + tables + routes + in_flight + per_cell * largest_region;
  if (need > budget && fits) {
    *fits = false;
    return plan;
  }
  if (need > budget)
    fail(Status::usage, "emitting level " + std::to_string(level) + " (" + std::to_string(cells) + " cells) region by region needs about " +
                            std::to_string(need >> 20) + " MiB (its cluster map " + std::to_string(map >> 20) + " MiB, " +
                            std::to_string(kLevelBytesPerCell) + " bytes a cell " + std::to_string(tables >> 20) +
                            " MiB, a region of " + std::to_string(largest_region) + " cells), more than --memory allows (" +
                            std::to_string(budget >> 20) + " MiB for the stage): raise --memory, or make the level coarser "
                            "(--cell-sizes, --target-triangles)");
  plan.batch_cells = (budget - map - tables - routes - in_flight) / per_cell;
  // The representatives pass holds a quadric per cell of its range, and its blocks' quadrics in flight.
  const uint64_t quadric_bytes = sizeof(core::Quadric) + 8;
  plan.reps_range_cells = std::max<uint64_t>(1, (budget - map - tables - in_flight) / quadric_bytes);
  return plan;
}

// Every level's cell colours (see CellColor), for the cells its output can use: those a kept triangle or
// edge uses or a kept point is on, and of a batch only its own and its halo's. The weight order (order.u32;
// with the mean representative, grades.f64 beside it) is read in chunks; each chunk's colours are gathered
// once, then every level sums them in a task of its own, streaming its cluster map (cells-L.map, the cell of
// each record in weight order: no random lookups in the group's packed map). Each cell's sums are formed
// serially in weight order, so they depend neither on the threads nor on the batches. Memory: the colour
// column mapped (4 bytes a vertex), per level 12 bytes a 64 cells and 44 a used cell (84 with the mean), and
// per chunk 4 bytes a record and level.
void sum_cell_colors(const std::string& store_dir, const StoreMeta& meta, const std::string& prefix, uint64_t records,
                     const EmitOptions& options, const std::vector<LevelState>& levels, std::vector<LevelColors>& out) {
  const size_t nl = levels.size();
  const bool grades = options.representative == Representative::mean && !options.grades_path.empty();
  std::vector<std::vector<CellColor>> sums(nl);
  std::vector<std::vector<CellWeighted>> weighted(nl);
  for (size_t l = 0; l < nl; ++l) {
    const LevelState& L = levels[l];
    RankedBits& cells = out[l].cells;
    cells = RankedBits(L.in.cells);
    for (uint32_t c : L.kept_points) cells.set(c);
    for (size_t w = 0; w < cells.bits.size(); ++w) {
      cells.bits[w] |= L.by_triangle.bits[w] | L.by_kept_edge.bits[w];
      if (L.in.batched) cells.bits[w] &= L.own.bits[w] | L.halo.bits[w];
    }
    cells.count();
    const uint64_t n = cells.ones();
    sums[l].assign(n, CellColor{});
    if (grades) weighted[l].assign(n, CellWeighted{});
  }
  io::MappedFile colors(store_dir + "/colors.rgba8");
  if (colors.size() != meta.vertices * 4) fail(Status::io_error, colors.path() + ": size does not match store.json");
  io::MappedFile order(order_path(prefix));
  if (order.size() != records * 4) fail(Status::io_error, order.path() + ": size does not match the weight index");
  constexpr uint64_t rb = sizeof(double);
  std::unique_ptr<io::MappedFile> index_file;
  if (grades) {
    index_file = std::make_unique<io::MappedFile>(options.grades_path);
    if (index_file->size() != records * rb) fail(Status::io_error, index_file->path() + ": size does not match the weight index");
  }
  if (records > 0) {
    const io::Window rgba = colors.map(0, colors.size(), io::MappedFile::Access::random);
    constexpr uint64_t kChunk = 1 << 18;
    std::vector<std::unique_ptr<CellMapReader>> maps;
    for (const LevelState& L : levels) maps.push_back(std::make_unique<CellMapReader>(cells_path(prefix, L.in.level)));
    std::vector<uint32_t> cells(nl * kChunk), chunk_rgba(kChunk);
    for (uint64_t first = 0; first < records; first += kChunk) {
      const uint64_t n = std::min<uint64_t>(kChunk, records - first);
      const io::Window ids = order.map(first * 4, (first + n) * 4);
      for (uint64_t i = 0; i < n; ++i) {
        uint32_t id;
        std::memcpy(&id, ids.data() + 4 * i, 4);
        std::memcpy(&chunk_rgba[i], rgba.data() + 4 * uint64_t{id}, 4);
      }
      io::Window g;
      if (grades) g = index_file->map(first * rb, (first + n) * rb);
      tbb::parallel_for(size_t{0}, nl, [&](size_t l) {
        uint32_t* cs = cells.data() + l * kChunk;
        maps[l]->read(std::span<uint32_t>(cs, n));
        const RankedBits& used_cells = out[l].cells;
        for (uint64_t i = 0; i < n; ++i) {
          if (cs[i] >= levels[l].in.cells) fail(Status::io_error, cells_path(prefix, levels[l].in.level) + ": cell id out of range");
          if (!used_cells.has(cs[i])) continue;
          const uint32_t j = used_cells.rank(cs[i]);
          const uint8_t* c = reinterpret_cast<const uint8_t*>(&chunk_rgba[i]);
          CellColor& s = sums[l][j];
          if (s.count == 0) std::memcpy(s.first, c, 4);
          s.count += 1;
          for (int k = 0; k < 4; ++k) s.sum[k] += c[k];
          if (grades) {
            double grade;
            std::memcpy(&grade, g.data() + i * rb, 8);
            CellWeighted& w = weighted[l][j];
            for (int k = 0; k < 4; ++k) w.weighted[k] += grade * c[k];
            w.weight += grade;
          }
        }
      });
    }
  }
  for (size_t l = 0; l < nl; ++l) {
    out[l].rgba.resize(4 * sums[l].size());
    for (size_t j = 0; j < sums[l].size(); ++j)
      cell_rgba(sums[l][j], grades ? &weighted[l][j] : nullptr, options.representative, &out[l].rgba[4 * j]);
  }
}

namespace {

// Routing (route_batches): the halo bits of every cell (pass H: like find_halos, for every routed batch at
// once), then every word's batches (pass R: a primitive goes to the batches of its cells and of their halos,
// exactly the primitives `visited` lets through in that batch). Halo bits only ever gain bits during pass H,
// and each word of routes is written by the one block that holds it (blocks start at multiples of 64), so the
// routes do not depend on the threads.
template <class RunBlocks, class RecordOf, class CellOf>
void route_level(const LevelState& L, std::span<const std::pair<uint32_t, uint32_t>> batches, const uint64_t* column_count,
                 RunBlocks& run_blocks, RecordOf& record_of, CellOf& cell, BatchRoutes& routes) {
  std::vector<uint8_t> batch_bit(L.in.cut->regions.size(), 0);  // per region: its batch's bit, or 0
  for (size_t i = 0; i < batches.size(); ++i)
    for (uint32_t r = batches[i].first; r < batches[i].second; ++r) batch_bit[r] = static_cast<uint8_t>(1u << i);
  auto own = [&](uint32_t c) { return batch_bit[L.in.regions->of(c)]; };
  std::vector<uint8_t>& halo = routes.halo;
  halo.assign(L.in.cells, 0);
  run_blocks(
      "emit", true,
      [&](const Block& b, std::span<const uint32_t> ids, BlockOut*, Scratch*) {
        const size_t arity = static_cast<size_t>(3 - b.kind);
        for (size_t i = 0; i < ids.size(); i += arity) {
          uint32_t c[3];
          uint8_t touched = 0, owner[3];
          for (size_t k = 0; k < arity; ++k) c[k] = cell(L, record_of(ids[i + k])), owner[k] = own(c[k]), touched |= owner[k];
          if (!touched) continue;
          for (size_t k = 0; k < arity; ++k) {
            const uint8_t add = static_cast<uint8_t>(touched & ~owner[k]);
            if (add && (std::atomic_ref<uint8_t>(halo[c[k]]).load(std::memory_order_relaxed) & add) != add)
              std::atomic_ref<uint8_t>(halo[c[k]]).fetch_or(add, std::memory_order_relaxed);
          }
        }
      },
      [](BlockOut*) {});
  for (int kind = 0; kind < 3; ++kind) routes.words[kind].assign((column_count[kind] + 63) / 64, 0);
  run_blocks(
      "emit", false,
      [&](const Block& b, std::span<const uint32_t> ids, BlockOut*, Scratch*) {
        const size_t arity = static_cast<size_t>(3 - b.kind);
        uint8_t* words = routes.words[b.kind].data();
        for (size_t i = 0; i < ids.size(); i += arity) {
          uint8_t m = 0;
          for (size_t k = 0; k < arity; ++k) {
            const uint32_t c = cell(L, record_of(ids[i + k]));
            m |= static_cast<uint8_t>(own(c) | halo[c]);
          }
          words[(b.first + i / arity) / 64] |= m;
        }
      },
      [](BlockOut*) {});
}

// The blocks of a routed batch: runs of its words, cut at kEmitBlock primitives (every block starts at a
// multiple of 64, as the collapsed bits need).
std::vector<Block> routed_blocks(const BatchRoutes& routes, unsigned bit, const uint64_t* column_count) {
  std::vector<Block> blocks;
  const uint8_t mask = static_cast<uint8_t>(1u << bit);
  for (int kind = 0; kind < 3; ++kind) {
    const std::vector<uint8_t>& words = routes.words[kind];
    if (words.size() != (column_count[kind] + 63) / 64) fail(Status::internal, "emit: routes of another input");
    for (uint64_t w = 0; w < words.size();) {
      if (!(words[w] & mask)) {
        ++w;
        continue;
      }
      uint64_t end = w + 1;
      while (end < words.size() && (words[end] & mask) && (end - w) * 64 < kEmitBlock) ++end;
      const uint64_t first = w * 64;
      blocks.push_back({kind, first, std::min(end * 64, column_count[kind]) - first});
      w = end;
    }
  }
  return blocks;
}

// The blocks of a bounded batch (block_bounds.h): within each block of kEmitBlock primitives (the blocks of a
// pass over the whole input), the span from its first box that reaches a marked voxel of `reach` to its last
// (every span starts at a multiple of kBoundsBlock, so of 64). One span per whole block, so that a cell's
// quadric, summed per block and merged in block order (pass A), adds what the whole input's pass adds in the
// same order: the boxes a span skips or spans over hold no triangle touching the batch's cells.
std::vector<Block> bounded_blocks(const BlockBounds& bounds, const ReachGrid& reach, const uint64_t* column_count) {
  static_assert(kEmitBlock % kBoundsBlock == 0 && kBoundsBlock % 64 == 0);
  constexpr uint64_t per_block = kEmitBlock / kBoundsBlock;
  std::vector<Block> blocks;
  for (int kind = 0; kind < 3; ++kind) {
    if (bounds.count[kind] != column_count[kind]) fail(Status::internal, "emit: block bounds of another input");
    const uint64_t n = bounds.blocks(kind);
    const double* box = bounds.box[kind].data();
    for (uint64_t b0 = 0; b0 < n; b0 += per_block) {
      uint64_t first = UINT64_MAX, last = 0;
      for (uint64_t b = b0; b < std::min(n, b0 + per_block); ++b)
        if (reach.reaches(&box[6 * b], &box[6 * b + 3])) first = std::min(first, b), last = b;
      if (first == UINT64_MAX) continue;
      blocks.push_back({kind, first * kBoundsBlock, std::min((last + 1) * kBoundsBlock, column_count[kind]) - first * kBoundsBlock});
    }
  }
  return blocks;
}

// Marks where a bounded group's passes must read: the anchors (emit_regions.h for_cell_anchors) of the cells
// of each level L with wanted(L, cell) (its own, those of its regions; then its halo's too; or, for pass Q,
// its ring's), each widened by the level's cell size (block_bounds.h). The cells, not their regions' boxes: a region of the octree cut is as large as
// its cells are sparse (on the 193 M-triangle city at N = 8, the first task's boxes reached 63% of the input
// for an eighth of the cells).
template <class Wanted>
void mark_reach(const std::vector<LevelState>& levels, const std::string& prefix, Representative representative,
                bool single_precision, Wanted&& wanted, ReachGrid& reach) {
  for (const LevelState& L : levels) {
    // A hair more than the cell size, so that the rounding of a box's corners never matters.
    const double r = L.in.cell_size * (1 + 0x1p-20);
    for_cell_anchors(
        prefix, L.in.level, L.in.cells, representative, single_precision, [&](uint64_t c) { return wanted(L, c); },
        [&](uint64_t, const double* p) {
          double lo[3], hi[3];
          for (int k = 0; k < 3; ++k) lo[k] = p[k] - r, hi[k] = p[k] + r;
          reach.mark(lo, hi);
        });
  }
  reach.finish();
}

// A unit of pass A (EmitOptions::classify_unit): classifies its blocks and writes each block's outputs
// (classify's BlockOut and the level's collapsed bits of the block, final once the block is classified: its
// words are its own) to each level's file, in block order (run_blocks merges in block order).
template <class RunBlocks, class Classify>
void write_classified(const ClassifyUnit& unit, const std::vector<Block>& blocks, const std::vector<LevelState>& levels,
                      RunBlocks& run_blocks, Classify& classify) {
  std::vector<std::unique_ptr<io::FileWriter>> files;
  for (const std::string& path : unit.paths) {
    files.push_back(std::make_unique<io::FileWriter>(path));
    files.back()->write(kClassifiedMagic, sizeof kClassifiedMagic);
  }
  uint64_t written = 0;
  run_blocks("emit", false, classify, [&](BlockOut* outs_l) {
    const Block& b = blocks[written++];
    for (size_t l = 0; l < levels.size(); ++l) write_block_out(*files[l], b, outs_l[l], levels[l].collapsed);
  });
  for (auto& f : files) {
    put(*f, kEndOfBlocks), put(*f, written), put(*f, uint64_t{0});
    f->commit();
  }
}

// A block's outputs as read from a unit's file hold only the level's cells, and a material (with
// `materials`) and a sub-block mask per primitive: Failure(io_error) naming the file otherwise (a file of
// another level or run), before any of it is merged.
void check_block_out(const BlockOut& o, uint64_t cells, bool materials, const std::string& path) {
  bool ok = o.edge_masks.size() == o.edges.size() && o.point_masks.size() == o.points.size() &&
            o.quadric_cells.size() == o.quadrics.size();
  const size_t m = materials ? 1 : 0;
  ok = ok && o.triangle_materials.size() == m * o.triangles.size() && o.edge_materials.size() == m * o.edges.size() &&
       o.point_materials.size() == m * o.points.size();
  for (const auto& t : o.triangles) ok = ok && t[0] < cells && t[1] < cells && t[2] < cells;
  for (const auto& e : o.edges) ok = ok && e[0] < cells && e[1] < cells;
  for (uint32_t c : o.points) ok = ok && c < cells;
  for (uint32_t c : o.quadric_cells) ok = ok && c < cells;
  if (!ok) fail(Status::io_error, path + ": not a unit of pass A of this level (a cell out of range or arrays that disagree)");
}

// Pass A from its units' files (EmitOptions::classified: per level of the group, its units' files in unit
// order): every block's outputs, in the order of the whole input's blocks, to merge_block, and each block's
// collapsed bits into the level's. Failure(io_error) where the files do not hold every block once, in order.
template <class MergeBlock>
void read_classified(const std::vector<std::vector<std::string>>& files, const std::vector<Block>& whole,
                     std::vector<LevelState>& levels, std::vector<BlockOut>& outs, bool materials, MergeBlock& merge_block,
                     Progress& progress) {
  const size_t nl = levels.size();
  if (files.size() != nl || nl == 0) fail(Status::internal, "emit: units of pass A for another group");
  const size_t units = files[0].size();
  uint64_t next = 0;  // in `whole`
  for (size_t u = 0; u < units; ++u) {
    progress.check();
    std::vector<std::unique_ptr<ClassifiedReader>> in;
    for (size_t l = 0; l < nl; ++l) {
      if (files[l].size() != units) fail(Status::internal, "emit: units of pass A for another group");
      in.push_back(std::make_unique<ClassifiedReader>(files[l][u]));
    }
    for (uint64_t read = 0;; ++read) {
      Block b;
      const bool more = in[0]->next(b, read);
      for (size_t l = 1; l < nl; ++l) {
        Block c;
        if (in[l]->next(c, read) != more || (more && (c.kind != b.kind || c.first != b.first || c.count != b.count)))
          fail(Status::io_error, files[l][u] + ": its blocks are not those of " + files[0][u]);
      }
      if (!more) break;
      if (next >= whole.size() || whole[next].kind != b.kind || whole[next].first != b.first || whole[next].count != b.count)
        fail(Status::io_error, files[0][u] + ": a block out of the input's order (units of another input or count)");
      ++next;
      for (size_t l = 0; l < nl; ++l) {
        in[l]->block_out(b, outs[l], levels[l].collapsed);
        check_block_out(outs[l], levels[l].in.cells, materials, files[l][u]);
      }
      merge_block(outs.data());
    }
    progress.report("emit", static_cast<double>(next) / static_cast<double>(std::max<size_t>(whole.size(), 1)));
  }
  if (next != whole.size()) fail(Status::io_error, "emit: the units of pass A do not cover the input (" + std::to_string(next) + " of " +
                                                       std::to_string(whole.size()) + " blocks)");
}

// The spans of `blocks` (triangles and segments) made of their sub-blocks of kBoundsBlock primitives
// marked in `marked` (per kind, a bit a sub-block), each span within kEmitBlock primitives.
std::vector<Block> marked_subblocks(const std::vector<Block>& blocks, const std::vector<uint64_t>* marked) {
  std::vector<Block> out;
  for (const Block& b : blocks) {
    if (b.kind == 2) continue;
    const uint64_t end = b.first + b.count;
    for (uint64_t p = b.first; p < end;) {
      const uint64_t sub = p / kBoundsBlock, next = std::min(end, (sub + 1) * kBoundsBlock);
      if (!(marked[b.kind][sub / 64] >> (sub % 64) & 1)) {
        p = next;
        continue;
      }
      if (!out.empty() && out.back().kind == b.kind && out.back().first + out.back().count == p &&
          out.back().count + (next - p) <= kEmitBlock)
        out.back().count += next - p;
      else
        out.push_back({b.kind, p, next - p});
      p = next;
    }
  }
  return out;
}

// Pass B's blocks when pass A came from units (read_classified), once elimination has found the kept edges
// and points (LevelState::k_edges): the sub-blocks that hold a primitive which collapsed to a kept edge or
// point in some level of the group, from the units' masks (BlockOut::edge_masks). Pass B finds its pairs in
// those only, so it collects the same pairs (their order is the sort's).
std::vector<Block> kept_subblocks(const std::vector<std::vector<std::string>>& files, const std::vector<Block>& blocks,
                                  const std::vector<LevelState>& levels, bool materials, const uint64_t* column_count) {
  static_assert(kEmitBlock % kBoundsBlock == 0 && kEmitBlock / kBoundsBlock <= 16);
  std::vector<uint64_t> kept[2];  // a bit a sub-block
  for (int kind = 0; kind < 2; ++kind) kept[kind].assign((column_count[kind] / kBoundsBlock + 1 + 63) / 64, 0);
  BlockOut o;
  for (size_t l = 0; l < levels.size(); ++l) {
    const LevelState& L = levels[l];
    if (L.k_edges.size() == 0) continue;
    for (const std::string& path : files[l]) {
      ClassifiedReader r(path);
      Block b;
      for (uint64_t read = 0; r.next(b, read); ++read) {
        r.block_out(b, o, nullptr);
        check_block_out(o, L.in.cells, materials, path);
        if (b.kind == 2) continue;
        uint32_t mask = 0;
        for (size_t i = 0; i < o.edges.size(); ++i)
          if (L.k_edges.find(o.edges[i]) != FlatMap<2>::empty) mask |= o.edge_masks[i];
        for (size_t i = 0; i < o.points.size(); ++i)
          if (L.k_edges.find({o.points[i], o.points[i]}) != FlatMap<2>::empty) mask |= o.point_masks[i];
        for (; mask; mask &= mask - 1) {
          const uint64_t sub = b.first / kBoundsBlock + static_cast<uint64_t>(std::countr_zero(mask));
          kept[b.kind][sub / 64] |= uint64_t{1} << (sub % 64);
        }
      }
    }
  }
  return marked_subblocks(blocks, kept);
}

// Pass B's blocks otherwise: the sub-blocks that hold a primitive which collapsed to an edge or a point in
// some level of the group (LevelState::collapsed, set by pass A), the only primitives pass B visits. A
// task's pass A reads the blocks whose boxes come near its cells; the primitives that collapsed in them are
// in a few of their sub-blocks.
std::vector<Block> collapsed_subblocks(const std::vector<Block>& blocks, const std::vector<LevelState>& levels,
                                       const uint64_t* column_count) {
  static_assert(kBoundsBlock % 64 == 0);
  constexpr uint64_t words = kBoundsBlock / 64;  // collapsed words a sub-block
  std::vector<uint64_t> marked[2];
  for (int kind = 0; kind < 2; ++kind) {
    const uint64_t subs = (column_count[kind] + kBoundsBlock - 1) / kBoundsBlock;
    marked[kind].assign((subs + 63) / 64, 0);
    for (const LevelState& L : levels) {
      const CollapsedBits& bits = L.collapsed[kind];
      for (uint64_t block = 0; block < bits.first_word.size(); ++block) {
        if (bits.first_word[block] == UINT32_MAX) continue;
        for (uint64_t j = 0; j < CollapsedBits::kBlockWords; ++j) {
          const uint64_t w = block * CollapsedBits::kBlockWords + j;  // the word's index in the whole column
          if (bits.words[bits.first_word[block] + j]) marked[kind][w / words / 64] |= uint64_t{1} << (w / words % 64);
        }
      }
    }
  }
  return marked_subblocks(blocks, marked);
}

// The group's packed map over every stored vertex (one machine's levels, a task's routed or counted ones),
// decoded from the levels' cluster maps in weight order, the welded vertices taking their canonical ones'
// records; or, for the next batch of a lone level or the next unit of pass A, the scratch's (map_key).
// Each record is composed from all the levels' maps at once and written once. The records are random
// writes (the weight index is in grade order); the threads split them by vertex range, each range a whole
// number of words so that no two threads write one word, and each thread reads every record (sequential,
// cheap).
void whole_packed_map(PackedMap& map, std::span<const LevelState> levels, unsigned bits, const std::string& prefix,
                      const std::string& canonical_path, const StoreMeta& meta, uint64_t records, bool routes,
                      const EmitOptions& options, EmitScratch& emit_scratch) {
  const size_t nl = levels.size();
  emit_scratch.paged.reset();
  const bool lone_batched = nl == 1 && (levels[0].in.batched || routes || options.representatives_only);
  std::string map_key;
  if (lone_batched) map_key = packed_map_key(prefix, canonical_path, levels[0].in, meta.vertices, records);
  if (options.classify_unit)
    for (const LevelState& L : levels) {
      const std::string k = packed_map_key(prefix, canonical_path, L.in, meta.vertices, records);
      if (k.empty()) {
        map_key.clear();
        break;
      }
      map_key += "|" + k;
    }
  const bool reuse = !map_key.empty() && emit_scratch.map_key == map_key;
  emit_scratch.map_key.clear();
  if (reuse) map.attach(emit_scratch.map, bits);
  else map.reset(emit_scratch.map, meta.vertices, bits);
  const size_t parts = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const uint64_t per_part = ((meta.vertices + parts - 1) / parts + 63) / 64 * 64;  // 64 records: whole words
  if (!reuse) {
    io::MappedFile order(order_path(prefix));
    if (order.size() != records * 4) fail(Status::io_error, order.path() + ": size does not match the weight index");
    constexpr uint64_t kChunk = 1 << 18;
    tbb::parallel_for(size_t{0}, parts, [&](size_t part) {
      const uint64_t lo = part * per_part, span = std::min(meta.vertices, lo + per_part) - std::min(meta.vertices, lo);
      if (span == 0) return;
      // The maps are bit streams read from their start (cell_map_file.h): every part decodes them whole.
      std::vector<std::unique_ptr<CellMapReader>> maps;
      for (const LevelState& L : levels) maps.push_back(std::make_unique<CellMapReader>(cells_path(prefix, L.in.level)));
      std::vector<uint32_t> cs(nl * kChunk);
      for (uint64_t first = 0; first < records; first += kChunk) {
        const uint64_t n = std::min(kChunk, records - first);
        const io::Window a = order.map(first * 4, (first + n) * 4);
        for (size_t l = 0; l < nl; ++l) maps[l]->read(std::span<uint32_t>(cs.data() + l * kChunk, n));
        const uint32_t* ids = reinterpret_cast<const uint32_t*>(a.data());
        for (uint64_t i = 0; i < n; ++i) {
          if (ids[i] - lo >= span) continue;  // another part's vertex (unsigned: below lo wraps around)
          uint64_t record = 0;
          for (size_t l = 0; l < nl; ++l) {
            const uint64_t c = cs[l * kChunk + i];
            if (c >= levels[l].in.cells) fail(Status::io_error, cells_path(prefix, levels[l].in.level) + ": cell id out of range");
            record |= c << levels[l].shift;
          }
          map.set(ids[i], record);
        }
      }
      for (size_t l = 0; l < nl; ++l) maps[l]->finish(records, levels[l].in.cells);
    });
    if (!canonical_path.empty())
      WeldFile(canonical_path, meta.vertices).for_each_welded([&](uint64_t v, uint32_t canon) { map.set(v, map.get(canon)); });
  }
  emit_scratch.map_key = map_key;
}

std::vector<EmitCounts> emit_or_route(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                                      const std::string& prefix, std::span<const EmitLevel> group, uint64_t records,
                                      const core::ClusterOptions& cluster, const EmitOptions& options, Progress& progress,
                                      EmitScratch& emit_scratch, const EmitSink& sink,
                                      std::span<const std::pair<uint32_t, uint32_t>> route_batches, BatchRoutes* routes) {
  const size_t nl = group.size();
  if (nl == 0) return {};
  std::vector<LevelState> levels(nl);
  unsigned bits = 0;
  for (size_t l = 0; l < nl; ++l) {
    LevelState& L = levels[l];
    L.in = group[l];
    const unsigned b = emit_bits(L.in.cells);
    L.shift = bits, L.mask = b == 64 ? ~uint64_t{0} : (uint64_t{1} << b) - 1;
    bits += b;
  }
  if (bits > 64) fail(Status::internal, "emit: a group's cluster maps need more than 64 bits per vertex");

  // The group's cluster maps: stored vertex id -> one record holding every level's cell (PackedMap).
  // A task's batched levels read theirs from each level's cells by vertex (vertex_cells.h), paged
  // (stream/paged_vertex_map.h): only the pages of 64 vertices that the blocks of each group of run_blocks
  // (and pass C's batches) touch are held, read before the group runs. The batches of a level and a
  // process's units of pass A (EmitOptions::classify_unit) keep the one paged map with its pages (map_key
  // names the files, their sizes and times included). Any other group: whole_packed_map.
  PackedMap map;
  bool by_file = options.vertex_cells && !routes && !options.count_only && !options.representatives_only;
  for (const LevelState& L : levels) by_file = by_file && L.in.batched;
  PagedVertexMap* paged = nullptr;
  if (by_file) {
    std::string key = "paged " + std::to_string(options.paged_map_capacity);
    for (const LevelState& L : levels) key += "|" + packed_map_key(prefix, canonical_path, L.in, meta.vertices, records, true);
    if (emit_scratch.map_key != key || !emit_scratch.paged) {
      emit_scratch.map_key.clear();
      emit_scratch.paged.reset();
      std::vector<uint64_t>().swap(emit_scratch.map);  // a whole map from before is not held beside the pages
      std::vector<PagedVertexMap::Level> files;
      for (const LevelState& L : levels) files.push_back({vertex_cells_path(prefix, L.in.level), L.in.cells, L.shift});
      emit_scratch.paged = std::make_unique<PagedVertexMap>(files, meta.vertices, options.paged_map_capacity, options.paged_figures);
    }
    emit_scratch.map_key = key;
    paged = emit_scratch.paged.get();
  } else {
    whole_packed_map(map, levels, bits, prefix, canonical_path, meta, records, routes != nullptr, options, emit_scratch);
  }

  StorePositions positions(store_dir, meta);
  positions.acquire();
  const std::string column_path[3] = {store_dir + "/triangles.u32", store_dir + "/lines.u32", store_dir + "/points.u32"};
  const uint64_t column_count[3] = {meta.triangles, meta.lines, meta.points};
  std::unique_ptr<io::MappedFile> columns[3];
  for (int kind = 0; kind < 3; ++kind) {
    if (column_count[kind] == 0) continue;
    columns[kind] = std::make_unique<io::MappedFile>(column_path[kind]);
    if (columns[kind]->size() != column_count[kind] * 4 * static_cast<uint64_t>(3 - kind))
      fail(Status::io_error, column_path[kind] + ": size does not match store.json");
  }
  const std::vector<Block> whole = whole_blocks(column_count);
  std::vector<Block> blocks = whole;
  if (nl == 1 && levels[0].in.batched && levels[0].in.routes && !routes)
    blocks = routed_blocks(*levels[0].in.routes, levels[0].in.route_bit, column_count);
  const ClassifyUnit* unit = options.classify_unit;
  if (unit) {
    if (unit->first > unit->end || unit->end > whole.size() || unit->paths.size() != nl)
      fail(Status::internal, "emit: a unit of pass A outside the input's blocks");
    blocks.assign(whole.begin() + static_cast<ptrdiff_t>(unit->first), whole.begin() + static_cast<ptrdiff_t>(unit->end));
  }
  // A bounded group: first the blocks near its own regions (all its halo pass needs), then, once the halo
  // is known, those near its halo cells too.
  bool bounded = options.block_bounds && !routes && !options.count_only && !options.representatives_only && !unit;
  for (const LevelState& L : levels) bounded = bounded && L.in.batched && !L.in.routes;
  std::unique_ptr<ReachGrid> reach;
  const core::SceneCube cube = scene_cube_of(meta);
  if (bounded) {
    reach = std::make_unique<ReachGrid>(cube);
    mark_reach(levels, prefix, options.representative, meta.single_precision, in_batch_regions, *reach);
    blocks = bounded_blocks(*options.block_bounds, *reach, column_count);
  }
  // Quadrics are summed for the levels that form their own representatives: a batched level reads them
  // (emit_regions.h), so a group of batched levels (a task's, or one machine's largest level) forms no
  // quadric and fetches no position in pass A.
  for (LevelState& L : levels)
    L.sums_quadrics = options.representative == Representative::quadric && !options.count_only &&
                      (!L.in.batched || options.own_representatives);
  const bool quadric = std::any_of(levels.begin(), levels.end(), [](const LevelState& L) { return L.sums_quadrics; });
  const bool materials = !meta.materials.empty() && !options.count_only && !options.representatives_only;
  std::vector<ObjectRun> material_runs[3];
  if (materials)
    for (int kind = 0; kind < 3; ++kind)
      if (column_count[kind]) material_runs[kind] = read_object_runs(store_dir, kind == 0 ? "triangle" : kind == 1 ? "line" : "point");

  // A vertex's record; every level's field is all ones exactly when the vertex has no cell, so the first
  // level's field tells.
  auto record_of = [&](uint32_t v) {
    const uint64_t r = paged ? paged->get(v) : map.get(v);
    if ((r & levels[0].mask) == levels[0].mask) fail(Status::internal, "emit: vertex " + std::to_string(v) + " has no cell");
    return r;
  };
  auto cell = [&](const LevelState& L, uint64_t record) { return static_cast<uint32_t>((record >> L.shift) & L.mask); };

  // Runs `work(block, ids, outs, scratches)` (one BlockOut and one Scratch per level) over the blocks in
  // parallel groups, and `merge(outs)` in block order: group g's outputs are merged (one thread) while group
  // g + 1 runs (the others), so the two sets of outputs alternate. Merges stay serial and in block order, so
  // this changes no sum.
  std::unique_ptr<WeldFile> weld;  // mapped during pass B only
  // With a paged map: each thread's pages of the blocks it looked at, for the group's load.
  tbb::enumerable_thread_specific<PagedVertexMap::PageSet> page_sets([&] { return PagedVertexMap::PageSet(paged ? meta.vertices : 0); });
  tbb::enumerable_thread_specific<std::vector<Scratch>> scratch([nl] { return std::vector<Scratch>(nl); });
  const size_t concurrent = 4 * static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  std::vector<BlockOut> outs[2] = {std::vector<BlockOut>(concurrent * nl), std::vector<BlockOut>(concurrent * nl)};
  auto run_blocks = [&](const char* stage, bool segments_and_triangles_only, auto&& work, auto&& merge) {
    size_t merged = 0;  // blocks merged so far
    for (size_t g = 0, k = 0; g < blocks.size() || merged < blocks.size(); g += concurrent, ++k) {
      progress.check();
      const size_t n = g < blocks.size() ? std::min(concurrent, blocks.size() - g) : 0;
      std::vector<BlockOut>& current = outs[k % 2];
      std::vector<BlockOut>& previous = outs[(k + 1) % 2];
      const size_t before = std::min(g, blocks.size());  // the blocks of the groups before g
      // The paged map's pages of the group's primitives, read before its blocks run (no merge reads it).
      // Each block is mapped here and again for its work: a few system calls a block, where keeping the
      // group's windows would hold 4 blocks' ids a thread at once.
      if (paged && n > 0) {
        tbb::parallel_for(size_t{0}, n, [&](size_t i) {
          const Block& b = blocks[g + i];
          if (segments_and_triangles_only && b.kind == 2) return;
          const uint64_t arity = static_cast<uint64_t>(3 - b.kind);
          const io::Window w = columns[b.kind]->map(b.first * arity * 4, (b.first + b.count) * arity * 4);
          page_sets.local().add(std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), b.count * arity));
        });
        for (PagedVertexMap::PageSet& set : page_sets) paged->want(set), set.clear();
        paged->load();
      }
      tbb::task_group merging;
      if (merged < before) merging.run([&] {
        for (size_t i = 0; merged + i < before; ++i) merge(&previous[i * nl]);
      });
      tbb::parallel_for(size_t{0}, n, [&](size_t i) {
        const Block& b = blocks[g + i];
        BlockOut* o = &current[i * nl];
        for (size_t l = 0; l < nl; ++l) o[l].clear();
        if (segments_and_triangles_only && b.kind == 2) return;
        const uint64_t arity = static_cast<uint64_t>(3 - b.kind);
        const io::Window w = columns[b.kind]->map(b.first * arity * 4, (b.first + b.count) * arity * 4);
        if (options.primitives_read) options.primitives_read->fetch_add(b.count, std::memory_order_relaxed);
        std::vector<Scratch>& s = scratch.local();
        for (Scratch& x : s) x.clear();
        work(b, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), b.count * arity), o, s.data());
      });
      merging.wait();
      merged = before;
      // Drop the position (and weld map) pages this group touched from the resident set (they stay in the
      // page cache). The weld map's pages, read at random through pass B, were 642 MiB of a group's peak on
      // the 1 B-triangle city (4.31 GiB at --memory 4G) before they were dropped here too.
      positions.release();
      positions.acquire();
      if (weld) weld->release(), weld->acquire();
      if (merged > 0) progress.report(stage, static_cast<double>(merged) / static_cast<double>(blocks.size()));
    }
  };

  if (routes) {
    route_level(levels[0], route_batches, column_count, run_blocks, record_of, cell, *routes);
    return {};
  }

  // Pass A: classify, dedupe per block, sum quadrics; a triangle's positions and quadric are formed once for
  // every level of the group.
  // Blocks start at multiples of 64 primitives: each word of the collapsed bits is written by one block,
  // hence one thread.
  static_assert(kEmitBlock % 64 == 0);
  for (LevelState& L : levels) {
    if (L.sums_quadrics && !L.in.batched) {
      L.quadric_base = options.representatives_only ? L.in.first_cell : 0;
      L.quadrics.resize(options.representatives_only ? L.in.end_cell - L.in.first_cell : L.in.cells);
    }
  }
  find_halos(levels, run_blocks, record_of, cell);
  // A batched level's quadrics: its own and halo cells', which are all it outputs or uses, by rank.
  for (LevelState& L : levels) {
    if (!L.sums_quadrics || !L.in.batched) continue;
    L.ranks_quadrics = true;
    L.touched = RankedBits(L.in.cells);
    for (size_t w = 0; w < L.touched.bits.size(); ++w) L.touched.bits[w] = L.own.bits[w] | L.halo.bits[w];
    L.touched.count();
    L.quadrics.resize(L.touched.ones());
  }
  if (bounded) {
    mark_reach(levels, prefix, options.representative, meta.single_precision,
               [](const LevelState& L, uint64_t c) { return in_batch(L, c); }, *reach);
    blocks = bounded_blocks(*options.block_bounds, *reach, column_count);
  }
  // The collapsed bits of the blocks pass A visits (from units: of every block).
  for (LevelState& L : levels)
    for (int kind = 0; kind < 2; ++kind)
      if (!options.count_only && !options.representatives_only)
        L.collapsed[kind].assign(column_count[kind], options.classified ? whole : blocks, kind);
  auto classify = [&](const Block& b, std::span<const uint32_t> ids, BlockOut* outs_l, Scratch* scratch_l) {
    auto mark = [&](LevelState& L, size_t i) {
      if (options.count_only) return;
      const uint64_t p = b.first + i;
      *L.collapsed[b.kind].word(p / 64) |= uint64_t{1} << (p % 64);
    };
    // The sub-block bit of the block's q-th primitive (units only: BlockOut::edge_masks).
    auto sub_bit = [&](size_t q) { return static_cast<uint16_t>(1u << ((b.first + q) % kEmitBlock / kBoundsBlock)); };
    auto edge = [&](BlockOut& o, Scratch& s, uint32_t c0, uint32_t c1, uint32_t m, size_t q) {
      const std::array<uint32_t, 2> key{std::min(c0, c1), std::max(c0, c1)};
      const auto [index, fresh] = s.edges.insert(key, static_cast<uint32_t>(o.edges.size()));
      if (fresh) {
        o.edges.push_back(key);
        if (materials) o.edge_materials.push_back(m);
        if (unit) o.edge_masks.push_back(0);
      }
      if (unit) o.edge_masks[index] |= sub_bit(q);
    };
    auto point = [&](BlockOut& o, Scratch& s, uint32_t c, uint32_t m, size_t q) {
      if (c != s.last_point) {
        s.last_point = c;
        const auto [index, fresh] = s.points.insert({c}, static_cast<uint32_t>(o.points.size()));
        if (fresh) {
          o.points.push_back(c);
          if (materials) o.point_materials.push_back(m);
          if (unit) o.point_masks.push_back(0);
        }
        s.last_point_index = index;
      }
      if (unit) o.point_masks[s.last_point_index] |= sub_bit(q);
    };
    const size_t arity = static_cast<size_t>(3 - b.kind);
    if (options.representatives_only && arity != 3) return;
    MaterialCursor material_of(material_runs[b.kind], b.first);
    for (size_t i = 0; i < ids.size(); i += arity) {
      const uint32_t m = materials ? material_of(b.first + i / arity) : 0;
      if (arity == 3) {
        const uint32_t v[3] = {ids[i], ids[i + 1], ids[i + 2]};
        const uint64_t r[3] = {record_of(v[0]), record_of(v[1]), record_of(v[2])};
        core::Quadric q;
        if (quadric) {
          double p[3][3];
          for (int k = 0; k < 3; ++k) positions.get(v[k], p[k]);
          q.add_triangle(p[0], p[1], p[2]);
        }
        for (size_t l = 0; l < nl; ++l) {
          LevelState& L = levels[l];
          BlockOut& o = outs_l[l];
          Scratch& s = scratch_l[l];
          const uint32_t c[3] = {cell(L, r[0]), cell(L, r[1]), cell(L, r[2])};
          if (!visited(L, c, 3)) continue;
          if (L.sums_quadrics) {
            for (int k = 0; k < 3; ++k) {
              if ((k > 0 && c[k] == c[0]) || (k > 1 && c[k] == c[1])) continue;
              if (options.representatives_only && (c[k] < L.in.first_cell || c[k] >= L.in.end_cell)) continue;
              if (L.in.batched && !in_batch(L, c[k])) continue;  // neither its own nor in its halo
              add_quadric(o, s, c[k], q);
            }
          }
          if (options.representatives_only) continue;
          if (c[0] != c[1] && c[1] != c[2] && c[0] != c[2]) {
            std::array<uint32_t, 3> key{c[0], c[1], c[2]};
            std::sort(key.begin(), key.end());
            if (s.triangles.insert(key, 0).second) {
              o.triangles.push_back({c[0], c[1], c[2]});
              if (materials) o.triangle_materials.push_back(m);
            }
          } else if (c[0] == c[1] && c[1] == c[2]) {
            point(o, s, c[0], m, i / 3);
            mark(L, i / 3);
          } else {
            edge(o, s, c[0], c[0] != c[1] ? c[1] : c[2], m, i / 3);
            mark(L, i / 3);
          }
        }
      } else if (arity == 2) {
        const uint64_t r0 = record_of(ids[i]), r1 = record_of(ids[i + 1]);
        for (size_t l = 0; l < nl; ++l) {
          const uint32_t c0 = cell(levels[l], r0), c1 = cell(levels[l], r1);
          const uint32_t c[2] = {c0, c1};
          if (!visited(levels[l], c, 2)) continue;
          if (c0 == c1) {
            point(outs_l[l], scratch_l[l], c0, m, i / 2);
            mark(levels[l], i / 2);
          } else {
            edge(outs_l[l], scratch_l[l], c0, c1, m, i / 2);
            mark(levels[l], i / 2);
          }
        }
      } else {
        const uint64_t r0 = record_of(ids[i]);
        for (size_t l = 0; l < nl; ++l) {
          const uint32_t c = cell(levels[l], r0);
          if (visited(levels[l], &c, 1)) point(outs_l[l], scratch_l[l], c, m, i);
        }
      }
    }
  };
  auto merge_block = [&](BlockOut* outs_l) {
    for (size_t l = 0; l < nl; ++l) {
      LevelState& L = levels[l];
      const BlockOut& o = outs_l[l];
      for (size_t i = 0; i < o.triangles.size(); ++i) {
        std::array<uint32_t, 3> key = o.triangles[i];
        std::sort(key.begin(), key.end());
        if (!L.g_triangles.insert(key, 0).second) continue;
        L.triangles.push_back(o.triangles[i]);
        if (materials) L.triangle_materials.push_back(o.triangle_materials[i]);
      }
      for (size_t i = 0; i < o.edges.size(); ++i) {
        if (!L.g_edges.insert(o.edges[i], static_cast<uint32_t>(L.edges.size())).second) continue;
        L.edges.push_back(o.edges[i]);
        if (materials) L.edge_materials.push_back(o.edge_materials[i]);
      }
      for (size_t i = 0; i < o.points.size(); ++i) {
        if (!L.g_points.insert({o.points[i]}, 0).second) continue;
        L.points.push_back(o.points[i]);
        if (materials) L.point_materials.push_back(o.point_materials[i]);
      }
      merge_quadrics(L, o);
    }
  };
  if (unit) {
    write_classified(*unit, blocks, levels, run_blocks, classify);
    return std::vector<EmitCounts>(nl);
  }
  if (options.classified) read_classified(*options.classified, whole, levels, outs[0], materials, merge_block, progress);
  else run_blocks("emit", false, classify, merge_block);
  if (options.representatives_only) {
    for (LevelState& L : levels)
      write_representative_range(prefix, L.in.level, L.in.cells, L.in.first_cell, L.in.end_cell - L.in.first_cell, L.quadrics,
                                 options.representative, cluster, L.in.cell_size, meta.single_precision);
    return std::vector<EmitCounts>(nl);
  }

  std::vector<EmitCounts> counts(nl);
  if (options.count_only) {
    for (size_t l = 0; l < nl; ++l) {
      counts[l].triangles = levels[l].triangles.size();
      counts[l].edges = levels[l].edges.size();
      counts[l].points = levels[l].points.size();
    }
    return counts;
  }

  // Pass Q (batched levels that form their own quadric representatives): the quadrics of the batch's ring,
  // the cells beyond its halo that corners of its triangles fall in. Their representatives place those
  // corners, which shape the normals of the halo's vertices; pass A saw only the triangles touching its own
  // cells and its halo, so a ring cell's quadric is summed here, alone, over every triangle touching it,
  // per block in store order and merged in block order, as for any other cell.
  bool any_ring = false;
  for (LevelState& L : levels) {
    if (!L.ranks_quadrics) continue;
    L.ring = RankedBits(L.in.cells);
    for (const auto& t : L.triangles)
      for (uint32_t c : t)
        if (!L.touched.has(c)) L.ring.set(c);
    L.ring.count();
    any_ring = any_ring || L.ring.ones() > 0;
    L.quadrics.resize(L.touched.ones() + L.ring.ones());
  }
  if (any_ring) {
    auto ring_cell = [](const LevelState& L, uint64_t c) { return L.ring.has(c); };
    const std::vector<Block> classified = blocks;
    if (bounded) {
      reach = std::make_unique<ReachGrid>(cube);
      mark_reach(levels, prefix, options.representative, meta.single_precision,
                 [&](const LevelState& L, uint64_t c) { return L.ranks_quadrics && ring_cell(L, c); }, *reach);
      blocks = bounded_blocks(*options.block_bounds, *reach, column_count);
    }
    run_blocks(
        "emit", true,
        [&](const Block& b, std::span<const uint32_t> ids, BlockOut* outs_l, Scratch* scratch_l) {
          if (b.kind != 0) return;
          for (size_t i = 0; i < ids.size(); i += 3) {
            const uint32_t v[3] = {ids[i], ids[i + 1], ids[i + 2]};
            const uint64_t r[3] = {record_of(v[0]), record_of(v[1]), record_of(v[2])};
            bool formed = false;
            core::Quadric q;
            for (size_t l = 0; l < nl; ++l) {
              LevelState& L = levels[l];
              if (!L.ranks_quadrics) continue;
              const uint32_t c[3] = {cell(L, r[0]), cell(L, r[1]), cell(L, r[2])};
              for (int k = 0; k < 3; ++k) {
                if ((k > 0 && c[k] == c[0]) || (k > 1 && c[k] == c[1]) || !ring_cell(L, c[k])) continue;
                if (!formed) {
                  double p[3][3];
                  for (int j = 0; j < 3; ++j) positions.get(v[j], p[j]);
                  q.add_triangle(p[0], p[1], p[2]);
                  formed = true;
                }
                add_quadric(outs_l[l], scratch_l[l], c[k], q);
              }
            }
          }
        },
        [&](BlockOut* outs_l) {
          for (size_t l = 0; l < nl; ++l) merge_quadrics(levels[l], outs_l[l]);
        });
    blocks = classified;
  }

  // Elimination, before the thickness passes, which then measure the kept edges only. Edges are few next to
  // triangle sides: look each side up among the edges.
  bool any_kept_edges = false;
  for (LevelState& L : levels) {
    L.g_triangles = FlatMap<3, false>();
    L.g_points = FlatMap<1, false>();
    std::vector<uint8_t> on_triangle(L.edges.size(), 0);
    L.by_triangle = RankedBits(L.in.cells), L.by_kept_edge = RankedBits(L.in.cells);
    // In parallel: the flags only ever go from 0 to 1, so the result does not depend on the threads.
    tbb::parallel_for(tbb::blocked_range<size_t>(0, L.triangles.size(), 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const auto& t = L.triangles[i];
        for (int k = 0; k < 3; ++k) {
          L.by_triangle.set_shared(t[k]);
          if (L.edges.empty()) continue;
          const uint32_t e = L.g_edges.find({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
          if (e != FlatMap<2>::empty) std::atomic_ref<uint8_t>(on_triangle[e]).store(1, std::memory_order_relaxed);
        }
      }
    });
    L.g_edges = FlatMap<2>();
    // A batch keeps the edges and points it owns (an edge is owned with its lower cell); every kept edge
    // marks its cells used, so that a point or a vertex of the batch's cells sees every edge that uses it.
    for (size_t i = 0; i < L.edges.size(); ++i) {
      const bool own = owned(L, L.edges[i][0]);
      if (on_triangle[i]) {
        if (own) ++L.counts.edges_on_triangles;
        continue;
      }
      L.by_kept_edge.set(L.edges[i][0]), L.by_kept_edge.set(L.edges[i][1]);
      if (!own) continue;
      L.k_edges.insert(L.edges[i], static_cast<uint32_t>(L.kept_edges.size()));
      L.kept_edges.push_back(L.edges[i]);
      if (materials) L.kept_edge_materials.push_back(L.edge_materials[i]);
    }
    std::vector<std::array<uint32_t, 2>>().swap(L.edges);
    std::vector<uint32_t>().swap(L.edge_materials);
    for (size_t i = 0; i < L.points.size(); ++i) {
      const uint32_t c = L.points[i];
      if (!owned(L, c)) continue;
      if (used(L, c)) {
        ++L.counts.points_covered;
        continue;
      }
      L.kept_points.push_back(c);
      if (materials) L.kept_point_materials.push_back(L.point_materials[i]);
    }
    std::vector<uint32_t>().swap(L.point_materials);
    std::vector<uint32_t>().swap(L.points);
    index_kept_points(L);
    L.kept_sums.resize(L.kept_edges.size() + L.kept_points.size());
    L.distances.resize(L.kept_sums.size());
    any_kept_edges = any_kept_edges || !L.kept_sums.empty();
  }

  release_free_memory();  // pass A's dedupe tables, before the thickness passes
  // Pass A from units: pass B reads only the sub-blocks that hold a primitive collapsed to a kept edge or point.
  if (options.classified && any_kept_edges) blocks = kept_subblocks(*options.classified, blocks, levels, materials, column_count);
  else if (any_kept_edges) blocks = collapsed_subblocks(blocks, levels, column_count);
  // Pass B visits the input triangles and segments that collapsed to a kept edge (or a kept point:
  // index_kept_points) in some level of the group (an eliminated edge's thickness would go unused), and
  // gives each of their corners as a pair {kept edge, canonical vertex} (corner_key): a vertex shared by
  // several of an edge's collapsing primitives counts once (Low & Tan §3.3.1 average over the vertices, not
  // over the triangles), so the thickness does not depend on how a strip was triangulated. Vertices are told
  // apart by their canonical id (the first stored vertex at the position), so an input that repeats a
  // position (OBJ seams, STL soups) counts it once too. A block's pairs are deduplicated in the block
  // (Scratch::corners); all of them go through one external sort (stream/external_sort.h), which puts each
  // kept edge's distinct corners together in vertex order, whatever the blocks, threads or memory.
  // The pairs grow with the scene (on a 48.6 M-triangle city's four coarse levels, 15 M distinct corners):
  // they are held in memory up to a share of options.corner_bytes and spilled in sorted runs beyond, never hashed.
  // It also clears the bit of every primitive whose edge was eliminated.
  if (any_kept_edges && !canonical_path.empty() && meta.vertices > 0) {
    weld = std::make_unique<WeldFile>(canonical_path, meta.vertices);
    weld->acquire();
  }
  auto canonical = [&](uint32_t v) { return weld ? (*weld)(v) : v; };
  uint64_t targets = 0;
  for (LevelState& L : levels) L.first_target = targets, targets += L.kept_sums.size();
  if (targets > UINT32_MAX) fail(Status::internal, "emit: more than 2^32 kept edges and points in one group");
  auto corner_key = [](uint64_t target, uint32_t vertex) { return target << 32 | vertex; };
  auto collect_corners = [&](const Block& b, std::span<const uint32_t> ids, BlockOut* outs_l, Scratch* scratch_l) {
    const size_t arity = static_cast<size_t>(3 - b.kind);
    const uint64_t first_word = b.first / 64, words = (b.count + 63) / 64;  // b.first is a multiple of 64
    for (uint64_t w = first_word; w < first_word + words; ++w) {
      uint64_t any = 0;  // the primitives of this word that collapsed in some level, visited in order
      for (size_t l = 0; l < nl; ++l)
        if (const uint64_t* word = levels[l].collapsed[b.kind].word(w)) any |= *word;
      for (; any; any &= any - 1) {
        const uint64_t bit = uint64_t{1} << std::countr_zero(any);
        const uint32_t* v = &ids[(w * 64 + static_cast<uint64_t>(std::countr_zero(any)) - b.first) * arity];
        uint64_t r[3];
        uint32_t cv[3];
        for (size_t k = 0; k < arity; ++k) r[k] = record_of(v[k]);
        bool fetched = false;
        for (size_t l = 0; l < nl; ++l) {
          LevelState& L = levels[l];
          uint64_t* held = L.collapsed[b.kind].word(w);
          if (!held || !(*held & bit)) continue;
          uint64_t& word = *held;
          uint32_t lo = UINT32_MAX, hi = 0;
          for (size_t k = 0; k < arity; ++k) lo = std::min(lo, cell(L, r[k])), hi = std::max(hi, cell(L, r[k]));
          const uint32_t e = L.k_edges.find({lo, hi});
          if (e == FlatMap<2>::empty) {
            word &= ~bit;
            continue;
          }
          if (!fetched)
            for (size_t k = 0; k < arity; ++k) cv[k] = canonical(v[k]);
          fetched = true;
          for (size_t k = 0; k < arity; ++k)
            if (scratch_l[l].corners.insert({e, cv[k]}, 0).second) outs_l[l].corners.push_back(corner_key(L.first_target + e, cv[k]));
        }
      }
    }
  };

  // Pass B, then pass C in two streams over the distinct pairs in (edge, vertex) order, their positions read
  // in batches through the page cache (stream/position_gather.h, the read way: a kept edge's corners are
  // spread over the whole column): C1 sums each edge's corners in A and in B, for P_A and P_B (a corner in
  // the lower cell goes to A); C2 sums their distances to the line P_A P_B. The sums run in that order,
  // serially, so they depend on the input and options only. The distinct pairs of C1 are pushed, already in
  // order, into a second sorter that keeps them (in memory, or in runs) for C2.
  if (any_kept_edges) {
    // Each of the two sorters a third of corner_bytes, the positions' batch the rest.
    uint64_t sort_bytes = options.corner_bytes / 3;
    if (options.chunk_bytes) sort_bytes = std::min(sort_bytes, options.chunk_bytes);
    std::unique_ptr<WorkDir> own_dir;  // a temporary directory for the runs, should they spill
    if (!options.work) own_dir = std::make_unique<WorkDir>("");
    const WorkDir& dir = options.work ? *options.work : *own_dir;
    ExternalSorter<uint64_t, std::less<uint64_t>> pairs(dir, "corners", sort_bytes);
    run_blocks("emit", true, collect_corners, [&](BlockOut* outs_l) {
      for (size_t l = 0; l < nl; ++l) pairs.push(std::span<const uint64_t>(outs_l[l].corners));
    });
    weld.reset();
    positions.release();
    const std::string column = positions_column_path(store_dir, meta);
    const PositionGather gather(column, meta.single_precision, meta.vertices, false);
    PositionGather::Scratch gs;
    std::vector<uint64_t> batch;
    std::vector<uint32_t> ids;
    std::vector<double> xyz;
    // Calls visit(level, edge, vertex, position) for the pairs of `batch`, in order.
    auto visit_batch = [&](auto&& visit) {
      ids.resize(batch.size());
      for (size_t i = 0; i < batch.size(); ++i) ids[i] = static_cast<uint32_t>(batch[i]);
      if (paged) paged->want(ids), paged->load();
      xyz.resize(3 * batch.size());
      gather.gather(ids, xyz.data(), gs);
      size_t l = 0;
      for (size_t i = 0; i < batch.size(); ++i) {
        const uint64_t t = batch[i] >> 32;
        while (l + 1 < nl && t >= levels[l + 1].first_target) ++l;
        LevelState& L = levels[l];
        const uint32_t e = static_cast<uint32_t>(t - L.first_target);
        visit(L, e, cell(L, record_of(ids[i])) == lower_cell(L, e), &xyz[3 * i]);
      }
      batch.clear();
    };
    // A pair in the batch: its key, id, position and the gather's slot (8 + 4 + 24 + 4 bytes).
    // With a paged map, no more pairs than its capacity holds pages (a pair's vertex may be on a page of its
    // own): the batch's pages are held at once. The batches change no sum (they are in pair order).
    uint64_t batch_pairs = options.corner_bytes / 3 / 40;
    if (paged) batch_pairs = std::min(batch_pairs, paged->capacity_pages());
    const size_t batch_size = static_cast<size_t>(std::max<uint64_t>(batch_pairs, 1024));
    ExternalSorter<uint64_t, std::less<uint64_t>> distinct(dir, "corners-distinct", sort_bytes);
    auto sum_positions = [&](LevelState& L, uint32_t e, bool in_a, const double* p) {
      EdgeSums& s = L.kept_sums[e];
      if (in_a) add(s.a, p), ++s.na;
      else add(s.b, p), ++s.nb;
    };
    uint64_t last = UINT64_MAX;
    pairs.merge([&](uint64_t key) {
      if (key == last) return;
      last = key;
      distinct.push(key);
      batch.push_back(key);
      if (batch.size() == batch_size) visit_batch(sum_positions);
    });
    visit_batch(sum_positions);
    for (LevelState& L : levels) {
      L.pa.resize(L.kept_sums.size()), L.pb.resize(L.kept_sums.size());
      for (size_t i = 0; i < L.kept_sums.size(); ++i)
        for (int k = 0; k < 3; ++k) {
          L.pa[i][k] = L.kept_sums[i].na ? L.kept_sums[i].a[k] / static_cast<double>(L.kept_sums[i].na) : 0;
          L.pb[i][k] = L.kept_sums[i].nb ? L.kept_sums[i].b[k] / static_cast<double>(L.kept_sums[i].nb) : 0;
        }
      for (size_t i = L.kept_edges.size(); i < L.kept_sums.size(); ++i) L.pb[i] = L.pa[i];  // a point: distances to P_A
    }
    auto sum_distances = [&](LevelState& L, uint32_t e, bool in_a, const double* p) {
      const double d = distance_to_line(p, L.pa[e].data(), L.pb[e].data());
      if (in_a) L.distances[e].a += d;
      else L.distances[e].b += d;
    };
    distinct.merge([&](uint64_t key) {
      batch.push_back(key);
      if (batch.size() == batch_size) visit_batch(sum_distances);
    });
    visit_batch(sum_distances);
  }
  positions.release();
  for (BlockOut& o : outs[0]) o = BlockOut();
  for (BlockOut& o : outs[1]) o = BlockOut();
  std::vector<LevelColors> colors(nl);
  if (meta.colors) sum_cell_colors(store_dir, meta, prefix, records, options, levels, colors);

  for (size_t l = 0; l < nl; ++l) {
    LevelState& L = levels[l];
    for (auto& b : L.collapsed) b = CollapsedBits();
    L.k_edges = FlatMap<2>();
    std::vector<float> thickness(L.kept_edges.size());
    for (size_t i = 0; i < L.kept_edges.size(); ++i) {
      const double da = L.kept_sums[i].na ? L.distances[i].a / static_cast<double>(L.kept_sums[i].na) : 0;
      const double db = L.kept_sums[i].nb ? L.distances[i].b / static_cast<double>(L.kept_sums[i].nb) : 0;
      thickness[i] = static_cast<float>(da + db);
    }
    const std::vector<float> point_size = kept_point_sizes(L);
    std::vector<EdgeSums>().swap(L.kept_sums);
    std::vector<Distances>().swap(L.distances);
    std::vector<std::array<double, 3>>().swap(L.pa);
    std::vector<std::array<double, 3>>().swap(L.pb);
    build_parts(L, thickness, point_size, meta.colors ? &colors[l] : nullptr, materials ? &meta.materials : nullptr, prefix,
                cluster, options, meta.single_precision, [&](RegionPart& part) { sink(l, part); });
    colors[l] = LevelColors();
    counts[l] = L.counts;
  }
  return counts;
}

}  // namespace

uint64_t emit_block_count(const StoreMeta& meta) {
  const uint64_t column_count[3] = {meta.triangles, meta.lines, meta.points};
  return whole_blocks(column_count).size();
}

std::vector<EmitCounts> emit_levels(const std::string& store_dir, const StoreMeta& meta,
                                    const std::string& canonical_path, const std::string& prefix,
                                    std::span<const EmitLevel> group, uint64_t records,
                                    const core::ClusterOptions& cluster, const EmitOptions& options,
                                    Progress& progress, EmitScratch& scratch, const EmitSink& sink) {
  return emit_or_route(store_dir, meta, canonical_path, prefix, group, records, cluster, options, progress, scratch, sink, {},
                       nullptr);
}

void route_batches(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                   const std::string& prefix, const EmitLevel& level, std::span<const std::pair<uint32_t, uint32_t>> batches,
                   uint64_t records, const core::ClusterOptions& cluster, Progress& progress, EmitScratch& scratch,
                   BatchRoutes& routes) {
  if (batches.size() > kRouteBatches || !level.cut || !level.regions)
    fail(Status::internal, "emit: at most " + std::to_string(kRouteBatches) + " batches of a cut level are routed at once");
  EmitOptions options;
  options.count_only = true;  // nothing beyond the packed map and the two passes
  emit_or_route(store_dir, meta, canonical_path, prefix, std::span<const EmitLevel>(&level, 1), records, cluster, options, progress,
                scratch, [](size_t, RegionPart&) {}, batches, &routes);
}

}  // namespace lodstream::stream

// Stage 5: emit a group of levels in one pass over the input. See emit_stage.h for the rules.
#include "stream/emit_stage.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
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
#include "io/mapped_file.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_stage.h"
#include "stream/flat_map.h"
#include "stream/store_access.h"
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
// A corner of a primitive that collapsed to a kept edge: the edge, the corner's canonical vertex (the
// first stored vertex at its position), and its position.
struct Corner {
  uint32_t edge, vertex;
  double p[3];
};

struct Block {
  int kind = 0;  // 0 triangles, 1 segments, 2 points
  uint64_t first = 0, count = 0;
};

struct BlockOut {
  std::vector<std::array<uint32_t, 3>> triangles;  // input winding
  std::vector<std::array<uint32_t, 2>> edges;      // lower cell first
  std::vector<uint32_t> points;
  // With materials: per triangle, edge and point above, the material of the input primitive that made it.
  std::vector<uint32_t> triangle_materials, edge_materials, point_materials;
  std::vector<uint32_t> quadric_cells;
  std::vector<core::Quadric> quadrics;
  std::vector<Corner> corners;  // pass B: the block's distinct corners of kept edges, in primitive order
  void clear() {
    triangles.clear(), edges.clear(), points.clear();
    triangle_materials.clear(), edge_materials.clear(), point_materials.clear();
    quadric_cells.clear(), quadrics.clear(), corners.clear();
  }
};

struct Scratch {
  FlatMap<3, false> triangles;
  FlatMap<2> edges;
  FlatMap<1, false> points;
  FlatMap<1> cells;  // pass A: a cell's quadric slot
  FlatMap<2, false> corners;  // pass B: {kept edge, canonical vertex} pairs seen in the block
  // Pass A: the last point and the last quadric cell of the block. Neighbouring triangles mostly fall in
  // the same cell at coarse levels; these skip the hash table then (same result: the cell is in it).
  uint32_t last_point = UINT32_MAX, last_cell = UINT32_MAX, last_slot = 0;
  void clear() {
    triangles.clear(), edges.clear(), points.clear(), cells.clear(), corners.clear();
    last_point = last_cell = UINT32_MAX;
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

// The colours of the output vertices: triangle vertices (their slots in `vertex_slot`) first, then the
// vertices edges and points added (out_vertex: slot -> its first output vertex).
void triangle_vertex_colors(std::span<const uint32_t> vertex_slot, std::span<const uint8_t> slot_rgba, std::vector<uint8_t>* colors) {
  colors->resize(4 * vertex_slot.size());
  for (size_t i = 0; i < vertex_slot.size(); ++i) std::memcpy(&(*colors)[4 * i], &slot_rgba[4 * uint64_t{vertex_slot[i]}], 4);
}
void end_vertex_colors(std::span<const uint32_t> out_vertex, std::span<const uint8_t> slot_rgba, core::LodMesh* mesh) {
  const uint64_t triangle_vertices = mesh->colors.size() / 4;
  mesh->colors.resize(4 * mesh->vertex_count());
  for (size_t slot = 0; slot < out_vertex.size(); ++slot)
    if (out_vertex[slot] != UINT32_MAX && out_vertex[slot] >= triangle_vertices)
      std::memcpy(&mesh->colors[4 * uint64_t{out_vertex[slot]}], &slot_rgba[4 * slot], 4);
}

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

// One level of a group: its field in the packed map and what it accumulates.
struct LevelState {
  EmitLevel in;
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
  // One bit per input triangle and segment that collapsed to an edge, so that passes B and C visit only
  // those.
  std::vector<uint64_t> collapsed[2];
  // Elimination, passes B and C.
  std::vector<std::array<uint32_t, 2>> kept_edges;  // in edge order; k_edges finds them by cells
  FlatMap<2> k_edges;
  std::vector<uint32_t> kept_points;
  std::vector<uint32_t> kept_edge_materials, kept_point_materials;
  std::vector<EdgeSums> kept_sums;
  // Pass B: every distinct {kept edge, canonical vertex} pair, in order of first appearance (block order,
  // then primitive and corner order), found through corner_set.
  FlatMap<2, false> corner_set;
  std::vector<std::array<uint32_t, 2>> corners;
  std::vector<std::array<double, 3>> pa, pb;
  std::vector<Distances> distances;
  EmitCounts counts;
};

}  // namespace

unsigned emit_bits(uint64_t cells) { return std::max(1u, static_cast<unsigned>(std::bit_width(cells))); }

uint64_t emit_level_bytes(uint64_t cells, uint64_t primitives, const EmitOptions& options) {
  // Measured on the 48M-triangle city scene at its finest level (2.56M cells, 5.4M output triangles): the
  // dedupe tables (half-full open addressing, doubled while they grow), the output arrays and the
  // per-thread block tables peak at about 240 bytes per cell during pass A; the quadrics add 80. Measured
  // on the 193M-triangle city with three coarse levels in one group (60K cells): each level also holds
  // about 25 MB whatever its cells, its share of the block outputs and per-thread tables of the blocks in
  // flight (two sets of 4 per thread, 16 here): 24 bytes per primitive in flight.
  // With vertex colours, each cell's CellColor sums (held from the colour pass to the level's output).
  const bool quadric = options.representative == Representative::quadric && !options.count_only;
  const bool colors = options.colors && !options.count_only;
  const bool mean = options.representative == Representative::mean;
  return cells * (240 + (quadric ? sizeof(core::Quadric) : 0) +
                  (colors ? sizeof(CellColor) + (mean ? sizeof(CellWeighted) : 0) : 0)) +
         24 * std::min(primitives, 16 * kEmitBlock);
}

uint64_t emit_map_bytes(uint64_t vertices, unsigned bits) { return (vertices * bits + 63) / 64 * 8 + 8; }

void check_emit_budget(std::span<const uint64_t> cells, size_t first, uint64_t vertices, uint64_t primitives,
                       uint64_t budget, uint64_t resident, const EmitOptions& options) {
  const uint64_t need =
      resident + emit_map_bytes(vertices, emit_bits(cells[first])) + emit_level_bytes(cells[first], primitives, options);
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
  uint64_t work = emit_level_bytes(cells[first], primitives, options);
  size_t end = first + 1;
  while (end < cells.size()) {
    const unsigned b = bits + emit_bits(cells[end]);
    const uint64_t w = work + emit_level_bytes(cells[end], primitives, options);
    if (b > 64 || resident + emit_map_bytes(vertices, b) + w > budget) break;
    bits = b, work = w, ++end;
  }
  return end;
}

// Every level's cell colours (see CellColor). The weight order (order.u32; with the mean representative,
// grades.f64 beside it) is read in chunks; each chunk's colours are gathered once, then every level sums
// them in a task of its own, streaming its cluster map (cells-L.map, the cell of each record in weight
// order: no random lookups in the group's packed map). Each level's cells are summed serially in weight
// order, so the sums do not depend on the threads. Memory: the colour column mapped (4 bytes a vertex), 40
// bytes a cell of each level of the group (80 with the mean), and per chunk 4 bytes a record and level.
void sum_cell_colors(const std::string& store_dir, const StoreMeta& meta, const std::string& prefix, uint64_t records,
                     const EmitOptions& options, const std::vector<LevelState>& levels,
                     std::vector<std::vector<CellColor>>& out, std::vector<std::vector<CellWeighted>>& weighted_out) {
  const size_t nl = levels.size();
  const bool grades = options.representative == Representative::mean && !options.grades_path.empty();
  for (size_t l = 0; l < nl; ++l) {
    out[l].assign(levels[l].in.cells, CellColor{});
    if (grades) weighted_out[l].assign(levels[l].in.cells, CellWeighted{});
  }
  io::MappedFile colors(store_dir + "/colors.rgba8");
  if (colors.size() != meta.vertices * 4) fail(Status::io_error, colors.path() + ": size does not match store.json");
  io::MappedFile order(order_path(prefix));
  if (order.size() != records * 4) fail(Status::io_error, order.path() + ": size does not match the weight index");
  constexpr uint64_t rb = sizeof(double);
  std::unique_ptr<io::MappedFile> index;
  if (grades) {
    index = std::make_unique<io::MappedFile>(options.grades_path);
    if (index->size() != records * rb) fail(Status::io_error, index->path() + ": size does not match the weight index");
  }
  if (records == 0) return;
  const io::Window rgba = colors.map(0, colors.size());
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
    if (grades) g = index->map(first * rb, (first + n) * rb);
    tbb::parallel_for(size_t{0}, nl, [&](size_t l) {
      uint32_t* cs = cells.data() + l * kChunk;
      maps[l]->read(std::span<uint32_t>(cs, n));
      std::vector<CellColor>& sums = out[l];
      for (uint64_t i = 0; i < n; ++i) {
        if (cs[i] >= sums.size()) fail(Status::io_error, cells_path(prefix, levels[l].in.level) + ": cell id out of range");
        const uint8_t* c = reinterpret_cast<const uint8_t*>(&chunk_rgba[i]);
        CellColor& s = sums[cs[i]];
        if (s.count == 0) std::memcpy(s.first, c, 4);
        s.count += 1;
        for (int k = 0; k < 4; ++k) s.sum[k] += c[k];
        if (grades) {
          double grade;
          std::memcpy(&grade, g.data() + i * rb, 8);
          CellWeighted& w = weighted_out[l][cs[i]];
          for (int k = 0; k < 4; ++k) w.weighted[k] += grade * c[k];
          w.weight += grade;
        }
      }
    });
  }
}

std::vector<EmitCounts> emit_levels(const std::string& store_dir, const StoreMeta& meta,
                                    const std::string& canonical_path, const std::string& prefix,
                                    std::span<const EmitLevel> group, uint64_t records,
                                    const core::ClusterOptions& cluster, const EmitOptions& options,
                                    Progress& progress, EmitScratch& emit_scratch, const EmitSink& sink) {
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

  // The group's cluster maps: stored vertex id -> one record holding every level's cell. Each record is
  // composed from all the levels' cell files at once and written once. The records are random writes (the
  // weight index is in grade order); the threads split them by vertex range, each range a whole number of
  // words so that no two threads write one word, and each thread reads every record (sequential, cheap).
  PackedMap map;
  map.reset(emit_scratch.map, meta.vertices, bits);
  {
    io::MappedFile order(order_path(prefix));
    if (order.size() != records * 4) fail(Status::io_error, order.path() + ": size does not match the weight index");
    const size_t parts = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
    const uint64_t per_part = ((meta.vertices + parts - 1) / parts + 63) / 64 * 64;  // 64 records: whole words
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

  StorePositions positions(store_dir, meta);
  positions.acquire();
  const std::string column_path[3] = {store_dir + "/triangles.u32", store_dir + "/lines.u32", store_dir + "/points.u32"};
  const uint64_t column_count[3] = {meta.triangles, meta.lines, meta.points};
  std::unique_ptr<io::MappedFile> columns[3];
  std::vector<Block> blocks;
  for (int kind = 0; kind < 3; ++kind) {
    if (column_count[kind] == 0) continue;
    columns[kind] = std::make_unique<io::MappedFile>(column_path[kind]);
    if (columns[kind]->size() != column_count[kind] * 4 * static_cast<uint64_t>(3 - kind))
      fail(Status::io_error, column_path[kind] + ": size does not match store.json");
    for (uint64_t first = 0; first < column_count[kind]; first += kEmitBlock)
      blocks.push_back({kind, first, std::min(kEmitBlock, column_count[kind] - first)});
  }
  const bool quadric = options.representative == Representative::quadric && !options.count_only;
  const bool materials = !meta.materials.empty() && !options.count_only;
  std::vector<ObjectRun> material_runs[3];
  if (materials)
    for (int kind = 0; kind < 3; ++kind)
      if (column_count[kind]) material_runs[kind] = read_object_runs(store_dir, kind == 0 ? "triangle" : kind == 1 ? "line" : "point");

  // A vertex's record; every level's field is all ones exactly when the vertex has no cell, so the first
  // level's field tells.
  auto record_of = [&](uint32_t v) {
    const uint64_t r = map.get(v);
    if ((r & levels[0].mask) == levels[0].mask) fail(Status::internal, "emit: vertex " + std::to_string(v) + " has no cell");
    return r;
  };
  auto cell = [&](const LevelState& L, uint64_t record) { return static_cast<uint32_t>((record >> L.shift) & L.mask); };

  // Runs `work(block, ids, outs, scratches)` (one BlockOut and one Scratch per level) over the blocks in
  // parallel groups, and `merge(outs)` in block order: group g's outputs are merged (one thread) while group
  // g + 1 runs (the others), so the two sets of outputs alternate. Merges stay serial and in block order, so
  // this changes no sum.
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
        std::vector<Scratch>& s = scratch.local();
        for (Scratch& x : s) x.clear();
        work(b, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), b.count * arity), o, s.data());
      });
      merging.wait();
      merged = before;
      // Drop the position pages this group touched from the resident set (they stay in the page cache).
      positions.release();
      positions.acquire();
      if (merged > 0) progress.report(stage, static_cast<double>(merged) / static_cast<double>(blocks.size()));
    }
  };

  // Pass A: classify, dedupe per block, sum quadrics; a triangle's positions and quadric are formed once for
  // every level of the group.
  // Blocks start at multiples of 64 primitives: each word of the collapsed bits is written by one block,
  // hence one thread.
  static_assert(kEmitBlock % 64 == 0);
  for (LevelState& L : levels) {
    if (quadric) L.quadrics.resize(L.in.cells);
    for (int kind = 0; kind < 2; ++kind)
      if (!options.count_only) L.collapsed[kind].assign((column_count[kind] + 63) / 64, 0);
  }
  auto classify = [&](const Block& b, std::span<const uint32_t> ids, BlockOut* outs_l, Scratch* scratch_l) {
    auto mark = [&](LevelState& L, size_t i) {
      if (options.count_only) return;
      const uint64_t p = b.first + i;
      L.collapsed[b.kind][p / 64] |= uint64_t{1} << (p % 64);
    };
    auto edge = [&](BlockOut& o, Scratch& s, uint32_t c0, uint32_t c1, uint32_t m) {
      const std::array<uint32_t, 2> key{std::min(c0, c1), std::max(c0, c1)};
      if (s.edges.insert(key, 0).second) {
        o.edges.push_back(key);
        if (materials) o.edge_materials.push_back(m);
      }
    };
    auto point = [&](BlockOut& o, Scratch& s, uint32_t c, uint32_t m) {
      if (c == s.last_point) return;
      s.last_point = c;
      if (s.points.insert({c}, 0).second) {
        o.points.push_back(c);
        if (materials) o.point_materials.push_back(m);
      }
    };
    const size_t arity = static_cast<size_t>(3 - b.kind);
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
          if (quadric) {
            for (int k = 0; k < 3; ++k) {
              if ((k > 0 && c[k] == c[0]) || (k > 1 && c[k] == c[1])) continue;
              if (c[k] == s.last_cell) {
                o.quadrics[s.last_slot].add(q);
                continue;
              }
              const auto [slot, fresh] = s.cells.insert({c[k]}, static_cast<uint32_t>(o.quadrics.size()));
              if (fresh) o.quadric_cells.push_back(c[k]), o.quadrics.push_back(q);
              else o.quadrics[slot].add(q);
              s.last_cell = c[k], s.last_slot = slot;
            }
          }
          if (c[0] != c[1] && c[1] != c[2] && c[0] != c[2]) {
            std::array<uint32_t, 3> key{c[0], c[1], c[2]};
            std::sort(key.begin(), key.end());
            if (s.triangles.insert(key, 0).second) {
              o.triangles.push_back({c[0], c[1], c[2]});
              if (materials) o.triangle_materials.push_back(m);
            }
          } else if (c[0] == c[1] && c[1] == c[2]) {
            point(o, s, c[0], m);
          } else {
            edge(o, s, c[0], c[0] != c[1] ? c[1] : c[2], m);
            mark(L, i / 3);
          }
        }
      } else if (arity == 2) {
        const uint64_t r0 = record_of(ids[i]), r1 = record_of(ids[i + 1]);
        for (size_t l = 0; l < nl; ++l) {
          const uint32_t c0 = cell(levels[l], r0), c1 = cell(levels[l], r1);
          if (c0 == c1) {
            point(outs_l[l], scratch_l[l], c0, m);
          } else {
            edge(outs_l[l], scratch_l[l], c0, c1, m);
            mark(levels[l], i / 2);
          }
        }
      } else {
        const uint64_t r0 = record_of(ids[i]);
        for (size_t l = 0; l < nl; ++l) point(outs_l[l], scratch_l[l], cell(levels[l], r0), m);
      }
    }
  };
  run_blocks("emit", false, classify, [&](BlockOut* outs_l) {
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
      for (size_t i = 0; i < o.quadric_cells.size(); ++i) L.quadrics[o.quadric_cells[i]].add(o.quadrics[i]);
    }
  });

  std::vector<EmitCounts> counts(nl);
  if (options.count_only) {
    for (size_t l = 0; l < nl; ++l) {
      counts[l].triangles = levels[l].triangles.size();
      counts[l].edges = levels[l].edges.size();
      counts[l].points = levels[l].points.size();
    }
    return counts;
  }

  // Elimination, before the thickness passes, which then measure the kept edges only. Edges are few next to
  // triangle sides: look each side up among the edges.
  bool any_kept_edges = false;
  for (LevelState& L : levels) {
    L.g_triangles = FlatMap<3, false>();
    L.g_points = FlatMap<1, false>();
    std::vector<uint8_t> on_triangle(L.edges.size(), 0);
    std::vector<uint8_t> used(L.in.cells, 0);
    // In parallel: the flags only ever go from 0 to 1, so the result does not depend on the threads.
    tbb::parallel_for(tbb::blocked_range<size_t>(0, L.triangles.size(), 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const auto& t = L.triangles[i];
        for (int k = 0; k < 3; ++k) {
          std::atomic_ref<uint8_t>(used[t[k]]).store(1, std::memory_order_relaxed);
          if (L.edges.empty()) continue;
          const uint32_t e = L.g_edges.find({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
          if (e != FlatMap<2>::empty) std::atomic_ref<uint8_t>(on_triangle[e]).store(1, std::memory_order_relaxed);
        }
      }
    });
    L.g_edges = FlatMap<2>();
    for (size_t i = 0; i < L.edges.size(); ++i) {
      if (on_triangle[i]) {
        ++L.counts.edges_on_triangles;
        continue;
      }
      L.k_edges.insert(L.edges[i], static_cast<uint32_t>(L.kept_edges.size()));
      L.kept_edges.push_back(L.edges[i]);
      if (materials) L.kept_edge_materials.push_back(L.edge_materials[i]);
      used[L.edges[i][0]] = used[L.edges[i][1]] = 1;
    }
    std::vector<std::array<uint32_t, 2>>().swap(L.edges);
    std::vector<uint32_t>().swap(L.edge_materials);
    for (size_t i = 0; i < L.points.size(); ++i) {
      const uint32_t c = L.points[i];
      if (used[c]) {
        ++L.counts.points_covered;
        continue;
      }
      L.kept_points.push_back(c);
      if (materials) L.kept_point_materials.push_back(L.point_materials[i]);
    }
    std::vector<uint32_t>().swap(L.point_materials);
    std::vector<uint32_t>().swap(L.points);
    L.kept_sums.resize(L.kept_edges.size());
    L.distances.resize(L.kept_edges.size());
    any_kept_edges = any_kept_edges || !L.kept_edges.empty();
  }

  // Pass B visits the input triangles and segments that collapsed to a kept edge in some level of the
  // group (an eliminated edge's thickness would go unused), fetching their corners once, and collects each
  // kept edge's distinct corners: a vertex shared by several of its collapsing primitives counts once
  // (Low & Tan §3.3.1 average over the vertices, not over the triangles), so the thickness does not depend
  // on how a strip was triangulated. Vertices are told apart by their canonical id (the first stored vertex
  // at the position), so an input that repeats a position (OBJ seams, STL soups) counts it once too.
  // A block's corners are deduplicated in the block (Scratch::corners) and then in the level
  // (LevelState::corner_set) while merging in block order, so that the sums and the corner order do not
  // depend on the threads. It also clears the bit of every primitive whose edge was eliminated.
  std::unique_ptr<WeldFile> weld;
  if (any_kept_edges && !canonical_path.empty() && meta.vertices > 0) {
    weld = std::make_unique<WeldFile>(canonical_path, meta.vertices);
    weld->acquire();
  }
  auto canonical = [&](uint32_t v) { return weld ? (*weld)(v) : v; };
  auto collect_corners = [&](const Block& b, std::span<const uint32_t> ids, BlockOut* outs_l, Scratch* scratch_l) {
    const size_t arity = static_cast<size_t>(3 - b.kind);
    const uint64_t first_word = b.first / 64, words = (b.count + 63) / 64;  // b.first is a multiple of 64
    for (uint64_t w = first_word; w < first_word + words; ++w) {
      uint64_t any = 0;  // the primitives of this word that collapsed in some level, visited in order
      for (size_t l = 0; l < nl; ++l) any |= levels[l].collapsed[b.kind][w];
      for (; any; any &= any - 1) {
        const uint64_t bit = uint64_t{1} << std::countr_zero(any);
        const uint32_t* v = &ids[(w * 64 + static_cast<uint64_t>(std::countr_zero(any)) - b.first) * arity];
        uint64_t r[3];
        uint32_t cv[3];
        for (size_t k = 0; k < arity; ++k) r[k] = record_of(v[k]);
        double p[3][3];
        bool fetched = false;
        for (size_t l = 0; l < nl; ++l) {
          LevelState& L = levels[l];
          uint64_t& word = L.collapsed[b.kind][w];
          if (!(word & bit)) continue;
          uint32_t lo = UINT32_MAX, hi = 0;
          for (size_t k = 0; k < arity; ++k) lo = std::min(lo, cell(L, r[k])), hi = std::max(hi, cell(L, r[k]));
          const uint32_t e = L.k_edges.find({lo, hi});
          if (e == FlatMap<2>::empty) {
            word &= ~bit;
            continue;
          }
          if (!fetched)
            for (size_t k = 0; k < arity; ++k) cv[k] = canonical(v[k]), positions.get(cv[k], p[k]);
          fetched = true;
          for (size_t k = 0; k < arity; ++k)
            if (scratch_l[l].corners.insert({e, cv[k]}, 0).second)
              outs_l[l].corners.push_back({e, cv[k], {p[k][0], p[k][1], p[k][2]}});
        }
      }
    }
  };

  // Pass B: the distinct corners of the kept edges and their sums, for P_A and P_B (a corner in the lower
  // cell goes to A).
  if (any_kept_edges) {
    run_blocks("emit", true, collect_corners, [&](BlockOut* outs_l) {
      for (size_t l = 0; l < nl; ++l) {
        LevelState& L = levels[l];
        for (const Corner& c : outs_l[l].corners) {
          if (!L.corner_set.insert({c.edge, c.vertex}, 0).second) continue;
          L.corners.push_back({c.edge, c.vertex});
          EdgeSums& e = L.kept_sums[c.edge];
          if (cell(L, record_of(c.vertex)) == L.kept_edges[c.edge][0]) add(e.a, c.p), ++e.na;
          else add(e.b, c.p), ++e.nb;
        }
      }
    });
  }
  weld.reset();

  // Pass C: mean distances of the distinct corners to the line through the mean positions, from the corner
  // list (no pass over the input): distances in parallel, summed per edge in corner order.
  for (LevelState& L : levels) {
    L.corner_set = FlatMap<2, false>();
    L.pa.resize(L.kept_edges.size()), L.pb.resize(L.kept_edges.size());
    for (size_t i = 0; i < L.kept_edges.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        L.pa[i][k] = L.kept_sums[i].na ? L.kept_sums[i].a[k] / static_cast<double>(L.kept_sums[i].na) : 0;
        L.pb[i][k] = L.kept_sums[i].nb ? L.kept_sums[i].b[k] / static_cast<double>(L.kept_sums[i].nb) : 0;
      }
    std::vector<double> d(L.corners.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, L.corners.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const auto [e, v] = L.corners[i];
        double p[3];
        positions.get(v, p);
        d[i] = distance_to_line(p, L.pa[e].data(), L.pb[e].data());
      }
    });
    for (size_t i = 0; i < L.corners.size(); ++i) {
      const auto [e, v] = L.corners[i];
      if (cell(L, record_of(v)) == L.kept_edges[e][0]) L.distances[e].a += d[i];
      else L.distances[e].b += d[i];
    }
    std::vector<std::array<uint32_t, 2>>().swap(L.corners);
  }
  positions.release();
  for (BlockOut& o : outs[0]) o = BlockOut();
  for (BlockOut& o : outs[1]) o = BlockOut();
  std::vector<std::vector<CellColor>> cell_colors(meta.colors ? nl : 0);
  std::vector<std::vector<CellWeighted>> cell_weighted(meta.colors ? nl : 0);
  if (meta.colors) sum_cell_colors(store_dir, meta, prefix, records, options, levels, cell_colors, cell_weighted);

  for (size_t l = 0; l < nl; ++l) {
    LevelState& L = levels[l];
    const uint64_t cells = L.in.cells;
    const double cell_size = L.in.cell_size;
    for (auto& b : L.collapsed) std::vector<uint64_t>().swap(b);
    L.k_edges = FlatMap<2>();
    std::vector<float> thickness(L.kept_edges.size());
    for (size_t i = 0; i < L.kept_edges.size(); ++i) {
      const double da = L.kept_sums[i].na ? L.distances[i].a / static_cast<double>(L.kept_sums[i].na) : 0;
      const double db = L.kept_sums[i].nb ? L.distances[i].b / static_cast<double>(L.kept_sums[i].nb) : 0;
      thickness[i] = static_cast<float>(da + db);
    }
    std::vector<EdgeSums>().swap(L.kept_sums);
    std::vector<Distances>().swap(L.distances);
    std::vector<std::array<double, 3>>().swap(L.pa);
    std::vector<std::array<double, 3>>().swap(L.pb);

    // The cells in use, numbered in order of first use: triangle corners, then edge and point ends.
    std::vector<uint32_t> slot_of(cells, UINT32_MAX);
    std::vector<uint32_t> slot_cell;
    auto use = [&](uint32_t c) {
      if (slot_of[c] == UINT32_MAX) slot_of[c] = static_cast<uint32_t>(slot_cell.size()), slot_cell.push_back(c);
      return slot_of[c];
    };
    std::vector<uint32_t> tri_slots;
    tri_slots.reserve(3 * L.triangles.size());
    for (const auto& t : L.triangles)
      for (uint32_t c : t) tri_slots.push_back(use(c));
    std::vector<std::array<uint32_t, 3>>().swap(L.triangles);
    const size_t triangle_slots = slot_cell.size();
    for (const auto& e : L.kept_edges) use(e[0]), use(e[1]);
    for (uint32_t c : L.kept_points) use(c);

    // Their representatives, reading the cell table through windows in cell order, the windows in parallel
    // (each representative depends on its cell alone, so the bytes do not depend on the threads).
    std::vector<double> rep(3 * slot_cell.size());
    {
      const CellInfoReader f(cell_info_path(prefix, L.in.level), cells, cell_info_kind(options.representative), meta.single_precision);
      constexpr uint64_t window_cells = 1 << 16;
      tbb::parallel_for(uint64_t{0}, (cells + window_cells - 1) / window_cells, [&](uint64_t window) {
        const uint64_t first = window * window_cells, end = std::min(cells, first + window_cells);
        io::Window w;
        for (uint64_t c = first; c < end; ++c) {
          const uint32_t slot = slot_of[c];
          if (slot == UINT32_MAX) continue;
          if (!w.data()) w = f.map(first, end);
          const CellInfo ci = f.get(w, c - first);
          double* p = &rep[3 * slot];
          double mean[3];
          for (int k = 0; k < 3; ++k) mean[k] = ci.sum[k] / static_cast<double>(ci.vertices);
          if (options.representative == Representative::center) {
            std::copy(ci.center, ci.center + 3, p);
          } else if (options.representative == Representative::mean) {
            for (int k = 0; k < 3; ++k) p[k] = ci.weight > 0 ? ci.weighted[k] / ci.weight : mean[k];
          } else {
            double lo[3], hi[3];
            for (int k = 0; k < 3; ++k) {
              if (cluster.clustering == core::Clustering::uniform) {
                const double sq = static_cast<double>(core::grid_square(ci.center[k], cell_size));
                lo[k] = sq * cell_size, hi[k] = (sq + 1) * cell_size;
              } else {
                lo[k] = ci.center[k] - cell_size / 2, hi[k] = ci.center[k] + cell_size / 2;
              }
            }
            const std::array<double, 3> x = core::quadric_minimizer(L.quadrics[c], mean, lo, hi);
            std::copy(x.begin(), x.end(), p);
          }
        }
      });
    }
    std::vector<core::Quadric>().swap(L.quadrics);

    // Output vertices: triangle corners split by normal (core/normals.h), then edge and point ends, which
    // reuse a triangle vertex of their cell when there is one.
    core::LodMesh mesh;
    core::CreaseNormals normals;
    core::crease_normals(std::span<const double>(rep.data(), 3 * triangle_slots), tri_slots,
                         options.normals ? options.crease_degrees : 180.0, normals);
    std::vector<uint32_t>().swap(tri_slots);
    mesh.positions.reserve(3 * (normals.vertex.size() + slot_cell.size() - triangle_slots));
    for (uint32_t v : normals.vertex)
      for (int k = 0; k < 3; ++k) mesh.positions.push_back(static_cast<float>(rep[3 * v + k]));
    mesh.normals = std::move(normals.normals);
    mesh.triangles = std::move(normals.triangles);
    std::vector<uint8_t> slot_rgba;
    if (meta.colors) {
      slot_rgba.resize(4 * slot_cell.size());
      for (size_t s = 0; s < slot_cell.size(); ++s) cell_rgba(cell_colors[l][slot_cell[s]],
                                                     cell_weighted[l].empty() ? nullptr : &cell_weighted[l][slot_cell[s]],
                                                     options.representative, &slot_rgba[4 * s]);
      triangle_vertex_colors(normals.vertex, slot_rgba, &mesh.colors);
    }
    std::vector<uint32_t> out_vertex(slot_cell.size(), UINT32_MAX);
    for (size_t i = 0; i < normals.vertex.size(); ++i)
      if (out_vertex[normals.vertex[i]] == UINT32_MAX) out_vertex[normals.vertex[i]] = static_cast<uint32_t>(i);
    std::vector<uint32_t>().swap(normals.vertex);
    auto end_vertex = [&](uint32_t c) {
      const uint32_t slot = slot_of[c];
      if (out_vertex[slot] == UINT32_MAX) {
        out_vertex[slot] = static_cast<uint32_t>(mesh.positions.size() / 3);
        for (int k = 0; k < 3; ++k) mesh.positions.push_back(static_cast<float>(rep[3 * slot + k])), mesh.normals.push_back(0.0f);
      }
      return out_vertex[slot];
    };
    for (const auto& e : L.kept_edges) {
      mesh.edges.push_back(end_vertex(e[0]));
      mesh.edges.push_back(end_vertex(e[1]));
    }
    mesh.thickness = std::move(thickness);
    for (uint32_t c : L.kept_points) mesh.points.push_back(end_vertex(c));
    if (meta.colors) {
      end_vertex_colors(out_vertex, slot_rgba, &mesh);
      std::vector<CellColor>().swap(cell_colors[l]);
      std::vector<CellWeighted>().swap(cell_weighted[l]);
    }
    if (materials) {
      mesh.materials = meta.materials;
      mesh.triangle_materials = std::move(L.triangle_materials);
      mesh.edge_materials = std::move(L.kept_edge_materials);
      mesh.point_materials = std::move(L.kept_point_materials);
    }
    std::vector<std::array<uint32_t, 2>>().swap(L.kept_edges);
    std::vector<uint32_t>().swap(L.kept_points);
    // The mesh alone goes to the sink: the cell tables (about 36 bytes a used cell) are freed first.
    std::vector<uint32_t>().swap(slot_of);
    std::vector<uint32_t>().swap(slot_cell);
    std::vector<uint32_t>().swap(out_vertex);
    std::vector<double>().swap(rep);

    counts[l] = L.counts;
    counts[l].triangles = mesh.triangle_count();
    counts[l].edges = mesh.edge_count();
    counts[l].points = mesh.point_count();
    sink(l, mesh);
  }
  return counts;
}

}  // namespace lodstream::stream

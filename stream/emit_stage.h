// Stage 5 of the pipeline (../shared/DESIGN.md "emit"; Low & Tan 1997 §3.3–3.5): map every input
// primitive through one level's cluster map and build that level's mesh.
//
// - Classification: a triangle whose corners fall in three distinct cells stays a triangle (input
//   winding kept); in two, it collapses to an edge between them; in one, to a point. An input segment
//   likewise gives an edge or a point, an input point a point.
// - Elimination: no two triangles on the same three cells (the first in store order is kept, with its
//   winding), no two edges on the same two cells, no edge that is a side of an output triangle, no point
//   on a cell an output triangle or edge uses.
// - Thickness (§3.3.1): for an edge between cells A and B, over the distinct corner vertices (in A or B)
//   of the input triangles and segments that collapsed to it: P_A, P_B the mean positions of those in A and
//   in B, D_A, D_B their mean distances to the line P_A P_B; thickness = D_A + D_B. A vertex shared by
//   several collapsing primitives counts once (vertices told apart by position, through the weld's
//   canonical ids), so a strip of width w has thickness w however it is triangulated.
// - Representatives: center (the cell's center vertex), mean (grade-weighted mean of the cell's vertices;
//   the plain mean when every grade is 0), quadric (Lindstrom 2000: area-weighted plane quadrics of every
//   input triangle touching the cell, minimised around the cell's mean and clamped into the cell's box).
// - Normals: per vertex with a crease angle (core/normals.h).
// - Materials (a store with a material table): every kept triangle, edge and point takes the material of
//   the input primitive it was first made from, in store order (the one whose cells the dedupe kept).
// - Colours (a store with vertex colours): every output vertex takes its cell's colour, weighted as the
//   representative is: center the center vertex's (the cell's first vertex in weight order), mean the
//   grade-weighted mean of its vertices' colours (the plain mean when every grade is 0), quadric the plain
//   mean; rounded to the nearest byte. So edge and point ends take the colour of the vertices they stand for.
//
// Determinism: primitives are processed in fixed blocks of the store (not of the parse or memory plan),
// each block's sums are formed in store order and merged in block order; output primitives and vertices
// are numbered in order of first appearance. So the bytes depend on the input and options only.
// Levels are emitted in groups that share one pass over the input (emit_levels, emit_group_end below), and
// each level region by region (stream/emit_regions.h): a level too large for the memory plan in batches of
// regions, each batch visiting the primitives that touch its cells or its halo's, so that every cell it
// outputs, and every neighbour's vertex its parts use, sees its whole neighbourhood. Routed batches
// (route_batches) read only the words of 64 primitives that hold such primitives; their packed map is
// built once for the level (EmitScratch).
// Memory: the group's packed cluster maps (bit_width(cells) bits per stored vertex and level, kept in
// EmitScratch between groups; a sharded task's paged, stream/paged_vertex_map.h: only the pages of the
// vertices its groups of blocks touch) and per level one bit per input triangle and segment of the blocks
// it visits (collapsed to an edge or not), plus what grows with the output: at the peak (classification), the triangle and edge dedupe
// tables and the quadrics. Elimination runs before the thickness passes: pass B visits only the
// primitives that collapsed to a kept edge and keeps their distinct corners (a set of {edge, vertex} pairs
// and a list of them, about 40 bytes a corner); pass C reads that list, not the input.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/floating_cell.h"
#include "core/mesh.h"
#include "lodstream/lodstream.h"
#include "stream/block_bounds.h"
#include "stream/memory.h"
#include "stream/paged_vertex_map.h"
#include "stream/emit_regions.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

struct ClassifyUnit;  // below

struct EmitOptions {
  Representative representative = Representative::center;
  double crease_degrees = 30;
  bool normals = true;
  bool count_only = false;  // stop after classification and triangle dedupe (target search)
  // Only sum the quadrics of the levels' cell ranges and write their representatives (emit_regions.h).
  bool representatives_only = false;
  // grades.f64 of the weight index (stream/grade_stage.h, written for the mean representative only), for
  // the grade weights of vertex colours under the mean representative; empty: plain means.
  std::string grades_path = {};
  bool colors = false;     // the store has vertex colours (emit_level_bytes: nothing at the peak)
  bool materials = false;  // the store has a material table: counted in emit_level_bytes
  // Where passes B and C (thickness, point sizes) spill the sorted runs of their {kept edge, corner} pairs
  // when these outgrow their share (corner_bytes: emit_corner_bytes of the stage's budget); none: in a
  // temporary directory.
  const WorkDir* work = nullptr;
  uint64_t corner_bytes = 40 << 20;
  uint64_t chunk_bytes = 0;  // --chunk-bytes (0: none) caps those sorts' memory too, so that tests make them spill
  // Batched levels only (a sharded task's, stream/shard.h): read only the blocks whose box comes within a
  // cell size of the batch's regions, then of its halo cells (stream/block_bounds.h). The same bytes.
  const BlockBounds* block_bounds = nullptr;
  // Batched levels only: read the group's packed map from the levels' vertex-cells files (written by the
  // shared stages, stream/vertex_cells.h) instead of decoding every record of the cluster maps, paged
  // (stream/paged_vertex_map.h): only the pages of the vertices the group's blocks touch, at most
  // paged_map_capacity bytes of them but a group's own. The same records.
  bool vertex_cells = false;
  uint64_t paged_map_capacity = 64ull << 20;
  PagedMapFigures* paged_figures = nullptr;  // where the paged maps' figures are added, if anywhere
  // Batched levels only (a sharded task's, stream/shard.h): form the representatives of the batch's own and
  // halo cells from the cell table and, for quadric representatives, quadrics summed in pass A, instead of
  // reading them from the level's representatives file. The same bytes: pass A visits every triangle that
  // touches such a cell, and a bounded batch's blocks are spans of the whole input's blocks
  // (bounded_blocks), so each cell's quadric is summed per block in store order and merged in block order
  // as a pass over the whole input sums it.
  bool own_representatives = false;
  // When set, the primitives the passes read are added to it (the blocks' sizes, pass by pass).
  std::atomic<uint64_t>* primitives_read = nullptr;
  // Pass A as units (a sharded run's wide levels, stream/wide_units.h). With classify_unit, pass A runs over
  // the unit's blocks of the whole input's (emit_blocks) and writes each block's outputs to the unit's file
  // of each level of the group, and the emit stops there. With classified (per level of the group, its
  // units' files in unit order), pass A's outputs are read from those files instead of being formed: each
  // block's are the same outputs, merged in the same block order, so the level gets the same bytes.
  // Only for groups of batched levels whose batch is every region (visited() is then true for every
  // primitive, in the unit as in the task that reads it).
  const ClassifyUnit* classify_unit = nullptr;
  const std::vector<std::vector<std::string>>* classified = nullptr;
};

// Pass A's blocks: kEmitBlock primitives each (fixed, so that sums do not depend on the memory plan or the
// threads), the triangles', then the segments', then the points', each kind in store order.
uint64_t emit_block_count(const StoreMeta& meta);
// A unit of pass A (EmitOptions::classify_unit): blocks [first, end) of emit_block_count's, and per level of
// the group the file its outputs go to.
struct ClassifyUnit {
  uint64_t first = 0, end = 0;
  std::vector<std::string> paths;
};

struct EmitCounts {
  uint64_t triangles = 0, edges = 0, points = 0;
  uint64_t edges_on_triangles = 0, points_covered = 0;  // eliminated
};

// What one group of levels leaves to the next: the buffer of the packed cluster maps, so that every group
// does not fault in and zero fresh pages for it (measured at a tenth of the stage's time on a 48M-triangle
// scene). Holds no result: any scratch, fresh or used, gives the same output.
// The map of a lone level emitted in batches is kept whole for its next batches: map_key names what it was
// made from (empty: nothing reusable), and a batch whose key matches does not build it again.
struct EmitScratch {
  std::vector<uint64_t> map;
  std::string map_key;
  // A task's paged map (EmitOptions::vertex_cells), kept with its pages for the next batch or unit of the
  // same levels (map_key).
  std::unique_ptr<PagedVertexMap> paged;
};

// Which batches of a batched level visit which primitives (route_batches below): per kind (triangles,
// segments, points) one byte per word of 64 primitives (in store order), whose bit i says that batch i of the
// routed batches visits a primitive of the word (it touches a cell of the batch or of its halo).
// At most kRouteBatches batches are routed at once.
inline constexpr size_t kRouteBatches = 8;
// `halo`: per cell of the level, bit i set when the cell is in batch i's halo (the batch then takes it
// from here instead of a pass of its own).
struct BatchRoutes {
  std::vector<uint8_t> words[3];
  std::vector<uint8_t> halo;
};

// One level to emit: its index in the cluster stage's files, its cell count and size.
struct EmitLevel {
  size_t level = 0;
  uint64_t cells = 0;
  double cell_size = 0;
  // Partitioned emit (neither count_only nor representatives_only): the level's cut and the regions of its
  // cells (at least of those in [first_region, end_region)); the parts of regions [first_region, end_region)
  // are made. `batched`: those regions are not
  // the whole level: only the input primitives touching a cell of theirs or of their halo (the cells that
  // share an input primitive with one of theirs) are visited, which gives every cell of either its complete
  // neighbourhood, and representatives are read from representatives_path (written before).
  const LevelCut* cut = nullptr;
  const CellRegions* regions = nullptr;
  uint32_t first_region = 0, end_region = 0;
  bool batched = false;
  // representatives_only: the cells whose quadrics are summed.
  uint64_t first_cell = 0, end_cell = 0;
  // Batched, with routes: only the words of 64 primitives whose route_bit is set in `routes` are read (the
  // batch's halo and classification passes then cost its share of the input, not the whole input).
  const BatchRoutes* routes = nullptr;
  unsigned route_bit = 0;
};


// One region's part of a level, as emit hands it on: the part the region sink gets, and what welds the parts
// into the level's mesh. A vertex of the level is (cell, variant): the variant-th output vertex of the cell
// (its corners split by normal, in order of first appearance over the level's triangles; a cell used only
// by edges and points has one vertex, with a zero normal).
// `mesh` holds exactly the primitives the region owns (a triangle with its lowest cell, an edge with its lower
// cell, a point with its cell), in the level's order, and the vertices they use numbered in order of first
// use; a vertex of a neighbouring region's cell appears with the same position and normal, to the bit, as
// in that region's parts.
struct RegionPart {
  uint32_t region = 0;  // index in the level's cut
  core::LodMesh mesh;
  std::vector<uint64_t> vertex_key;  // per vertex of mesh: cell << 32 | variant
  // The vertices the region owns (those of its cells used by the level), in cell order, then variant.
  std::vector<uint64_t> owned_key;
  std::vector<float> owned_positions, owned_normals;
  std::vector<uint8_t> owned_colors;  // RGBA per owned vertex when the store has vertex colours, else empty
};

// Emits the levels of `group` (cells of all of them together fit in 64 bits per vertex: the sum over the
// levels of emit_bits(cells)) in one pass over the input: each triangle's corners, positions and quadric
// are read and formed once and serve every level. Every level gets the same bytes as when emitted alone:
// its sums are still formed per block and merged in block order. `sink(i, part)` receives the parts of
// group[i], region by region in region order, as soon as the level's batch is finished, in group order,
// and may consume them.
// With options.count_only the sink is not called. `canonical_path` empty: every stored vertex is canonical.
// `prefix`: the cluster stage's files.
using EmitSink = std::function<void(size_t, RegionPart&)>;
std::vector<EmitCounts> emit_levels(const std::string& store_dir, const StoreMeta& meta,
                                    const std::string& canonical_path, const std::string& prefix,
                                    std::span<const EmitLevel> group, uint64_t records,
                                    const core::ClusterOptions& cluster, const EmitOptions& options,
                                    Progress& progress, EmitScratch& scratch, const EmitSink& sink);

// Routes `batches` (at most kRouteBatches [first, end) region ranges of `level`, whose cut and regions are
// set) in two passes over the input, instead of two per batch: the first marks each cell's halo batches (one
// byte a cell: the batches, other than its own, that it shares an input triangle or segment with), the second
// each word's batches. A batch emitted with these routes visits exactly the primitives it visits without them,
// and has the same halo. Memory: the level's packed map, a byte a cell and a byte per 64 primitives (the
// routes, held beside each batch).
void route_batches(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                   const std::string& prefix, const EmitLevel& level, std::span<const std::pair<uint32_t, uint32_t>> batches,
                   uint64_t records, const core::ClusterOptions& cluster, Progress& progress, EmitScratch& scratch,
                   BatchRoutes& routes);

// Memory model of the grouping. A level of C cells takes emit_bits(C) bits of each packed map record.
unsigned emit_bits(uint64_t cells);
// What passes B and C (thickness, point sizes) hold beside what pass A leaves, once per group, for a stage
// budget of `budget` bytes: a twenty-fourth of it, within [1 MiB, 40 MiB]; a third each for the two sorts of
// {kept edge, corner} pairs (beyond, they spill) and for a batch of corner positions. Counted on top of pass
// A's peak, not inside it: elimination frees pass A's hash tables, but the allocator keeps most of their
// pages (measured on the 193 M-triangle city at --memory 1G: 46 MiB of pass A's 189 came back).
uint64_t emit_corner_bytes(uint64_t budget);
// Working memory of one level in a group (its dedupe tables, outputs and quadrics at the peak, pass A,
// plus its share of the buffers of the blocks in flight, of an input of `primitives` primitives).
uint64_t emit_level_bytes(uint64_t cells, uint64_t primitives, const EmitOptions& options);
// The packed cluster maps of `vertices` stored vertices at `bits` bits each.
uint64_t emit_map_bytes(uint64_t vertices, unsigned bits);
// The memory contract: Failure(Status::usage), naming the level, its cells and the memory it needs, when
// level `first` alone (its map and working memory) and `resident` (what the caller holds beside the stage;
// simplify holds nothing, since it writes each level as soon as it is finished) do not fit in `budget`, so
// that the stage stops instead of passing the budget.
void check_emit_budget(std::span<const uint64_t> cells, size_t first, uint64_t vertices, uint64_t primitives,
                       uint64_t budget, uint64_t resident, const EmitOptions& options);
// The end of the group that starts at level `first` (levels of `cells` cells, finest first): the levels
// after it join while their records fit in 64 bits and the map, their working memory and `resident` (as in
// check_emit_budget) fit in `budget`. The first level always runs, alone if need be. The
// grouping changes no output byte, only how many passes the input gets.
size_t emit_group_end(std::span<const uint64_t> cells, size_t first, uint64_t vertices, uint64_t primitives, uint64_t budget,
                      uint64_t resident, const EmitOptions& options);

// Partitioned emit (not count_only). A level is emitted whole (one batch of every region, sharing a pass
// with other levels as emit_group_end allows) when its map, its working memory (emit_level_bytes) and its
// per-cell tables fit in `budget`; otherwise in batches of regions, each batch's owned cells at most
// batch_cells, after its representatives are written in ranges of at most reps_range_cells cells. A level
// holds kLevelBytesPerCell bytes a cell beside its batches: its cells' regions (4: CellRegions of the
// whole cut), a batch's bits (about 2, kBatchBitsPer64Cells), its slots (4 a numbered cell, all of them when
// the level is whole), the level files' tables (8).
inline constexpr uint64_t kLevelBytesPerCell = 18;
// What a batched level holds per cell of the whole level, whoever holds its regions and level files: a
// batch's bits (own and halo cells, those numbering its quadrics and its ring, cells used by a triangle or a
// kept edge, cells numbered for output, the colours' cells; RankedBits, counts included where they are
// ranked): 96 bytes a 64 cells.
inline constexpr uint64_t kBatchBitsPer64Cells = 96;
// And per cell of a batch (its own, halo and ring cells): its slot by rank (4) and, for its own cells, its
// region by rank (4: the regions of a sharded task's run, CellRegions).
inline constexpr uint64_t kBatchCellBytes = 8;
struct EmitLevelPlan {
  bool batched = false;
  uint64_t batch_cells = 0, reps_range_cells = 0;
};
// Fails with Status::usage, naming the level, its cells and the memory it needs, when even a batch of its
// largest region (`largest_region` cells) does not fit, so that the stage stops before it starts; with
// `fits`, sets it to false instead.
EmitLevelPlan plan_emit_level(size_t level, uint64_t cells, uint64_t largest_region, uint64_t vertices,
                              uint64_t primitives, uint64_t budget, const EmitOptions& options, bool* fits = nullptr);

}  // namespace lodstream::stream

// Every level's cluster map by stored vertex, for sharded tasks (stream/shard.h).
//
// WORK/vertex-cells-L.bits holds, for each stored vertex in id order, its cell in level L (a welded
// vertex: its canonical vertex's cell), or none, packed to the level's bits: a field of
// vertex_cell_bits(C) bits a vertex for a level of C cells (all ones: no cell), the field the emit's packed
// map gives the level (emit_stage.cpp), at bit v·b of an array of 64-bit words in the machine's byte order.
// (Until 2026-12-05 a uint32 a vertex: twice the bytes to write, keep on the shared disk and read in every
// task, on the 193 M-triangle city's five levels 82 bits a vertex instead of 160.) A range of vertices that
// starts at a multiple of 64 starts on a word, so the units below, ranges of such starts, write whole words
// of their own. The cluster stage's maps (stream/cell_map_file.h) are
// bit streams in weight order, readable only whole, so a task that built its group's packed map from them
// decoded every record of the scene whatever its share (3.1 and 2.9 s for the two groups of one task of
// eight on the 193 M-triangle city: a third of the task); from these files it reads the packed map in
// vertex order, sequentially. They are written once by the shared stages (write_vertex_cells); a level
// clustered whole by a cluster share, by that share (stream/cluster_shares.h).
// (Looking the cells up in the mapped files instead of packing the map did not hold the memory cap: a
// group of blocks whose primitives reach all over the vertex ids, as the 193 M-triangle city's 484 K
// segments, stored after its triangles, do, maps every page of every level's file: a task of eight at
// --memory 1G peaked at 1.9 GiB. Since 2026-12-06 a task reads them into a paged map instead,
// stream/paged_vertex_map.h: the records of the pages of 64 vertices each group of blocks references, read
// with pread, at most a capacity of them beside a group's own.)
//
// Invariant: field v of vertex-cells-L.bits is the field that the packed map of the emit stage
// (emit_stage.cpp) gives v for level L, so a task that reads these emits the same bytes.
// Memory: one range of vertices at 4 bytes each and its packed words, as many as `budget` allows.
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "stream/bit_fields.h"
#include "stream/progress.h"

namespace lodstream::stream {

inline constexpr uint32_t kNoCell = UINT32_MAX;

std::string vertex_cells_path(const std::string& prefix, size_t level);

// Bits of a level of `cells` cells a vertex: bit_width(cells), at least 1 (the cells 0 .. 2^b - 2, and all
// ones for no cell).
unsigned vertex_cell_bits(uint64_t cells);
// Bytes of `n` fields of `bits` bits, in whole words.
inline uint64_t packed_field_bytes(uint64_t n, unsigned bits) { return (n * bits + 63) / 64 * 8; }
// The size of a level's file.
inline uint64_t vertex_cells_bytes(uint64_t vertices, uint64_t cells) { return packed_field_bytes(vertices, vertex_cell_bits(cells)); }
// `cells` (kNoCell: none) as fields of `bits` bits from bit 0 of `words`, resized to whole words.
void pack_vertex_cells(std::span<const uint32_t> cells, unsigned bits, std::vector<uint64_t>& words);
// Field i of `bits` bits (at most 32) of the words at `data` (read_bits).
inline uint64_t packed_field(const char* data, uint64_t i, unsigned bits) { return read_bits(data, i * bits, bits); }
// Unit u of `units`' vertices: [u·V/units, (u+1)·V/units), each end rounded down to a multiple of 64 (but
// the last, V), so that the unit's fields start on a word.
std::pair<uint64_t, uint64_t> vertex_cells_unit_range(uint64_t vertices, unsigned unit, unsigned units);

// Writes level `level`'s file from the cluster stage's files under `prefix` (its cell map and the weight
// index's order) and the weld map at `canonical_path` (empty: none). Throws Failure(io_error) on a map
// that does not match `records` records of `cells` cells.
void write_vertex_cells(const std::string& prefix, const std::string& canonical_path, uint64_t vertices, uint64_t records,
                        size_t level, uint64_t cells, uint64_t budget, Progress& progress);
// The same from a map at `map_path` and an order at `order_path`, into `path` (a cluster share's whole
// level: stream/cluster_shares.h).
void write_vertex_cells_of(const std::string& map_path, const std::string& order_path, const std::string& canonical_path,
                           const std::string& path, uint64_t vertices, uint64_t records, uint64_t cells, uint64_t budget,
                           Progress& progress);

// Where one level's cells come from for the units below, and where its cells by vertex go.
struct VertexCellsSource {
  std::vector<std::string> pairs_paths;  // its pairs by vertex range (stream/vertex_pairs.h), read in place of its map; or none
};
struct VertexCellsLevel : VertexCellsSource {
  std::string map_path;  // its cell map
  std::string path;      // its cells by vertex, sized beforehand (vertex_cells_bytes)
  uint64_t cells = 0;
};

// Every level of `levels`' file as `units` units by vertex range, for the prepare jobs of a sharded run
// (stream/units.h): unit u writes the vertices vertex_cells_unit_range(V, u, units) of each level in place. A level
// with pairs reads only its range's buckets of them, and the buckets holding the canonical vertices before
// the unit that its welded vertices name; one without, one decoding of the map in weight order, keeping
// those cells. Then its welded vertices take their canonical vertices'.
// The same bytes as write_vertex_cells_of. Memory: 4 bytes a vertex of the unit and its packed words, 8 a welded vertex of it,
// a bit and a half a vertex of the scene.
void write_vertex_cells_unit(const std::vector<VertexCellsLevel>& levels, const std::string& order_path,
                             const std::string& canonical_path, uint64_t vertices, uint64_t records, unsigned unit, unsigned units,
                             Progress& progress);
// Every level of `levels` (cells[l] cells each) as `units` units, taken up by every process that calls it
// and its threads (take_units_on_threads, from unit `index`) in prefix/vertex-cells-units/, the files sized
// once for `key`; returns the units' figures (seconds, runners), or null for no level.
// `sources`: empty, or per level of `levels` where its cells come from (write_vertex_cells_unit).
nlohmann::ordered_json write_vertex_cells_in_units(const std::string& prefix, const std::string& canonical_path, uint64_t vertices,
                                                   uint64_t records, const std::vector<size_t>& levels,
                                                   const std::vector<uint64_t>& cells, const std::vector<VertexCellsSource>& sources,
                                                   unsigned units, unsigned index, const nlohmann::ordered_json& key, uint64_t budget,
                                                   Progress& progress);

}  // namespace lodstream::stream

// Every level's cluster map by stored vertex, for sharded tasks (stream/shard.h).
//
// WORK/vertex-cells-L.u32 holds, for each stored vertex in id order, its cell in level L (a welded
// vertex: its canonical vertex's cell), or kNoCell. The cluster stage's maps (stream/cell_map_file.h) are
// bit streams in weight order, readable only whole, so a task that built its group's packed map from them
// decoded every record of the scene whatever its share (3.1 and 2.9 s for the two groups of one task of
// eight on the 193 M-triangle city: a third of the task); from these files it reads the packed map in
// vertex order, sequentially. They are written once by the shared stages (write_vertex_cells); a level
// clustered whole by a cluster share, by that share (stream/cluster_shares.h).
// (Looking the cells up in the mapped files instead of packing the map did not hold the memory cap: a
// group of blocks whose primitives reach all over the vertex ids, as the 193 M-triangle city's 484 K
// segments, stored after its triangles, do, maps every page of every level's file: a task of eight at
// --memory 1G peaked at 1.9 GiB.)
//
// Invariant: vertex-cells-L.u32[v] is the cell that the packed map of the emit stage (emit_stage.cpp)
// gives v for level L, so a task that reads these emits the same bytes.
// Memory: one range of vertices at 4 bytes each, as many as `budget` allows.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "stream/progress.h"

namespace lodstream::stream {

inline constexpr uint32_t kNoCell = UINT32_MAX;

std::string vertex_cells_path(const std::string& prefix, size_t level);

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
  std::string plain_path;                // its plain cells (stream/cluster_merge.h), read in place of decoding its map; or ""
  std::vector<std::string> pairs_paths;  // its pairs by vertex range (stream/vertex_pairs.h), read in place of both; or none
};
struct VertexCellsLevel : VertexCellsSource {
  std::string map_path;  // its cell map
  std::string path;      // its cells by vertex, sized beforehand to 4 bytes a vertex
  uint64_t cells = 0;
};

// Every level of `levels`' file as `units` units by vertex range, for the prepare jobs of a sharded run
// (stream/units.h): unit u writes the vertices [u·V/units, (u+1)·V/units) of each level in place. A level
// with pairs reads only its range's buckets of them, and the buckets holding the canonical vertices before
// the unit that its welded vertices name; one without, one decoding of the map (or one read of its plain
// cells) in weight order, keeping those cells. Then its welded vertices take their canonical vertices'.
// The same bytes as write_vertex_cells_of. Memory: 4 bytes a vertex of the unit, 8 a welded vertex of it,
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

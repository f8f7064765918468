// A scene store's primitives in chunks that each carry their own vertices, for the report's out-of-core
// tracing of an original (stream/report.cpp): the primitives in store order, triangles, then lines, then
// points ("global ids" 0..primitives), cut into consecutive ranges whose estimated bytes stay within a
// budget. A chunk's vertices are the distinct vertices its primitives use, numbered in increasing store
// id, so a chunk's arrays depend on its range only; its positions are read through short mapped windows
// (the positions column is never mapped whole: its pages would count as resident).
//
// Memory: a bit per store vertex and a 32-bit count per 64 of them (3/16 byte a vertex), beside the
// chunk's own arrays.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "stream/scene_store.h"

namespace lodstream::stream {

// Estimated bytes of a chunk: per triangle, line, point and distinct vertex.
struct ChunkCosts {
  double triangle = 0, line = 0, point = 0, vertex = 0;
};

struct StoreChunk {
  uint64_t first = 0, end = 0;  // global ids [first, end)
  uint64_t vertices = 0;        // distinct vertices its primitives use
};

struct ChunkGeometry {
  uint64_t first = 0;                              // global id of the chunk's first primitive
  std::vector<float> xyz;                          // its vertices (store positions as float)
  std::vector<uint32_t> triangles, lines, points;  // local vertex ids
  // With a store that has vertex colours or materials: RGB per triangle, line and point, as
  // core::primitive_rgb draws it; else empty.
  std::vector<uint8_t> triangle_rgb, line_rgb, point_rgb;
};

class StoreChunks {
 public:
  StoreChunks(const std::string& store_dir, const StoreMeta& meta);

  // Cuts the store into chunks of at most `bytes` by `costs` (at least one primitive each). Also marks
  // every vertex any primitive uses (used()).
  void plan(const ChunkCosts& costs, uint64_t bytes);
  // The same over the primitives [first, end) only (a report task's range, stream/report_shard.h): the
  // chunks cover that range, and used() marks the vertices its primitives use.
  void plan_range(const ChunkCosts& costs, uint64_t bytes, uint64_t first, uint64_t end);
  // Cuts again, from chunk `from` on (the chunks before it stay), by other costs or another size: for a
  // caller that measured what a chunk really takes. One pass over the ids from there.
  void replan(size_t from, const ChunkCosts& costs, uint64_t bytes);
  const std::vector<StoreChunk>& chunks() const { return chunks_; }
  // Reads chunk `index` into `out`; with `colors`, its primitives' colours too (ChunkGeometry::*_rgb).
  void read(size_t index, ChunkGeometry* out, bool colors = false);

  // Vertices used by any primitive, after plan(): the count, and their positions in store order.
  uint64_t used_vertices() const { return used_count_; }
  void for_used_vertices(const std::function<void(std::span<const float> xyz)>& visit_block) const;
  // Positions of the given store vertices (any order), as float.
  std::vector<float> positions_of(const std::vector<uint32_t>& ids) const;
  // Positions of the given store vertices, in increasing id order (each id once), as float: read in runs
  // of nearby ids, not one id at a time.
  std::vector<float> positions_of_sorted(std::span<const uint32_t> ids) const;
  // The used vertices' bits after plan() (a bit a store vertex).
  std::span<const uint64_t> used_bits() const { return used_; }

 private:
  // Cuts [from, primitives) into chunks appended to chunks_; with `mark`, sets used_ too.
  void cut(uint64_t from, const ChunkCosts& costs, uint64_t bytes, bool mark);
  // visit(global id of the first primitive, arity, its ids) over consecutive blocks of [first, end).
  void for_ids(uint64_t first, uint64_t end,
               const std::function<void(uint64_t, int, std::span<const uint32_t>)>& visit) const;
  // Positions of the vertices whose bits are set, bits[0] being store word word0, in increasing order.
  void read_positions(std::span<const uint64_t> bits, uint64_t word0, uint64_t count, std::vector<float>& xyz) const;
  // The chunk's primitive colours (ChunkGeometry::*_rgb), its `count` vertices those whose bits are set.
  void read_colors(const StoreChunk& c, std::span<const uint64_t> bits, uint64_t count, ChunkGeometry* out);

  std::string dir_;
  StoreMeta meta_;
  std::vector<StoreChunk> chunks_;
  uint64_t end_ = 0;            // the planned range's end (global id)
  std::vector<uint64_t> used_;  // bit per vertex
  uint64_t used_count_ = 0;
  // Per kind (triangle, line, point), the store's object runs, read by the first chunk that needs them
  // (read_colors with materials) and kept for the others.
  std::vector<ObjectRun> runs_[3];
  bool runs_read_[3] = {false, false, false};
};

}  // namespace lodstream::stream

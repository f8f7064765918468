// Positions of vertex ids that come in an order spread over the whole column (the weight index's order):
// the cluster and labels stages read them by id. Two ways, the same values either way:
// - mapped: the column mapped whole. Fastest, but every page it touches counts in the process's resident
//   set (the memory contract counts mapped file pages), and in weight order it touches them all: 12 bytes
//   a stored vertex for a float store, 1.64 GB on a 193 M-triangle scene.
// - read: the ids of a batch go through the column's segments in file order, each segment with one pread
//   of the span its ids need where they are dense, one pread per id where they are sparse (a read costs
//   about as much as copying a few KiB, kGatherGapBytes). The bytes come through the OS page cache, which
//   is not the process's: the process holds the batch's arrays and a segment buffer per thread, whatever
//   the column's size. Remapping the column to drop its pages does not bound it instead: a fault maps pages
//   around the one it needs (fault-around), so a block of random ids maps far more than its bytes.
// A batch of b ids costs about min(b, segments) reads and min(b · kGatherGapBytes, column) bytes copied:
// larger batches read the column fewer times.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/progress.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

inline constexpr uint64_t kGatherSegmentBytes = 256 << 10;  // the read buffer: one segment of the column
inline constexpr uint64_t kGatherGapBytes = 4096;           // a segment's ids closer than this on average: one read
// What a batch of ids costs the read way beside its positions: a 4-byte slot per id, plus the buffer and the
// per-segment counts (fixed).
inline constexpr uint64_t kGatherBytesPerId = 4;

// Whether a stage maps the column of `column_bytes` whole: where it takes at most half of the stage's
// `memory_bytes` and no `chunk_cap` (--chunk-bytes, 0: none) below its size asks for small reads (which
// tests use to force the read way on small scenes). Nothing else decides it, and neither way changes a byte.
bool map_positions_whole(uint64_t column_bytes, uint64_t memory_bytes, uint64_t chunk_cap);

class PositionGather {
 public:
  // The store's column of `vertices` positions at `path` (float if single_precision, else double).
  // Throws Failure(io_error) when its size does not match.
  PositionGather(const std::string& path, bool single_precision, uint64_t vertices, bool mapped,
                 uint64_t segment_bytes = kGatherSegmentBytes);
  ~PositionGather();
  PositionGather(const PositionGather&) = delete;
  PositionGather& operator=(const PositionGather&) = delete;

  // One per thread that gathers.
  struct Scratch {
    std::vector<uint32_t> slot;    // ids' indices, grouped by segment
    std::vector<uint32_t> start;   // per segment, its first entry in slot (then its end)
    std::vector<uint32_t> lo, hi;  // per segment, its lowest and highest id in the batch
  };
  // xyz[3i .. 3i + 2] = the position of ids[i], widened to double (exact for a float store). Thread-safe
  // with one Scratch per thread. The read way runs its segments as TBB tasks (a segment's buffer each). Throws Failure(io_error) on a read error, Failure(internal) for an id
  // past the column.
  void gather(std::span<const uint32_t> ids, double* xyz, Scratch& scratch) const;

  bool mapped() const { return mapped_; }
  uint64_t column_bytes() const { return vertices_ * stride_; }

 private:
  void gather_read(std::span<const uint32_t> ids, double* xyz, Scratch& s) const;
  void read_exact(char* out, uint64_t bytes, uint64_t offset) const;
  void put(const char* p, double* out) const;

  io::MappedFile file_;
  bool single_, mapped_;
  uint64_t vertices_, stride_, segment_vertices_;
  io::Window window_;  // mapped: the whole column
  int fd_ = -1;        // read: the column, opened for pread
};

// The weight index's positions in weight order (issue 19): WORK/positions-w.f32 (or .f64) holds, for record
// i of order.u32, the position of its vertex at the store's precision (12 or 24 bytes a record). A sharded
// run's grading merge units write it, each its records' part in place (one machine does not: its work
// directory stays within 1.5x the input), so that the passes that read positions in weight order (a whole
// level's cluster share and its sums, the prepare job's sums, the labels stage) read them sequentially
// (RecordPositions), where gathering them by id the read way costs a copy of most of the column per batch:
// on the 193 M-triangle city at --memory 1G about 40 GB through pread for one whole level's share (its two
// passes), a third of its CPU.
// Invariant: record i holds exactly the bytes the store's column holds for vertex order[i].
std::string ordered_positions_path(const std::string& prefix, bool single_precision);
// Once the clustering merge of a sharded run has summed its cells nothing reads the file (the emit reads
// the store's column), so it is spent (stream/cluster_merge.h): emptied, its name kept because the grading
// stage's stamp names it (1.17 GB of the 193 M-triangle city's shared directory, gone before the pairs, the
// cells by vertex and the tasks' parts are written). A pass that needs positions in weight order again (a clustering at other sizes) finds it empty
// and reads the store's column by id instead (live_ordered_positions), the same positions.
void spend_ordered_positions(const std::string& path);
// `path` when it holds positions (not spent, not absent), else "" (read the store's column).
std::string live_ordered_positions(const std::string& path);

// Records a gathering batch of write_ordered_positions holds under `memory_bytes` (at least 1): half of it.
uint64_t ordered_positions_batch(uint64_t memory_bytes);

// Writes the positions of records [first, first + n) of the weight index at `order_path` (uint32 ids) into
// `out`, sized beforehand to the whole index, at their records' offsets: gathered from the column of the
// store in `store_dir` (`meta`'s), mapped whole where it takes at most half of `memory_bytes`, else in
// batches of ordered_positions_batch(memory_bytes) records (each a copy of the column's segments that hold
// its ids; the 193 M-triangle city's merge units at --memory 1G, 12.2 M records each, take one). Memory:
// within `memory_bytes`. Throws Failure(io_error) on a read or write error.
void write_ordered_positions(const std::string& store_dir, const StoreMeta& meta, const std::string& order_path,
                             uint64_t first, uint64_t n, const io::OffsetFile& out, uint64_t memory_bytes, Progress& progress);

// Reads a file written by write_ordered_positions, sequentially, through mapped windows.
class OrderedPositions {
 public:
  // Throws Failure(io_error) unless `path` holds `records` positions at the given precision.
  OrderedPositions(const std::string& path, bool single_precision, uint64_t records);
  // xyz[3i .. 3i + 2] = the position of record first + i, widened to double (exact for a float store), for i < n.
  // Thread-safe.
  void read(uint64_t first, uint64_t n, double* xyz) const;

 private:
  io::MappedFile file_;
  bool single_;
  uint64_t records_;
};

// The positions of the weight index's records, block by block in weight order, as the passes in weight
// order read them: from the ordered file when `ordered_path` names one, else from the store's column at
// `column_path` by id, mapped whole when `map_whole` (the caller's budget rule), else the read way.
class RecordPositions {
 public:
  RecordPositions(const std::string& column_path, bool single_precision, uint64_t vertices, const std::string& ordered_path,
                  uint64_t records, bool map_whole);
  // Whether a small block costs no more than a large one (the ordered file, or the column mapped whole);
  // else blocks should be large, since each costs a copy of the column's segments that hold its ids.
  bool per_block() const { return ordered_ || column_.mapped(); }
  // xyz = the positions of records [first, first + ids.size()), whose ids are `ids`. Thread-safe with one
  // Scratch per thread.
  void load(uint64_t first, std::span<const uint32_t> ids, double* xyz, PositionGather::Scratch& scratch) const;

 private:
  std::unique_ptr<OrderedPositions> ordered_;
  PositionGather column_;
};

}  // namespace lodstream::stream

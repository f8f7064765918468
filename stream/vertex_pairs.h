// A split level's cells bucketed by vertex range: what the clustering merge's map units (stream/cluster_merge.h)
// hand to the cells by vertex (stream/vertex_cells.h).
//
// The map units make the cells in weight order; the cells by vertex need them in vertex order. Read from
// the plain cells, each cells-by-vertex unit scanned the whole weight order and every record's cell and
// kept the eighth of them in its vertex range: 16 units read 12.5 GB and took 27 thread-seconds on the
// 193 M-triangle city, growing with the units (the tasks) as much as with the scene. So each map unit also
// writes its records as (vertex, cell) pairs into one file, in buckets of 2^shift vertex ids (at most
// kVertexPairBuckets buckets), and a cells-by-vertex unit reads only the buckets of its range: every pair is
// written once and read about once.
//
// File layout (little-endian, per split level L and map unit u: WORK/cluster-merge/map/pairs-L-u.bin):
// vertices (u64), the unit's first record and its end (u64 each), shift (u32), buckets (u32), then
// buckets + 1 pair offsets (u64: bucket b's pairs are [offset[b], offset[b + 1])), then the pairs
// (u32 vertex, u32 cell), each bucket's in record order.
// Invariant: a level's files hold every record of the weight index once, its vertex (the order's id) with
// its cell, in the bucket of vertex >> shift.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "io/offset_file.h"

namespace lodstream::stream {

inline constexpr unsigned kVertexPairBuckets = 64;

// The bucket shift for `vertices` vertices: vertex >> shift < kVertexPairBuckets.
unsigned vertex_pair_shift(uint64_t vertices);

// Writes one map unit's pairs of one level into `path`, bucket by bucket at offsets known from the
// bucket counts (`counts[b]`: the unit's records whose vertex is in bucket b, of every level alike).
// add() takes the records in order; commit() checks every bucket got its count. A buffer of
// kBufferPairs pairs a bucket. Throws Failure(io_error), Failure(internal) on a count that does not match.
class VertexPairsWriter {
 public:
  static constexpr size_t kBufferPairs = 8192;
  VertexPairsWriter(const std::string& path, uint64_t vertices, uint64_t first_record, uint64_t end_record,
                    std::span<const uint64_t> counts);
  void add(uint32_t vertex, uint32_t cell) {
    const uint32_t b = vertex >> shift_;
    std::vector<uint32_t>& buf = buffers_[b];
    buf.push_back(vertex), buf.push_back(cell);
    if (buf.size() == 2 * kBufferPairs) flush(b);
  }
  void commit();

 private:
  void flush(uint32_t b);
  io::OffsetFile file_;
  unsigned shift_;
  std::vector<uint64_t> next_, end_;  // per bucket: the next pair's offset, and its end
  std::vector<std::vector<uint32_t>> buffers_;
};

// The bucket counts of the vertices `ids` for `vertices` vertices, added to `counts` (kVertexPairBuckets).
void count_vertex_pairs(std::span<const uint32_t> ids, uint64_t vertices, std::span<uint64_t> counts);

// A level's pair files, every map unit's (`paths`), checked to hold `records` records of `vertices`
// vertices, their record ranges tiling [0, records). Throws Failure(io_error) otherwise.
class VertexPairs {
 public:
  VertexPairs(std::vector<std::string> paths, uint64_t vertices, uint64_t records);
  // Calls f(vertex, cell) for every pair whose vertex is in [lo, hi), in file and bucket order.
  // Failure(io_error) on a vertex of the wrong bucket or a cell >= cells.
  template <class F>
  void for_each_in(uint64_t lo, uint64_t hi, uint64_t cells, F&& f) const {
    std::vector<uint32_t> buf;
    for (const File& file : files_)
      for (uint64_t b = lo >> shift_; b < file.offsets.size() - 1 && (b << shift_) < hi; ++b)
        for (uint64_t at = file.offsets[b]; at < file.offsets[b + 1];) {
          const uint64_t n = std::min<uint64_t>(file.offsets[b + 1] - at, kReadPairs);
          buf.resize(2 * n);
          file.file->read(buf.data(), 8 * n, at * 8 + file.pairs_at);
          for (uint64_t i = 0; i < n; ++i) {
            const uint32_t v = buf[2 * i], c = buf[2 * i + 1];
            if (v >> shift_ != b || c >= cells) bad(file);
            if (v - lo < hi - lo) f(v, c);  // unsigned: below lo wraps around
          }
          at += n;
        }
  }
  unsigned shift() const { return shift_; }

 private:
  static constexpr uint64_t kReadPairs = 1 << 16;
  struct File {
    std::unique_ptr<io::OffsetFile> file;
    uint64_t pairs_at = 0;          // byte offset of the first pair
    std::vector<uint64_t> offsets;  // per bucket and one past, in pairs
  };
  [[noreturn]] static void bad(const File& file);
  std::vector<File> files_;
  unsigned shift_ = 0;
};

}  // namespace lodstream::stream

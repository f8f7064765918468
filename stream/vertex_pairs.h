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
// File layout (the machine's byte order, per split level L and map unit u: WORK/cluster-merge/map/pairs-L-u.bin):
// vertices (u64), the unit's first record and its end (u64 each), shift, buckets, cell bits and pair bits
// (u32 each), then the buckets' pair counts (u64 each), then each bucket's pairs in record order, packed:
// pair i of a bucket at bit i·w of the bucket's words (w = shift + cell bits), the vertex's low `shift` bits
// (its bucket gives the rest) and above them its cell in bit_width(cells - 1) bits (at least 1); each bucket
// starts on a word. (Until 2026-12-05 a u32 vertex and a u32 cell: 64 bits a pair where the 193 M-triangle
// city's levels take 32 to 45, 60 % of that over its five levels; the pairs were then the largest item of
// the shared directory's peak.)
// Invariant: a level's files hold every record of the weight index once, its vertex (the order's id) with
// its cell, in the bucket of vertex >> shift.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "io/offset_file.h"
#include "stream/bit_fields.h"

namespace lodstream::stream {

inline constexpr unsigned kVertexPairBuckets = 64;

// The bucket shift for `vertices` vertices: vertex >> shift < kVertexPairBuckets.
unsigned vertex_pair_shift(uint64_t vertices);

// Writes one map unit's pairs of one level of `cells` cells into `path`, bucket by bucket at offsets known
// from the bucket counts (`counts[b]`: the unit's records whose vertex is in bucket b, of every level
// alike). add() takes the records in order (each cell below `cells`); commit() checks every bucket got its
// count. A buffer of kBufferPairs words a bucket. Throws Failure(io_error), Failure(internal) on a count
// that does not match.
class VertexPairsWriter {
 public:
  static constexpr size_t kBufferPairs = 8192;
  VertexPairsWriter(const std::string& path, uint64_t vertices, uint64_t first_record, uint64_t end_record, uint64_t cells,
                    std::span<const uint64_t> counts);
  void add(uint32_t vertex, uint32_t cell) {
    if (cell >= cells_) cell_past_the_level();
    Bucket& k = buckets_[vertex >> shift_];
    const uint64_t pair = (vertex & low_) | (uint64_t{cell} << shift_);
    if (k.bit == 64) k.words.push_back(0), k.bit = 0;
    k.words.back() |= pair << k.bit;
    if (k.bit + width_ > 64) {
      k.words.push_back(pair >> (64 - k.bit));
      k.bit += width_ - 64;
    } else {
      k.bit += width_;
    }
    if (k.words.size() > kBufferPairs) flush(k, false);
  }
  void commit();

 private:
  struct Bucket {
    std::vector<uint64_t> words;  // the last one filled to `bit` bits (64: full)
    unsigned bit = 64;
    uint64_t next = 0, end = 0;   // its next word's offset in the file, and its end
  };
  void flush(Bucket& k, bool last);
  [[noreturn]] void cell_past_the_level() const;
  io::OffsetFile file_;
  uint64_t cells_;
  unsigned shift_, width_;
  uint64_t low_;  // the vertex bits a pair holds
  std::vector<Bucket> buckets_;
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
    std::vector<uint64_t> buf;
    for (const File& file : files_) {
      if (file.cell_bits != pair_cell_bits(cells)) bad(file);
      const unsigned w = shift_ + file.cell_bits;
      const uint64_t low = (uint64_t{1} << shift_) - 1;
      for (uint64_t b = lo >> shift_; b < file.counts.size() && (b << shift_) < hi; ++b)
        for (uint64_t i = 0; i < file.counts[b];) {
          // Pairs [i, i + n): the words from the one holding pair i's first bit to the one holding the last's.
          const uint64_t n = std::min<uint64_t>(file.counts[b] - i, kReadPairs), w0 = i * w / 64;
          const uint64_t words = ((i + n) * w + 63) / 64 - w0;
          buf.resize(words);
          file.file->read(buf.data(), 8 * words, file.words_at + 8 * (file.offsets[b] + w0));
          for (uint64_t k = i; k < i + n; ++k) {
            const uint64_t x = read_bits(reinterpret_cast<const char*>(buf.data()), k * w - 64 * w0, w);
            const uint64_t v = (b << shift_) | (x & low), c = x >> shift_;
            if (c >= cells) bad(file);
            if (v - lo < hi - lo) f(static_cast<uint32_t>(v), static_cast<uint32_t>(c));  // unsigned: below lo wraps around
          }
          i += n;
        }
    }
  }
  unsigned shift() const { return shift_; }
  // Bits of a pair's cell for a level of `cells` cells.
  static unsigned pair_cell_bits(uint64_t cells);

 private:
  static constexpr uint64_t kReadPairs = 1 << 16;
  struct File {
    std::unique_ptr<io::OffsetFile> file;
    unsigned cell_bits = 0;
    uint64_t words_at = 0;          // byte offset of the first bucket's words
    std::vector<uint64_t> counts;   // pairs per bucket
    std::vector<uint64_t> offsets;  // per bucket, its first word (from words_at)
  };
  [[noreturn]] static void bad(const File& file);
  std::vector<File> files_;
  unsigned shift_ = 0;
};

}  // namespace lodstream::stream

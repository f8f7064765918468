// A level's cluster map on disk: the cell of every weight-index record, in weight order, bit-packed.
//
// Cells are numbered in order of creation (core/floating_cell.h): the cell of record i is at most the
// number n_i of cells made before it (equal when the record makes it). So it is written in bit_width(n_i)
// bits, which the reader knows from the cells it has read: a self-delimiting stream of at most
// bit_width(cells) bits a record, where 32-bit ids took 32 (on the 48.6 M-triangle city 22, 19, 16, 13
// and 10 bits for its five default levels). The stream can only be read in order, which is how the
// cluster stage's sums pass and the emit stage read it. Bits fill 64-bit little-endian words from the low end.
#pragma once

#include <algorithm>
#include <bit>
#include <cstring>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"

namespace lodstream::stream {

class CellMapWriter {
 public:
  void open(const std::string& path, size_t buffer_bytes) {
    path_ = path;
    out_.open(path, buffer_bytes);
  }
  // Appends the cells of the next records. Throws Failure(internal) for a cell that skips a number.
  void write(std::span<const uint32_t> cells) {
    for (uint32_t c : cells) {
      if (c > count_) fail(Status::internal, path_ + ": cell " + std::to_string(c) + " skips ahead of " + std::to_string(count_));
      put(c, static_cast<unsigned>(std::bit_width(count_)));
      count_ += c == count_;
    }
    if (words_.size() >= kFlushWords) flush();
  }
  void commit() {
    if (used_) words_.push_back(word_), word_ = 0, used_ = 0;
    flush();
    out_.commit();
  }
  uint64_t cells() const { return count_; }

 private:
  static constexpr size_t kFlushWords = 1 << 12;
  void put(uint64_t value, unsigned bits) {
    if (bits == 0) return;
    word_ |= value << used_;
    if (used_ + bits >= 64) {
      words_.push_back(word_);
      const unsigned spill = used_ + bits - 64;  // the high bits that did not fit
      word_ = spill ? value >> (bits - spill) : 0;
      used_ = spill;
    } else {
      used_ += bits;
    }
  }
  void flush() {
    out_.write_array(std::span<const uint64_t>(words_));
    words_.clear();
  }
  std::string path_;
  io::FileWriter out_;
  std::vector<uint64_t> words_;
  uint64_t word_ = 0;
  unsigned used_ = 0;
  uint64_t count_ = 0;
};

// Where a record's cell starts in a map: the bits of the records before it, and the cells made before it
// (its rank among the level's centers in weight order). A reader needs both to enter the stream there;
// the clustering merge knows them from its centers' bits (stream/cluster_merge.h).
struct MapEntry {
  uint64_t bit = 0, cells = 0;
};

// Reads a CellMapWriter's stream from its start, or from an entry, through mapped windows of the file.
class CellMapReader {
 public:
  explicit CellMapReader(const std::string& path, MapEntry entry = {}) : file_(path), bits_read_(entry.bit), count_(entry.cells) {
    if (file_.size() % 8) fail(Status::io_error, path + ": not a cell map (size)");
  }
  // The cells of the next out.size() records. Throws Failure(io_error) past the end of the file.
  void read(std::span<uint32_t> out) {
    for (uint32_t& c : out) {
      const unsigned bits = static_cast<unsigned>(std::bit_width(count_));
      const uint64_t v = take(bits);
      c = static_cast<uint32_t>(v);
      count_ += v == count_;
    }
  }
  // Throws Failure(io_error) unless the stream held exactly `records` records of `cells` cells.
  void finish(uint64_t records, uint64_t cells) const {
    const uint64_t words = (bits_read_ + 63) / 64;
    if (count_ != cells || words * 8 != file_.size())
      fail(Status::io_error, file_.path() + ": does not hold " + std::to_string(records) + " records of " +
                                 std::to_string(cells) + " cells");
  }
  uint64_t cells() const { return count_; }
  const std::string& path() const { return file_.path(); }

 private:
  static constexpr uint64_t kWindowWords = 1 << 16;
  uint64_t word(uint64_t i) {
    if (i >= window_first_ + window_words_) {
      if (i * 8 >= file_.size()) fail(Status::io_error, file_.path() + ": cell map ends early");
      window_first_ = i;
      window_words_ = std::min(kWindowWords, file_.size() / 8 - i);
      window_.resize(kWindowWords);
      file_.read(i * 8, window_words_ * 8, window_.data());
    }
    return window_[i - window_first_];
  }
  uint64_t take(unsigned bits) {
    if (bits == 0) return 0;
    const uint64_t i = bits_read_ / 64;
    const unsigned at = static_cast<unsigned>(bits_read_ % 64);
    uint64_t v = word(i) >> at;
    if (at + bits > 64) v |= word(i + 1) << (64 - at);
    bits_read_ += bits;
    return bits == 64 ? v : v & ((uint64_t{1} << bits) - 1);
  }
  io::MappedFile file_;
  std::vector<uint64_t> window_;  // words [window_first_, window_first_ + window_words_), read (pread)
  uint64_t window_first_ = 0, window_words_ = 0;
  uint64_t bits_read_ = 0;
  uint64_t count_ = 0;
};

}  // namespace lodstream::stream

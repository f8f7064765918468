// The weld map on disk (grade stage): every stored vertex's canonical id, the smallest id at its exact
// position. Most vertices are their own canonical vertex, so the file holds one bit per stored vertex (set:
// welded to a smaller id), a rank per 64 of them, and the canonical ids of the welded vertices alone, in
// vertex order: on the 48.6 M-triangle city (34.8 M stored vertices, 10.1 M welded) 47 MB, where 4 bytes
// a vertex took 139 MB. A lookup is a bit test, and for a welded vertex a popcount and one more read.
//
// Layout (little-endian): vertices (u64), welded (u64), ceil(vertices / 64) bit words (u64), as many ranks
// (u32: set bits in the words before), padded to 8 bytes, then `welded` canonical ids (u32).
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"

namespace lodstream::stream {

namespace weld_detail {
inline uint64_t words(uint64_t vertices) { return (vertices + 63) / 64; }
inline uint64_t ranks_offset(uint64_t vertices) { return 16 + 8 * words(vertices); }
inline uint64_t targets_offset(uint64_t vertices) { return ranks_offset(vertices) + (4 * words(vertices) + 7) / 8 * 8; }
}  // namespace weld_detail

// Writes a weld map in one sequential pass: the header, the bits (bit v set: vertex v is welded) and
// their ranks first, then, by add() in increasing vertex order, every welded vertex's canonical id.
// commit() checks that there were as many as bits. Throws Failure(io_error), Failure(internal) on a
// count that does not match.
class WeldFileWriter {
 public:
  WeldFileWriter(const std::string& path, uint64_t vertices, std::span<const uint64_t> bits) : out_(path, 4 << 20) {
    const uint64_t w = weld_detail::words(vertices);
    if (bits.size() != w) fail(Status::internal, path + ": weld map bits for the wrong vertex count");
    std::vector<uint32_t> ranks(w + (w & 1), 0);
    for (uint64_t i = 0, r = 0; i < w; ++i) ranks[i] = static_cast<uint32_t>(r), r += static_cast<uint64_t>(std::popcount(bits[i]));
    for (uint64_t b : bits) welded_ += static_cast<uint64_t>(std::popcount(b));
    const uint64_t header[2] = {vertices, welded_};
    out_.write(header, sizeof header);
    out_.write_array(bits);
    out_.write_array(std::span<const uint32_t>(ranks));
    targets_.reserve(1 << 16);
  }
  void add(uint32_t target) {
    targets_.push_back(target);
    if (targets_.size() == targets_.capacity()) flush();
  }
  void commit() {
    flush();
    if (added_ != welded_)
      fail(Status::internal, out_.path() + ": " + std::to_string(added_) + " canonical ids for " + std::to_string(welded_) +
                                 " welded vertices (weld map)");
    out_.commit();
  }

 private:
  void flush() {
    out_.write_array(std::span<const uint32_t>(targets_));
    added_ += targets_.size();
    targets_.clear();
  }
  io::FileWriter out_;
  uint64_t welded_ = 0, added_ = 0;
  std::vector<uint32_t> targets_;
};

// Writes `canonical` (canonical[v] <= v for every v) to `path`. Throws Failure(io_error).
inline void write_weld_file(const std::string& path, std::span<const uint32_t> canonical) {
  const uint64_t n = canonical.size();
  std::vector<uint64_t> bits(weld_detail::words(n), 0);
  for (uint64_t v = 0; v < n; ++v)
    if (canonical[v] != v) bits[v / 64] |= uint64_t{1} << (v % 64);
  WeldFileWriter out(path, n, bits);
  for (uint64_t v = 0; v < n; ++v)
    if (canonical[v] != v) out.add(canonical[v]);
  out.commit();
}

class WeldFile {
 public:
  // Throws Failure(io_error) when the file does not describe `vertices` vertices.
  WeldFile(const std::string& path, uint64_t vertices) : file_(path), vertices_(vertices) {
    uint64_t header[2] = {0, 0};
    if (file_.size() >= 16) {
      const io::Window w = file_.map(0, 16);
      std::memcpy(header, w.data(), 16);
    }
    welded_ = header[1];
    if (header[0] != vertices || file_.size() != weld_detail::targets_offset(vertices) + 4 * welded_)
      fail(Status::io_error, path + ": does not match the store (weld map)");
  }
  // Maps the file whole for operator(); release() unmaps it (its pages then stop counting as resident).
  void acquire() {
    if (!window_.data()) window_ = file_.map(0, file_.size(), io::MappedFile::Access::random);
  }
  void release() { window_.reset(); }
  uint32_t operator()(uint32_t v) const {
    const char* base = window_.data();
    uint64_t word;
    std::memcpy(&word, base + 16 + 8 * (v / 64), 8);
    if (!(word >> (v % 64) & 1)) return v;
    uint32_t rank, target;
    std::memcpy(&rank, base + weld_detail::ranks_offset(vertices_) + 4 * (v / 64), 4);
    const uint64_t below = (v % 64) ? word << (64 - v % 64) : 0;
    std::memcpy(&target, base + weld_detail::targets_offset(vertices_) + 4 * (rank + std::popcount(below)), 4);
    return target;
  }
  // Calls visit(v, canonical id) for every welded vertex, in increasing v, through short-lived windows.
  template <class Visit>
  void for_each_welded(Visit&& visit) const {
    for_each_welded_in(0, vertices_, visit);
  }
  // The same for the welded vertices v in [lo, hi) alone: the words from lo's on, from the rank of lo's.
  template <class Visit>
  void for_each_welded_in(uint64_t lo, uint64_t hi, Visit&& visit) const {
    constexpr uint64_t kWords = 1 << 16;
    hi = std::min(hi, vertices_);
    if (lo >= hi) return;
    const uint64_t w = weld_detail::words(hi), targets = weld_detail::targets_offset(vertices_);
    uint32_t rank = 0;
    {
      const io::Window rw = file_.map(weld_detail::ranks_offset(vertices_) + 4 * (lo / 64), weld_detail::ranks_offset(vertices_) + 4 * (lo / 64) + 4);
      std::memcpy(&rank, rw.data(), 4);
    }
    uint64_t k = rank;
    io::Window tw;
    uint64_t t_first = 0, t_end = 0;
    for (uint64_t first = lo / 64; first < w; first += kWords) {
      const uint64_t end = std::min(w, first + kWords);
      const io::Window bw = file_.map(16 + 8 * first, 16 + 8 * end);
      for (uint64_t i = first; i < end; ++i) {
        uint64_t word;
        std::memcpy(&word, bw.data() + 8 * (i - first), 8);
        for (; word; word &= word - 1, ++k) {
          const uint64_t v = 64 * i + static_cast<uint64_t>(std::countr_zero(word));
          if (v < lo) continue;
          if (v >= hi) return;
          if (k >= t_end) {
            if (k >= welded_) fail(Status::io_error, file_.path() + ": more welded vertices than it lists (weld map)");
            t_first = k, t_end = std::min(welded_, k + (kWords << 1));
            tw = file_.map(targets + 4 * t_first, targets + 4 * t_end);
          }
          uint32_t target;
          std::memcpy(&target, tw.data() + 4 * (k - t_first), 4);
          visit(v, target);
        }
      }
    }
  }

 private:
  io::MappedFile file_;
  uint64_t vertices_ = 0, welded_ = 0;
  io::Window window_;
};

}  // namespace lodstream::stream

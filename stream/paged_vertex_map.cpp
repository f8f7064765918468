// A sharded task's packed cluster map, paged (see paged_vertex_map.h).
#include "stream/paged_vertex_map.h"

#include <algorithm>
#include <utility>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "core/status.h"
#include "stream/bit_fields.h"
#include "stream/vertex_cells.h"

namespace lodstream::stream {

namespace {

uint64_t pages_of(uint64_t vertices) { return (vertices + 63) / 64; }

}  // namespace

uint64_t paged_map_bytes(uint64_t vertices, unsigned bits, uint64_t capacity) {
  const uint64_t pages = pages_of(vertices);
  return std::min(capacity, pages * bits * 8) + 8 + pages * 4 + (pages + 63) / 64 * 8;
}

uint64_t paged_map_capacity(uint64_t budget, uint64_t chunk_bytes) {
  return chunk_bytes ? std::max<uint64_t>(1, chunk_bytes / 8) : std::max<uint64_t>(32ull << 20, budget / 8);
}

PagedVertexMap::PagedVertexMap(const std::vector<Level>& levels, uint64_t vertices, uint64_t capacity, PagedMapFigures* figures)
    : vertices_(vertices), wanted_(vertices) {
  if (figures) figures_ = figures;
  for (const Level& l : levels) {
    File f;
    f.file = std::make_unique<io::MappedFile>(l.path);
    f.bits = vertex_cell_bits(l.cells), f.shift = l.shift, f.cells = l.cells;
    f.mask = (uint64_t{1} << f.bits) - 1;
    if (f.file->size() != vertex_cells_bytes(vertices, l.cells))
      fail(Status::io_error, l.path + ": size does not match the store and the level's cells");
    bits_ = std::max(bits_, f.shift + f.bits);
    files_.push_back(std::move(f));
  }
  if (bits_ == 0 || bits_ > 64) fail(Status::internal, "paged vertex map: a record of " + std::to_string(bits_) + " bits");
  mask_ = bits_ == 64 ? ~uint64_t{0} : (uint64_t{1} << bits_) - 1;
  const uint64_t pages = pages_of(vertices);
  if (pages >= kNone) fail(Status::internal, "paged vertex map: more than 2^32 pages");
  ++figures_->maps;
  figures_->pages = std::max(figures_->pages, pages);
  capacity_pages_ = std::max<uint64_t>(1, capacity / (8ull * bits_));
  slot_.assign(pages, kNone);
  // Reserved, not touched: growing within the capacity never copies the held pages.
  words_.reserve(std::min(capacity_pages_, pages) * bits_ + 1);
  words_.assign(1, 0);
}

void PagedVertexMap::missing(uint64_t v) {
  fail(Status::internal, "emit: vertex " + std::to_string(v) + " looked up outside the pages its group loaded");
}

void PagedVertexMap::load() {
  const std::span<const uint32_t> wanted = wanted_.pages();
  std::vector<uint32_t> missing;
  for (uint32_t p : wanted)
    if (slot_[p] == kNone) missing.push_back(p);
  if (!held_.empty() && held_.size() + missing.size() > capacity_pages_) {
    // Drop every held page: the group's own are read again below (those it shares with the held ones too).
    for (uint32_t p : held_) slot_[p] = kNone;
    held_.clear();
    ++figures_->drops;
    missing.assign(wanted.begin(), wanted.end());
  }
  figures_->largest_group = std::max<uint64_t>(figures_->largest_group, wanted.size());
  wanted_.clear();
  if (missing.empty()) return;
  std::sort(missing.begin(), missing.end());
  const uint64_t slots = held_.size() + missing.size();
  if (words_.size() < slots * bits_ + 1) {
    // Past the capacity only for a group whose own pages exceed it (nothing else is held then).
    words_.resize(slots * bits_ + 1);
  }
  figures_->largest_bytes = std::max<uint64_t>(figures_->largest_bytes, slots * bits_ * 8);
  // Runs of consecutive pages, each read in one pread a level, at most 4096 pages a read; their slots set
  // and zeroed here, then the runs read on the threads (each writes only its own pages' words).
  constexpr uint64_t kRunPages = 4096;
  std::vector<std::pair<uint64_t, uint64_t>> runs;
  for (size_t i = 0; i < missing.size();) {
    size_t j = i + 1;
    while (j < missing.size() && missing[j] == missing[j - 1] + 1 && j - i < kRunPages) ++j;
    runs.push_back({missing[i], uint64_t{missing[i]} + (j - i)});
    i = j;
  }
  const uint64_t first_slot = held_.size();
  held_.insert(held_.end(), missing.begin(), missing.end());
  for (size_t k = 0; k < missing.size(); ++k) slot_[missing[k]] = static_cast<uint32_t>(first_slot + k);
  std::fill(words_.begin() + static_cast<std::ptrdiff_t>(first_slot * bits_), words_.begin() + static_cast<std::ptrdiff_t>(slots * bits_),
            uint64_t{0});
  tbb::enumerable_thread_specific<std::vector<uint64_t>> buffers;
  tbb::parallel_for(size_t{0}, runs.size(), [&](size_t r) { read_run(runs[r].first, runs[r].second, buffers.local()); });
  figures_->pages_read += missing.size();
  figures_->reads += runs.size() * files_.size();
}

// Reads pages [first, end), whose slots are set and zeroed: each level's fields, checked, ORed in at its shift.
void PagedVertexMap::read_run(uint64_t first, uint64_t end, std::vector<uint64_t>& buffer) {
  const uint64_t v0 = first * 64, v1 = std::min(vertices_, end * 64);
  // A run's pages have consecutive slots.
  uint64_t* words = words_.data() + uint64_t{slot_[first]} * bits_;
  for (const File& f : files_) {
    const uint64_t begin = first * f.bits * 8, bytes = std::min(f.file->size(), end * f.bits * 8) - begin;
    buffer.resize(bytes / 8 + 1);
    f.file->read(begin, bytes, buffer.data());
    buffer[bytes / 8] = 0;
    const char* data = reinterpret_cast<const char*>(buffer.data());
    for (uint64_t v = v0; v < v1; ++v) {
      const uint64_t c = read_bits(data, (v - v0) * f.bits, f.bits);
      if (c != f.mask && c >= f.cells) fail(Status::io_error, f.file->path() + ": cell id out of range");
      or_bits(words, (v - v0) * bits_, c << f.shift, bits_);
    }
  }
}

}  // namespace lodstream::stream

// A sharded task's packed cluster map, paged: only the records of the vertices its blocks touch are held.
//
// The emit's packed map (emit_stage.cpp, PackedMap) holds a record of every stored vertex: each level's
// cell in its field of bit_width(cells) bits. A task of a sharded run (stream/shard.h) reads only the blocks
// near its cells, yet held that map over every vertex: on the 193 M-triangle city a 22-bit level is 370 MB
// of a 1 GiB task, on the 1 B-triangle one 1.9 GB, so a 1 B task needed about one machine's --memory.
// Looking the cells up in the mapped files did not hold the cap either (stream/vertex_cells.h): a group of
// blocks whose primitives reach all over the vertex ids (the city's segments, stored after its triangles)
// maps every 4 KiB page of every level's file.
//
// Here a page is 64 consecutive vertices' records: `bits` words (64 records of `bits` bits). Level L's
// fields of those 64 vertices are bits_L words of its cells-by-vertex file (vertex_cells.h: a field of
// bits_L bits a vertex from bit 0), at word p·bits_L for page p, so a page is read with one pread a level,
// a run of consecutive pages with one. Before a group of blocks runs, want() is given every vertex id of
// its primitives and load() reads the pages not held; when those do not fit beside the held pages in the
// capacity, every held page is dropped first. A group's own pages are always held, even past the capacity:
// at most a page a distinct vertex of the group (a group is a few blocks of kEmitBlock primitives, so this
// does not grow with the scene). The page table is 4 bytes a page (1/16 byte a vertex).
//
// Invariant: between load() and the next want(), get(v) for every v given to want() is the packed map's
// record of v (the fields of every level of the group, at their shifts), so the emit reads the same bytes.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "io/mapped_file.h"

namespace lodstream::stream {

// The bytes a paged map of `vertices` records holds with `capacity` bytes of pages (the group's overflow
// aside): the pages, at most the whole map of `bits` bits a record, its page table and a bit a page.
uint64_t paged_map_bytes(uint64_t vertices, unsigned bits, uint64_t capacity);
// The capacity a task gives its paged maps from its stage's budget: an eighth, at least 32 MiB; with
// --chunk-bytes (`chunk_bytes`, so that tests make groups drop their pages), an eighth of that.
uint64_t paged_map_capacity(uint64_t budget, uint64_t chunk_bytes);

// What paged maps did, for a task's figures (summed over its maps).
struct PagedMapFigures {
  uint64_t maps = 0;           // paged maps made
  uint64_t pages_read = 0;     // pages read from the files (a page read again after a drop counts again)
  uint64_t reads = 0;          // preads (one a run of consecutive pages and a level)
  uint64_t drops = 0;          // times every held page was dropped for a group's
  uint64_t largest_group = 0;  // the most pages one group needed
  uint64_t largest_bytes = 0;  // the most bytes of pages one map held
  uint64_t pages = 0;          // pages of the scene
};

class PagedVertexMap {
 public:
  struct Level {
    std::string path;   // its cells by vertex (vertex_cells.h)
    uint64_t cells = 0;  // field of vertex_cell_bits(cells) bits
    unsigned shift = 0;  // its field's place in the record
  };
  // `capacity`: bytes of pages to hold before dropping them. `figures`: where its figures are added (none:
  // its own). Throws Failure(io_error) when a file's size does not match `vertices` and its cells.
  PagedVertexMap(const std::vector<Level>& levels, uint64_t vertices, uint64_t capacity, PagedMapFigures* figures = nullptr);
  PagedVertexMap(const PagedVertexMap&) = delete;
  PagedVertexMap& operator=(const PagedVertexMap&) = delete;

  // The distinct pages of some ids, gathered on one thread (a block's), for want(PageSet).
  class PageSet {
   public:
    explicit PageSet(uint64_t vertices) : bits_((vertices + 64 * 64 - 1) / (64 * 64), 0) {}
    void add(std::span<const uint32_t> ids) {
      for (uint32_t v : ids) {
        const uint32_t p = v >> 6;
        if (p == last_) continue;
        last_ = p;
        insert(p);
      }
    }
    void insert(uint32_t p) {
      uint64_t& w = bits_[p / 64];
      const uint64_t bit = uint64_t{1} << (p % 64);
      if (w & bit) return;
      w |= bit;
      pages_.push_back(p);
    }
    void clear() {
      for (uint32_t p : pages_) bits_[p / 64] = 0;
      pages_.clear(), last_ = UINT64_MAX;
    }
    std::span<const uint32_t> pages() const { return pages_; }

   private:
    friend class PagedVertexMap;
    std::vector<uint64_t> bits_;  // a bit a page of the scene
    std::vector<uint32_t> pages_;
    uint64_t last_ = UINT64_MAX;
  };
  // Notes the pages of `ids`, or of `set`, for the next load(). Not thread-safe.
  void want(std::span<const uint32_t> ids) { wanted_.add(ids); }
  void want(const PageSet& set) {
    for (uint32_t p : set.pages_) wanted_.insert(p);
  }
  // Holds every page wanted since the last load(). Throws Failure(io_error) on a cell out of a level's range.
  void load();
  // The record of `v`, whose page is held (Failure(internal) if not).
  uint64_t get(uint64_t v) const {
    const uint32_t s = slot_[v >> 6];
    if (s == kNone) missing(v);
    const uint64_t bit = (v & 63) * bits_, o = bit % 64;
    const uint64_t* w = words_.data() + uint64_t{s} * bits_ + bit / 64;
    uint64_t x = w[0] >> o;
    if (o + bits_ > 64) x |= w[1] << (64 - o);
    return x & mask_;
  }
  unsigned bits() const { return bits_; }
  uint64_t capacity_pages() const { return capacity_pages_; }
  const PagedMapFigures& figures() const { return *figures_; }

 private:
  static constexpr uint32_t kNone = UINT32_MAX;
  [[noreturn]] static void missing(uint64_t v);
  // Thread-safe for runs of distinct pages.
  void read_run(uint64_t first, uint64_t end, std::vector<uint64_t>& buffer);

  struct File {
    std::unique_ptr<io::MappedFile> file;
    unsigned bits = 0, shift = 0;
    uint64_t cells = 0, mask = 0;
  };
  std::vector<File> files_;
  uint64_t vertices_ = 0;
  unsigned bits_ = 0;
  uint64_t mask_ = 0;
  uint64_t capacity_pages_ = 0;
  std::vector<uint32_t> slot_;          // per page: its slot in words_, or kNone
  std::vector<uint32_t> held_;          // the held pages, by slot
  std::vector<uint64_t> words_;         // bits_ words a slot, and one word past the last (get() reads one past)
  PageSet wanted_;                      // the pages wanted since the last load()
  PagedMapFigures own_figures_;
  PagedMapFigures* figures_ = &own_figures_;
};

}  // namespace lodstream::stream

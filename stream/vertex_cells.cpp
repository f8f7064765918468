// Cluster maps by vertex (see vertex_cells.h).
#include "stream/vertex_cells.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <utility>
#include <cstring>
#include <filesystem>
#include <memory>
#include <vector>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/status.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_stage.h"
#include "stream/ranked_bits.h"
#include "stream/units.h"
#include "stream/vertex_pairs.h"
#include "stream/weld_file.h"

namespace lodstream::stream {

namespace {

// A file written at offsets and read back, through pwrite and pread; removed unless committed.
class RandomFile {
 public:
  explicit RandomFile(const std::string& path) : path_(path), partial_(path + ".partial") {
    fd_ = ::open(partial_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) fail(Status::io_error, partial_ + ": cannot create: " + std::strerror(errno));
  }
  ~RandomFile() {
    if (fd_ >= 0) ::close(fd_), ::unlink(partial_.c_str());
  }
  void write(const void* data, uint64_t bytes, uint64_t offset) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pwrite(fd_, p, std::min<uint64_t>(bytes, 1 << 30), static_cast<off_t>(offset));
      if (n <= 0) fail(Status::io_error, partial_ + ": cannot write: " + std::strerror(n < 0 ? errno : ENOSPC));
      p += n, bytes -= static_cast<uint64_t>(n), offset += static_cast<uint64_t>(n);
    }
  }
  // Field i of `bits` bits, read back (its words are written).
  uint32_t read_field(uint64_t i, unsigned bits) const {
    const uint64_t bit = i * bits;
    const size_t bytes = bit % 64 + bits > 64 ? 16 : 8;
    char w[16];
    if (::pread(fd_, w, bytes, static_cast<off_t>(bit / 64 * 8)) != static_cast<ssize_t>(bytes))
      fail(Status::io_error, partial_ + ": cannot read back");
    const uint64_t v = read_bits(w, bit % 64, bits);
    return v == (uint64_t{1} << bits) - 1 ? kNoCell : static_cast<uint32_t>(v);
  }
  void commit() {
    if (::close(fd_) != 0) {
      fd_ = -1;
      fail(Status::io_error, partial_ + ": cannot write: " + std::strerror(errno));
    }
    fd_ = -1;
    std::error_code ec;
    std::filesystem::rename(partial_, path_, ec);
    if (ec) fail(Status::io_error, path_ + ": cannot write: " + ec.message());
  }

 private:
  std::string path_, partial_;
  int fd_ = -1;
};

// Calls f(vertex id, cell) for every record of the weight index at `order` (`records` of them), in weight
// order, its cell from one decoding of the map at `map_path` (`cells` cells); checks both.
template <class F>
void for_each_record_cell(const std::string& map_path, const io::MappedFile& order, uint64_t records, uint64_t cells,
                          uint64_t vertices, Progress& progress, F&& f) {
  constexpr uint64_t kChunk = 1 << 18;
  CellMapReader reader(map_path);
  std::vector<uint32_t> cs(kChunk), ids(kChunk);
  for (uint64_t first = 0; first < records; first += kChunk) {
    progress.check();
    const uint64_t k = std::min(kChunk, records - first);
    order.read(first * 4, k * 4, ids.data());
    reader.read(std::span<uint32_t>(cs.data(), k));
    for (uint64_t i = 0; i < k; ++i) {
      if (cs[i] >= cells) fail(Status::io_error, reader.path() + ": cell id out of range");
      if (ids[i] >= vertices) fail(Status::io_error, order.path() + ": vertex id out of range");
      f(ids[i], cs[i]);
    }
  }
  reader.finish(records, cells);
}

}  // namespace

std::string vertex_cells_path(const std::string& prefix, size_t level) {
  return prefix + "vertex-cells-" + std::to_string(level) + ".bits";
}

unsigned vertex_cell_bits(uint64_t cells) { return std::max(1u, static_cast<unsigned>(std::bit_width(cells))); }

void pack_vertex_cells(std::span<const uint32_t> cells, unsigned bits, std::vector<uint64_t>& words) {
  const uint64_t none = (uint64_t{1} << bits) - 1;
  words.assign(packed_field_bytes(cells.size(), bits) / 8, 0);
  for (uint64_t i = 0; i < cells.size(); ++i) {
    or_bits(words.data(), i * bits, cells[i] == kNoCell ? none : cells[i], bits);
  }
}

std::pair<uint64_t, uint64_t> vertex_cells_unit_range(uint64_t vertices, unsigned unit, unsigned units) {
  auto start = [&](unsigned u) { return u >= units ? vertices : vertices * u / units / 64 * 64; };
  return {start(unit), start(unit + 1)};
}

void write_vertex_cells(const std::string& prefix, const std::string& canonical_path, uint64_t vertices, uint64_t records,
                        size_t level, uint64_t cells, uint64_t budget, Progress& progress) {
  write_vertex_cells_of(cells_path(prefix, level), order_path(prefix), canonical_path, vertex_cells_path(prefix, level), vertices,
                        records, cells, budget, progress);
}

void write_vertex_cells_of(const std::string& map_path, const std::string& order_path, const std::string& canonical_path,
                           const std::string& path, uint64_t vertices, uint64_t records, uint64_t cells, uint64_t budget,
                           Progress& progress) {
  io::MappedFile order(order_path);
  if (order.size() != records * 4) fail(Status::io_error, order.path() + ": size does not match the weight index");
  std::unique_ptr<WeldFile> weld;
  if (!canonical_path.empty()) weld = std::make_unique<WeldFile>(canonical_path, vertices);
  RandomFile out(path);
  const unsigned bits = vertex_cell_bits(cells);
  // Ranges of a multiple of 64 vertices (whole words), of 4 bytes a vertex and their packed words.
  const uint64_t range = std::clamp<uint64_t>(budget / 5 / 64 * 64, 4096, std::max<uint64_t>(vertices, 1));
  std::vector<uint32_t> buf;
  std::vector<uint64_t> words;
  for (uint64_t lo = 0; lo < vertices; lo += range) {
    const uint64_t n = std::min(range, vertices - lo);
    buf.assign(n, kNoCell);
    // Pass 1: the weight index's vertices (canonical ones) in this range, from the map in weight order.
    // The threads split the range into whole parts, each decoding the stream whole (it is read only in
    // order) and writing the cells of its own vertices.
    const size_t parts = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
    const uint64_t per_part = (n + parts - 1) / parts;
    tbb::parallel_for(size_t{0}, parts, [&](size_t part) {
      const uint64_t plo = lo + part * per_part, pn = std::min(n, (part + 1) * per_part) - std::min(n, part * per_part);
      if (pn == 0) return;
      for_each_record_cell(map_path, order, records, cells, vertices, progress, [&](uint32_t id, uint32_t cell) {
        if (id - plo < pn) buf[id - lo] = cell;  // unsigned: below plo wraps around
      });
    });
    // Pass 2: welded vertices take their canonical vertex's cell (canonical ids are smaller, and canonical:
    // weld_file.h), from this range or, read back, from an earlier one.
    if (weld)
      weld->for_each_welded([&](uint64_t v, uint32_t c) {
        if (v - lo < n) buf[v - lo] = c >= lo ? buf[c - lo] : out.read_field(c, bits);
      });
    pack_vertex_cells(buf, bits, words);
    out.write(words.data(), 8 * words.size(), lo * bits / 8);
    progress.report("vertex cells", static_cast<double>(lo + n) / static_cast<double>(vertices));
  }
  out.commit();
}

void write_vertex_cells_unit(const std::vector<VertexCellsLevel>& levels, const std::string& order_path,
                             const std::string& canonical_path, uint64_t vertices, uint64_t records, unsigned unit, unsigned units,
                             Progress& progress) {
  const auto [lo, hi] = vertex_cells_unit_range(vertices, unit, units);
  if (lo == hi) return;
  // The unit's welded vertices, and the canonical vertices before the unit that they name (a canonical id is
  // smaller than its welded vertices' and is its own canonical vertex: weld_file.h), with the buckets of the
  // pairs by vertex range (vertex_pairs.h) that hold those.
  std::vector<std::pair<uint32_t, uint32_t>> welded;  // (vertex, canonical)
  RankedBits outside(canonical_path.empty() ? 0 : vertices);
  static_assert(kVertexPairBuckets <= 64, "a bit a bucket in one word");
  uint64_t outside_buckets = 0;  // bit b: bucket b holds one
  const unsigned shift = vertex_pair_shift(vertices);
  if (!canonical_path.empty()) {
    const WeldFile weld(canonical_path, vertices);
    weld.for_each_welded_in(lo, hi, [&](uint64_t v, uint32_t c) {
      welded.emplace_back(static_cast<uint32_t>(v), c);
      if (c < lo) outside.set(c), outside_buckets |= uint64_t{1} << (c >> shift);
    });
    outside.count();
  }
  std::vector<uint32_t> outside_cells(outside.ones());
  std::vector<uint32_t> buf(hi - lo);
  std::vector<uint64_t> words;
  const bool any_outside = !outside_cells.empty();
  std::unique_ptr<io::MappedFile> order;
  for (const VertexCellsLevel& level : levels) {
    progress.check();
    std::fill(buf.begin(), buf.end(), kNoCell);
    std::fill(outside_cells.begin(), outside_cells.end(), kNoCell);
    auto keep_outside = [&](uint32_t id, uint32_t cell) {
      if (id < lo && outside.has(id)) outside_cells[outside.rank(id)] = cell;
    };
    if (!level.pairs_paths.empty()) {
      // The unit's buckets of every map unit's pairs; then, for the canonical vertices before the unit, the
      // buckets that hold one.
      const VertexPairs pairs(level.pairs_paths, vertices, records);
      pairs.for_each_in(lo, hi, level.cells, [&](uint32_t id, uint32_t cell) { buf[id - lo] = cell; });
      for (uint64_t m = outside_buckets; m; m &= m - 1) {
        const uint64_t b = static_cast<uint64_t>(std::countr_zero(m));
        pairs.for_each_in(b << shift, std::min(lo, (b + 1) << shift), level.cells, keep_outside);
      }
    } else {
      // One decoding of the map in weight order: the unit's vertices' cells and those canonical vertices'.
      if (!order) {
        order = std::make_unique<io::MappedFile>(order_path);
        if (order->size() != records * 4) fail(Status::io_error, order->path() + ": size does not match the weight index");
      }
      for_each_record_cell(level.map_path, *order, records, level.cells, vertices, progress,
                           [&](uint32_t id, uint32_t cell) {
                             if (id - lo < hi - lo) buf[id - lo] = cell;  // unsigned: below lo wraps around
                             else if (any_outside) keep_outside(id, cell);
                           });
    }
    // Welded vertices take their canonical vertex's cell (in increasing order: a canonical vertex in the unit
    // is not welded, so its cell is final).
    for (const auto& [v, c] : welded) buf[v - lo] = c >= lo ? buf[c - lo] : outside_cells[outside.rank(c)];
    const unsigned bits = vertex_cell_bits(level.cells);
    pack_vertex_cells(buf, bits, words);
    io::OffsetFile(level.path, O_WRONLY).write(words.data(), 8 * words.size(), lo * bits / 8);
  }
}

nlohmann::ordered_json write_vertex_cells_in_units(const std::string& prefix, const std::string& canonical_path, uint64_t vertices,
                                                   uint64_t records, const std::vector<size_t>& levels,
                                                   const std::vector<uint64_t>& cells, const std::vector<VertexCellsSource>& sources,
                                                   unsigned units, unsigned index, const nlohmann::ordered_json& key, uint64_t budget,
                                                   Progress& progress) {
  if (levels.empty()) return nullptr;
  if (!sources.empty() && sources.size() != levels.size()) fail(Status::internal, "write_vertex_cells_in_units: sources a level");
  // At least as many units as the budget needs (a unit's bytes below), and at least one a vertex.
  const uint64_t fixed = vertices * 3 / 16 + (4 << 20), room = budget > fixed + (1 << 20) ? budget - fixed : (1 << 20);
  units = static_cast<unsigned>(std::clamp<uint64_t>(std::max<uint64_t>(units, (16 * vertices + room - 1) / room), 1,
                                                     std::max<uint64_t>(vertices, 1)));
  const std::string dir = prefix + "vertex-cells-units/";
  const nlohmann::ordered_json unit_key{{"key", key}, {"levels", levels}, {"units", units}, {"by_range", true}};
  start_once(dir, vertex_cells_path(prefix, levels.back()), unit_key, {"vertex-cells-"}, [&] {
    for (size_t l : levels)
      io::OffsetFile(vertex_cells_path(prefix, l), O_WRONLY | O_CREAT | O_TRUNC).resize(vertex_cells_bytes(vertices, cells[l]));
  });
  std::vector<VertexCellsLevel> unit_levels;
  for (size_t j = 0; j < levels.size(); ++j) {
    VertexCellsLevel& L = unit_levels.emplace_back();
    L.map_path = cells_path(prefix, levels[j]), L.path = vertex_cells_path(prefix, levels[j]), L.cells = cells[levels[j]];
    if (!sources.empty()) L.pairs_paths = sources[j].pairs_paths;
  }
  // A unit (a range of vertices, every level) at a time on each thread the budget holds: 4 bytes a vertex
  // of its share and at most as much of packed words, a bit and a half a vertex for the canonical vertices
  // it looks up, 8 bytes a welded vertex of its share.
  const uint64_t unit_bytes = 16 * (vertices / units + 64) + vertices * 3 / 16 + (4 << 20);
  const unsigned threads = unit_threads(units, std::max<uint64_t>(budget / unit_bytes, 1));
  const auto values = take_units_on_threads(dir, units, index, threads, "vertex-cells", unit_key, [&](unsigned u) {
    write_vertex_cells_unit(unit_levels, order_path(prefix), canonical_path, vertices, records, u, units, progress);
    return nlohmann::ordered_json::object();
  });
  return {{"units", units}, {"levels", levels}, {"unit", unit_figures(values)}};
}

}  // namespace lodstream::stream

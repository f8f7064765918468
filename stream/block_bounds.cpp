// Block boxes of the store's primitives and the grid a task tests them against (see block_bounds.h).
#include "stream/block_bounds.h"

#include <fcntl.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/parallel_for.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "stream/store_access.h"
#include "stream/units.h"

namespace lodstream::stream {

namespace {

constexpr int kArity[3] = {3, 2, 1};

const char* column_name(int kind) { return kind == 0 ? "/triangles.u32" : kind == 1 ? "/lines.u32" : "/points.u32"; }

uint64_t column_count(const StoreMeta& meta, int kind) { return kind == 0 ? meta.triangles : kind == 1 ? meta.lines : meta.points; }

}  // namespace

std::string block_bounds_path(const std::string& prefix) { return prefix + "block-bounds.f64"; }

namespace {

// The boxes of the blocks of `ids` (n primitives of `arity` ids, from a block's first), one thread a box:
// the boxes do not depend on the threads.
void block_boxes(const std::string& column, const StoreMeta& meta, const StorePositions& positions, std::span<const uint32_t> ids,
                 size_t arity, std::vector<double>& boxes) {
  const uint64_t n = ids.size() / arity;
  const uint64_t nb = (n + kBoundsBlock - 1) / kBoundsBlock;
  boxes.assign(6 * nb, 0.0);
  tbb::parallel_for(uint64_t{0}, nb, [&](uint64_t b) {
    double lo[3], hi[3];
    for (int k = 0; k < 3; ++k) lo[k] = std::numeric_limits<double>::infinity(), hi[k] = -lo[k];
    const uint64_t end = std::min(n, (b + 1) * kBoundsBlock) * arity;
    for (uint64_t i = b * kBoundsBlock * arity; i < end; ++i) {
      if (ids[i] >= meta.vertices) fail(Status::io_error, column + ": vertex id out of range");
      double p[3];
      positions.get(ids[i], p);
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
    }
    std::copy(lo, lo + 3, &boxes[6 * b]);
    std::copy(hi, hi + 3, &boxes[6 * b + 3]);
  });
}

// Steps of many boxes: a window of the column and the positions it touches at a time.
constexpr uint64_t kStepBlocks = 256;

}  // namespace

void write_block_bounds(const std::string& store_dir, const StoreMeta& meta, const std::string& path, Progress& progress) {
  StorePositions positions(store_dir, meta);
  io::FileWriter out(path, 1 << 20);
  const uint64_t total = std::max<uint64_t>(meta.primitives(), 1);
  uint64_t done = 0;
  std::vector<double> boxes;
  for (int kind = 0; kind < 3; ++kind) {
    const std::string column = store_dir + column_name(kind);
    const size_t arity = static_cast<size_t>(kArity[kind]);
    for_column_blocks(column, column_count(meta, kind), kArity[kind], kBoundsBlock * kStepBlocks, [&](uint64_t, std::span<const uint32_t> ids) {
      progress.check();
      positions.acquire();
      block_boxes(column, meta, positions, ids, arity, boxes);
      out.write(boxes.data(), boxes.size() * sizeof(double));
      // Mapped pages count as resident (the memory contract): drop the positions this step touched.
      positions.release();
      done += ids.size() / arity;
      progress.report("bounds", static_cast<double>(done) / static_cast<double>(total));
    });
  }
  out.commit();
}

void write_block_bounds_unit(const std::string& store_dir, const StoreMeta& meta, const std::string& path, unsigned unit,
                             unsigned units, Progress& progress) {
  StorePositions positions(store_dir, meta);
  const io::OffsetFile out(path, O_WRONLY);
  std::vector<double> boxes;
  uint64_t before = 0;  // the blocks of the kinds before
  for (int kind = 0; kind < 3; ++kind) {
    const uint64_t count = column_count(meta, kind), blocks = (count + kBoundsBlock - 1) / kBoundsBlock;
    const uint64_t b0 = blocks * unit / units, b1 = blocks * (unit + 1) / units;
    const std::string column = store_dir + column_name(kind);
    const size_t arity = static_cast<size_t>(kArity[kind]);
    if (b0 < b1) {
      const io::MappedFile file(column);
      if (file.size() != count * 4 * arity) fail(Status::io_error, column + ": size does not match store.json");
      for (uint64_t b = b0; b < b1; b += kStepBlocks) {
        progress.check();
        const uint64_t first = b * kBoundsBlock, end = std::min(count, std::min(b1, b + kStepBlocks) * kBoundsBlock);
        const io::Window w = file.map(first * 4 * arity, end * 4 * arity);
        positions.acquire();
        block_boxes(column, meta, positions, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), (end - first) * arity),
                    arity, boxes);
        out.write(boxes.data(), boxes.size() * sizeof(double), (before + b) * 6 * sizeof(double));
        positions.release();
      }
    }
    before += blocks;
  }
}

nlohmann::ordered_json write_block_bounds_in_units(const std::string& store_dir, const StoreMeta& meta, const std::string& path,
                                                   const std::string& dir, unsigned units, unsigned index,
                                                   const nlohmann::ordered_json& key, Progress& progress) {
  uint64_t blocks = 0;
  for (int kind = 0; kind < 3; ++kind) blocks += (column_count(meta, kind) + kBoundsBlock - 1) / kBoundsBlock;
  units = static_cast<unsigned>(std::clamp<uint64_t>(units, 1, std::max<uint64_t>(blocks, 1)));
  const nlohmann::ordered_json unit_key{{"key", key}, {"units", units}};
  start_once(dir, path, unit_key, {"block-bounds-"}, [&] { io::OffsetFile(path, O_WRONLY | O_CREAT | O_TRUNC).resize(blocks * 6 * sizeof(double)); });
  // One unit at a time (its boxes' threads are the process's).
  const auto values = take_units_on_threads(dir, units, index, 1, "block-bounds", unit_key, [&](unsigned u) {
    write_block_bounds_unit(store_dir, meta, path, u, units, progress);
    return nlohmann::ordered_json::object();
  });
  return {{"units", units}, {"unit", unit_figures(values)}};
}

BlockBounds read_block_bounds(const std::string& path, const StoreMeta& meta) {
  BlockBounds b;
  uint64_t doubles = 0;
  for (int kind = 0; kind < 3; ++kind) b.count[kind] = column_count(meta, kind), doubles += 6 * b.blocks(kind);
  io::MappedFile file(path);
  if (file.size() != doubles * sizeof(double)) fail(Status::io_error, path + ": size does not match the store's blocks");
  if (doubles == 0) return b;
  const io::Window w = file.map(0, file.size());
  const double* d = reinterpret_cast<const double*>(w.data());
  for (int kind = 0; kind < 3; ++kind) {
    b.box[kind].assign(d, d + 6 * b.blocks(kind));
    d += 6 * b.blocks(kind);
  }
  return b;
}

ReachGrid::ReachGrid(const core::SceneCube& cube)
    : cube_(cube), marked_(static_cast<size_t>(kSide) * kSide * kSide, 0) {}

void ReachGrid::range(const double* lo, const double* hi, int widen, int* a, int* b) const {
  const double scale = kSide / cube_.side;
  for (int k = 0; k < 3; ++k) {
    // A coordinate outside the cube (or NaN: every comparison with it is false) widens to the border.
    const double v0 = std::floor((lo[k] - cube_.min[k]) * scale), v1 = std::floor((hi[k] - cube_.min[k]) * scale);
    a[k] = v0 >= widen ? static_cast<int>(std::min(v0 - widen, double{kSide - 1})) : 0;
    b[k] = v1 < kSide - 1 - widen && v1 >= -widen ? static_cast<int>(v1) + widen : v1 < -widen ? 0 : kSide - 1;
  }
}

void ReachGrid::mark(const double* lo, const double* hi) {
  int a[3], b[3];
  range(lo, hi, 1, a, b);
  for (int z = a[2]; z <= b[2]; ++z)
    for (int y = a[1]; y <= b[1]; ++y)
      std::fill_n(&marked_[(static_cast<size_t>(z) * kSide + y) * kSide + a[0]], b[0] - a[0] + 1, uint8_t{1});
}

void ReachGrid::finish() {
  constexpr size_t S = kSide + 1;
  sums_.assign(S * S * S, 0);
  auto at = [&](size_t x, size_t y, size_t z) -> uint32_t& { return sums_[(z * S + y) * S + x]; };
  for (size_t z = 1; z < S; ++z)
    for (size_t y = 1; y < S; ++y)
      for (size_t x = 1; x < S; ++x)
        at(x, y, z) = marked_[((z - 1) * kSide + (y - 1)) * kSide + (x - 1)] + at(x - 1, y, z) + at(x, y - 1, z) + at(x, y, z - 1) -
                      at(x - 1, y - 1, z) - at(x - 1, y, z - 1) - at(x, y - 1, z - 1) + at(x - 1, y - 1, z - 1);
}

bool ReachGrid::reaches(const double* lo, const double* hi) const {
  int a[3], b[3];
  range(lo, hi, 0, a, b);
  constexpr size_t S = kSide + 1;
  auto at = [&](int x, int y, int z) { return int64_t{sums_[(static_cast<size_t>(z) * S + y) * S + x]}; };
  const int x0 = a[0], y0 = a[1], z0 = a[2], x1 = b[0] + 1, y1 = b[1] + 1, z1 = b[2] + 1;
  const int64_t n = at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0) + at(x0, y0, z1) + at(x0, y1, z0) +
                    at(x1, y0, z0) - at(x0, y0, z0);
  return n > 0;
}

}  // namespace lodstream::stream

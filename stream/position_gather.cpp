// Positions by id, mapped or read through the page cache; see position_gather.h.
#include "stream/position_gather.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/status.h"

namespace lodstream::stream {

bool map_positions_whole(uint64_t column_bytes, uint64_t memory_bytes, uint64_t chunk_cap) {
  return column_bytes <= memory_bytes / 2 && (chunk_cap == 0 || chunk_cap >= column_bytes);
}

PositionGather::PositionGather(const std::string& path, bool single_precision, uint64_t vertices, bool mapped,
                               uint64_t segment_bytes)
    : file_(path), single_(single_precision), mapped_(mapped), vertices_(vertices), stride_(single_precision ? 12 : 24) {
  if (file_.size() != vertices_ * stride_) fail(Status::io_error, file_.path() + ": size does not match store.json");
  segment_vertices_ = std::max<uint64_t>(segment_bytes / stride_, 1);
  if (vertices_ == 0) return;
  if (mapped_) {
    window_ = file_.map(0, file_.size(), io::MappedFile::Access::random);
    return;
  }
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail(Status::io_error, path + ": cannot open: " + std::strerror(errno));
}

PositionGather::~PositionGather() {
  if (fd_ >= 0) ::close(fd_);
}

void PositionGather::put(const char* p, double* out) const {
  if (single_) {
    float f[3];
    std::memcpy(f, p, sizeof f);
    out[0] = f[0], out[1] = f[1], out[2] = f[2];
  } else {
    std::memcpy(out, p, 24);
  }
}

void PositionGather::read_exact(char* out, uint64_t bytes, uint64_t offset) const {
  while (bytes > 0) {
    const ssize_t got = ::pread(fd_, out, bytes, static_cast<off_t>(offset));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) fail(Status::io_error, file_.path() + ": read failed at byte " + std::to_string(offset));
    out += got, offset += static_cast<uint64_t>(got), bytes -= static_cast<uint64_t>(got);
  }
}

void PositionGather::gather(std::span<const uint32_t> ids, double* xyz, Scratch& scratch) const {
  for (uint32_t v : ids)
    if (v >= vertices_) fail(Status::internal, file_.path() + ": vertex " + std::to_string(v) + " past the column");
  if (!mapped_) return gather_read(ids, xyz, scratch);
  // The ids are spread over the column: each cache miss is fetched well ahead of its use.
  constexpr size_t kAhead = 16;
  for (size_t i = 0; i < ids.size(); ++i) {
    if (i + kAhead < ids.size()) __builtin_prefetch(window_.data() + stride_ * ids[i + kAhead]);
    put(window_.data() + stride_ * ids[i], xyz + 3 * i);
  }
}

// The batch's ids bucketed by segment (a counting sort: two passes over the ids, no comparison), then the
// segments in parallel, each thread's in file order: the page cache reads ahead, and a dense segment costs
// one read of the span from its lowest id to its highest. Each entry is written by the one segment that
// holds its id.
void PositionGather::gather_read(std::span<const uint32_t> ids, double* xyz, Scratch& s) const {
  if (ids.empty()) return;
  const uint64_t segments = (vertices_ + segment_vertices_ - 1) / segment_vertices_;
  s.start.assign(segments + 1, 0);
  s.lo.assign(segments, UINT32_MAX);
  s.hi.assign(segments, 0);
  for (uint32_t v : ids) {
    const uint64_t g = v / segment_vertices_;
    ++s.start[g + 1];
    s.lo[g] = std::min(s.lo[g], v);
    s.hi[g] = std::max(s.hi[g], v);
  }
  for (uint64_t g = 0; g < segments; ++g) s.start[g + 1] += s.start[g];
  s.slot.resize(ids.size());
  // invariant after this loop: segment g's slots are slot[start[g - 1] .. start[g]) (start[-1] = 0)
  for (size_t i = 0; i < ids.size(); ++i) s.slot[s.start[ids[i] / segment_vertices_]++] = static_cast<uint32_t>(i);
  constexpr uint64_t kGrain = 16;  // segments a task reads: 4 MiB
  tbb::parallel_for(tbb::blocked_range<uint64_t>(0, segments, kGrain), [&](const tbb::blocked_range<uint64_t>& r) {
    std::vector<char> buffer;
    for (uint64_t g = r.begin(); g < r.end(); ++g) {
      const uint64_t begin = g == 0 ? 0 : s.start[g - 1], end = s.start[g];
      if (end == begin) continue;
      const uint64_t lo = s.lo[g], span = (uint64_t{s.hi[g]} - lo + 1) * stride_;
      if ((end - begin) * kGatherGapBytes >= span) {
        buffer.resize(segment_vertices_ * stride_);
        read_exact(buffer.data(), span, lo * stride_);
        for (uint64_t k = begin; k < end; ++k) {
          const uint32_t i = s.slot[k];
          put(buffer.data() + (ids[i] - lo) * stride_, xyz + 3 * uint64_t{i});
        }
      } else {
        for (uint64_t k = begin; k < end; ++k) {
          const uint32_t i = s.slot[k];
          char one[24];
          read_exact(one, stride_, ids[i] * stride_);
          put(one, xyz + 3 * uint64_t{i});
        }
      }
    }
  });
}

std::string ordered_positions_path(const std::string& prefix, bool single_precision) {
  return prefix + (single_precision ? "positions-w.f32" : "positions-w.f64");
}

void spend_ordered_positions(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) std::filesystem::resize_file(path, 0, ec);
  if (ec) fail(Status::io_error, path + ": cannot empty: " + ec.message());
}

std::string live_ordered_positions(const std::string& path) {
  std::error_code ec;
  const uint64_t bytes = path.empty() ? 0 : std::filesystem::file_size(path, ec);
  return !ec && bytes > 0 ? path : std::string();
}

uint64_t ordered_positions_batch(uint64_t memory_bytes) {
  constexpr uint64_t per_record = 4 + 24 + kGatherBytesPerId;  // id, position as doubles (narrowed in place), slot
  // Half the budget: each batch costs a copy of most of the column, and the callers hold little else then.
  return std::max<uint64_t>(memory_bytes / 2 / per_record, 1);
}

void write_ordered_positions(const std::string& store_dir, const StoreMeta& meta, const std::string& order_path,
                             uint64_t first, uint64_t n, const io::OffsetFile& out, uint64_t memory_bytes, Progress& progress) {
  const io::MappedFile order(order_path);
  if (order.size() < (first + n) * 4) fail(Status::io_error, order.path() + ": shorter than its records");
  const uint64_t stride = position_bytes(meta.single_precision);
  const bool mapped = map_positions_whole(meta.vertices * stride, memory_bytes, 0);
  const PositionGather column(positions_column_path(store_dir, meta), meta.single_precision, meta.vertices, mapped);
  const uint64_t batch = std::min(ordered_positions_batch(mapped ? memory_bytes / 2 : memory_bytes), std::max<uint64_t>(n, 1));
  std::vector<uint32_t> ids(batch);
  std::vector<double> xyz(3 * batch);
  PositionGather::Scratch scratch;
  for (uint64_t at = first; at < first + n; at += batch) {
    progress.check();
    const uint64_t k = std::min(batch, first + n - at);
    {
      const io::Window w = order.map(at * 4, (at + k) * 4);
      std::memcpy(ids.data(), w.data(), k * 4);
    }
    column.gather(std::span<const uint32_t>(ids.data(), k), xyz.data(), scratch);
    if (meta.single_precision) {
      // Narrowed back to the store's floats (exact: they were widened from them), in place from the front:
      // float i goes to bytes [4i, 4i + 4), never past double i, which is read first.
      char* bytes = reinterpret_cast<char*>(xyz.data());
      for (uint64_t i = 0; i < 3 * k; ++i) {
        const float f = static_cast<float>(xyz[i]);
        std::memcpy(bytes + 4 * i, &f, 4);
      }
      out.write(bytes, stride * k, at * stride);
    } else {
      out.write(xyz.data(), stride * k, at * stride);
    }
    progress.report("positions", static_cast<double>(at + k - first) / static_cast<double>(n));
  }
}

OrderedPositions::OrderedPositions(const std::string& path, bool single_precision, uint64_t records)
    : file_(path), single_(single_precision), records_(records) {
  if (file_.size() != records * position_bytes(single_precision))
    fail(Status::io_error, path + ": size does not match the weight index");
}

void OrderedPositions::read(uint64_t first, uint64_t n, double* xyz) const {
  if (first + n > records_) fail(Status::internal, file_.path() + ": record past the index");
  const uint64_t stride = position_bytes(single_);
  if (!single_) {
    file_.read(first * stride, n * stride, xyz);
    return;
  }
  // The floats read into the back half of xyz and widened front to back: double i (bytes [8i, 8i + 8))
  // never reaches a float not yet widened (at 12n + 4j, j > i, since i < 3n).
  char* floats = reinterpret_cast<char*>(xyz) + 12 * n;
  file_.read(first * stride, n * stride, floats);
  for (uint64_t i = 0; i < 3 * n; ++i) {
    float f;
    std::memcpy(&f, floats + 4 * i, 4);
    xyz[i] = f;
  }
}

RecordPositions::RecordPositions(const std::string& column_path, bool single_precision, uint64_t vertices,
                                 const std::string& ordered_path, uint64_t records, bool map_whole)
    : ordered_(ordered_path.empty() ? nullptr : std::make_unique<OrderedPositions>(ordered_path, single_precision, records)),
      column_(column_path, single_precision, vertices, !ordered_ && map_whole) {}

void RecordPositions::load(uint64_t first, std::span<const uint32_t> ids, double* xyz, PositionGather::Scratch& scratch) const {
  if (ordered_) ordered_->read(first, ids.size(), xyz);
  else column_.gather(ids, xyz, scratch);
}

}  // namespace lodstream::stream

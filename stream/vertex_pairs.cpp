// A split level's cells bucketed by vertex range (see vertex_pairs.h).
#include "stream/vertex_pairs.h"

#include <fcntl.h>

#include <algorithm>
#include <bit>
#include <filesystem>

#include "core/status.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kHeaderBytes = 32;

uint64_t bucket_count(uint64_t vertices, unsigned shift) { return vertices == 0 ? 1 : ((vertices - 1) >> shift) + 1; }

}  // namespace

unsigned vertex_pair_shift(uint64_t vertices) {
  const unsigned width = static_cast<unsigned>(std::bit_width(vertices > 0 ? vertices - 1 : 0));
  constexpr unsigned kBucketBits = std::bit_width(kVertexPairBuckets - 1);
  return width > kBucketBits ? width - kBucketBits : 0;
}

void count_vertex_pairs(std::span<const uint32_t> ids, uint64_t vertices, std::span<uint64_t> counts) {
  const unsigned shift = vertex_pair_shift(vertices);
  for (uint32_t id : ids) ++counts[id >> shift];
}

VertexPairsWriter::VertexPairsWriter(const std::string& path, uint64_t vertices, uint64_t first_record, uint64_t end_record,
                                     std::span<const uint64_t> counts)
    : file_(path, O_WRONLY | O_CREAT | O_TRUNC), shift_(vertex_pair_shift(vertices)) {
  const uint64_t buckets = bucket_count(vertices, shift_);
  for (uint64_t b = buckets; b < counts.size(); ++b)
    if (counts[b]) fail(Status::internal, path + ": a vertex past the store's vertices");
  std::vector<uint64_t> offsets(buckets + 1, 0);
  for (uint64_t b = 0; b < buckets; ++b) offsets[b + 1] = offsets[b] + counts[b];
  const uint64_t header[3] = {vertices, first_record, end_record};
  const uint32_t layout[2] = {shift_, static_cast<uint32_t>(buckets)};
  file_.write(header, sizeof header, 0);
  file_.write(layout, sizeof layout, sizeof header);
  file_.write(offsets.data(), 8 * offsets.size(), kHeaderBytes);
  const uint64_t pairs_at = kHeaderBytes + 8 * offsets.size();
  file_.resize(pairs_at + 8 * offsets.back());
  for (uint64_t b = 0; b < buckets; ++b) next_.push_back(pairs_at + 8 * offsets[b]), end_.push_back(pairs_at + 8 * offsets[b + 1]);
  buffers_.resize(buckets);
  for (std::vector<uint32_t>& buf : buffers_) buf.reserve(2 * kBufferPairs);
}

void VertexPairsWriter::flush(uint32_t b) {
  std::vector<uint32_t>& buf = buffers_[b];
  const uint64_t bytes = 4 * buf.size();
  if (next_[b] + bytes > end_[b]) fail(Status::internal, file_.path() + ": more pairs than counted in a bucket");
  file_.write(buf.data(), bytes, next_[b]);
  next_[b] += bytes;
  buf.clear();
}

void VertexPairsWriter::commit() {
  for (uint32_t b = 0; b < buffers_.size(); ++b) {
    if (!buffers_[b].empty()) flush(b);
    if (next_[b] != end_[b]) fail(Status::internal, file_.path() + ": fewer pairs than counted in a bucket");
  }
  file_.close();
}

VertexPairs::VertexPairs(std::vector<std::string> paths, uint64_t vertices, uint64_t records) : shift_(vertex_pair_shift(vertices)) {
  const uint64_t buckets = bucket_count(vertices, shift_);
  std::vector<std::pair<uint64_t, uint64_t>> ranges;  // each file's records
  uint64_t pairs = 0;
  for (const std::string& path : paths) {
    File f;
    f.file = std::make_unique<io::OffsetFile>(path, O_RDONLY);
    uint64_t header[3] = {0, 0, 0};
    uint32_t layout[2] = {0, 0};
    const uint64_t size = std::filesystem::file_size(path);
    if (size >= kHeaderBytes) f.file->read(header, sizeof header, 0), f.file->read(layout, sizeof layout, sizeof header);
    if (size < kHeaderBytes || header[0] != vertices || layout[0] != shift_ || layout[1] != buckets || header[1] > header[2] ||
        size < kHeaderBytes + 8 * (buckets + 1))
      fail(Status::io_error, path + ": not the vertex pairs of this weight index");
    f.offsets.resize(buckets + 1);
    f.file->read(f.offsets.data(), 8 * f.offsets.size(), kHeaderBytes);
    f.pairs_at = kHeaderBytes + 8 * f.offsets.size();
    if (f.offsets[0] != 0 || !std::is_sorted(f.offsets.begin(), f.offsets.end()) || f.offsets.back() != header[2] - header[1] ||
        size != f.pairs_at + 8 * f.offsets.back())
      fail(Status::io_error, path + ": cut short or not the vertex pairs of this weight index");
    pairs += f.offsets.back();
    ranges.emplace_back(header[1], header[2]);
    files_.push_back(std::move(f));
  }
  std::sort(ranges.begin(), ranges.end());
  uint64_t next = 0;
  for (const auto& [lo, hi] : ranges) {
    if (lo != next) break;
    next = hi;
  }
  if (next != records || pairs != records)
    fail(Status::io_error, (paths.empty() ? std::string("vertex pairs") : paths.front()) + ": the map units' pairs do not cover the weight index");
}

void VertexPairs::bad(const File& file) {
  fail(Status::io_error, file.file->path() + ": a pair in the wrong bucket or past the level's cells");
}

}  // namespace lodstream::stream

// A split level's cells bucketed by vertex range (see vertex_pairs.h).
#include "stream/vertex_pairs.h"

#include <fcntl.h>

#include <algorithm>
#include <bit>
#include <filesystem>

#include "core/status.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kHeaderBytes = 40;

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

unsigned VertexPairs::pair_cell_bits(uint64_t cells) {
  return std::max(1u, static_cast<unsigned>(std::bit_width(cells > 0 ? cells - 1 : 0)));
}

namespace {

// Words of `pairs` pairs of `width` bits.
uint64_t pair_words(uint64_t pairs, unsigned width) { return (pairs * width + 63) / 64; }

}  // namespace

VertexPairsWriter::VertexPairsWriter(const std::string& path, uint64_t vertices, uint64_t first_record, uint64_t end_record,
                                     uint64_t cells, std::span<const uint64_t> counts)
    : file_(path, O_WRONLY | O_CREAT | O_TRUNC), cells_(cells), shift_(vertex_pair_shift(vertices)) {
  const unsigned cell_bits = VertexPairs::pair_cell_bits(cells);
  width_ = shift_ + cell_bits;
  low_ = (uint64_t{1} << shift_) - 1;
  const uint64_t buckets = bucket_count(vertices, shift_);
  for (uint64_t b = buckets; b < counts.size(); ++b)
    if (counts[b]) fail(Status::internal, path + ": a vertex past the store's vertices");
  const uint64_t header[3] = {vertices, first_record, end_record};
  const uint32_t layout[4] = {shift_, static_cast<uint32_t>(buckets), cell_bits, width_};
  file_.write(header, sizeof header, 0);
  file_.write(layout, sizeof layout, sizeof header);
  file_.write(counts.data(), 8 * buckets, kHeaderBytes);
  uint64_t at = kHeaderBytes + 8 * buckets;
  buckets_.resize(buckets);
  for (uint64_t b = 0; b < buckets; ++b) {
    Bucket& k = buckets_[b];
    k.next = at, at += 8 * pair_words(counts[b], width_), k.end = at;
    k.words.reserve(kBufferPairs + 2);
  }
  file_.resize(at);
}

void VertexPairsWriter::flush(Bucket& k, bool last) {
  // All but a last word still being filled, unless it is the bucket's end.
  const size_t n = last || k.bit == 64 ? k.words.size() : k.words.size() - 1;
  const uint64_t bytes = 8 * n;
  if (k.next + bytes > k.end) fail(Status::internal, file_.path() + ": more pairs than counted in a bucket");
  file_.write(k.words.data(), bytes, k.next);
  k.next += bytes;
  k.words.erase(k.words.begin(), k.words.begin() + static_cast<std::ptrdiff_t>(n));
}

void VertexPairsWriter::cell_past_the_level() const {
  fail(Status::internal, file_.path() + ": a cell past the level's cells");
}

void VertexPairsWriter::commit() {
  for (Bucket& k : buckets_) {
    if (!k.words.empty()) flush(k, true);
    if (k.next != k.end) fail(Status::internal, file_.path() + ": fewer pairs than counted in a bucket");
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
    uint32_t layout[4] = {0, 0, 0, 0};
    const uint64_t size = std::filesystem::file_size(path);
    if (size >= kHeaderBytes) f.file->read(header, sizeof header, 0), f.file->read(layout, sizeof layout, sizeof header);
    if (size < kHeaderBytes || header[0] != vertices || layout[0] != shift_ || layout[1] != buckets || layout[2] == 0 ||
        layout[2] > 32 || layout[3] != shift_ + layout[2] || header[1] > header[2] || size < kHeaderBytes + 8 * buckets)
      fail(Status::io_error, path + ": not the vertex pairs of this weight index");
    f.cell_bits = layout[2];
    f.counts.resize(buckets);
    f.file->read(f.counts.data(), 8 * buckets, kHeaderBytes);
    f.words_at = kHeaderBytes + 8 * buckets;
    uint64_t words = 0, n = 0;
    for (uint64_t c : f.counts) f.offsets.push_back(words), words += pair_words(c, layout[3]), n += c;
    if (n != header[2] - header[1] || size != f.words_at + 8 * words)
      fail(Status::io_error, path + ": cut short or not the vertex pairs of this weight index");
    pairs += n;
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
  fail(Status::io_error, file.file->path() + ": a pair past the level's cells, or the pairs of another level");
}

}  // namespace lodstream::stream

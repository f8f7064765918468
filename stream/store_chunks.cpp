// Chunks of a scene store with their own vertices; see store_chunks.h.
#include "stream/store_chunks.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "core/primitive_color.h"
#include "core/status.h"
#include "io/mapped_file.h"

namespace lodstream::stream {
namespace {

constexpr uint64_t kBlock = 1 << 20;            // primitives per mapped window of a primitive column
constexpr uint64_t kPositionWindow = 64 << 20;  // bytes per mapped window of the positions column
// Vertices read by position at a time, as words of a bit a vertex: 64 × 4096, so that the positions read stay small.
constexpr uint64_t kPositionBlockWords = 4096;

bool test_and_set(std::vector<uint64_t>& bits, uint32_t v) {
  uint64_t& w = bits[v >> 6];
  const uint64_t m = uint64_t{1} << (v & 63);
  const bool was = (w & m) != 0;
  w |= m;
  return !was;
}

}  // namespace

StoreChunks::StoreChunks(const std::string& store_dir, const StoreMeta& meta) : dir_(store_dir), meta_(meta) {}

void StoreChunks::for_ids(uint64_t first, uint64_t end,
                          const std::function<void(uint64_t, int, std::span<const uint32_t>)>& visit) const {
  struct Column {
    const char* name;
    uint64_t count;
    int arity;
  };
  const Column columns[3] = {{"/triangles.u32", meta_.triangles, 3}, {"/lines.u32", meta_.lines, 2},
                             {"/points.u32", meta_.points, 1}};
  uint64_t base = 0;
  for (const Column& c : columns) {
    const uint64_t lo = std::max(first, base), hi = std::min(end, base + c.count);
    if (lo < hi) {
      io::MappedFile file(dir_ + c.name);
      const uint64_t stride = 4ull * static_cast<uint64_t>(c.arity);
      if (file.size() != c.count * stride) fail(Status::io_error, file.path() + ": size does not match store.json");
      for (uint64_t at = lo; at < hi; at += kBlock) {
        const uint64_t n = std::min(kBlock, hi - at);
        const io::Window w = file.map((at - base) * stride, (at - base + n) * stride);
        visit(at, c.arity, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), n * uint64_t(c.arity)));
      }
    }
    base += c.count;
  }
}

void StoreChunks::plan(const ChunkCosts& costs, uint64_t bytes) { plan_range(costs, bytes, 0, meta_.primitives()); }

void StoreChunks::plan_range(const ChunkCosts& costs, uint64_t bytes, uint64_t first, uint64_t end) {
  chunks_.clear();
  used_.assign((meta_.vertices + 63) / 64, 0);
  used_count_ = 0;
  end_ = std::min(end, meta_.primitives());
  cut(std::min(first, end_), costs, bytes, true);
}

void StoreChunks::replan(size_t from, const ChunkCosts& costs, uint64_t bytes) {
  if (from >= chunks_.size()) return;
  const uint64_t first = chunks_[from].first;
  chunks_.resize(from);
  cut(first, costs, bytes, false);
}

void StoreChunks::cut(uint64_t from, const ChunkCosts& costs, uint64_t bytes, bool mark) {
  const uint64_t words = (meta_.vertices + 63) / 64;
  std::vector<uint64_t> in_chunk(words, 0);
  StoreChunk chunk{from, from, 0};
  double cost = 0;
  const double prim_cost[4] = {0, costs.point, costs.line, costs.triangle};  // by arity
  for_ids(from, end_, [&](uint64_t first, int arity, std::span<const uint32_t> ids) {
    for (size_t i = 0; i < ids.size(); i += static_cast<size_t>(arity)) {
      const uint32_t* p = ids.data() + i;
      int fresh = 0;
      for (int k = 0; k < arity; ++k) {
        if (p[k] >= meta_.vertices) fail(Status::io_error, dir_ + ": a primitive's vertex id is out of range");
        fresh += (in_chunk[p[k] >> 6] >> (p[k] & 63) & 1) == 0;
      }
      const double added = prim_cost[arity] + fresh * costs.vertex;
      const uint64_t g = first + i / static_cast<size_t>(arity);
      if (g > chunk.first && cost + added > double(bytes)) {
        chunk.end = g;
        chunks_.push_back(chunk);
        chunk = StoreChunk{g, g, 0};
        std::fill(in_chunk.begin(), in_chunk.end(), 0);
        cost = 0;
        fresh = arity;  // an empty chunk: every vertex is new (a primitive's ids are distinct)
      }
      cost += prim_cost[arity] + fresh * costs.vertex;
      for (int k = 0; k < arity; ++k) {
        if (test_and_set(in_chunk, p[k])) ++chunk.vertices;
        if (mark && test_and_set(used_, p[k])) ++used_count_;
      }
    }
  });
  chunk.end = end_;
  if (chunk.end > chunk.first) chunks_.push_back(chunk);
}

void StoreChunks::read_positions(std::span<const uint64_t> bits, uint64_t word0, uint64_t count,
                                 std::vector<float>& xyz) const {
  xyz.resize(3 * count);
  if (count == 0) return;
  io::MappedFile file(positions_column_path(dir_, meta_));
  const uint64_t stride = meta_.single_precision ? 12 : 24;
  if (file.size() != meta_.vertices * stride) fail(Status::io_error, file.path() + ": size does not match store.json");
  io::Window w;
  uint64_t out = 0;
  for (uint64_t word = 0; word < bits.size(); ++word) {
    for (uint64_t b = bits[word]; b != 0; b &= b - 1) {
      const uint64_t v = (word0 + word) * 64 + static_cast<uint64_t>(std::countr_zero(b));
      const uint64_t at = v * stride;
      if (at < w.begin() || at + stride > w.end()) w = file.map(at, at + std::max(kPositionWindow, stride));
      const char* src = w.data() + (at - w.begin());
      if (meta_.single_precision) {
        std::memcpy(&xyz[3 * out], src, 12);
      } else {
        double p[3];
        std::memcpy(p, src, 24);
        for (int k = 0; k < 3; ++k) xyz[3 * out + k] = static_cast<float>(p[k]);
      }
      ++out;
    }
  }
}

void StoreChunks::read(size_t index, ChunkGeometry* out, bool colors) {
  const StoreChunk& c = chunks_.at(index);
  const uint64_t words = (meta_.vertices + 63) / 64;
  std::vector<uint64_t> bits(words, 0);
  uint64_t count = 0;
  for_ids(c.first, c.end, [&](uint64_t, int, std::span<const uint32_t> ids) {
    for (uint32_t v : ids) count += test_and_set(bits, v);
  });
  // rank[w]: set bits before word w, so a vertex's local id is rank[w] + the set bits below it in w.
  std::vector<uint32_t> rank(words);
  uint64_t run = 0;
  for (uint64_t w = 0; w < words; ++w) rank[w] = static_cast<uint32_t>(run), run += static_cast<uint64_t>(std::popcount(bits[w]));
  out->first = c.first;
  out->triangles.clear(), out->lines.clear(), out->points.clear();
  // Exact sizes, so that no array grows by doubling (its peak would be up to twice its size).
  const auto overlap = [&](uint64_t lo, uint64_t n) {
    const uint64_t a = std::max(c.first, lo), b = std::min(c.end, lo + n);
    return b > a ? b - a : 0;
  };
  out->triangles.reserve(3 * overlap(0, meta_.triangles));
  out->lines.reserve(2 * overlap(meta_.triangles, meta_.lines));
  out->points.reserve(overlap(meta_.triangles + meta_.lines, meta_.points));
  read_positions(bits, 0, count, out->xyz);
  for_ids(c.first, c.end, [&](uint64_t, int arity, std::span<const uint32_t> ids) {
    std::vector<uint32_t>& dst = arity == 3 ? out->triangles : arity == 2 ? out->lines : out->points;
    const size_t at = dst.size();
    dst.resize(at + ids.size());
    for (size_t i = 0; i < ids.size(); ++i) {
      const uint32_t v = ids[i];
      const uint64_t below = bits[v >> 6] & ((uint64_t{1} << (v & 63)) - 1);
      dst[at + i] = rank[v >> 6] + static_cast<uint32_t>(std::popcount(below));
    }
  });
  out->triangle_rgb.clear(), out->line_rgb.clear(), out->point_rgb.clear();
  if (colors) read_colors(c, bits, count, out);
}

void StoreChunks::read_colors(const StoreChunk& c, std::span<const uint64_t> bits, uint64_t count, ChunkGeometry* out) {
  if (!meta_.colors && meta_.materials.empty()) return;
  std::vector<uint8_t> rgba;
  if (meta_.colors) {
    rgba.resize(4 * count);
    io::MappedFile file(dir_ + "/colors.rgba8");
    if (file.size() != meta_.vertices * 4) fail(Status::io_error, file.path() + ": size does not match store.json");
    io::Window w;
    uint64_t n = 0;
    for (uint64_t word = 0; word < bits.size(); ++word)
      for (uint64_t b = bits[word]; b != 0; b &= b - 1) {
        const uint64_t at = (word * 64 + static_cast<uint64_t>(std::countr_zero(b))) * 4;
        if (at < w.begin() || at + 4 > w.end()) w = file.map(at, std::min(file.size(), at + kPositionWindow));
        std::memcpy(&rgba[4 * n++], w.data() + (at - w.begin()), 4);
      }
  }
  const char* kinds[3] = {"triangle", "line", "point"};
  const std::vector<uint32_t>* ids[3] = {&out->triangles, &out->lines, &out->points};
  std::vector<uint8_t>* rgb[3] = {&out->triangle_rgb, &out->line_rgb, &out->point_rgb};
  uint64_t base = 0;  // the kind's first global primitive id
  const uint64_t counts[3] = {meta_.triangles, meta_.lines, meta_.points};
  for (int kind = 0; kind < 3; ++kind) {
    const int arity = 3 - kind;
    const uint64_t n = ids[kind]->size() / static_cast<uint64_t>(arity);
    const uint64_t first = std::max(c.first, base) - base;  // the kind's first primitive in the chunk
    base += counts[kind];
    if (n == 0) continue;
    if (!meta_.materials.empty() && !runs_read_[kind]) runs_[kind] = read_object_runs(dir_, kinds[kind]), runs_read_[kind] = true;
    const std::vector<ObjectRun>& runs = runs_[kind];
    // The run holding the chunk's first primitive of the kind (runs are in primitive order), or the first.
    size_t r = 0;
    if (!runs.empty()) {
      const auto after = std::upper_bound(runs.begin(), runs.end(), first,
                                          [](uint64_t at, const ObjectRun& run) { return at < run.first; });
      r = after == runs.begin() ? 0 : static_cast<size_t>(after - runs.begin() - 1);
    }
    rgb[kind]->resize(3 * n);
    for (uint64_t i = 0; i < n; ++i) {
      const core::Material* material = nullptr;
      if (!runs.empty()) {
        while (r + 1 < runs.size() && runs[r + 1].first <= first + i) ++r;
        if (runs[r].material < meta_.materials.size()) material = &meta_.materials[runs[r].material];
      }
      const uint8_t* v[3];
      for (int j = 0; j < arity; ++j) v[j] = meta_.colors ? &rgba[4 * uint64_t{(*ids[kind])[static_cast<uint64_t>(arity) * i + j]}] : nullptr;
      core::primitive_rgb(meta_.colors ? v : nullptr, arity, material, &(*rgb[kind])[3 * i]);
    }
  }
}

void StoreChunks::for_used_vertices(const std::function<void(std::span<const float>)>& visit_block) const {
  std::vector<float> xyz;
  for (uint64_t w0 = 0; w0 < used_.size(); w0 += kPositionBlockWords) {
    const std::span<const uint64_t> block(used_.data() + w0, std::min<uint64_t>(kPositionBlockWords, used_.size() - w0));
    uint64_t count = 0;
    for (uint64_t w : block) count += static_cast<uint64_t>(std::popcount(w));
    if (count == 0) continue;
    read_positions(block, w0, count, xyz);
    visit_block(xyz);
  }
}

std::vector<float> StoreChunks::positions_of_sorted(std::span<const uint32_t> ids) const {
  // The ids of one block of vertices at a time, as that block's bits.
  constexpr uint64_t kWords = kPositionBlockWords;
  std::vector<float> out, xyz;
  std::vector<uint64_t> block;
  for (size_t i = 0; i < ids.size();) {
    const uint64_t w0 = ids[i] / 64 / kWords * kWords;
    block.assign(kWords, 0);
    uint64_t count = 0;
    for (; i < ids.size() && ids[i] / 64 < w0 + kWords; ++i, ++count) block[ids[i] / 64 - w0] |= uint64_t{1} << (ids[i] & 63);
    block.resize(std::min(kWords, (meta_.vertices + 63) / 64 - w0));
    read_positions(block, w0, count, xyz);
    out.insert(out.end(), xyz.begin(), xyz.end());
  }
  return out;
}

std::vector<float> StoreChunks::positions_of(const std::vector<uint32_t>& ids) const {
  std::vector<float> out, p;
  for (uint32_t v : ids) {
    const uint64_t one = uint64_t{1} << (v & 63);
    read_positions(std::span<const uint64_t>(&one, 1), v >> 6, 1, p);
    out.insert(out.end(), p.begin(), p.end());
  }
  return out;
}

}  // namespace lodstream::stream

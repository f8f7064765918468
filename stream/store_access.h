// Read access to a complete scene store for the stages after ingest: positions by vertex id (the column is
// mapped whole, for random access; release() unmaps it so its pages stop counting as resident), and
// primitive columns visited in fixed blocks through short-lived mapped windows.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>

#include "core/status.h"
#include "io/mapped_file.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

class StorePositions {
 public:
  StorePositions(const std::string& store_dir, const StoreMeta& meta)
      : StorePositions(store_dir + (meta.single_precision ? "/positions.f32" : "/positions.f64"), meta.single_precision,
                       meta.vertices) {}
  // The column at `path` of `vertices` positions, float or double.
  StorePositions(const std::string& path, bool single_precision, uint64_t vertices)
      : file_(path), single_(single_precision), count_(vertices) {
    if (file_.size() != count_ * 3 * (single_ ? 4 : 8))
      fail(Status::io_error, file_.path() + ": size does not match store.json");
  }
  // (Re)maps the column; positions are readable until release().
  void acquire() {
    if (!window_.data() && count_ > 0) window_ = file_.map(0, file_.size(), io::MappedFile::Access::random);
  }
  void release() { window_.reset(); }
  void prefetch(uint64_t v) const { __builtin_prefetch(window_.data() + (single_ ? 12 : 24) * v); }
  void get(uint64_t v, double* out) const {
    if (single_) {
      const float* p = reinterpret_cast<const float*>(window_.data()) + 3 * v;
      out[0] = p[0], out[1] = p[1], out[2] = p[2];
    } else {
      std::memcpy(out, window_.data() + 24 * v, 24);
    }
  }

 private:
  io::MappedFile file_;
  bool single_;
  uint64_t count_;
  io::Window window_;
};

// Calls visit(first_element, span of arity * n ids) for consecutive blocks of at most `block` elements of a
// uint32 column holding `count` elements of `arity` ids each.
template <class Visit>
void for_column_blocks(const std::string& path, uint64_t count, int arity, uint64_t block, Visit&& visit) {
  if (count == 0) return;
  io::MappedFile file(path);
  const uint64_t stride = 4ull * static_cast<uint64_t>(arity);
  if (file.size() != count * stride) fail(Status::io_error, path + ": size does not match store.json");
  for (uint64_t first = 0; first < count; first += block) {
    const uint64_t n = std::min(block, count - first);
    const io::Window w = file.map(first * stride, (first + n) * stride);
    visit(first, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), n * static_cast<uint64_t>(arity)));
  }
}

}  // namespace lodstream::stream

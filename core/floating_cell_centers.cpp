// The centers of one floating-cell level. This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2
// See floating_cell_centers.h for the covered voxels and the invariant.
#include "core/floating_cell_centers.h"

#include <algorithm>
#include <cmath>

#include "core/status.h"

namespace lodstream::core {

namespace {

ClusterOptions heaviest(ClusterOptions o) {
  o.choice = CellChoice::heaviest;  // the centers do not depend on the choice; the heaviest scans least
  return o;
}

}  // namespace

namespace {

// The voxels of side 1 / inv over the bounds: the first voxel's index and the count per axis; returns their
// product.
double voxel_grid(std::span<const double, 6> bounds, double inv, int64_t first[3], int64_t dims[3]) {
  double voxels = 1;
  for (int a = 0; a < 3; ++a) {
    first[a] = static_cast<int64_t>(std::floor(bounds[a] * inv));
    dims[a] = static_cast<int64_t>(std::floor(bounds[3 + a] * inv)) - first[a] + 1;
    voxels *= static_cast<double>(dims[a]);
  }
  return voxels;
}

// The largest power of two at most x, as its exponent.
int exponent_at_most(double x) {
  const int e = std::ilogb(x);
  return std::ldexp(1.0, e) > x ? e - 1 : e;
}

// A brick key's first slot in a table of `slots` (a power of two).
uint64_t first_slot(uint64_t stored, size_t slots) { return (stored * 0x9E3779B97F4A7C15ull) >> 20 & (slots - 1); }

}  // namespace

CenterPass::CenterPass(double cell_size, ClusterOptions options, std::span<const double, 6> bounds, uint64_t bitmap_bytes,
                       uint64_t brick_bytes)
    : clusterer_(std::span<const double>(&cell_size, 1), heaviest(options), bounds) {
  if (options.clustering != Clustering::floating) fail(Status::internal, "CenterPass: floating cells only");
  const double h = cell_size / 2;
  half_ = options.shape == CellShape::sphere ? h * 0.5773 : h;
  // The finest power of two at most c/16 whose voxels over the bounds fit the bitmap, up to c/4.
  for (int e = exponent_at_most(cell_size / 16); std::ldexp(1.0, e) <= cell_size / 4; ++e) {
    const double voxels = voxel_grid(bounds, std::ldexp(1.0, -e), first_, dims_);
    if (voxels / 8 + 8 > static_cast<double>(bitmap_bytes)) continue;
    voxel_ = std::ldexp(1.0, e), inverse_ = std::ldexp(1.0, -e);
    bits_.assign((static_cast<uint64_t>(voxels) + 63) / 64, 0);
    return;
  }
  // Too large a scene for a dense bitmap at c/4: bricks of 8³ voxels of side at most c/4, in a hash table.
  if (brick_bytes == 0) brick_bytes = bitmap_bytes;
  if (brick_bytes < kMinSparseBytes) return;
  const int e = exponent_at_most(cell_size / 4);
  voxel_grid(bounds, std::ldexp(1.0, -e), first_, dims_);
  for (int a = 0; a < 3; ++a)
    if (dims_[a] >= (int64_t{1} << 24)) return;  // brick coordinates of 21 bits
  voxel_ = std::ldexp(1.0, e), inverse_ = std::ldexp(1.0, -e), sparse_ = true, budget_ = brick_bytes;
  keys_.assign(kFirstSlots, 0);
  bricks_.assign(kFirstSlots, Brick{});
}

const CenterPass::Brick* CenterPass::find_brick(uint64_t key) const {
  const uint64_t stored = key + 1;  // 0 marks an empty slot
  for (uint64_t at = first_slot(stored, keys_.size());; at = (at + 1) & (keys_.size() - 1)) {
    if (keys_[at] == stored) return &bricks_[at];
    if (keys_[at] == 0) return nullptr;
  }
}

CenterPass::Brick* CenterPass::add_brick(uint64_t key) {
  const uint64_t stored = key + 1;
  if (2 * (used_ + 1) > keys_.size()) {  // half full: grow the table, or stop adding
    if (2 * keys_.size() * (sizeof(uint64_t) + sizeof(Brick)) > budget_) return nullptr;  // marks dropped: conservative
    std::vector<uint64_t> keys(2 * keys_.size(), 0);
    std::vector<Brick> bricks(keys.size());
    for (size_t i = 0; i < keys_.size(); ++i) {
      if (!keys_[i]) continue;
      uint64_t at = first_slot(keys_[i], keys.size());
      while (keys[at]) at = (at + 1) & (keys.size() - 1);
      keys[at] = keys_[i], bricks[at] = bricks_[i];
    }
    keys_.swap(keys), bricks_.swap(bricks);
  }
  for (uint64_t at = first_slot(stored, keys_.size());; at = (at + 1) & (keys_.size() - 1)) {
    if (keys_[at] == stored) return &bricks_[at];
    if (keys_[at] == 0) {
      keys_[at] = stored;
      ++used_;
      return &bricks_[at];
    }
  }
}

bool CenterPass::covered(const double* p) const {
  int64_t j[3];
  for (int a = 0; a < 3; ++a) {
    j[a] = static_cast<int64_t>(std::floor(p[a] * inverse_)) - first_[a];
    if (j[a] < 0 || j[a] >= dims_[a]) return false;
  }
  if (sparse_) {
    const Brick* b = find_brick(brick_key(j));
    const unsigned bit = brick_bit(j);
    return b && (b->bits[bit >> 6] >> (bit & 63) & 1);
  }
  const uint64_t at = dense_bit(j);
  return bits_[at >> 6] >> (at & 63) & 1;
}

// Marks the voxels wholly inside the cell centred on p (see the header: the bounds one ulp inwards).
void CenterPass::mark(const double* p) {
  int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const double l = std::nextafter(p[a] - half_, HUGE_VAL), u = std::nextafter(p[a] + half_, -HUGE_VAL);
    lo[a] = std::max<int64_t>(static_cast<int64_t>(std::ceil(l * inverse_)) - first_[a], 0);
    hi[a] = std::min<int64_t>(static_cast<int64_t>(std::floor(u * inverse_)) - 1 - first_[a], dims_[a] - 1);
    if (lo[a] > hi[a]) return;
  }
  uint64_t last = UINT64_MAX;  // sparse: the brick of the voxel before, kept while the next is in it
  Brick* b = nullptr;
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y)
      for (int64_t x = lo[0]; x <= hi[0]; ++x) {
        const int64_t j[3] = {x, y, z};
        if (!sparse_) {
          const uint64_t at = dense_bit(j);
          bits_[at >> 6] |= uint64_t{1} << (at & 63);
          continue;
        }
        if (const uint64_t key = brick_key(j); key != last) last = key, b = add_brick(key);
        if (!b) continue;  // the table is at its budget
        const unsigned bit = brick_bit(j);
        b->bits[bit >> 6] |= uint64_t{1} << (bit & 63);
      }
}

void CenterPass::visit_block(std::span<const double> xyz, std::span<uint8_t> is_center) {
  const size_t n = is_center.size();
  if (xyz.size() != 3 * n) fail(Status::internal, "CenterPass::visit_block: positions do not match");
  ids_.clear(), xyz_.clear(), where_.clear();
  for (size_t i = 0; i < n; ++i) {
    is_center[i] = 0;
    if (voxel_ > 0 && covered(&xyz[3 * i])) {
      ++skipped_;
      continue;
    }
    ids_.push_back(static_cast<uint32_t>(i));
    xyz_.insert(xyz_.end(), &xyz[3 * i], &xyz[3 * i] + 3);
    where_.push_back(i);
  }
  cells_.resize(ids_.size());
  uint32_t next = clusterer_.cell_count(0);
  clusterer_.assign_block(ids_, xyz_, cells_);
  for (size_t k = 0; k < where_.size(); ++k) {
    if (cells_[k] != next) continue;  // a member: its cell came before it
    ++next;
    is_center[where_[k]] = 1;
    if (voxel_ > 0) mark(&xyz_[3 * k]);
  }
}

}  // namespace lodstream::core

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

CenterPass::CenterPass(double cell_size, ClusterOptions options, std::span<const double, 6> bounds, uint64_t bitmap_bytes)
    : clusterer_(std::span<const double>(&cell_size, 1), heaviest(options), bounds) {
  if (options.clustering != Clustering::floating) fail(Status::internal, "CenterPass: floating cells only");
  const double h = cell_size / 2;
  half_ = options.shape == CellShape::sphere ? h * 0.5773 : h;
  // The finest power of two at most c/16 whose voxels over the bounds fit the bitmap, up to c/4.
  int e = std::ilogb(cell_size / 16);
  if (std::ldexp(1.0, e) > cell_size / 16) --e;
  for (; std::ldexp(1.0, e) <= cell_size / 4; ++e) {
    const double v = std::ldexp(1.0, e), inv = std::ldexp(1.0, -e);
    double voxels = 1;
    int64_t first[3], dims[3];
    for (int a = 0; a < 3; ++a) {
      first[a] = static_cast<int64_t>(std::floor(bounds[a] * inv));
      dims[a] = static_cast<int64_t>(std::floor(bounds[3 + a] * inv)) - first[a] + 1;
      voxels *= static_cast<double>(dims[a]);
    }
    if (voxels / 8 + 8 > static_cast<double>(bitmap_bytes)) continue;
    voxel_ = v, inverse_ = inv;
    std::copy(first, first + 3, first_);
    std::copy(dims, dims + 3, dims_);
    bits_.assign((static_cast<uint64_t>(voxels) + 63) / 64, 0);
    break;
  }
}

bool CenterPass::covered(const double* p) const {
  uint64_t at = 0;
  for (int a = 2; a >= 0; --a) {
    const int64_t j = static_cast<int64_t>(std::floor(p[a] * inverse_)) - first_[a];
    if (j < 0 || j >= dims_[a]) return false;
    at = at * static_cast<uint64_t>(dims_[a]) + static_cast<uint64_t>(j);
  }
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
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y) {
      const uint64_t row = (static_cast<uint64_t>(z) * static_cast<uint64_t>(dims_[1]) + static_cast<uint64_t>(y)) *
                           static_cast<uint64_t>(dims_[0]);
      for (int64_t x = lo[0]; x <= hi[0]; ++x) {
        const uint64_t at = row + static_cast<uint64_t>(x);
        bits_[at >> 6] |= uint64_t{1} << (at & 63);
      }
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

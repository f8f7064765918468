// Metro-style surface sampling; see surface_sampling.h.
#include "core/surface_sampling.h"

#include <algorithm>
#include <cmath>

namespace lodstream::core {
namespace {

// Stream numbers below the caller's: positions of face and edge samples, barycentric pairs, vertex picks.
enum : uint64_t { kFacePositions = 1, kEdgePositions = 2, kBarycentric = 3, kVertexPick = 4 };

// The weights both passes use; one function each, so the two passes sum identical values.
double triangle_area(const float* a, const float* b, const float* c) {
  const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  const double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2], z = u[0] * v[1] - u[1] * v[0];
  return 0.5 * std::sqrt(x * x + y * y + z * z);
}
double segment_length(const float* a, const float* b) {
  const double d[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  return std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}
void push_lerp(const float* a, const float* b, double t, std::vector<float>& out) {
  for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(a[k] + (double(b[k]) - a[k]) * t));
}

}  // namespace

std::vector<double> sorted_uniform_positions(uint64_t n, double total, uint64_t seed, uint64_t stream) {
  std::vector<double> pos;
  if (!(total > 0)) return pos;
  pos.resize(n);
  for (uint64_t i = 0; i < n; ++i) pos[i] = std::min(uniform01(seed, stream, i) * total, std::nextafter(total, 0.0));
  std::sort(pos.begin(), pos.end());
  return pos;
}

void SurfaceSampler::measure_triangle(const float* a, const float* b, const float* c) {
  block_.area += triangle_area(a, b, c);
  block_.length += segment_length(a, b) + segment_length(b, c) + segment_length(c, a);
}

void SurfaceSampler::measure_segment(const float* a, const float* b) { block_.length += segment_length(a, b); }

SamplerSums SurfaceSampler::end_block() {
  const SamplerSums b = block_;
  block_ = {};
  return b;
}

void SurfaceSampler::add_block(const SamplerSums& block) {
  area_total_ += block.area;
  length_total_ += block.length;
}

void SurfaceSampler::begin_sampling() {
  add_block(end_block());
  face_pos_ = sorted_uniform_positions(n_, area_total_, seed_, mix64(stream_) ^ kFacePositions);
  edge_pos_ = sorted_uniform_positions(n_, length_total_, seed_, mix64(stream_) ^ kEdgePositions);
}

void SurfaceSampler::begin_block(const SamplerSums& before) {
  before_ = before, run_ = {};
  // Every position before the block belongs to the blocks before it (the invariant).
  face_next_ = static_cast<uint64_t>(std::lower_bound(face_pos_.begin(), face_pos_.end(), before.area) - face_pos_.begin());
  edge_next_ = static_cast<uint64_t>(std::lower_bound(edge_pos_.begin(), edge_pos_.end(), before.length) - edge_pos_.begin());
}

void SurfaceSampler::sample_triangle(const float* a, const float* b, const float* c, std::vector<float>& faces,
                                     std::vector<float>& edges) {
  // Faces: a point uniform in the triangle, from two fresh uniforms (Osada et al. 2002, eq. 1).
  const double area = triangle_area(a, b, c);
  const double area_run = run_.area + area, area_end = before_.area + area_run;
  while (face_next_ < face_pos_.size() && face_pos_[face_next_] < area_end) {
    const double r1 = std::sqrt(uniform01(seed_, mix64(stream_) ^ kBarycentric, 2 * face_next_));
    const double r2 = uniform01(seed_, mix64(stream_) ^ kBarycentric, 2 * face_next_ + 1);
    const double wa = 1 - r1, wb = r1 * (1 - r2), wc = r1 * r2;
    for (int k = 0; k < 3; ++k) faces.push_back(static_cast<float>(wa * a[k] + wb * b[k] + wc * c[k]));
    ++face_next_;
  }
  run_.area = area_run;
  // Sides: the position within the element's perimeter picks the side and the point on it.
  const double lab = segment_length(a, b), lbc = segment_length(b, c), lca = segment_length(c, a);
  const double length_start = before_.length + run_.length, length_run = run_.length + (lab + lbc + lca);
  const double length_end = before_.length + length_run;
  while (edge_next_ < edge_pos_.size() && edge_pos_[edge_next_] < length_end) {
    double s = edge_pos_[edge_next_] - length_start;
    if (s < lab || (lbc == 0 && lca == 0)) {
      push_lerp(a, b, lab > 0 ? std::min(s / lab, 1.0) : 0.0, edges);
    } else if ((s -= lab) < lbc || lca == 0) {
      push_lerp(b, c, lbc > 0 ? std::min(s / lbc, 1.0) : 0.0, edges);
    } else {
      s -= lbc;
      push_lerp(c, a, std::min(s / lca, 1.0), edges);
    }
    ++edge_next_;
  }
  run_.length = length_run;
}

void SurfaceSampler::sample_segment(const float* a, const float* b, std::vector<float>& edges) {
  const double len = segment_length(a, b);
  const double start = before_.length + run_.length, run = run_.length + len, end = before_.length + run;
  while (edge_next_ < edge_pos_.size() && edge_pos_[edge_next_] < end) {
    push_lerp(a, b, len > 0 ? std::min((edge_pos_[edge_next_] - start) / len, 1.0) : 0.0, edges);
    ++edge_next_;
  }
  run_.length = run;
}

bool SurfaceSampler::take_vertex() {
  // Algorithm S: take the vertex with probability (still needed) / (still to visit).
  const uint64_t left = vertices_ - vertex_seen_;
  const uint64_t needed = std::min(n_, vertices_) - vertex_taken_;
  const bool take = needed > 0 && (needed >= left || uniform01(seed_, mix64(stream_) ^ kVertexPick, vertex_seen_) *
                                                             static_cast<double>(left) < static_cast<double>(needed));
  ++vertex_seen_;
  vertex_taken_ += take;
  return take;
}

void SurfaceSampler::sample_vertex(const float* p, std::vector<float>& vertices) {
  if (take_vertex()) vertices.insert(vertices.end(), p, p + 3);
}

}  // namespace lodstream::core

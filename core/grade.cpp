// Vertex grading (pipeline stage 2). This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.1
// Jarek Rossignac and Paul Borrel. Multi-resolution 3D approximations for rendering complex scenes. 1993
//
// The largest angle θ between incident edges is found in two steps. First the dot products of unit
// vectors rank the pairs cheaply (no trigonometry in the O(k²) loop). Then θ is the largest angle
// atan2(|a×b|, a·b) — accurate at 0 and π, where acos of a dot product loses half its digits — over the
// candidate pairs whose dot lies within kDotBand of the smallest dot. The band is wider than the rounding
// error of the dots, so the candidates always include the pair with the truly largest angle and every pair
// tied with it; pairs outside the band are smaller by more than atan2's error. The result is therefore the
// same whatever order the edges come in (the invariant stated in grade.h).
#include "core/grade.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <utility>

#include "core/status.h"

namespace lodstream::core {
namespace {

constexpr double kPi = std::numbers::pi;

// A dot of two unit vectors built as below carries at most about 20 roundings of 2^-53 (≈2.2e-15), so two
// dots are each within that of the truth, and atan2 of the scaled vectors errs by about 1e-15. Since the
// angle moves at least as fast as its cosine, a pair whose dot exceeds the smallest by more than 1e-14 has
// a computed angle strictly below the widest pair's. Only near-ties (regular fans, grids) fall inside it.
constexpr double kDotBand = 1e-14;

// Angle between scaled edges i and j of the SoA arrays s (x at s[0..k), y at s[k..2k), z at s[2k..3k)).
// Scaled vectors have components in [-1, 1], so the cross and dot products neither overflow nor lose the
// angle of nearly parallel or nearly opposite edges.
inline double exact_angle(const double* sx, const double* sy, const double* sz, size_t i, size_t j) {
  // Where the compiler fuses a·b − c·d into an FMA (aarch64 by default, x86 with -march), the cross
  // product is not exactly antisymmetric: (i, j) and (j, i) could differ in the last bit, and a vector
  // crossed with itself or its negation gives a rounding error instead of 0. So each unordered pair is
  // evaluated in one orientation fixed by the vectors' values, and equal or opposite scaled vectors (which
  // is what parallel edges become: e / max|e| is the same correctly rounded quotient) are exactly 0 or π
  // apart.
  if (sx[i] == sx[j] && sy[i] == sy[j] && sz[i] == sz[j]) return 0;
  if (sx[i] == -sx[j] && sy[i] == -sy[j] && sz[i] == -sz[j]) return kPi;
  if (sx[j] < sx[i] || (sx[j] == sx[i] && (sy[j] < sy[i] || (sy[j] == sy[i] && sz[j] < sz[i]))))
    std::swap(i, j);
  const double cx = sy[i] * sz[j] - sz[i] * sy[j];
  const double cy = sz[i] * sx[j] - sx[i] * sz[j];
  const double cz = sx[i] * sy[j] - sy[i] * sx[j];
  const double dot = sx[i] * sx[j] + sy[i] * sy[j] + sz[i] * sz[j];
  return std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot);
}

// The kernel shared by every entry point. edges: 3k doubles; work: at least 6k doubles.
// Kept out of line so that the seam path and the batch path run the very same machine code: a compiler
// allowed to contract a·b + c into an FMA could otherwise round two inlined copies differently.
[[gnu::noinline]] VertexGrade kernel(const double* edges, size_t k, Grading mode, double* work) {
  double* sx = work;
  double* sy = work + k;
  double* sz = work + 2 * k;
  double* ux = work + 3 * k;
  double* uy = work + 4 * k;
  double* uz = work + 5 * k;
  size_t n = 0;
  double lmax = 0;
  for (size_t i = 0; i < k; ++i) {
    const double x = edges[3 * i], y = edges[3 * i + 1], z = edges[3 * i + 2];
    const double m = std::max(std::max(std::fabs(x), std::fabs(y)), std::fabs(z));
    if (m == 0) continue;  // zero-length edge: no direction, no length
    // Dividing by the largest magnitude first keeps the squares in [0, 1] (no overflow or underflow for
    // any finite edge) and makes that component exactly ±1.
    const double a = x / m, b = y / m, c = z / m;
    const double r = std::sqrt(a * a + b * b + c * c);  // in [1, √3]
    lmax = std::max(lmax, m * r);
    sx[n] = a, sy[n] = b, sz[n] = c;
    const double inv = 1 / r;  // unit vectors only rank pairs: one division instead of three
    ux[n] = a * inv, uy[n] = b * inv, uz[n] = c * inv;
    ++n;
  }
  VertexGrade out;
  if (n == 0) return out;  // isolated: θ = 0, Lmax = 0, grade 0 in both modes

  // Pass 1: the smallest and second smallest dot; stop at once on two exactly opposite edges, since
  // nothing exceeds θ = π.
  double theta = 0;
  double dmin = 2, d2 = 2;
  size_t imin = 0, jmin = 0;
  bool opposite = false;
  for (size_t i = 0; i < n && !opposite; ++i) {
    for (size_t j = i + 1; j < n; ++j) {
      const double d = ux[i] * ux[j] + uy[i] * uy[j] + uz[i] * uz[j];
      if (d < dmin) {
        d2 = dmin, dmin = d, imin = i, jmin = j;
        if (d <= kDotBand - 1 && exact_angle(sx, sy, sz, i, j) == kPi) {
          opposite = true;
          break;
        }
      } else if (d < d2) {
        d2 = d;
      }
    }
  }
  if (opposite) {
    theta = kPi;
  } else if (n >= 2 && d2 > dmin + kDotBand) {
    theta = exact_angle(sx, sy, sz, imin, jmin);  // the usual case: one clear widest pair
  } else if (n >= 2) {
    // Near-ties: take the largest exact angle among all candidates, so the answer does not depend on
    // which of them the edge order made "the" minimum.
    const double limit = dmin + kDotBand;
    for (size_t i = 0; i < n && theta != kPi; ++i) {
      for (size_t j = i + 1; j < n; ++j) {
        const double d = ux[i] * ux[j] + uy[i] * uy[j] + uz[i] * uz[j];
        if (d > limit) continue;
        theta = std::max(theta, exact_angle(sx, sy, sz, i, j));
        if (theta == kPi) break;
      }
    }
  }
  // n == 1: one direction, θ = 0.

  out.theta = theta;
  out.lmax = lmax;
  if (mode == Grading::lowtan) {
    // cos(θ/2) written as sin((π − θ)/2), so that the double nearest π stands for π: θ = π gives exactly 0
    // with no special case (cos(fl(π)/2) would be 6e-17), π − θ is exact for θ ≥ π/2, and θ = 0 still
    // gives sin(fl(π)/2) = 1 exactly.
    out.grade = std::sin((kPi - theta) * 0.5) * lmax;
  } else {
    out.grade = lmax / std::max(theta, kRossignacMinTheta);
  }
  return out;
}

double* grow(std::vector<double>& v, size_t size) {
  if (v.size() < size) v.resize(size);
  return v.data();
}

// Sorts the short list [b, e) (a vertex's neighbours; valence is small in any mesh but a fan centre).
void sort_ids(uint32_t* b, uint32_t* e) {
  if (e - b > 16) {
    std::sort(b, e);
    return;
  }
  for (uint32_t* i = b + 1; i < e; ++i) {
    const uint32_t v = *i;
    uint32_t* j = i;
    for (; j > b && j[-1] > v; --j) *j = j[-1];
    *j = v;
  }
}

[[gnu::cold, gnu::noinline]] void id_out_of_range(const char* what, size_t index, const uint32_t* ids, int n,
                                                  uint32_t first_vertex, uint32_t vertex_count) {
  std::string message = "build_adjacency: ";
  message.append(what).append(" ").append(std::to_string(index)).append(" (");
  for (int i = 0; i < n; ++i) message.append(i ? " " : "").append(std::to_string(ids[i]));
  message.append(") uses a vertex outside the local range [").append(std::to_string(first_vertex));
  message.append(", ").append(std::to_string(uint64_t{first_vertex} + vertex_count)).append(")");
  fail(Status::internal, message);
}

}  // namespace

VertexGrade grade_edges(std::span<const double> edges, Grading mode, GradeScratch& scratch) {
  if (edges.size() % 3 != 0) fail(Status::internal, "grade_edges: edge coordinates not a multiple of 3");
  const size_t k = edges.size() / 3;
  return kernel(edges.data(), k, mode, grow(scratch.work, 6 * k));
}

VertexGrade grade_edges(std::span<const double> edges, Grading mode) {
  GradeScratch scratch;
  return grade_edges(edges, mode, scratch);
}

VertexGrade grade_vertex(std::span<const double, 3> position, std::span<const double> neighbour_positions,
                         Grading mode, GradeScratch& scratch) {
  if (neighbour_positions.size() % 3 != 0)
    fail(Status::internal, "grade_vertex: neighbour coordinates not a multiple of 3");
  const size_t k = neighbour_positions.size() / 3;
  double* e = grow(scratch.edges, 3 * k);
  const double* q = neighbour_positions.data();
  // The same subtraction as in grade_vertices, so both paths feed the kernel the same bits.
  for (size_t i = 0; i < k; ++i) {
    e[3 * i] = q[3 * i] - position[0];
    e[3 * i + 1] = q[3 * i + 1] - position[1];
    e[3 * i + 2] = q[3 * i + 2] - position[2];
  }
  return kernel(e, k, mode, grow(scratch.work, 6 * k));
}

void build_adjacency(std::span<const uint32_t> triangles, std::span<const uint32_t> segments,
                     uint32_t first_vertex, uint32_t vertex_count, Adjacency& out) {
  if (triangles.size() % 3 != 0) fail(Status::internal, "build_adjacency: triangle ids not a multiple of 3");
  if (segments.size() % 2 != 0) fail(Status::internal, "build_adjacency: segment ids not a multiple of 2");
  if (uint64_t{first_vertex} + vertex_count > (uint64_t{1} << 32))
    fail(Status::internal, "build_adjacency: vertex range exceeds 32-bit ids");
  out.first_vertex = first_vertex;
  out.vertex_count = vertex_count;
  out.offsets.assign(size_t{vertex_count} + 1, 0);
  const uint32_t* tri = triangles.data();
  const uint32_t* seg = segments.data();
  const size_t nt = triangles.size() / 3, ns = segments.size() / 2;

  // Pass 1: degrees, counted in offsets[v + 1]. Ids become local here; unsigned wrap-around turns an id
  // below first_vertex into one >= vertex_count, so a single compare checks both ends.
  uint64_t* deg = out.offsets.data() + 1;
  auto count = [deg](uint32_t a, uint32_t b) {
    if (a != b) ++deg[a], ++deg[b];
  };
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t a = tri[3 * t] - first_vertex, b = tri[3 * t + 1] - first_vertex,
                   c = tri[3 * t + 2] - first_vertex;
    if ((a >= vertex_count) | (b >= vertex_count) | (c >= vertex_count))
      id_out_of_range("triangle", t, tri + 3 * t, 3, first_vertex, vertex_count);
    count(a, b), count(b, c), count(c, a);
  }
  for (size_t s = 0; s < ns; ++s) {
    const uint32_t a = seg[2 * s] - first_vertex, b = seg[2 * s + 1] - first_vertex;
    if ((a >= vertex_count) | (b >= vertex_count))
      id_out_of_range("segment", s, seg + 2 * s, 2, first_vertex, vertex_count);
    count(a, b);
  }

  // Exclusive prefix sum shifted by one: offsets[v + 1] = start of v. Filling then advances it to the end
  // of v, which is the start of v + 1, so no separate cursor array is needed.
  uint64_t total = 0;
  for (uint32_t v = 0; v < vertex_count; ++v) {
    const uint64_t c = deg[v];
    deg[v] = total;
    total += c;
  }
  out.neighbours.resize(total);
  uint32_t* nb = out.neighbours.data();

  // Pass 2: fill. The ids were checked in pass 1.
  auto add = [deg, nb](uint32_t a, uint32_t b) {
    if (a != b) nb[deg[a]++] = b, nb[deg[b]++] = a;
  };
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t a = tri[3 * t] - first_vertex, b = tri[3 * t + 1] - first_vertex,
                   c = tri[3 * t + 2] - first_vertex;
    add(a, b), add(b, c), add(c, a);
  }
  for (size_t s = 0; s < ns; ++s) add(seg[2 * s] - first_vertex, seg[2 * s + 1] - first_vertex);

  // Pass 3: dedupe each list (a side shared by two triangles appears twice), compacting in place; the
  // write position never passes the read position. mark[u] == v says u is already in v's list: O(1) per
  // entry and branch-free, where sorting first cost more than the rest of the build. Local ids are below
  // 2^32 - 1, so the initial mark matches no vertex. The short deduped list is then sorted, so that the
  // lists do not depend on primitive order.
  std::vector<uint32_t> mark(vertex_count, UINT32_MAX);
  uint32_t* seen = mark.data();
  uint64_t w = 0, begin = 0;
  for (uint32_t v = 0; v < vertex_count; ++v) {
    const uint64_t end = out.offsets[v + 1];
    const uint64_t first = w;
    for (uint64_t i = begin; i < end; ++i) {
      const uint32_t u = nb[i];
      nb[w] = u;
      w += seen[u] != v;
      seen[u] = v;
    }
    sort_ids(nb + first, nb + w);
    out.offsets[v + 1] = w;
    begin = end;
  }
  out.neighbours.resize(w);
}

void grade_vertices(const Adjacency& adjacency, std::span<const double> positions, Grading mode,
                    GradeScratch& scratch, std::span<double> grade, std::span<double> theta,
                    std::span<double> lmax) {
  const uint32_t vc = adjacency.vertex_count;
  if (positions.size() < 3 * size_t{vc}) fail(Status::internal, "grade_vertices: too few positions");
  if (grade.size() < vc || (!theta.empty() && theta.size() < vc) || (!lmax.empty() && lmax.size() < vc))
    fail(Status::internal, "grade_vertices: output span shorter than the vertex count");
  const double* p = positions.data();
  const uint64_t* off = adjacency.offsets.data();
  const uint32_t* nb = adjacency.neighbours.data();
  for (uint32_t v = 0; v < vc; ++v) {
    const size_t k = off[v + 1] - off[v];
    double* e = grow(scratch.edges, 3 * k);
    const uint32_t* list = nb + off[v];
    const double x = p[3 * size_t{v}], y = p[3 * size_t{v} + 1], z = p[3 * size_t{v} + 2];
    for (size_t i = 0; i < k; ++i) {
      const double* q = p + 3 * size_t{list[i]};
      e[3 * i] = q[0] - x, e[3 * i + 1] = q[1] - y, e[3 * i + 2] = q[2] - z;
    }
    const VertexGrade g = kernel(e, k, mode, grow(scratch.work, 6 * k));
    grade[v] = g.grade;
    if (!theta.empty()) theta[v] = g.theta;
    if (!lmax.empty()) lmax[v] = g.lmax;
  }
}

void grade_vertices(std::span<const double> positions, std::span<const uint32_t> triangles,
                    std::span<const uint32_t> segments, uint32_t first_vertex, uint32_t vertex_count,
                    Grading mode, std::span<double> grade, std::span<double> theta, std::span<double> lmax) {
  Adjacency adjacency;
  GradeScratch scratch;
  build_adjacency(triangles, segments, first_vertex, vertex_count, adjacency);
  grade_vertices(adjacency, positions, mode, scratch, grade, theta, lmax);
}

}  // namespace lodstream::core

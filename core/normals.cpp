// Vertex normals with a crease angle (pipeline stage 5). This work is based on:
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §2 step 6
//
// The pass is vertex-major, then triangle-major. Per vertex, the incident triangles (a CSR list in increasing
// triangle order: the fill runs over the triangles backwards into end offsets) get their face normals
// computed afresh (a pure function of the positions, so each of a triangle's vertices sees the same bits,
// and no per-triangle array is kept), are grouped by their unit normal, the crease test runs on pairs of
// groups, and the vertex's distinct corner normals become numbered (vertex, normal) pairs whose ids are
// written into its corners. Then one scan over the corners in triangle order numbers the pairs in order of
// first appearance: those are the output vertices, exactly as "a corner reuses an output vertex of the same
// input vertex with the same normal bits, else creates one". Only the grouping makes the O(k²) crease test
// cheap on flat CAD fans; the result is a function of the input arrays alone: no hashing, no dependence on
// anything but the fixed orders stated in normals.h (the per-vertex pass runs in fixed vertex chunks in the
// caller's TBB arena; pair numbers are offset by the chunks' counts in chunk order, so threads change
// nothing).
#include "core/normals.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "core/status.h"

namespace lodstream::core {
namespace {

constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();

// A dot product of two unit vectors (each component computed with a few roundings) is within a few times
// 2^-53 of the truth, and cos(crease) within one ulp: outside a band of 1e-14 the dot decides the test for
// sure, inside it the angle is evaluated directly.
constexpr double kDotBand = 1e-14;

// Cube-map fallback (normals.h): 16 × 16 bins per face, about 5.6° each.
constexpr int kCubeBins = 16;
constexpr size_t kCubeBinCount = 6 * kCubeBins * kCubeBins;

// −0 → +0, anything else unchanged (x + 0 is not folded away without -ffast-math, for this very reason).
inline double plus_zero(double x) {
  return x + 0.0;
}
inline float plus_zero(float x) {
  return x + 0.0f;
}

// u = c / |c| with scaling (no overflow or underflow for any finite c), components canonicalised to +0.
// False when c is zero or not finite: the vector has no direction.
bool unit(const double* c, double* u) {
  if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2])) return false;
  const double m = std::max(std::max(std::fabs(c[0]), std::fabs(c[1])), std::fabs(c[2]));
  if (m == 0) return false;
  const double a = c[0] / m, b = c[1] / m, d = c[2] / m;
  const double r = std::sqrt(a * a + b * b + d * d);  // in [1, √3]
  u[0] = plus_zero(a / r), u[1] = plus_zero(b / r), u[2] = plus_zero(d / r);
  return true;
}

// The float32 output of a unit direction. False when n has no direction.
bool unit_float(const double* n, float* out) {
  double u[3];
  if (!unit(n, u)) return false;
  for (int i = 0; i < 3; ++i) out[i] = plus_zero(static_cast<float>(u[i]));
  return true;
}

void unit_float_from_unit(const double* u, float* out) {
  for (int i = 0; i < 3; ++i) out[i] = plus_zero(static_cast<float>(u[i]));
}

// The crease test of normals.h for crease in (0°, 180°) (or 0°, where it admits exactly parallel normals).
struct Crease {
  double radians = 0;
  double dot_in = 0;    // dot above this: inside
  double dot_out = 0;   // dot below this: outside
  bool smooth = false;  // crease >= 180°: everything inside

  explicit Crease(double degrees) {
    if (std::isnan(degrees)) fail(Status::usage, "crease_normals: crease angle is NaN");
    if (degrees >= 180) {
      smooth = true;
      return;
    }
    radians = std::max(degrees, 0.0) * (std::numbers::pi / 180);
    const double c = std::cos(radians);
    dot_in = c + kDotBand;
    dot_out = c - kDotBand;
  }

  bool within(const double* a, const double* b) const {
    const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    if (dot > dot_in) return true;
    if (dot < dot_out) return false;
    const double cx = a[1] * b[2] - a[2] * b[1];
    const double cy = a[2] * b[0] - a[0] * b[2];
    const double cz = a[0] * b[1] - a[1] * b[0];
    return std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot) <= radians;
  }
};

// One distinct unit normal among a vertex's incident triangles.
struct Group {
  uint32_t first = 0;    // lowest triangle in the group (its position in the vertex's incidence list)
  double sum[3] = {};    // Σ c_t over the group, in increasing t
  double u[3] = {};      // the common unit normal
  uint32_t bin = 0;      // fallback only: index into the vertex's bins
  float normal[3] = {};  // the corner normal of the group's triangles
};

struct Bin {
  double sum[3] = {};  // Σ of its groups' sums, in group order
  double u[3] = {};    // rep direction: unit(sum), or the first group's u
  float normal[3] = {};
};

// The cube-map bin of a unit vector: major axis (ties to the lower axis), its sign, and two coordinates.
uint32_t cube_bin(const double* u) {
  int a = 0;
  if (std::fabs(u[1]) > std::fabs(u[a])) a = 1;
  if (std::fabs(u[2]) > std::fabs(u[a])) a = 2;
  const int face = 2 * a + (u[a] < 0 ? 1 : 0);
  const double m = std::fabs(u[a]);
  auto cell = [m](double x) {
    const int i = static_cast<int>(std::floor((x / m + 1) * (kCubeBins / 2.0)));
    return std::clamp(i, 0, kCubeBins - 1);
  };
  const int i = cell(u[(a + 1) % 3]), j = cell(u[(a + 2) % 3]);
  return static_cast<uint32_t>((face * kCubeBins + i) * kCubeBins + j);
}

// Bitwise equality of two float32 normals (no NaN reaches here, and zeros are +0).
bool same_bits(const float* a, const float* b) {
  return std::bit_cast<uint32_t>(a[0]) == std::bit_cast<uint32_t>(b[0]) &&
         std::bit_cast<uint32_t>(a[1]) == std::bit_cast<uint32_t>(b[1]) &&
         std::bit_cast<uint32_t>(a[2]) == std::bit_cast<uint32_t>(b[2]);
}

void add3(double* s, const double* x) {
  s[0] += x[0], s[1] += x[1], s[2] += x[2];
}

// Face normal of triangle t: c_t into `cross`, u_t into `u`; false (and c_t = 0, so that it contributes
// nothing even if it overflowed) when the triangle has no direction. A pure function of the positions: the
// per-vertex pass calls it once for every vertex of t and gets the same bits each time.
bool face(const double* pos, const uint32_t* tri, size_t t, double* cross, double* u) {
  const double* p0 = pos + 3 * size_t{tri[3 * t]};
  const double* p1 = pos + 3 * size_t{tri[3 * t + 1]};
  const double* p2 = pos + 3 * size_t{tri[3 * t + 2]};
  const double e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
  const double e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
  cross[0] = e1[1] * e2[2] - e1[2] * e2[1];
  cross[1] = e1[2] * e2[0] - e1[0] * e2[2];
  cross[2] = e1[0] * e2[1] - e1[1] * e2[0];
  if (unit(cross, u)) return true;
  cross[0] = cross[1] = cross[2] = 0;
  return false;
}

// Per-call working memory; the per-vertex vectors grow to the largest valence.
struct Work {
  std::vector<uint32_t> offsets;   // CSR: vertex_count + 1
  std::vector<uint32_t> incident;  // CSR: triangle ids, increasing per vertex
  // per vertex, indexed by the position i of a triangle in the vertex's incidence list
  std::vector<double> cross;       // c_t, 3 per incident triangle
  std::vector<double> unitn;       // u_t, 3 per incident triangle (valid where ok[i])
  std::vector<uint8_t> ok;         // the triangle has a direction
  std::vector<uint32_t> order;     // positions of the non-degenerate incident triangles, sorted by (u bits, i)
  std::vector<uint32_t> group_of;  // parallel to order
  std::vector<Group> groups;
  std::vector<uint32_t> by_first;  // group ids in order of their lowest triangle
  std::vector<uint32_t> normal_of;  // per group: its pair id (below)
  std::vector<Bin> bins;
  std::vector<uint32_t> bin_slot;  // kCubeBinCount entries, kNone when unused at this vertex
};

// Groups the k incident triangles of one vertex (in increasing order; their face normals in w.cross,
// w.unitn, w.ok) by unit normal and sets every group's corner normal; returns the normal of the vertex's
// degenerate corners in `degenerate`.
void vertex_normals(size_t k, const Crease& crease, Work& w, float* degenerate) {
  const double* un = w.unitn.data();
  w.order.clear();
  for (size_t i = 0; i < k; ++i)
    if (w.ok[i]) w.order.push_back(static_cast<uint32_t>(i));
  // Group by unit normal bits. Canonical +0 makes bitwise equality value equality (no NaN reaches here).
  auto key = [un](uint32_t i) {
    const double* u = un + 3 * size_t{i};
    return std::array<uint64_t, 3>{std::bit_cast<uint64_t>(u[0]), std::bit_cast<uint64_t>(u[1]),
                                   std::bit_cast<uint64_t>(u[2])};
  };
  // Positions increase with triangle ids, so ties by position are ties by triangle.
  std::sort(w.order.begin(), w.order.end(), [&](uint32_t a, uint32_t b) {
    const auto ka = key(a), kb = key(b);
    return ka != kb ? ka < kb : a < b;
  });
  w.groups.clear();
  w.group_of.resize(w.order.size());
  for (size_t n = 0; n < w.order.size(); ++n) {
    const uint32_t i = w.order[n];
    if (n == 0 || key(i) != key(w.order[n - 1])) {
      Group g;
      g.first = i;  // the lowest triangle of the group: ties sort by position
      std::copy(un + 3 * size_t{i}, un + 3 * size_t{i} + 3, g.u);
      w.groups.push_back(g);
    }
    w.group_of[n] = static_cast<uint32_t>(w.groups.size() - 1);
    add3(w.groups.back().sum, &w.cross[3 * size_t{i}]);  // increasing t within the group
  }
  const size_t d = w.groups.size();
  // The summation order of normals.h: groups by their lowest triangle.
  w.by_first.resize(d);
  for (size_t g = 0; g < d; ++g) w.by_first[g] = static_cast<uint32_t>(g);
  std::sort(w.by_first.begin(), w.by_first.end(),
            [&](uint32_t a, uint32_t b) { return w.groups[a].first < w.groups[b].first; });

  // Degenerate corners: normalize(Σ c_s) over all faces, else the lowest-index face's u, else +z.
  double all[3] = {0, 0, 0};
  for (uint32_t g : w.by_first) add3(all, w.groups[g].sum);
  if (!unit_float(all, degenerate)) {
    if (d > 0) {
      unit_float_from_unit(w.groups[w.by_first[0]].u, degenerate);
    } else {
      degenerate[0] = 0, degenerate[1] = 0, degenerate[2] = 1;
    }
  }
  if (d == 0) return;

  if (crease.smooth) {
    float n[3];
    const bool ok = unit_float(all, n);
    for (Group& g : w.groups) {
      if (ok)
        std::copy(n, n + 3, g.normal);
      else
        unit_float_from_unit(g.u, g.normal);
    }
    return;
  }

  if (d <= kMaxPairwiseDirections) {
    for (Group& g : w.groups) {
      double sum[3] = {0, 0, 0};
      for (uint32_t h : w.by_first) {
        const Group& other = w.groups[h];
        if (&other == &g || crease.within(g.u, other.u)) add3(sum, other.sum);
      }
      if (!unit_float(sum, g.normal)) unit_float_from_unit(g.u, g.normal);
    }
    return;
  }

  // Cube-map fallback: bins in order of first appearance in group order, each the sum of its groups.
  if (w.bin_slot.empty()) w.bin_slot.assign(kCubeBinCount, kNone);
  w.bins.clear();
  for (uint32_t g : w.by_first) {
    Group& group = w.groups[g];
    const uint32_t key_bin = cube_bin(group.u);
    if (w.bin_slot[key_bin] == kNone) {
      w.bin_slot[key_bin] = static_cast<uint32_t>(w.bins.size());
      Bin b;
      std::copy(group.u, group.u + 3, b.u);  // rep direction until the sum is known
      w.bins.push_back(b);
    }
    group.bin = w.bin_slot[key_bin];
    add3(w.bins[group.bin].sum, group.sum);
  }
  for (Bin& b : w.bins) unit(b.sum, b.u);  // keeps the first group's u when the sum has no direction
  for (Bin& b : w.bins) {
    double sum[3] = {0, 0, 0};
    for (const Bin& other : w.bins)
      if (&other == &b || crease.within(b.u, other.u)) add3(sum, other.sum);
    if (!unit_float(sum, b.normal)) unit_float_from_unit(b.u, b.normal);
  }
  for (Group& g : w.groups) std::copy(w.bins[g.bin].normal, w.bins[g.bin].normal + 3, g.normal);
  for (const Group& g : w.groups) w.bin_slot[cube_bin(g.u)] = kNone;
}

[[noreturn]] void bad_input(const std::string& what) {
  fail(Status::internal, "crease_normals: " + what);
}

}  // namespace

void crease_normals(std::span<const double> positions, std::span<const uint32_t> triangles,
                    double crease_degrees, CreaseNormals& out) {
  const Crease crease(crease_degrees);
  if (positions.size() % 3 != 0) bad_input("positions.size() is not a multiple of 3");
  if (triangles.size() % 3 != 0) bad_input("triangles.size() is not a multiple of 3");
  if (triangles.size() > kNone) bad_input("more than 2^32 - 1 corners");
  const size_t vertex_count = positions.size() / 3;
  const size_t triangle_count = triangles.size() / 3;
  const uint32_t* tri = triangles.data();
  const double* pos = positions.data();

  Work w;
  // The incidence (a triangle counts once per distinct vertex): counts, end offsets, then a backward fill
  // that leaves offsets[v] at the start of v's list and each list in increasing triangle order.
  w.offsets.assign(vertex_count + 1, 0);
  for (size_t t = 0; t < triangle_count; ++t) {
    const uint32_t a = tri[3 * t], b = tri[3 * t + 1], c = tri[3 * t + 2];
    if (a >= vertex_count || b >= vertex_count || c >= vertex_count)
      bad_input("triangle " + std::to_string(t) + " has a vertex id out of range");
    ++w.offsets[a];
    if (b != a) ++w.offsets[b];
    if (c != a && c != b) ++w.offsets[c];
  }
  for (size_t v = 1; v <= vertex_count; ++v) w.offsets[v] += w.offsets[v - 1];  // [vertex_count]: the total
  w.incident.resize(w.offsets[vertex_count]);
  for (size_t t = triangle_count; t-- > 0;) {
    const uint32_t a = tri[3 * t], b = tri[3 * t + 1], c = tri[3 * t + 2];
    w.incident[--w.offsets[a]] = static_cast<uint32_t>(t);
    if (b != a) w.incident[--w.offsets[b]] = static_cast<uint32_t>(t);
    if (c != a && c != b) w.incident[--w.offsets[c]] = static_cast<uint32_t>(t);
  }

  // Corner normals, vertex by vertex. A vertex's distinct corner normals (bitwise) become "pairs" (vertex,
  // normal), numbered in vertex order; each corner holds its pair id in out.triangles until the last pass
  // renumbers them. The vertices run in fixed chunks in parallel (each vertex reads only the positions and
  // writes only its own corners): a chunk numbers its pairs from 0 with their normals in its own array, and
  // the chunks' pair counts, summed in chunk order, give the same numbers as one pass in vertex order.
  out.triangles.assign(triangles.size(), 0);
  constexpr size_t kChunk = 1 << 14;  // vertices
  const size_t chunks = (vertex_count + kChunk - 1) / kChunk;
  std::vector<std::vector<float>> chunk_normals(chunks);
  tbb::enumerable_thread_specific<Work> works;
  tbb::parallel_for(size_t{0}, chunks, [&](size_t ch) {
    Work& vw = works.local();  // per-vertex scratch (the CSR stays in w)
    std::vector<float>& pair_normals = chunk_normals[ch];
    auto pair_of = [&](size_t first_pair, const float* n) {
      const size_t pairs = pair_normals.size() / 3;
      for (size_t p = first_pair; p < pairs; ++p)
        if (same_bits(&pair_normals[3 * p], n)) return static_cast<uint32_t>(p);
      pair_normals.insert(pair_normals.end(), n, n + 3);
      return static_cast<uint32_t>(pairs);
    };
    for (size_t v = ch * kChunk; v < std::min(vertex_count, (ch + 1) * kChunk); ++v) {
      const uint32_t begin = w.offsets[v], end = w.offsets[v + 1];
      if (begin == end) continue;
      const uint32_t* inc = w.incident.data() + begin;
      const size_t k = end - begin;
      vw.cross.resize(3 * k);
      vw.unitn.resize(3 * k);
      vw.ok.resize(k);
      for (size_t i = 0; i < k; ++i) vw.ok[i] = face(pos, tri, inc[i], &vw.cross[3 * i], &vw.unitn[3 * i]);
      float degenerate[3];
      vertex_normals(k, crease, vw, degenerate);
      const size_t first_pair = pair_normals.size() / 3;
      vw.normal_of.resize(vw.groups.size());
      for (size_t g = 0; g < vw.groups.size(); ++g) vw.normal_of[g] = pair_of(first_pair, vw.groups[g].normal);
      auto write = [&](uint32_t t, uint32_t pair) {
        for (size_t j = 3 * size_t{t}; j < 3 * size_t{t} + 3; ++j)
          if (tri[j] == v) out.triangles[j] = pair;
      };
      for (size_t n = 0; n < vw.order.size(); ++n) write(inc[vw.order[n]], vw.normal_of[vw.group_of[n]]);
      if (vw.order.size() < k) {
        const uint32_t pair = pair_of(first_pair, degenerate);
        for (size_t i = 0; i < k; ++i)
          if (!vw.ok[i]) write(inc[i], pair);
      }
    }
  });
  std::vector<size_t> chunk_first(chunks + 1, 0);  // the global id of each chunk's first pair
  for (size_t ch = 0; ch < chunks; ++ch) chunk_first[ch + 1] = chunk_first[ch] + chunk_normals[ch].size() / 3;
  std::vector<uint32_t>().swap(w.incident);
  std::vector<uint32_t>().swap(w.offsets);

  // Output vertices: the pairs in order of first appearance over the corners. Every pair has a corner.
  const size_t pairs = chunk_first[chunks];
  std::vector<uint32_t> output_of(pairs, kNone);
  out.vertex.clear();
  out.normals.clear();
  out.vertex.reserve(pairs);
  out.normals.reserve(3 * pairs);
  for (size_t j = 0; j < triangles.size(); ++j) {
    const size_t ch = tri[j] / kChunk, local = out.triangles[j], p = chunk_first[ch] + local;
    if (output_of[p] == kNone) {
      output_of[p] = static_cast<uint32_t>(out.vertex.size());
      out.vertex.push_back(tri[j]);
      const float* n = &chunk_normals[ch][3 * local];
      out.normals.insert(out.normals.end(), n, n + 3);
    }
    out.triangles[j] = output_of[p];
  }
}

}  // namespace lodstream::core

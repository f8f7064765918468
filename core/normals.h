// Vertex normals with a crease angle, pipeline stage 5 ("recompute normals"): the triangles of a level are
// mostly flat CAD faces that must stay flat, with sharp creases between them, so a vertex is split into one
// output vertex per distinct normal its corners need.
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §2 step 6 ("adjustment of normals"):
// the normals of the resulting triangles are reconstructed from the simplified mesh, not carried over from
// the input. (Edges and points get theirs elsewhere: dynamic normals, §3.3.2.) The crease rule is the usual
// "auto-smooth" of modelling packages, stated per corner:
//
//   face normal     c_t = (p1 − p0) × (p2 − p0)   (length = twice the area, so sums are area weighted)
//   unit normal     u_t = c_t / |c_t|
//   corner (t, v)   n = normalize( Σ c_s  over the triangles s incident on v with angle(u_s, u_t) <= crease )
//
// Corners of a vertex whose normals are equal (bitwise, as the float32 output) share one output vertex;
// every other corner gets an output vertex of its own, in order of first appearance when the triangles'
// corners are scanned in order (triangle 0 corners 0, 1, 2, triangle 1, ...).
//
// Units: positions in scene units (double); crease in degrees; normals unit length in float32 (the double
// result rounded once, so |n| = 1 within float rounding; axis-aligned normals are exact).
//
// Definitions, so that a build gives the same bits on every run, for any number of threads (the per-vertex
// pass runs in fixed vertex chunks in parallel in the caller's TBB arena):
// - Zero normals are +0: every component of every output normal is canonicalised (−0 → +0) before the
//   bitwise comparison and the output.
// - Angle test: t always includes itself. Otherwise the angle is decided on the dot product of the unit
//   normals, u_s·u_t >= cos(crease), except within 1e-14 of cos(crease), where it is evaluated as
//   atan2(|u_s × u_t|, u_s·u_t) <= crease (accurate at 0°, where the dot product cannot resolve angles
//   below 1e-8 rad). So crease 0 merges only faces whose unit normals are exactly parallel.
// - crease >= 180: everything incident on v is included (smooth shading); crease <= 0 behaves as 0 (flat
//   shading; corners whose normals come out identical still share). NaN: Failure(Status::usage).
// - Summation order: a vertex's incident triangles are grouped by their unit normal (bitwise); each group's
//   sum runs over its triangles in increasing index, and the corner's sum over its included groups in order
//   of their lowest triangle index. Since the angle test depends only on unit normals, corners whose included
//   groups are the same get bitwise the same normal and share an output vertex (a vertex inside a smooth or
//   flat region gets exactly one).
// - Zero-area triangles (c_t exactly 0, including a repeated vertex id, or c_t not finite, i.e. coordinates
//   beyond about 1e150): no unit normal, so they contribute to no corner. Their own corners take the plain
//   area-weighted average of all faces incident on v, normalize(Σ c_s); if that is zero or not finite, the
//   unit normal of the lowest-index non-degenerate triangle incident on v; if there is none, (0, 0, 1).
// - A corner whose included sum cancels to zero or overflows (opposite faces under crease >= 180, say)
//   takes its own triangle's unit normal u_t. Hence no output normal is ever NaN or zero.
//
// Cost: two passes over the triangles build the vertex → triangle incidence (CSR, 4 bytes per vertex + 4 per
// corner); then per vertex of valence k with d distinct face directions, k face normals (each triangle's is
// computed once per vertex, three times in all, rather than stored), O(k log k) to group and O(d²) angle
// tests and additions. Flat CAD fans (a fan-triangulated cap has valence in the thousands but d = 1)
// stay cheap. Pathological vertices with d > kMaxPairwiseDirections fall back to binning the directions on
// a cube map of 6 × 16 × 16 bins (a bin is about 5.6° wide): the groups of a bin share one included set,
// decided on the bins' area-weighted mean directions, so the cost is O(d + 1536²) and the crease is only
// approximate (within about a bin width) at such vertices. Temporary memory, allocated once per call besides
// the output: 4 bytes per input vertex and per corner (the incidence, freed before the last pass), and 16
// bytes per output vertex (its normal in vertex order and its renumbering), i.e. about 12 bytes per triangle,
// 4 per input vertex and 16 per output vertex; per-vertex scratch grows to the largest valence.
//
// Preconditions: positions.size() and triangles.size() are multiples of 3, every id is < positions.size()/3,
// and there are at most 2^32 − 1 corners (so output ids fit in 32 bits); otherwise Failure(Status::internal)
// (a caller bug: the store checks indices). Coordinates finite.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace lodstream::core {

// A vertex with more distinct face directions than this uses the cube-map fallback described above.
inline constexpr size_t kMaxPairwiseDirections = 1024;

struct CreaseNormals {
  std::vector<uint32_t> vertex;     // per output vertex: the input vertex whose position it copies
  std::vector<float> normals;       // xyz per output vertex, unit length
  std::vector<uint32_t> triangles;  // 3 per input triangle, same order and winding, output vertex ids
};

// Fills `out` (its vectors are cleared and reused). positions: xyz per input vertex; triangles: 3 input
// vertex ids each. Input vertices used by no triangle produce no output vertex. out.triangles has exactly
// triangles.size() entries; out.vertex.size() is between the number of distinct vertices used and the number
// of corners.
void crease_normals(std::span<const double> positions, std::span<const uint32_t> triangles,
                    double crease_degrees, CreaseNormals& out);

}  // namespace lodstream::core

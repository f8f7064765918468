// Vertex grading, pipeline stage 2: the weight that orders vertices for floating-cell clustering.
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.1:
//   grade = cos(θ/2) · Lmax
// Rossignac & Borrel, "Multi-resolution 3D approximations for rendering complex scenes", 1993 (Low & Tan's
// reference [13]), kept for comparison:
//   grade = Lmax / θ
// where θ is the largest angle between any two edges incident on the vertex and Lmax the length of its
// longest incident edge.
//
// Units: positions and edges in scene units; θ in radians, in [0, π]; Lmax and the grade in scene units
// (Rossignac: scene units per radian). Everything is in double precision.
//
// Special cases (the same in every entry point):
// - Zero-length edges (a neighbour at the vertex's own position, or a degenerate primitive) are ignored.
//   Duplicate edges are allowed and change nothing.
// - No non-zero edge (an isolated vertex, or one used only by points): θ = 0, Lmax = 0, grade = 0 in both
//   modes.
// - One distinct edge direction (the end of a line, the tip of a spike): θ = 0, so the Low–Tan grade is
//   Lmax (cos 0 = 1: such a vertex shows on a silhouette from almost every direction).
// - θ = π (two exactly opposite edges, as at a flat interior vertex of a grid): the Low–Tan grade is exactly
//   0, not cos(fl(π)/2)·Lmax ≈ 6e-17·Lmax. The factor is evaluated as sin((π − θ)/2), which takes the double
//   nearest π as π: exact at θ = π, and equal to cos(θ/2) elsewhere within rounding.
// - Rossignac mode divides by max(θ, kRossignacMinTheta), so θ = 0 gives Lmax · 2^24 (finite), and the
//   grade stays non-increasing in θ for a given Lmax.
//
// Preconditions: coordinates are finite and every edge (difference of two positions) is finite, i.e.
// |coordinate| < 8.9e307; ingest rejects NaN and infinities. Edge lengths are computed with scaling, so
// tiny or huge (but finite) edges neither underflow to zero nor overflow.
//
// Invariant (what lets stage 2 run per chunk): the grade, θ and Lmax of a vertex depend only on its own
// position and the SET of its distinct neighbour positions — not on their order, their multiplicity, or
// which primitive or chunk contributed them. Any split of the primitives into chunks that, once the seam
// records are merged, gives each vertex all of its incident primitives yields the same bits as grading the
// whole mesh at once. (grade_vertices and grade_vertex share one kernel; the kernel's result is the largest
// exactly evaluated angle over a candidate set that always contains every pair tied for the largest angle,
// so it does not depend on the order the edges come in.)
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace lodstream::core {

enum class Grading {
  lowtan,     // cos(θ/2) · Lmax (Low & Tan §3.1)
  rossignac,  // Lmax / max(θ, kRossignacMinTheta) (Rossignac & Borrel)
};

// Below this angle Rossignac's 1/θ factor is clamped. 2^-24 rad is about the angular resolution of float32
// input coordinates (float epsilon is 2^-23), so smaller angles are indistinguishable from 0 for most
// inputs; a power of two makes the θ = 0 grade exactly Lmax · 2^24.
inline constexpr double kRossignacMinTheta = 0x1p-24;

struct VertexGrade {
  double grade = 0;  // see Grading
  double theta = 0;  // radians, [0, π]
  double lmax = 0;   // scene units
};

// Reusable working memory for the kernel: grows to the largest valence met, so that grading a whole chunk
// allocates only a handful of times. Not thread-safe: one per thread.
struct GradeScratch {
  std::vector<double> edges;  // 3 per edge, built from neighbour positions
  std::vector<double> work;   // 6 per edge, the kernel's scaled and unit vectors
};

// The per-vertex kernel. `edges` holds xyz per incident edge (other endpoint minus the vertex), so
// edges.size() must be a multiple of 3. Cost O(k²) in the number k of non-zero edges.
VertexGrade grade_edges(std::span<const double> edges, Grading mode, GradeScratch& scratch);
// The same, allocating its own scratch: for tests and one-off calls.
VertexGrade grade_edges(std::span<const double> edges, Grading mode);

// The seam entry point: grades a vertex at `position` (xyz) from the positions of its neighbours (xyz per
// neighbour, in any order, duplicates allowed, the vertex's own position allowed and ignored). The stream
// stage uses it for vertices whose incident primitives span several chunks: given the union of the
// neighbour positions every chunk saw, it returns the same bits as grade_vertices on the whole mesh.
VertexGrade grade_vertex(std::span<const double, 3> position, std::span<const double> neighbour_positions,
                         Grading mode, GradeScratch& scratch);

// Vertex adjacency of a local vertex range [first_vertex, first_vertex + vertex_count) in CSR form.
// neighbours[offsets[v] .. offsets[v + 1]) are the local ids (vertex id − first_vertex) of the distinct
// vertices sharing a triangle side or a segment with local vertex v, sorted ascending; v itself never
// appears (a degenerate primitive's repeated corner gives no edge).
struct Adjacency {
  uint32_t first_vertex = 0;
  uint32_t vertex_count = 0;
  std::vector<uint64_t> offsets;     // vertex_count + 1 entries
  std::vector<uint32_t> neighbours;  // offsets[vertex_count] entries
  std::span<const uint32_t> of(uint32_t local) const {
    return {neighbours.data() + offsets[local], neighbours.data() + offsets[local + 1]};
  }
};

// Builds `out` (its vectors are reused) from triangles (3 vertex ids each: sides ab, bc, ca) and segments
// (2 vertex ids each), in two passes over the primitives (count, then fill) and one over the lists (dedupe,
// compact, sort). Every id must lie in the local range and first_vertex + vertex_count must not exceed
// 2^32; otherwise throws lodstream::Failure with Status::internal (the store has already checked indices,
// so this is a caller bug). Memory: 12 bytes per vertex (8 kept as offsets, 4 temporary) + 4 bytes per
// (triangle side or segment) endpoint before dedupe, i.e. at most 24 bytes per triangle and 8 per segment.
void build_adjacency(std::span<const uint32_t> triangles, std::span<const uint32_t> segments,
                     uint32_t first_vertex, uint32_t vertex_count, Adjacency& out);

// Grades every vertex of adjacency's local range. positions: xyz per local vertex, at least
// 3 · vertex_count doubles. grade: vertex_count entries written; theta and lmax: written only when
// non-empty, and then must also have vertex_count entries. Throws lodstream::Failure (Status::internal) on
// a size mismatch.
void grade_vertices(const Adjacency& adjacency, std::span<const double> positions, Grading mode,
                    GradeScratch& scratch, std::span<double> grade, std::span<double> theta = {},
                    std::span<double> lmax = {});

// The per-chunk batch: build_adjacency, then grade_vertices, with temporary memory of its own. For
// repeated calls on one thread, keep an Adjacency and a GradeScratch and call the two functions above.
void grade_vertices(std::span<const double> positions, std::span<const uint32_t> triangles,
                    std::span<const uint32_t> segments, uint32_t first_vertex, uint32_t vertex_count,
                    Grading mode, std::span<double> grade, std::span<double> theta = {},
                    std::span<double> lmax = {});

}  // namespace lodstream::core

// Metro-style surface sampling for the two-sided Hausdorff distance (Cignoni, Rocchini & Scopigno,
// "Metro: measuring error on simplified surfaces", 1998), arranged to mirror MeshLab's "Hausdorff
// Distance" filter (vcglib SurfaceSampling: VertexUniform, EdgeUniform, Montecarlo), so that the two agree:
// - vertex samples: every used vertex when there are at most n of them, else exactly n of them chosen by
//   selection sampling (Knuth, TAOCP vol. 2, Algorithm S) in visiting order;
// - edge samples: n points uniform in length over the sides of every triangle (a side shared by two
//   triangles counts twice, so no edge table is needed out of core) and over the mesh's own edges;
// - face samples: n points uniform in area over the triangles (Montecarlo).
// Uniform positions are drawn from a counter-based generator (SplitMix64, Steele, Lea & Flood 2014) and
// sorted, and the mesh is streamed twice in the same fixed order (measure, then sample), so the sample
// set depends on the mesh, n and the seed only: never on threads or memory.
//
// Blocks: the elements may be measured and sampled in consecutive blocks (end_block, begin_block), each
// block's weights summed on their own from 0 and the blocks' sums added to the totals in block order, so
// that a block can be measured and sampled by another process than its neighbours (a report's tasks,
// stream/report.cpp) with the same samples; without blocks the whole mesh is one.
//
// Invariant of the sampling pass: within a block, the running sum of weights is computed by the same
// function, in the same order, as in the measuring pass, and a position is compared with the sums before
// the block plus it (one rounding), so the block ends exactly at the next block's start, the last block at
// the measured total, and every drawn position (< total) is reached.
#pragma once

#include <cstdint>
#include <vector>

namespace lodstream::core {

// SplitMix64's output function: a bijective 64-bit mix.
inline uint64_t mix64(uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
// Uniform double in [0, 1) for (seed, stream, index): 53 random bits.
inline double uniform01(uint64_t seed, uint64_t stream, uint64_t index) {
  const uint64_t h = mix64(mix64(mix64(seed) ^ stream) ^ index);
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

// Sorted positions of n independent uniform draws in [0, total).
std::vector<double> sorted_uniform_positions(uint64_t n, double total, uint64_t seed, uint64_t stream);

// Area and length sums of a block of elements, or of every block before one.
struct SamplerSums {
  double area = 0, length = 0;
};

class SurfaceSampler {
 public:
  // n: samples of each kind. seed/stream: the random sequence (use distinct streams for distinct meshes).
  SurfaceSampler(uint64_t n, uint64_t seed, uint64_t stream) : n_(n), seed_(seed), stream_(stream) {}

  // Pass 1, in the order pass 2 will use.
  void measure_triangle(const float* a, const float* b, const float* c);
  void measure_segment(const float* a, const float* b);
  void measure_vertex() { ++vertices_; }
  // Closes the block measured since the last one (pass 1) and returns its sums, for add_block.
  SamplerSums end_block();
  // Adds a block's sums to the totals, the blocks in their order (whichever process measured them).
  void add_block(const SamplerSums& block);
  // Vertices measured elsewhere (instead of measure_vertex).
  void add_vertices(uint64_t count) { vertices_ += count; }
  // Between the passes: adds the block still open (all of pass 1 without blocks) and draws the positions.
  void begin_sampling();
  // Pass 2, before a block's elements: the totals of every block before it, as pass 1 added them. Without
  // it, the elements continue the block so far (the first: from 0).
  void begin_block(const SamplerSums& before);
  // Pass 2: appends the samples falling in each element as xyz triples: face samples to `faces`, samples on
  // triangle sides and segments to `edges`, vertex samples to `vertices`.
  void sample_triangle(const float* a, const float* b, const float* c, std::vector<float>& faces,
                       std::vector<float>& edges);
  void sample_segment(const float* a, const float* b, std::vector<float>& edges);
  void sample_vertex(const float* p, std::vector<float>& vertices);
  // The same decision alone: whether the next vertex is taken (its position is then the caller's to add).
  bool take_vertex();

  double area() const { return area_total_; }
  double length() const { return length_total_; }
  uint64_t vertex_samples() const { return vertex_taken_; }
  uint64_t edge_samples() const { return edge_next_; }
  uint64_t face_samples() const { return face_next_; }

 private:
  uint64_t n_, seed_, stream_;
  // pass 1
  double area_total_ = 0, length_total_ = 0;
  SamplerSums block_;  // of the block being measured
  uint64_t vertices_ = 0;
  // pass 2
  std::vector<double> face_pos_, edge_pos_;
  SamplerSums before_, run_;  // the blocks before this one; this block's running sums
  uint64_t face_next_ = 0, edge_next_ = 0;
  uint64_t vertex_seen_ = 0, vertex_taken_ = 0;
};

}  // namespace lodstream::core

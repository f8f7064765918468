// Quadric-placed cluster representatives, pipeline stage 5 (the `quadric` representative of DESIGN.md).
//
// Lindstrom, "Out-of-core simplification of large polygonal models", SIGGRAPH 2000: every cell accumulates
// the plane quadrics of the triangles that touch it (Garland & Heckbert, "Surface simplification using
// quadric error metrics", 1997), and its representative is the point that minimizes the summed squared
// distance to those planes. Where the planes do not pin a point down (a flat region: one plane; a crease: a
// line), the underconstrained directions are left at a reference point the caller chooses, by a
// pseudo-inverse solved around that point:
//
//   plane of a triangle   n·x = d, n its unit normal, d = n·(centroid), weight w = its area
//   quadric               A = Σ w n nᵀ,  b = Σ w d n,  c = Σ w d²   (symmetric 3×3, 3-vector, scalar)
//   error                 E(x) = xᵀAx − 2bᵀx + c = Σ w (n·x − d)²   (area × squared distance)
//   representative        x = ref + A⁺(b − A·ref), then clamped into the cell's box
//
// A⁺ comes from a symmetric eigen decomposition A = V Λ Vᵀ (cyclic Jacobi, to convergence in double):
// eigenvalues below relative_threshold × the largest are treated as zero (their eigenvector directions keep
// ref's coordinate), the others are inverted. Two equal-area planes at an angle θ have eigenvalues in the
// ratio tan²(θ/2), so with the default 1e-3 they must be more than about 3.6° apart before their
// intersection line is trusted over ref;
// nearly flat regions therefore stay at ref projected onto their mean plane instead of jumping to a far,
// ill-conditioned intersection.
//
// "Kept inside the cell" means clamped: each coordinate of the minimizer is clamped to [box_min, box_max]
// (the caller passes the cell's axis-aligned box: for a floating cube cell center ± c/2, for a sphere cell
// the same box, which contains the ball, for a uniform cell its grid square). This is not the minimizer of
// E over the box (Lindstrom & Silva, Visualization 2001, solve that constrained problem); it is cheap, keeps
// the representative within the cell's box, and is exact whenever the unconstrained minimizer is inside.
//
// Units: positions in scene units; A in scene units² (area), b in units³, c in units⁴; the error E in
// units⁴ (area × distance²). All double precision.
//
// Special cases:
// - Zero-area triangles (cross product exactly zero, or not finite) add nothing.
// - A quadric with no positive eigenvalue (nothing added, or only degenerate triangles), or any non-finite
//   entry: the result is ref, clamped. The result is never NaN (ref and the box must be finite).
// - Precision: b − A·ref cancels when coordinates are large compared with the cell; the solution loses about
//   log10(|p| / cell size) of double's 16 digits (1e5 m scenes at 1 cm cells: 1e-9 of a cell).
//
// Determinism: floating-point sums depend on the order of additions. add_triangle and add give the same bits
// for the same sequence of calls; a caller that merges per-chunk partial quadrics must do so in an order that
// does not depend on the chunking (e.g. accumulate per cell in global triangle order) to keep the
// "same bytes for any chunk size" contract.
#pragma once

#include <array>

namespace lodstream::core {

inline constexpr double kQuadricRelativeThreshold = 1e-3;

struct Quadric {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0;  // A, upper triangle
  double b0 = 0, b1 = 0, b2 = 0;                                // b
  double c = 0;

  // Adds weight · (plane n·x = d): n must be unit length, weight >= 0.
  void add_plane(const double* n, double d, double weight);
  // Adds the area-weighted plane of the triangle p0 p1 p2 (xyz each); orientation does not matter.
  void add_triangle(const double* p0, const double* p1, const double* p2);
  // Adds another quadric, field by field.
  void add(const Quadric& q);
  // E(x) = xᵀAx − 2bᵀx + c, evaluated as written (so it cancels for large coordinates; for tests and
  // diagnostics).
  double error(const double* x) const;
};

// The minimizer of q around ref (see above), clamped to [box_min, box_max] per coordinate. ref, box_min and
// box_max: xyz, finite, box_min <= box_max; otherwise Failure(Status::internal). relative_threshold in
// [0, 1): eigenvalues below relative_threshold × the largest are dropped.
std::array<double, 3> quadric_minimizer(const Quadric& q, const double* ref, const double* box_min,
                                        const double* box_max,
                                        double relative_threshold = kQuadricRelativeThreshold);

}  // namespace lodstream::core

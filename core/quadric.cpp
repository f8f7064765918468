// Quadric-placed cluster representatives (pipeline stage 5). This work is based on:
// Peter Lindstrom. Out-of-Core Simplification of Large Polygonal Models. SIGGRAPH 2000
// Michael Garland and Paul S. Heckbert. Surface simplification using quadric error metrics. 1997
//
// The solve scales A by its largest entry first, so the Jacobi rotations see entries in [-1, 1] whatever
// the scene's units (areas of 1e-12 or 1e12 alike), and the relative eigenvalue threshold is unaffected.
// Cyclic Jacobi on a 3×3 symmetric matrix converges quadratically: a handful of sweeps, each three
// rotations; it is deterministic and keeps the eigenvectors orthonormal to rounding, which is what the
// pseudo-inverse needs (a general 3×3 inverse or Cramer's rule would blow up on the rank-deficient quadrics
// of flat regions and creases, the common case in CAD).
#include "core/quadric.h"

#include <algorithm>
#include <cmath>

#include "core/status.h"

namespace lodstream::core {
namespace {

constexpr int kMaxSweeps = 64;

// One Jacobi rotation zeroing a[p][q] of the symmetric a, accumulated into the columns of v
// (Numerical Recipes' formulation, which keeps the update of the diagonal accurate).
void rotate(double a[3][3], double v[3][3], int p, int q) {
  const double apq = a[p][q];
  if (apq == 0) return;
  const double h = a[q][q] - a[p][p];
  double t;
  if (std::fabs(h) + 100 * std::fabs(apq) == std::fabs(h)) {
    t = apq / h;  // tiny angle: t ≈ 1 / (2θ) without squaring θ
  } else {
    const double theta = 0.5 * h / apq;
    t = 1 / (std::fabs(theta) + std::sqrt(1 + theta * theta));
    if (theta < 0) t = -t;
  }
  const double c = 1 / std::sqrt(1 + t * t);
  const double s = t * c;
  const double tau = s / (1 + c);
  a[p][p] -= t * apq;
  a[q][q] += t * apq;
  a[p][q] = a[q][p] = 0;
  const int r = 3 - p - q;
  const double g = a[r][p], k = a[r][q];
  a[r][p] = a[p][r] = g - s * (k + g * tau);
  a[r][q] = a[q][r] = k + s * (g - k * tau);
  for (int i = 0; i < 3; ++i) {
    const double x = v[i][p], y = v[i][q];
    v[i][p] = x - s * (y + x * tau);
    v[i][q] = y + s * (x - y * tau);
  }
}

// Eigen decomposition of the symmetric a (destroyed: its diagonal ends up holding the eigenvalues);
// eigenvectors in the columns of v.
void jacobi(double a[3][3], double v[3][3]) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) v[i][j] = i == j ? 1 : 0;
  for (int sweep = 0; sweep < kMaxSweeps; ++sweep) {
    if (a[0][1] == 0 && a[0][2] == 0 && a[1][2] == 0) return;
    for (int p = 0; p < 2; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        // An off-diagonal entry below the rounding of both diagonal entries is zero to working precision.
        const double g = 100 * std::fabs(a[p][q]);
        if (sweep > 3 && std::fabs(a[p][p]) + g == std::fabs(a[p][p]) &&
            std::fabs(a[q][q]) + g == std::fabs(a[q][q])) {
          a[p][q] = a[q][p] = 0;
        } else {
          rotate(a, v, p, q);
        }
      }
    }
  }
}

bool finite3(const double* x) {
  return std::isfinite(x[0]) && std::isfinite(x[1]) && std::isfinite(x[2]);
}

}  // namespace

void Quadric::add_plane(const double* n, double d, double weight) {
  const double wn0 = weight * n[0], wn1 = weight * n[1], wn2 = weight * n[2];
  a00 += wn0 * n[0], a01 += wn0 * n[1], a02 += wn0 * n[2];
  a11 += wn1 * n[1], a12 += wn1 * n[2];
  a22 += wn2 * n[2];
  b0 += wn0 * d, b1 += wn1 * d, b2 += wn2 * d;
  c += weight * d * d;
}

void Quadric::add_triangle(const double* p0, const double* p1, const double* p2) {
  const double e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
  const double e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
  const double x = e1[1] * e2[2] - e1[2] * e2[1];
  const double y = e1[2] * e2[0] - e1[0] * e2[2];
  const double z = e1[0] * e2[1] - e1[1] * e2[0];
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return;
  // Scaled norm: no overflow or underflow of the squares for any finite cross product.
  const double m = std::max(std::max(std::fabs(x), std::fabs(y)), std::fabs(z));
  if (m == 0) return;
  const double sx = x / m, sy = y / m, sz = z / m;
  const double r = std::sqrt(sx * sx + sy * sy + sz * sz);
  const double n[3] = {sx / r, sy / r, sz / r};
  const double area = 0.5 * (m * r);
  // The centroid, not a vertex: the plane then does not depend on which corner comes first.
  const double d =
      (n[0] * (p0[0] + p1[0] + p2[0]) + n[1] * (p0[1] + p1[1] + p2[1]) + n[2] * (p0[2] + p1[2] + p2[2])) / 3;
  add_plane(n, d, area);
}

void Quadric::add(const Quadric& q) {
  a00 += q.a00, a01 += q.a01, a02 += q.a02, a11 += q.a11, a12 += q.a12, a22 += q.a22;
  b0 += q.b0, b1 += q.b1, b2 += q.b2;
  c += q.c;
}

double Quadric::error(const double* x) const {
  const double ax0 = a00 * x[0] + a01 * x[1] + a02 * x[2];
  const double ax1 = a01 * x[0] + a11 * x[1] + a12 * x[2];
  const double ax2 = a02 * x[0] + a12 * x[1] + a22 * x[2];
  return x[0] * ax0 + x[1] * ax1 + x[2] * ax2 - 2 * (b0 * x[0] + b1 * x[1] + b2 * x[2]) + c;
}

std::array<double, 3> quadric_minimizer(const Quadric& q, const double* ref, const double* box_min,
                                        const double* box_max, double relative_threshold) {
  if (!finite3(ref) || !finite3(box_min) || !finite3(box_max))
    fail(Status::internal, "quadric_minimizer: reference point or cell box not finite");
  for (int i = 0; i < 3; ++i)
    if (box_min[i] > box_max[i]) fail(Status::internal, "quadric_minimizer: cell box is empty");
  if (!(relative_threshold >= 0 && relative_threshold < 1))
    fail(Status::internal, "quadric_minimizer: relative threshold outside [0, 1)");

  std::array<double, 3> x = {ref[0], ref[1], ref[2]};
  const double entries[] = {q.a00, q.a01, q.a02, q.a11, q.a12, q.a22, q.b0, q.b1, q.b2};
  bool finite = true;
  for (double e : entries) finite = finite && std::isfinite(e);
  const double scale = std::max({std::fabs(q.a00), std::fabs(q.a01), std::fabs(q.a02), std::fabs(q.a11),
                                 std::fabs(q.a12), std::fabs(q.a22)});
  if (finite && scale > 0) {
    // r = b − A·ref, in the original units.
    const double r[3] = {q.b0 - (q.a00 * ref[0] + q.a01 * ref[1] + q.a02 * ref[2]),
                         q.b1 - (q.a01 * ref[0] + q.a11 * ref[1] + q.a12 * ref[2]),
                         q.b2 - (q.a02 * ref[0] + q.a12 * ref[1] + q.a22 * ref[2])};
    double a[3][3] = {{q.a00 / scale, q.a01 / scale, q.a02 / scale},
                      {q.a01 / scale, q.a11 / scale, q.a12 / scale},
                      {q.a02 / scale, q.a12 / scale, q.a22 / scale}};
    double v[3][3];
    jacobi(a, v);
    const double largest = std::max({a[0][0], a[1][1], a[2][2]});
    double delta[3] = {0, 0, 0};
    if (largest > 0) {
      for (int i = 0; i < 3; ++i) {
        const double lambda = a[i][i];
        if (!(lambda > 0) || lambda < relative_threshold * largest) continue;  // dropped: ref stays
        // v_i (v_iᵀ r) / (λ_i · scale), scaled back in two steps so that neither factor overflows.
        const double proj = (v[0][i] * r[0] + v[1][i] * r[1] + v[2][i] * r[2]) / scale / lambda;
        for (int j = 0; j < 3; ++j) delta[j] += v[j][i] * proj;
      }
    }
    const double y[3] = {ref[0] + delta[0], ref[1] + delta[1], ref[2] + delta[2]};
    if (finite3(y)) x = {y[0], y[1], y[2]};
  }
  for (int i = 0; i < 3; ++i) x[i] = std::clamp(x[i], box_min[i], box_max[i]);
  return x;
}

}  // namespace lodstream::core

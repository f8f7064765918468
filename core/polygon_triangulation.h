// Polygon triangulation in the polygon's best-fit plane: a face of n >= 3 corners becomes n - 2
// triangles over its own corners, inside the polygon when the polygon is simple (concave or not).
//
// Sources:
//   Martin Newell's method for the plane of a polygon: Sutherland, Sproull and Schumacker, "A
//     Characterization of Ten Hidden-Surface Algorithms", Computing Surveys 6(1), 1974, p. 15; as
//     presented by F. Tampieri, "Newell's Method for Computing the Plane Equation of a Polygon",
//     Graphics Gems III, 1992.
//   Projection onto the two axes the normal is least aligned with: Schneider and Eberly, "Geometric
//     Tools for Computer Graphics", 2003, §13.3 (point in polygon, 3D case).
//   Ear clipping: G. H. Meisters, "Polygons Have Ears", American Mathematical Monthly 82(6), 1975 (every
//     simple polygon of n > 3 corners has two non-overlapping ears); D. Eberly, "Triangulation by Ear
//     Clipping", Geometric Tools, 2002 (the O(n^2) clipping loop, collinear and coincident corners).
//
// Units: positions in the caller's units (double); the result is corner numbers 0..n-1.
#pragma once

#include <cstdint>
#include <vector>

namespace lodstream::core {

// How a polygon was triangulated.
enum class Triangulation : uint8_t {
  fan,           // convex in its plane: the fan (0, i, i+1), exactly what a fan triangulator gives
  diagonal,      // a concave quad: cut along the diagonal 1-3, the one inside it
  ear_clipping,  // a concave polygon of five corners or more, clipped ear by ear
  fallback,      // no plane (collinear corners, zero area), no ear left or clipped triangles whose areas
                 // exceed the polygon's (a self-intersecting ring): the fan (0, i, i+1), deterministic
                 // but not inside a polygon that has no inside
};

// Scratch reused across polygons (no allocation per polygon once it has grown to the largest one).
struct PolygonScratch {
  std::vector<double> uv;        // projected corners, 2 per corner
  std::vector<uint32_t> prev, next;
};

// Triangulates the polygon whose n >= 3 corners are xyz[3*i .. 3*i+2], in ring order. Writes exactly
// 3 * (n - 2) corner numbers into `triangles` (the caller sizes it) and returns the method used.
//
// Guarantees, for a simple polygon (no two edges crossing; corners may repeat positions or be
// collinear): the triangles cover the polygon's projection onto its Newell plane exactly, do not overlap
// (zero-area triangles may be emitted for collinear corners), and have the ring's orientation. Whenever
// the fan (0, i, i+1) lies inside the polygon (every convex polygon, within a relative tolerance of 1e-12
// on the turns) it is the result, so convex faces keep the triangles a fan triangulator gave them; a
// concave quad whose diagonal 0-2 lies outside is cut along 1-3. The result depends on the positions
// alone (no state is carried between calls), so it is the same for any chunking or thread.
Triangulation triangulate_polygon(const double* xyz, uint32_t n, uint32_t* triangles, PolygonScratch* scratch);

// Twice the signed area of the polygon in its Newell plane (the length of the Newell normal): the
// reference the tests compare the triangles' areas with.
double polygon_area2(const double* xyz, uint32_t n);

}  // namespace lodstream::core

// Adaptive subdivision of gridded samples into surface-fitting polygons (DeHaemer 1989, chapters II-III),
// on plain arrays: no files, no threads.
//
// Samples are addressed by id = j * width + i (i east, j south: row 0 is the north row). A polygon is an
// axis-aligned rectangle of samples [i0, i1] x [j0, j1] (i0 < i1, j0 < j1) "over" which every sample with
// i0 <= i <= i1, j0 <= j <= j1 lies. Its drawn surface is a triangulation defined once (draw_triangles())
// and used both for the accuracy test and for the output, so that for the crack-free variants the
// measured vertical error of the output is <= tolerance by construction.
//
// Cylindrical range grids (thesis §II.B: a Cyberware scan's radii at uniformly spaced latitudes and
// longitudes) use the same rectangles in the (longitude, latitude) domain with GridSamples::cylinder set:
// z is the radius, and the drawn triangles are the 3D triangles between the samples' points. The error of
// a sample is then measured along its ray, from the axis at the sample's height in the sample's direction,
// against the plane of the 3D triangle that ray passes through (a chord of a circle lies inside the arc,
// so interpolating radii in the domain would miss it). See CylinderFrame.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <vector>

namespace lodstream::core {

// The frame of a cylindrical grid. In local coordinates (c, s, a) -- a right-handed frame whose third axis
// is the cylinder's axis -- sample (i, j) of radius r is the point
//   (r cos(i * angle_step), r sin(i * angle_step), y_bottom + (height - 1 - j) * height_step),
// so longitude grows by the right-hand rule about the axis and row 0 is the top row. A rectangle's drawn
// triangles, counter-clockwise in (longitude, height), then face away from the axis.
//
// Every rectangle spans at most 90 degrees of longitude (wider ones fail the trial test and split across
// longitude). Then a polygon's vertices lie in an open half-space through the axis, no ray from the axis
// meets a triangle twice, a polygon's triangles cover exactly its sector as seen from the axis (its west
// and east sides lie in the half-planes of their longitudes, its north and south sides in their
// horizontal planes), and the drawn mesh is star-shaped about the axis: each sample's ray meets the
// surface at the triangles of the polygons over it only.
struct CylinderFrame {
  double angle_step = 0;   // radians, in (0, pi)
  double height_step = 1;  // > 0
  double y_bottom = 0;     // height of the last row
  // A full turn: the last column is the first one again (the caller appends a copy of column 0, so
  // width = columns + 1). Its corners are shared with column 0's, so the polygons on both sides of the
  // seam get each other's corners as extra vertices (or fill polygons): no crack at 360 degrees. Sample
  // ids in the output may name the last column: they stand for column 0's samples.
  bool wrap = false;
};

struct GridSamples {
  uint32_t width = 0, height = 0;
  double spacing = 1;               // sample distance in x and y (z units), for normals (SplitRule::curvature)
  std::span<const float> z;         // width*height heights, row-major, row 0 = north
  std::span<const uint8_t> valid;   // empty = every sample valid; 0 = NODATA (non-finite z is NODATA too)
  const CylinderFrame* cylinder = nullptr;  // set: z is a radius (> 0 where valid), see CylinderFrame
};

// The local-frame point of sample s of a cylindrical grid (CylinderFrame), the one the accuracy test
// measures against; the wrap column gives column 0's point exactly.
void cylinder_point(const GridSamples& grid, uint32_t s, double out[3]);

// Where a polygon that fails the accuracy test is split (thesis §II.C.3).
enum class SplitRule {
  center,     // the middle latitude and longitude
  first,      // the first sample over tolerance: rows north to south when the polygon is at least as wide
              // as tall, else columns west to east
  greatest,   // the sample of greatest error (ties: the first in that order)
  curvature,  // the sample of greatest normal difference, corners excluded (thesis Figure 10)
  random,     // a seeded counter-based draw per rectangle (independent of processing order)
};
enum class GapMode {
  none,            // corners only: the edge gaps (cracks) of T-junctions remain; counted
  extra_vertices,  // a polygon keeps every neighbour's corner that lies on its edges: no cracks, n-gons
  fill,            // corners only, plus one vertical fill polygon per polygon edge with T-junctions on it
};
enum class Method { subdivision, growth };

struct SubdivisionOptions {
  // Every sample under a polygon lies within this vertical distance of the drawn surface. With
  // target_polygons, +infinity (the default) means "no tolerance, stop at the count only".
  double tolerance = std::numeric_limits<double>::infinity();
  SplitRule split = SplitRule::greatest;
  unsigned divide = 4;              // 4: at a point; 2: across the longer side only
  GapMode gaps = GapMode::extra_vertices;
  // > 0: refine the polygon of greatest error first until this many polygons (fill polygons not counted)
  // or until every polygon is within tolerance, whichever comes first. When the count comes first the
  // tolerance no longer holds; otherwise the verification of extra vertices may add a few polygons.
  uint64_t target_polygons = 0;
  Method method = Method::subdivision;
  uint64_t seed = 1;                // SplitRule::random only
  // After the subdivision or growth, merge two polygons sharing a whole side while their union passes
  // the trial test (not in the thesis; see merge() in the .cpp). Ignored when a polygon target stopped
  // the refinement (no tolerance left to test against).
  bool merge = false;
};

struct Rect {
  uint32_t i0, j0, i1, j1;
  uint8_t diagonal;  // 0: SW-NE, 1: NW-SE
};

struct Subdivision {
  std::vector<Rect> polygons;       // the drawn rectangles, sorted by (j0, i0)
  uint64_t hole_cells = 0;          // cells touching NODATA, left out
  // Every drawn polygon as a ring of sample ids, counter-clockwise seen from above (x east, y north):
  // polygons first (same order), then fill polygons. ring_offsets has rings + 1 entries.
  std::vector<uint64_t> ring_offsets;
  std::vector<uint32_t> rings;
  uint64_t fill_polygons = 0;
  // The drawn surface: 3 sample ids per triangle, counter-clockwise from above (fill triangles are
  // vertical; their orientation is that of the fan).
  std::vector<uint32_t> triangles;
  uint64_t fill_triangles = 0;      // the last fill_triangles triangles
  // T-junctions: a polygon corner strictly inside another polygon's edge. A gap is one whose height
  // differs from that edge's straight line; it is an open crack with GapMode::none (cracks = gaps), and
  // closed by extra vertices or fill polygons otherwise (cracks = 0). max_gap: the largest such height.
  uint64_t t_junctions = 0, gaps = 0, cracks = 0;
  double max_gap = 0;
  uint64_t trials = 0;              // trial polygons tested
  uint64_t verify_splits = 0;       // polygons split again because extra vertices changed their surface
  uint64_t merges = 0;              // SubdivisionOptions::merge: pairs of polygons merged
};

// Called now and then with the fraction done, in [0, 1]. To cancel, throw from it: the exception leaves
// subdivide() unchanged and nothing is kept.
using SubdivisionProgress = std::function<void(double fraction)>;

// Subdivides the grid. Requires width, height >= 2 and z.size() == width*height (< 2^32 samples).
Subdivision subdivide(const GridSamples& grid, const SubdivisionOptions& options,
                      const SubdivisionProgress& progress = {});

// The drawn triangles of `rect` given the sample ids on its four sides between the corners: sides[0]
// south (west to east), [1] east (south to north), [2] north (east to west), [3] west (north to south).
// The diagonal splits the rectangle into two triangles; the side points of each half are joined by a
// zigzag that always advances along the shorter new edge. Appends CCW-from-above triangles to `out`.
void draw_triangles(const GridSamples& grid, const Rect& rect, const std::vector<uint32_t> (&sides)[4],
                    std::vector<uint32_t>* out);

// Cylindrical grids: the same figures along each sample's ray from the axis (the radius of the drawn
// surface there against the sample's), every triangle the ray meets counted (edges included); triangles
// seen edge-on from the axis (fill polygons) are skipped, and the wrap column is not counted twice.
struct VerticalError {
  double max = 0, rms = 0;
  uint64_t samples = 0;     // valid samples under at least one non-vertical triangle
  uint64_t uncovered = 0;   // valid samples under none (they border holes, or the surface has gaps)
  double covered_area = 0;  // sum of the triangles' areas in cells
};

// Vertical error of every valid sample against the triangles (sample ids) over it, in z units: per
// sample the largest |z - surface| over the triangles covering it (edges included); vertical triangles
// (zero area seen from above) are skipped.
// round_to_float (cylindrical grids only): measure the triangles with their vertices rounded to float, as
// a mesh file stores cylinder_point(); the error can then exceed the tolerance by that rounding.
VerticalError vertical_error(const GridSamples& grid, std::span<const uint32_t> triangles, bool round_to_float = false);

}  // namespace lodstream::core

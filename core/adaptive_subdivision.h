// Adaptive subdivision of gridded samples into surface-fitting polygons (DeHaemer 1989, chapters II-III),
// on plain arrays: no files, no threads.
//
// Samples are addressed by id = j * width + i (i east, j south: row 0 is the north row). A polygon is an
// axis-aligned rectangle of samples [i0, i1] x [j0, j1] (i0 < i1, j0 < j1) "over" which every sample with
// i0 <= i <= i1, j0 <= j <= j1 lies. Its drawn surface is a triangulation defined once (draw_triangles())
// and used both for the accuracy test and for the output, so that for the crack-free variants the
// measured vertical error of the output is <= tolerance by construction.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <vector>

namespace lodstream::core {

struct GridSamples {
  uint32_t width = 0, height = 0;
  double spacing = 1;               // sample distance in x and y (z units), for normals (SplitRule::curvature)
  std::span<const float> z;         // width*height heights, row-major, row 0 = north
  std::span<const uint8_t> valid;   // empty = every sample valid; 0 = NODATA (non-finite z is NODATA too)
};

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

struct VerticalError {
  double max = 0, rms = 0;
  uint64_t samples = 0;     // valid samples under at least one non-vertical triangle
  uint64_t uncovered = 0;   // valid samples under none (they border holes, or the surface has gaps)
  double covered_area = 0;  // sum of the triangles' areas in cells
};

// Vertical error of every valid sample against the triangles (sample ids) over it, in z units: per
// sample the largest |z - surface| over the triangles covering it (edges included); vertical triangles
// (zero area seen from above) are skipped.
VerticalError vertical_error(const GridSamples& grid, std::span<const uint32_t> triangles);

}  // namespace lodstream::core

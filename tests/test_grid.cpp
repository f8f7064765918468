// `grid`: adaptive subdivision of height grids (DeHaemer 1989). Exact small cases on arrays, the Fuji
// tile for every variant, the files written (read back and fan-triangulated as a viewer does), and the
// documented errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "core/adaptive_subdivision.h"
#include "io/grid_reader.h"
#include "io/lod_reader.h"
#include "lodstream/lodstream.h"
#include "test_util.h"

namespace lodstream {
namespace {

using core::GapMode;
using core::SplitRule;

struct Grid {
  uint32_t w, h;
  std::vector<float> z;
  std::vector<uint8_t> valid;
  core::GridSamples view() const { return {w, h, 1.0, z, valid}; }
};

Grid flat(uint32_t w, uint32_t h, float z) { return {w, h, std::vector<float>(uint64_t(w) * h, z), {}}; }

core::SubdivisionOptions opts(double tol, SplitRule split, GapMode gaps, unsigned divide = 4) {
  core::SubdivisionOptions o;
  o.tolerance = tol;
  o.split = split;
  o.gaps = gaps;
  o.divide = divide;
  return o;
}

const SplitRule kRules[] = {SplitRule::center, SplitRule::first, SplitRule::greatest, SplitRule::curvature, SplitRule::random};
const GapMode kGaps[] = {GapMode::none, GapMode::extra_vertices, GapMode::fill};

// Undirected ring edges of the rectangle polygons (fill polygons left out) with their use counts.
std::map<std::pair<uint32_t, uint32_t>, int> ring_edges(const core::Subdivision& s) {
  std::map<std::pair<uint32_t, uint32_t>, int> edges;
  for (size_t p = 0; p < s.polygons.size(); ++p)
    for (uint64_t k = s.ring_offsets[p]; k < s.ring_offsets[p + 1]; ++k) {
      const uint32_t a = s.rings[k], b = s.rings[k + 1 == s.ring_offsets[p + 1] ? s.ring_offsets[p] : k + 1];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  return edges;
}

bool on_border(uint32_t a, uint32_t b, uint32_t w, uint32_t h) {
  const uint32_t ai = a % w, aj = a / w, bi = b % w, bj = b / w;
  return (ai == bi && (ai == 0 || ai == w - 1)) || (aj == bj && (aj == 0 || aj == h - 1));
}

// Polygons tile the drawn cells exactly: the triangles' areas add up to the drawn cells, and the
// rectangles' areas too.
void expect_tiling(const Grid& g, const core::Subdivision& s) {
  uint64_t cells = 0;
  for (const core::Rect& r : s.polygons) cells += uint64_t(r.i1 - r.i0) * (r.j1 - r.j0);
  EXPECT_EQ(cells + s.hole_cells, uint64_t(g.w - 1) * (g.h - 1));
  const core::VerticalError e = core::vertical_error(g.view(), s.triangles);
  EXPECT_DOUBLE_EQ(e.covered_area, double(cells));
}

TEST(Grid, FlatGridBecomesOnePolygon) {
  const Grid g = flat(9, 7, 3.5f);
  for (SplitRule rule : kRules)
    for (GapMode gaps : kGaps)
      for (unsigned divide : {4u, 2u}) {
        const core::Subdivision s = core::subdivide(g.view(), opts(0, rule, gaps, divide));
        ASSERT_EQ(s.polygons.size(), 1u);
        EXPECT_EQ(s.polygons[0].i0, 0u);
        EXPECT_EQ(s.polygons[0].j1, 6u);
        EXPECT_EQ(s.rings, (std::vector<uint32_t>{6 * 9 + 0, 6 * 9 + 8, 8, 0}));  // SW SE NE NW
        EXPECT_EQ(s.triangles.size(), 6u);
        EXPECT_EQ(s.fill_polygons, 0u);
        EXPECT_EQ(s.t_junctions, 0u);
        EXPECT_EQ(core::vertical_error(g.view(), s.triangles).max, 0.0);
      }
  core::SubdivisionOptions grow = opts(0, SplitRule::greatest, GapMode::extra_vertices);
  grow.method = core::Method::growth;
  EXPECT_EQ(core::subdivide(g.view(), grow).polygons.size(), 1u);
  // A tilted plane too (within rounding: the plane's heights are computed in double).
  Grid t = flat(9, 7, 0);
  for (uint32_t j = 0; j < 7; ++j)
    for (uint32_t i = 0; i < 9; ++i) t.z[j * 9 + i] = 2.0f * i - 3.0f * j;
  EXPECT_EQ(core::subdivide(t.view(), opts(1e-9, SplitRule::center, GapMode::extra_vertices)).polygons.size(), 1u);
}

// A single spike at (10, 20) in a flat 33 x 33 grid, tolerance 1. `greatest` splits at the spike first;
// each quadrant then has the spike as a corner and splits at the sample next to it (its greatest error),
// until the spike is surrounded by four unit cells: 12 polygons in 21 trials, where `center` needs 28:
//   [0,10]x[0,19]  [10,11]x[0,19]  [11,32]x[0,20]
//   [0,9]x[19,20]  [9,10]x[19,20]  [10,11]x[19,20]
//   [0,9]x[20,21]  [9,10]x[20,21]  [10,11]x[20,21]  [11,32]x[20,32]
//   [0,10]x[21,32] [10,11]x[21,32]
TEST(Grid, SpikeIsIsolatedByGreatestInFewSplits) {
  Grid g = flat(33, 33, 0);
  g.z[20 * 33 + 10] = 100;
  const core::Subdivision greatest = core::subdivide(g.view(), opts(1, SplitRule::greatest, GapMode::none));
  const core::Subdivision center = core::subdivide(g.view(), opts(1, SplitRule::center, GapMode::none));
  expect_tiling(g, greatest);
  // Every polygon touching the spike is a unit cell (a larger one would lift samples next to the spike).
  uint32_t touching = 0;
  for (const core::Rect& r : greatest.polygons) {
    if (r.i0 <= 10 && r.i1 >= 10 && r.j0 <= 20 && r.j1 >= 20) {
      ++touching;
      EXPECT_EQ(r.i1 - r.i0, 1u);
      EXPECT_EQ(r.j1 - r.j0, 1u);
    }
  }
  EXPECT_EQ(touching, 4u);
  EXPECT_EQ(greatest.polygons.size(), 12u);
  EXPECT_EQ(greatest.trials, 21u);
  EXPECT_EQ(center.polygons.size(), 28u);
  EXPECT_EQ(core::vertical_error(g.view(), greatest.triangles).max, 0.0);
}

TEST(Grid, NodataHolesStayHoles) {
  Grid g = flat(20, 16, 0);
  g.valid.assign(20 * 16, 1);
  for (uint32_t j = 0; j < 16; ++j)
    for (uint32_t i = 0; i < 20; ++i) g.z[j * 20 + i] = float(std::sin(i * 0.7) * 10 + j * j * 0.3);
  for (uint32_t j = 6; j <= 9; ++j)
    for (uint32_t i = 5; i <= 8; ++i) g.valid[j * 20 + i] = 0;
  g.valid[0] = 0;  // a corner sample: one hole cell
  // Cells touching NODATA: the 4x4 block touches 5x5 cells; the corner sample 1 cell.
  const uint64_t hole_cells = 25 + 1;
  for (SplitRule rule : kRules)
    for (GapMode gaps : kGaps)
      for (bool growth : {false, true}) {
        core::SubdivisionOptions o = opts(0.5, rule, gaps);
        if (growth) o.method = core::Method::growth;
        const core::Subdivision s = core::subdivide(g.view(), o);
        EXPECT_EQ(s.hole_cells, hole_cells);
        expect_tiling(g, s);
        for (uint32_t v : s.triangles) EXPECT_TRUE(g.valid[v]) << "a drawn vertex is NODATA";
        for (const core::Rect& r : s.polygons)
          for (uint32_t j = r.j0; j <= r.j1; ++j)
            for (uint32_t i = r.i0; i <= r.i1; ++i) ASSERT_TRUE(g.valid[j * 20 + i]) << "a polygon covers NODATA";
        const core::VerticalError e = core::vertical_error(g.view(), s.triangles);
        EXPECT_LE(e.max, 0.5);
        EXPECT_EQ(e.uncovered, 0u);  // every valid sample borders a drawn cell here
      }
}

TEST(Grid, ExtraVerticesCloseEveryGapOnASmallGrid) {
  Grid g = flat(17, 17, 0);
  for (uint32_t j = 0; j < 17; ++j)
    for (uint32_t i = 0; i < 17; ++i) g.z[j * 17 + i] = float((i * 7 + j * 13) % 11) * (i > 8 ? 1.0f : 0.1f);
  for (SplitRule rule : kRules) {
    const core::Subdivision s = core::subdivide(g.view(), opts(0.6, rule, GapMode::extra_vertices));
    for (const auto& [edge, count] : ring_edges(s))
      EXPECT_EQ(count, on_border(edge.first, edge.second, 17, 17) ? 1 : 2);
    EXPECT_EQ(s.cracks, 0u);
    EXPECT_LE(core::vertical_error(g.view(), s.triangles).max, 0.6);
    expect_tiling(g, s);
  }
}

TEST(Grid, DrawTrianglesZigzagsBetweenSidePoints) {
  // A 4 x 2 rectangle with one extra vertex on its south side and one on its north side.
  const Grid g = flat(5, 3, 0);
  const core::Rect r{0, 0, 4, 2, 0};
  const std::vector<uint32_t> sides[4] = {{2 * 5 + 2}, {}, {2}, {}};
  std::vector<uint32_t> t;
  core::draw_triangles(g.view(), r, sides, &t);
  // Half SW-SE-NE: (SW, S2, NE), (S2, SE, NE); half NE-NW-SW: (NE, N2, SW), (N2, NW, SW).
  EXPECT_EQ(t, (std::vector<uint32_t>{10, 12, 4, 12, 14, 4, 4, 2, 10, 2, 0, 10}));
}

TEST(Grid, RandomSplitIsSeededAndDeterministic) {
  Grid g = flat(40, 30, 0);
  for (uint32_t j = 0; j < 30; ++j)
    for (uint32_t i = 0; i < 40; ++i) g.z[j * 40 + i] = float(std::cos(i * 0.3) * std::sin(j * 0.2) * 20);
  core::SubdivisionOptions o = opts(0.5, SplitRule::random, GapMode::extra_vertices);
  const core::Subdivision a = core::subdivide(g.view(), o), b = core::subdivide(g.view(), o);
  EXPECT_EQ(a.rings, b.rings);
  EXPECT_EQ(a.triangles, b.triangles);
  o.seed = 2;
  EXPECT_NE(core::subdivide(g.view(), o).rings, a.rings);
}

TEST(Grid, TargetPolygonsRefinesGreatestErrorFirst) {
  Grid g = flat(65, 65, 0);
  for (uint32_t j = 0; j < 65; ++j)
    for (uint32_t i = 0; i < 65; ++i) g.z[j * 65 + i] = float(std::cos(i * 0.2) * std::sin(j * 0.15) * 50);
  double last = 1e300;
  for (uint64_t target : {10u, 40u, 160u, 640u}) {
    core::SubdivisionOptions o = opts(std::numeric_limits<double>::infinity(), SplitRule::greatest, GapMode::none);
    o.target_polygons = target;
    const core::Subdivision s = core::subdivide(g.view(), o);
    EXPECT_GE(s.polygons.size(), target);
    EXPECT_LE(s.polygons.size(), target + 2);  // the last split of four adds three
    const double e = core::vertical_error(g.view(), s.triangles).max;
    EXPECT_LE(e, last);
    last = e;
  }
}

// ---- the Fuji tile ----

struct Fuji {
  io::HeightGrid grid;
  core::GridSamples view() const { return {grid.width, grid.height, grid.spacing, grid.z, grid.valid}; }
};

const Fuji* fuji() {
  static Fuji* f = [] {
    const std::string dir = test::shared_data_dir();
    if (dir.empty()) return static_cast<Fuji*>(nullptr);
    return new Fuji{io::read_height_grid(dir + "/terrain/fuji-terrain-rgb.png", {})};
  }();
  return f;
}

#define REQUIRE_FUJI()                                                                            \
  const Fuji* f = fuji();                                                                         \
  if (!f) GTEST_SKIP() << "skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)"

TEST(GridFuji, EveryVariantIsWithinTolerance) {
  REQUIRE_FUJI();
  const double tol = 5;
  for (SplitRule rule : kRules)
    for (unsigned divide : {4u, 2u})
      for (GapMode gaps : kGaps) {
        const core::Subdivision s = core::subdivide(f->view(), opts(tol, rule, gaps, divide));
        const core::VerticalError e = core::vertical_error(f->view(), s.triangles);
        SCOPED_TRACE(testing::Message() << "split " << int(rule) << " divide " << divide << " gaps " << int(gaps));
        EXPECT_LE(e.max, tol);
        EXPECT_EQ(e.samples, 512u * 512u);
        EXPECT_GT(s.polygons.size(), 1000u);
        if (gaps == GapMode::none) {
          EXPECT_GT(s.cracks, 1000u);  // counted and reported, left open
          EXPECT_EQ(s.cracks, s.gaps);
        } else {
          EXPECT_EQ(s.cracks, 0u);
        }
        EXPECT_EQ(s.fill_polygons > 0, gaps == GapMode::fill);
      }
  for (GapMode gaps : kGaps) {
    core::SubdivisionOptions o = opts(tol, SplitRule::greatest, gaps);
    o.method = core::Method::growth;
    const core::Subdivision s = core::subdivide(f->view(), o);
    EXPECT_LE(core::vertical_error(f->view(), s.triangles).max, tol);
  }
  core::SubdivisionOptions o = opts(tol, SplitRule::greatest, GapMode::extra_vertices);
  o.target_polygons = 1000000;  // never reached: refinement stops at the tolerance
  EXPECT_LE(core::vertical_error(f->view(), core::subdivide(f->view(), o).triangles).max, tol);
}

// The merge pass: every variant stays within tolerance with every gap mode, merges something, needs fewer
// triangles than without it, and still tiles the grid; the extra-vertices surface stays watertight.
TEST(GridFuji, MergeKeepsToleranceAndSavesTriangles) {
  REQUIRE_FUJI();
  const uint32_t w = f->grid.width, h = f->grid.height;
  for (double tol : {1.0, 5.0, 20.0})
    for (SplitRule rule : {SplitRule::center, SplitRule::greatest})
      for (unsigned divide : {4u, 2u})
        for (GapMode gaps : kGaps) {
          core::SubdivisionOptions o = opts(tol, rule, gaps, divide);
          const core::Subdivision plain = core::subdivide(f->view(), o);
          o.merge = true;
          const core::Subdivision s = core::subdivide(f->view(), o);
          SCOPED_TRACE(testing::Message() << "tol " << tol << " split " << int(rule) << " divide " << divide << " gaps " << int(gaps));
          const core::VerticalError e = core::vertical_error(f->view(), s.triangles);
          EXPECT_LE(e.max, tol);
          EXPECT_EQ(e.samples, 512u * 512u);
          EXPECT_GT(s.merges, 0u);
          EXPECT_LT(s.triangles.size(), plain.triangles.size());
          EXPECT_EQ(s.cracks == 0, gaps != GapMode::none);
          uint64_t cells = 0;
          for (const core::Rect& r : s.polygons) cells += uint64_t(r.i1 - r.i0) * (r.j1 - r.j0);
          EXPECT_EQ(cells, uint64_t(w - 1) * (h - 1));
          if (gaps == GapMode::extra_vertices) {
            for (const auto& [edge, count] : ring_edges(s)) {
              if (!on_border(edge.first, edge.second, w, h)) {
                ASSERT_EQ(count, 2);
              }
            }
          }
        }
  for (GapMode gaps : kGaps) {
    core::SubdivisionOptions o = opts(5, SplitRule::greatest, gaps);
    o.method = core::Method::growth;
    o.merge = true;
    const core::Subdivision s = core::subdivide(f->view(), o);
    EXPECT_LE(core::vertical_error(f->view(), s.triangles).max, 5.0);
  }
  // Stopped by a polygon count there is no tolerance to merge against: the merge pass does nothing.
  core::SubdivisionOptions o = opts(5, SplitRule::greatest, GapMode::fill);
  o.target_polygons = 500;
  const core::Subdivision a = core::subdivide(f->view(), o);
  o.merge = true;
  const core::Subdivision b = core::subdivide(f->view(), o);
  EXPECT_EQ(b.merges, 0u);
  EXPECT_EQ(a.triangles, b.triangles);
}

// The target, on the Fuji tile: center, divide 2, fill polygons and merge within 1.5 x Delatin's
// triangles (377,514 / 123,279 / 20,354 at 1 / 5 / 20 m, tools/terrain_peers.js).
TEST(GridFuji, MergeIsWithinOneAndAHalfDelatin) {
  REQUIRE_FUJI();
  const std::pair<double, double> delatin[] = {{1, 377514}, {5, 123279}, {20, 20354}};
  for (const auto& [tol, tris] : delatin) {
    core::SubdivisionOptions o = opts(tol, SplitRule::center, GapMode::fill, 2);
    o.merge = true;
    const core::Subdivision s = core::subdivide(f->view(), o);
    EXPECT_LE(double(s.triangles.size() / 3), 1.5 * tris) << "tolerance " << tol;
  }
}

TEST(GridFuji, ExtraVerticesLeaveNoBoundaryEdgeInsideTheGrid) {
  REQUIRE_FUJI();
  const uint32_t w = f->grid.width, h = f->grid.height;
  for (SplitRule rule : {SplitRule::greatest, SplitRule::center, SplitRule::random}) {
    const core::Subdivision s = core::subdivide(f->view(), opts(5, rule, GapMode::extra_vertices));
    uint64_t inner_boundary = 0, border = 0;
    for (const auto& [edge, count] : ring_edges(s)) {
      if (on_border(edge.first, edge.second, w, h)) {
        EXPECT_EQ(count, 1);
        ++border;
      } else if (count != 2) {
        ++inner_boundary;
      }
    }
    EXPECT_EQ(inner_boundary, 0u);
    EXPECT_GT(border, 0u);
    // The triangles too: every edge inside the grid is shared by exactly two triangles.
    std::map<std::pair<uint32_t, uint32_t>, int> tri_edges;
    for (size_t t = 0; t < s.triangles.size(); t += 3)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = s.triangles[t + k], b = s.triangles[t + (k + 1) % 3];
        ++tri_edges[{std::min(a, b), std::max(a, b)}];
      }
    for (const auto& [edge, count] : tri_edges)
      if (!on_border(edge.first, edge.second, w, h)) {
        ASSERT_EQ(count, 2);
      }
  }
  // With corners only the T-junctions leave edges used once inside the grid: the cracks.
  const core::Subdivision none = core::subdivide(f->view(), opts(5, SplitRule::greatest, GapMode::none));
  uint64_t inner_boundary = 0;
  for (const auto& [edge, count] : ring_edges(none))
    if (!on_border(edge.first, edge.second, w, h) && count != 2) ++inner_boundary;
  EXPECT_GT(inner_boundary, 0u);
}

TEST(GridFuji, PolygonCountsFallAsToleranceGrows) {
  REQUIRE_FUJI();
  for (GapMode gaps : kGaps) {
    uint64_t last = UINT64_MAX;
    for (double tol : {1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0}) {
      const core::Subdivision s = core::subdivide(f->view(), opts(tol, SplitRule::greatest, gaps));
      EXPECT_LT(s.polygons.size(), last) << "tolerance " << tol;
      last = s.polygons.size();
    }
  }
}

TEST(GridFuji, SummaryAndFilesThroughTheApi) {
  const std::string dir = test::shared_data_dir();
  if (dir.empty()) GTEST_SKIP() << "skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA)";
  test::TempDir tmp;
  GridOptions go;
  go.output_dir = tmp.file("out");
  go.tolerance = 5;
  GridReport rep;
  const Result r = grid(dir + "/terrain/fuji-terrain-rgb.png", go, Options{}, &rep);
  ASSERT_TRUE(r.ok()) << r.message;
  const auto j = nlohmann::json::parse(test::read_file(go.output_dir + "/summary.json"));
  for (const char* key : {"polygons", "triangles", "vertices", "draw_vertices", "bytes", "fill_polygons", "fill_vertices",
                          "max_error", "rms_error", "cracks", "seconds", "options"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["polygons"].get<uint64_t>(), rep.polygons);
  EXPECT_LE(j["max_error"].get<double>(), 5.0);
  EXPECT_EQ(j["options"]["gaps"], "extra-vertices");
  EXPECT_EQ(rep.bytes, 24 * rep.vertices + 12 * rep.polygons + 4 * rep.draw_vertices);
  EXPECT_EQ(j["obj_ply_faces"], "triangles");
  // OBJ: faces of 3 corners, the drawn triangles (by default); n-gons appear with --polygons (extra
  // vertices), and the face count matches.
  auto obj_faces = [](const std::string& path, int64_t* most_corners) {
    std::ifstream obj(path);
    uint64_t faces = 0;
    *most_corners = 0;
    for (std::string line; std::getline(obj, line);)
      if (line.rfind("f ", 0) == 0) {
        ++faces;
        *most_corners = std::max<int64_t>(*most_corners, std::count(line.begin(), line.end(), ' '));
      }
    return faces;
  };
  int64_t most_corners = 0;
  EXPECT_EQ(obj_faces(go.output_dir + "/grid.obj", &most_corners), rep.triangles);
  EXPECT_EQ(most_corners, 3);
  std::string ply = test::read_file(go.output_dir + "/grid.ply");
  EXPECT_NE(ply.find("element face " + std::to_string(rep.triangles) + "\n"), std::string::npos);
  EXPECT_NE(ply.find("element vertex " + std::to_string(rep.vertices) + "\n"), std::string::npos);
  GridOptions gp = go;
  gp.output_dir = tmp.file("polygons");
  gp.polygons = true;
  ASSERT_TRUE(grid(dir + "/terrain/fuji-terrain-rgb.png", gp, Options{}, &rep).ok());
  EXPECT_EQ(rep.obj_ply_faces, "polygons");
  EXPECT_EQ(obj_faces(gp.output_dir + "/grid.obj", &most_corners), rep.polygons);
  EXPECT_GT(most_corners, 4);
  ply = test::read_file(gp.output_dir + "/grid.ply");
  EXPECT_NE(ply.find("element face " + std::to_string(rep.polygons) + "\n"), std::string::npos);
  EXPECT_NE(ply.find("element vertex " + std::to_string(rep.vertices) + "\n"), std::string::npos);
  const std::string glb = test::read_file(go.output_dir + "/grid.glb");
  ASSERT_GE(glb.size(), 12u);
  EXPECT_EQ(glb.substr(0, 4), "glTF");
  for (const auto& e : std::filesystem::directory_iterator(go.output_dir))
    EXPECT_EQ(e.path().extension().string().find("partial"), std::string::npos) << e.path();
}

// ---- the files a user opens: grid.obj and grid.ply read back and fan-triangulated as a viewer does ----

struct FanError {
  double max = 0;          // largest |z - surface| over valid samples and the fan triangles covering them
  uint64_t over = 0;       // valid samples farther than the tolerance (plus kFloatSlack) from a fan triangle
  uint64_t uncovered = 0;  // valid samples under no non-vertical fan triangle
  uint64_t faces = 0;      // faces in the file
  uint64_t triangles = 0;  // fan triangles made of them
  core::LodMesh mesh;      // the file as read (positions and fan triangles)
};

// Heights are floats in the files and in the measure alike; this only absorbs the double arithmetic.
constexpr double kFloatSlack = 1e-6;

// Reads `path` back from disk (io/lod_reader.h: every face fan-triangulated from its first corner, as
// viewers and converters do), maps each vertex to the sample it stands on (x, y and z must be the
// sample's, as floats), and measures every valid sample against the fan triangles over it, in exact
// integer sample coordinates: edges included, vertical triangles (zero area seen from above) skipped.
FanError fan_error(const io::HeightGrid& g, const std::string& path, double tolerance) {
  FanError r;
  io::LodFileStats stats;
  r.mesh = io::read_lod_mesh(path, &stats);
  const core::LodMesh& m = r.mesh;
  r.faces = stats.faces;
  r.triangles = m.triangle_count();
  EXPECT_EQ(stats.degenerate_triangles, 0u) << path;
  std::vector<int64_t> vi(m.vertex_count()), vj(m.vertex_count());
  uint64_t off_sample = 0;
  for (uint64_t v = 0; v < m.vertex_count(); ++v) {
    const float* p = &m.positions[3 * v];
    const int64_t i = std::llround((double(p[0]) - g.origin_x) / g.spacing);
    const int64_t j = int64_t(g.height) - 1 - std::llround((double(p[1]) - g.origin_y) / g.spacing);
    if (i < 0 || j < 0 || i >= int64_t(g.width) || j >= int64_t(g.height)) {
      ADD_FAILURE() << path << ": vertex " << v << " lies outside the grid";
      return r;
    }
    const uint64_t s = uint64_t(j) * g.width + uint64_t(i);
    if (p[0] != float(g.x(uint32_t(i))) || p[1] != float(g.y(uint32_t(j))) || p[2] != g.z[s] ||
        !(g.valid.empty() || g.valid[s]))
      ++off_sample;
    vi[v] = i;
    vj[v] = j;
  }
  EXPECT_EQ(off_sample, 0u) << path << ": vertices that are not a valid sample's position";
  std::vector<double> err(uint64_t(g.width) * g.height, -1);
  for (uint64_t t = 0; t < m.triangle_count(); ++t) {
    const uint32_t a = m.triangles[3 * t], b = m.triangles[3 * t + 1], c = m.triangles[3 * t + 2];
    // Twice the signed area; per corner the edge function of the opposite edge (the area at the corner).
    auto edge = [&](uint32_t p, uint32_t q, int64_t i, int64_t j) {
      return (vi[q] - vi[p]) * (j - vj[p]) - (vj[q] - vj[p]) * (i - vi[p]);
    };
    const int64_t area = edge(a, b, vi[c], vj[c]);
    if (area == 0) continue;
    const int64_t sign = area > 0 ? 1 : -1;
    const double za = m.positions[3 * uint64_t(a) + 2], zb = m.positions[3 * uint64_t(b) + 2],
                 zc = m.positions[3 * uint64_t(c) + 2];
    for (int64_t j = std::min({vj[a], vj[b], vj[c]}); j <= std::max({vj[a], vj[b], vj[c]}); ++j)
      for (int64_t i = std::min({vi[a], vi[b], vi[c]}); i <= std::max({vi[a], vi[b], vi[c]}); ++i) {
        const int64_t wa = sign * edge(b, c, i, j), wb = sign * edge(c, a, i, j),
                      wc = sign * edge(a, b, i, j);
        const uint64_t s = uint64_t(j) * g.width + uint64_t(i);
        if (wa < 0 || wb < 0 || wc < 0 || !(g.valid.empty() || g.valid[s])) continue;
        const double z = (double(wa) * za + double(wb) * zb + double(wc) * zc) / double(sign * area);
        err[s] = std::max(err[s], std::abs(double(g.z[s]) - z));
      }
  }
  for (uint64_t s = 0; s < err.size(); ++s) {
    if (!(g.valid.empty() || g.valid[s])) continue;
    if (err[s] < 0) {
      ++r.uncovered;
      continue;
    }
    r.max = std::max(r.max, err[s]);
    if (err[s] > tolerance + kFloatSlack) ++r.over;
  }
  return r;
}

// The corners of the triangles grid.glb draws, as positions (9 floats per triangle).
std::vector<float> glb_corners(const std::string& path, uint64_t* vertices) {
  const std::string b = test::read_file(path);
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, b.data() + at, 4);
    return v;
  };
  if (b.size() < 28 || b.compare(0, 4, "glTF") != 0) {
    ADD_FAILURE() << path << ": not a GLB";
    return {};
  }
  const uint32_t json_len = u32(12);
  const auto gltf = nlohmann::json::parse(b.substr(20, json_len));
  const std::string bin = b.substr(20 + json_len + 8);
  const auto& prim = gltf["meshes"][0]["primitives"][0];
  EXPECT_EQ(prim["mode"], 4);
  auto accessor = [&](int a, uint32_t component_type) {
    const auto& acc = gltf["accessors"][a];
    EXPECT_EQ(acc["componentType"].get<uint32_t>(), component_type);
    const auto& view = gltf["bufferViews"][acc["bufferView"].get<int>()];
    const size_t at = view["byteOffset"].get<size_t>() + acc.value("byteOffset", size_t{0});
    const size_t n = acc["count"].get<size_t>() * (acc["type"] == "VEC3" ? 3 : 1);
    std::vector<uint32_t> out(n);
    EXPECT_LE(at + 4 * n, bin.size());
    if (at + 4 * n <= bin.size()) std::memcpy(out.data(), bin.data() + at, 4 * n);
    return out;
  };
  const std::vector<uint32_t> pos = accessor(prim["attributes"]["POSITION"].get<int>(), 5126);
  const std::vector<uint32_t> idx = accessor(prim["indices"].get<int>(), 5125);
  *vertices = pos.size() / 3;
  std::vector<float> corners;
  corners.reserve(3 * idx.size());
  for (uint32_t v : idx)
    for (int c = 0; c < 3; ++c) {
      float x;
      std::memcpy(&x, &pos[3 * uint64_t(v) + c], 4);
      corners.push_back(x);
    }
  return corners;
}

std::vector<float> mesh_corners(const core::LodMesh& m) {
  std::vector<float> corners;
  corners.reserve(3 * m.triangles.size());
  for (uint32_t v : m.triangles)
    for (int c = 0; c < 3; ++c) corners.push_back(m.positions[3 * uint64_t(v) + c]);
  return corners;
}

struct FileErrors {
  double triangles = 0, polygons = 0;  // max error of fan-triangulated grid.obj, default and --polygons
  uint64_t polygons_over = 0;          // samples beyond the tolerance in the --polygons OBJ
};

// Runs `grid` with `go` twice, drawn triangles (default) then --polygons, into `out`/triangles and
// `out`/polygons, and checks what a user opens:
// - default: grid.obj and grid.ply read back hold exactly the GLB's triangles (same vertex positions,
//   corner for corner), fan-triangulated they are within the tolerance on every valid sample (when
//   `tolerance_holds`), and they measure what summary.json says (max error, uncovered samples);
// - --polygons: the files hold the polygons (faces = polygons, fan triangles = vertices sent - 2 per
//   polygon), with the same vertices in the same order; summary.json keeps the thesis' columns unchanged
//   and says which form the files hold; the GLB is the same bytes.
FileErrors check_files(const std::string& input, GridOptions go, const std::string& out,
                       bool tolerance_holds) {
  FileErrors fe;
  const io::HeightGrid g = io::read_height_grid(input, io::GridReadOptions{go.z_scale, go.spacing});
  const double tol = go.tolerance;
  go.polygons = false;
  go.output_dir = out + "/triangles";
  GridReport tri;
  const Result r = grid(input, go, Options{}, &tri);
  EXPECT_TRUE(r.ok()) << r.message;
  if (!r.ok()) return fe;
  const auto jt = nlohmann::json::parse(test::read_file(go.output_dir + "/summary.json"));
  EXPECT_EQ(jt["obj_ply_faces"], "triangles");
  EXPECT_EQ(jt["options"]["polygons"], false);
  EXPECT_EQ(tri.obj_ply_faces, "triangles");
  const FanError obj = fan_error(g, go.output_dir + "/grid.obj", tol);
  const FanError ply = fan_error(g, go.output_dir + "/grid.ply", tol);
  uint64_t glb_vertices = 0;
  const std::vector<float> glb = glb_corners(go.output_dir + "/grid.glb", &glb_vertices);
  for (const FanError* f : {&obj, &ply}) {
    EXPECT_EQ(f->faces, tri.triangles);
    EXPECT_EQ(f->triangles, tri.triangles);
    EXPECT_EQ(f->mesh.vertex_count(), tri.vertices);
    EXPECT_EQ(f->mesh.vertex_count(), glb_vertices);
    EXPECT_TRUE(mesh_corners(f->mesh) == glb) << "the file's triangles are not the GLB's";
    if (tolerance_holds) {
      EXPECT_EQ(f->over, 0u);
      EXPECT_LE(f->max, tol + kFloatSlack);
    }
    EXPECT_NEAR(f->max, tri.max_error, kFloatSlack);
    EXPECT_EQ(f->uncovered, tri.uncovered_samples);
  }
  EXPECT_EQ(obj.mesh.positions, ply.mesh.positions);
  EXPECT_EQ(obj.mesh.triangles, ply.mesh.triangles);
  fe.triangles = obj.max;

  go.polygons = true;
  go.output_dir = out + "/polygons";
  GridReport poly;
  const Result rp = grid(input, go, Options{}, &poly);
  EXPECT_TRUE(rp.ok()) << rp.message;
  if (!rp.ok()) return fe;
  const auto jp = nlohmann::json::parse(test::read_file(go.output_dir + "/summary.json"));
  EXPECT_EQ(jp["obj_ply_faces"], "polygons");
  EXPECT_EQ(jp["options"]["polygons"], true);
  for (const char* key : {"polygons", "rect_polygons", "triangles", "vertices", "draw_vertices", "bytes",
                          "fill_polygons", "fill_vertices", "max_error", "rms_error", "uncovered_samples"})
    EXPECT_EQ(jp[key], jt[key]) << key;
  const FanError pobj = fan_error(g, go.output_dir + "/grid.obj", tol);
  const FanError pply = fan_error(g, go.output_dir + "/grid.ply", tol);
  for (const FanError* f : {&pobj, &pply}) {
    EXPECT_EQ(f->faces, poly.polygons);
    EXPECT_EQ(f->triangles, poly.draw_vertices - 2 * poly.polygons);
    EXPECT_EQ(f->mesh.positions, obj.mesh.positions);  // the same vertices in the same order
    EXPECT_EQ(f->uncovered, tri.uncovered_samples);
  }
  EXPECT_EQ(pobj.max, pply.max);
  EXPECT_EQ(test::read_file(out + "/triangles/grid.glb"), test::read_file(out + "/polygons/grid.glb"));
  fe.polygons = pobj.max;
  fe.polygons_over = pobj.over;
  return fe;
}

// A rugged 97 x 81 terrain written as an ESRI ASCII grid (cellsize 10, heights in metres, a NODATA lake):
// larger than the hill fixtures, so that big polygons with many extra vertices occur.
std::string write_ridges(const test::TempDir& tmp) {
  const uint32_t w = 97, h = 81;
  std::string text = fmt::format(
      "ncols {}\nnrows {}\nxllcorner 500\nyllcorner 700\ncellsize 10\nNODATA_value -9999\n", w, h);
  for (uint32_t j = 0; j < h; ++j) {
    for (uint32_t i = 0; i < w; ++i) {
      const double di = double(i) - 30, dj = double(j) - 40;
      const double z = 120 * std::sin(i * 0.11) * std::cos(j * 0.07) + 40 * std::sin((i + 2.0 * j) * 0.23) +
                       60 * std::abs(std::sin(i * 0.05 + j * 0.03)) + 0.02 * i * j;
      text += di * di + dj * dj < 36 ? std::string("-9999") : fmt::format("{:.2f}", z);
      text += i + 1 < w ? ' ' : '\n';
    }
  }
  return tmp.write("ridges.asc", text);
}

GridOptions grid_options(double tol, GridSplit split, unsigned divide, GridGaps gaps) {
  GridOptions go;
  go.tolerance = tol;
  go.split = split;
  go.divide = divide;
  go.gaps = gaps;
  return go;
}

const GridSplit kGridSplits[] = {GridSplit::center, GridSplit::first, GridSplit::greatest,
                                 GridSplit::curvature, GridSplit::random};
const GridGaps kGridGaps[] = {GridGaps::none, GridGaps::extra_vertices, GridGaps::fill};

// Every split rule with every gap mode, each gap mode with divide 4 and 2, with and without merge (the
// four combinations cycled over the split rules), growth, and a polygon target the tolerance stops first:
// on the repository's grids (the room's range grid; the hill fixtures, too small for more than a few
// variants) and on generated ridges. Every run writes and syncs its files twice, so the variants are
// cycled rather than multiplied out. On the room the --polygons files (the old default) leave the
// tolerance, so this test fails on the old code without ../shared/data too.
TEST(GridFiles, FanTriangulatedFilesStayWithinTolerance) {
  test::TempDir tmp;
  const std::string fixtures = test::source_dir() + "/tests/data/grids/";
  struct Input {
    std::string path;
    double tolerance;
    bool every_variant;
    bool polygons_leave_tolerance;
  };
  const Input inputs[] = {{fixtures + "hill.asc", 0.5, false, false},
                          {fixtures + "hill-terrain-rgb.png", 1.5, false, false},
                          {fixtures + "sample-room-heights.asc", 0.02, true, true},
                          {write_ridges(tmp), 2.0, true, false}};
  int run = 0;
  for (const Input& in : inputs) {
    double worst_polygons = 0;
    uint64_t polygons_over = 0;
    std::vector<std::pair<std::string, GridOptions>> variants;
    for (int g = 0; g < 3; ++g)
      for (int s = 0; s < (in.every_variant ? 5 : 2); ++s) {
        const int k = (s + g) % 4;
        GridOptions go =
            grid_options(in.tolerance, kGridSplits[in.every_variant ? s : 2], k % 2 ? 2 : 4, kGridGaps[g]);
        go.merge = in.every_variant && k >= 2;
        variants.push_back(
            {fmt::format("split {} divide {} gaps {} merge {}", int(go.split), go.divide, g, go.merge), go});
      }
    for (int g = 0; g < (in.every_variant ? 3 : 0); ++g) {
      GridOptions go = grid_options(in.tolerance, GridSplit::greatest, 4, kGridGaps[g]);
      go.method = GridMethod::growth;
      variants.push_back({fmt::format("growth gaps {}", g), go});
      go = grid_options(in.tolerance, GridSplit::greatest, 4, kGridGaps[g]);
      go.target_polygons = 1000000;
      variants.push_back({fmt::format("target gaps {}", g), go});
    }
    for (const auto& [name, go] : variants) {
      SCOPED_TRACE(in.path + ", tolerance " + std::to_string(in.tolerance) + ", " + name);
      const FileErrors fe = check_files(in.path, go, tmp.file("run" + std::to_string(run++)), true);
      worst_polygons = std::max(worst_polygons, fe.polygons / in.tolerance);
      polygons_over += fe.polygons_over;
    }
    if (in.polygons_leave_tolerance) {
      EXPECT_GT(polygons_over, 0u) << in.path;
    }
    std::printf(
        "%s: %zu variants; fan-triangulated --polygons grid.obj: worst max error %.3f x the tolerance\n",
        in.path.c_str(), variants.size(), worst_polygons);
  }
}

// A polygon target that stops before the tolerance holds: the files still measure what summary.json says.
TEST(GridFiles, PolygonTargetFilesMeasureAsReported) {
  test::TempDir tmp;
  GridOptions go = grid_options(-1, GridSplit::greatest, 4, GridGaps::extra_vertices);
  go.target_polygons = 40;
  const FileErrors fe = check_files(write_ridges(tmp), go, tmp.file("out"), false);
  EXPECT_GT(fe.triangles, 0.0);
}

// The measure on the Fuji tile at 1 and 5 m: the default files, fan-triangulated as a viewer does,
// stay within the tolerance on every sample; the --polygons files (the old default) leave it.
TEST(GridFuji, FanTriangulatedFilesStayWithinToleranceAndPolygonsDoNot) {
  LODSTREAM_REQUIRE_SHARED_DATA(dir);
  test::TempDir tmp;
  for (double tol : {1.0, 5.0}) {
    SCOPED_TRACE(testing::Message() << "tolerance " << tol);
    const FileErrors fe = check_files(dir + "/terrain/fuji-terrain-rgb.png",
                                      grid_options(tol, GridSplit::greatest, 4, GridGaps::extra_vertices),
                                      tmp.file("tol" + std::to_string(int(tol))), true);
    std::printf(
        "Fuji, tolerance %g m: fan-triangulated grid.obj max error %.4f m (default), %.4f m (--polygons: "
        "%llu samples beyond the tolerance)\n",
        tol, fe.triangles, fe.polygons, static_cast<unsigned long long>(fe.polygons_over));
    EXPECT_GT(fe.polygons, tol);
    EXPECT_GT(fe.polygons_over, 0u);
  }
}

TEST(GridFuji, FanTriangulatedFilesOfEveryKindOfVariant) {
  LODSTREAM_REQUIRE_SHARED_DATA(dir);
  test::TempDir tmp;
  std::vector<std::pair<std::string, GridOptions>> variants;
  GridOptions go = grid_options(5, GridSplit::center, 2, GridGaps::fill);
  go.merge = true;
  variants.push_back({"center divide 2 fill merge", go});
  variants.push_back({"greatest gaps none", grid_options(5, GridSplit::greatest, 4, GridGaps::none)});
  variants.push_back({"curvature", grid_options(5, GridSplit::curvature, 4, GridGaps::extra_vertices)});
  go = grid_options(5, GridSplit::random, 2, GridGaps::extra_vertices);
  go.merge = true;
  variants.push_back({"random divide 2 merge", go});
  go = grid_options(5, GridSplit::first, 4, GridGaps::fill);
  go.target_polygons = 1000000;
  variants.push_back({"first fill target", go});
  int run = 0;
  for (const auto& [name, o] : variants) {
    SCOPED_TRACE(name + ", tolerance " + std::to_string(o.tolerance));
    const FileErrors fe =
        check_files(dir + "/terrain/fuji-terrain-rgb.png", o, tmp.file("run" + std::to_string(run++)), true);
    std::printf(
        "Fuji, %s, tolerance %g m: fan-triangulated grid.obj max error %.4f m (default), %.4f m "
        "(--polygons)\n",
        name.c_str(), o.tolerance, fe.triangles, fe.polygons);
  }
}

// ---- errors ----

TEST(Grid, DocumentedErrors) {
  test::TempDir tmp;
  GridOptions go;
  go.output_dir = tmp.file("out");
  go.tolerance = 1;
  GridReport rep;
  const Options o;
  EXPECT_EQ(grid(tmp.file("missing.asc"), go, o, &rep).status, Status::no_input);
  EXPECT_EQ(grid(tmp.path().string(), go, o, &rep).status, Status::no_input);
  EXPECT_EQ(grid(tmp.write("short.pgm", "P2\n3 3\n255\n1 2 3 4\n"), go, o, &rep).status, Status::bad_data);
  EXPECT_EQ(grid(tmp.write("text.asc", "ncols 2\nnrows 2\ncellsize 1\nxllcorner 0\nyllcorner 0\n1 2 x 4\n"), go, o, &rep).status,
            Status::bad_data);
  const Result one_row = grid(tmp.write("row.pgm", "P2\n5 1\n255\n1 2 3 4 5\n"), go, o, &rep);
  EXPECT_EQ(one_row.status, Status::bad_data);
  EXPECT_NE(one_row.message.find("row.pgm"), std::string::npos);
  EXPECT_EQ(grid(tmp.write("what.bin", "hello, not a grid\n"), go, o, &rep).status, Status::usage);
  const std::string good = tmp.write("good.pgm", "P2\n3 3\n255\n1 2 3\n4 5 6\n7 8 9\n");
  GridOptions bad = go;
  bad.tolerance = -1;
  EXPECT_EQ(grid(good, bad, o, &rep).status, Status::usage);  // neither tolerance nor target
  bad = go;
  bad.divide = 3;
  EXPECT_EQ(grid(good, bad, o, &rep).status, Status::usage);
  bad = go;
  bad.method = GridMethod::growth;
  bad.tolerance = -1;
  bad.target_polygons = 10;
  EXPECT_EQ(grid(good, bad, o, &rep).status, Status::usage);
  bad = go;
  bad.tolerance = -1;
  bad.target_polygons = 10;
  bad.merge = true;
  EXPECT_EQ(grid(good, bad, o, &rep).status, Status::usage);  // merge needs a tolerance
  bad = go;
  bad.output_dir = good + "/sub";  // a file in the way
  EXPECT_EQ(grid(good, bad, o, &rep).status, Status::io_error);
  ASSERT_TRUE(grid(good, go, o, &rep).ok());
  EXPECT_EQ(rep.polygons, 1u);  // a plane
  EXPECT_EQ(rep.max_error, 0.0);
}

TEST(Grid, CliExitCodes) {
  test::TempDir tmp;
  const std::string good = tmp.write("good.pgm", "P2\n3 3\n255\n1 2 3\n4 5 6\n7 8 9\n");
  const std::string out = tmp.file("out");
  EXPECT_EQ(test::run_cli({"grid", good, "-o", out, "--tolerance", "1", "--split", "sideways"}, tmp).exit_code, 64);
  EXPECT_EQ(test::run_cli({"grid", good, "-o", out}, tmp).exit_code, 64);
  EXPECT_EQ(test::run_cli({"grid", tmp.file("nope.pgm"), "-o", out, "--tolerance", "1"}, tmp).exit_code, 66);
  EXPECT_EQ(test::run_cli({"grid", tmp.write("bad.pgm", "P2\n3 3\n255\n1 2\n"), "-o", out, "--tolerance", "1"}, tmp).exit_code, 65);
  const test::CliRun ok = test::run_cli({"grid", good, "-o", out, "--tolerance", "1", "--gaps", "fill", "--json"}, tmp);
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const auto j = nlohmann::json::parse(ok.out);
  EXPECT_EQ(j["polygons"], 1);
  EXPECT_EQ(j["options"]["gaps"], "fill");
  const test::CliRun merged = test::run_cli({"grid", good, "-o", out, "--tolerance", "1", "--merge", "--json"}, tmp);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  EXPECT_EQ(nlohmann::json::parse(merged.out)["options"]["merge"], true);
  EXPECT_EQ(nlohmann::json::parse(merged.out)["obj_ply_faces"], "triangles");
  const test::CliRun polygons =
      test::run_cli({"grid", good, "-o", out, "--tolerance", "1", "--polygons", "--json"}, tmp);
  ASSERT_EQ(polygons.exit_code, 0) << polygons.err;
  EXPECT_EQ(nlohmann::json::parse(polygons.out)["obj_ply_faces"], "polygons");
  EXPECT_NE(test::read_file(out + "/grid.obj").find("\nf 3//3 4//4 2//2 1//1\n"),
            std::string::npos);  // SW SE NE NW
  const test::CliRun table = test::run_cli({"grid", good, "-o", out, "--tolerance", "1"}, tmp);
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_NE(table.out.find("grid.obj and grid.ply hold the drawn triangles"), std::string::npos) << table.out;
  EXPECT_EQ(test::read_file(out + "/grid.obj").find("\nf 3//3 4//4 2//2 1//1\n"), std::string::npos);
}

}  // namespace
}  // namespace lodstream

// `grid`: adaptive subdivision of height grids (DeHaemer 1989). Exact small cases on arrays, the Fuji
// tile for every variant, the files written, and the documented errors.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "core/adaptive_subdivision.h"
#include "io/grid_reader.h"
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
  // OBJ: n-gons appear (extra vertices), and the face count matches.
  std::ifstream obj(go.output_dir + "/grid.obj");
  uint64_t faces = 0, ngons = 0;
  for (std::string line; std::getline(obj, line);)
    if (line.rfind("f ", 0) == 0) {
      ++faces;
      if (std::count(line.begin(), line.end(), ' ') > 4) ++ngons;
    }
  EXPECT_EQ(faces, rep.polygons);
  EXPECT_GT(ngons, 0u);
  const std::string ply = test::read_file(go.output_dir + "/grid.ply");
  EXPECT_NE(ply.find("element face " + std::to_string(rep.polygons) + "\n"), std::string::npos);
  EXPECT_NE(ply.find("element vertex " + std::to_string(rep.vertices) + "\n"), std::string::npos);
  const std::string glb = test::read_file(go.output_dir + "/grid.glb");
  ASSERT_GE(glb.size(), 12u);
  EXPECT_EQ(glb.substr(0, 4), "glTF");
  for (const auto& e : std::filesystem::directory_iterator(go.output_dir))
    EXPECT_EQ(e.path().extension().string().find("partial"), std::string::npos) << e.path();
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
}

}  // namespace
}  // namespace lodstream

// `grid --cylindrical`: cylindrical range grids (DeHaemer 1989 §II.B). Every written mesh is read back
// from grid.glb and checked with Embree rays from the axis, one per valid sample (the radius there within
// the tolerance), and for cracks by its edges (the seam at 360 degrees included); exact small cylinders,
// trimming, errors; scans of the real busts in ../shared/data made by tools/scan_cylindrical.
#include <embree3/rtcore.h>
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <regex>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli_harness.h"
#include "core/adaptive_subdivision.h"
#include "core/ray_scene.h"
#include "io/grid_reader.h"
#include "test_util.h"

namespace lodstream {
namespace {

using nlohmann::json;

struct Mesh {
  std::vector<float> xyz;
  std::vector<uint32_t> tri;
};

// The TRIANGLES primitive of a one-mesh GLB (io/glb_writer.h layout).
Mesh read_glb(const std::string& path) {
  const std::string b = test::read_file(path);
  Mesh m;
  if (b.size() < 20 || b.substr(0, 4) != "glTF") {
    ADD_FAILURE() << path << ": not a GLB";
    return m;
  }
  auto u32 = [&](size_t at) {
    uint32_t v;
    std::memcpy(&v, b.data() + at, 4);
    return v;
  };
  const uint32_t json_len = u32(12);
  const json j = json::parse(b.substr(20, json_len));
  const size_t bin = 20 + json_len + 8;
  const json& prim = j["meshes"][0]["primitives"][0];
  EXPECT_EQ(prim.value("mode", 4), 4);
  auto accessor = [&](int index, size_t comps, auto* out) {
    const json& a = j["accessors"][size_t(index)];
    const json& v = j["bufferViews"][a["bufferView"].get<size_t>()];
    const size_t at = bin + v.value("byteOffset", size_t{0}) + a.value("byteOffset", size_t{0});
    out->resize(a["count"].get<size_t>() * comps);
    std::memcpy(out->data(), b.data() + at, out->size() * 4);
  };
  accessor(prim["attributes"]["POSITION"].get<int>(), 3, &m.xyz);
  accessor(prim["indices"].get<int>(), 1, &m.tri);
  return m;
}

// A radius grid as `grid --cylindrical` sees it (before trimming), with its frame. GLB frame: axis Y,
// longitude 0 at +Z, growing towards +X (core::CylinderFrame, --axis y).
struct Scan {
  io::HeightGrid g;
  double angle_step = 0;  // radians
  double height_step = 1;
  bool valid(int64_t i, int64_t j) const {
    if (j < 0 || j >= g.height) return false;
    if (closed()) i = (i + g.width) % g.width;
    if (i < 0 || i >= g.width) return false;
    const uint64_t s = uint64_t(j) * g.width + uint64_t(i);
    return (g.valid.empty() || g.valid[s]) && g.z[s] > 0;
  }
  bool closed() const { return std::abs(angle_step * g.width - 2 * std::numbers::pi) < 1e-9; }
  double height(uint32_t j) const { return g.origin_y + double(g.height - 1 - j) * height_step; }
};

// Each vertex's (column, row) from its longitude and height.
void grid_coords(const Scan& scan, const Mesh& m, std::vector<int64_t>* vi, std::vector<int64_t>* vj) {
  const size_t n = m.xyz.size() / 3;
  vi->resize(n);
  vj->resize(n);
  for (size_t v = 0; v < n; ++v) {
    const double x = m.xyz[3 * v], y = m.xyz[3 * v + 1], z = m.xyz[3 * v + 2];
    (*vj)[v] = std::llround((scan.height(0) - y) / scan.height_step);
    double a = std::atan2(x, z);
    if (a < -1e-6) a += 2 * std::numbers::pi;
    (*vi)[v] = std::llround(a / scan.angle_step) % (scan.closed() ? int64_t(scan.g.width) : INT64_MAX);
  }
}

struct RayCheck {
  uint64_t rays = 0, hits = 0, misses = 0, misses_away_from_borders = 0, over = 0, edge_on = 0, retried = 0;
  double max_error = 0;
};

// One Embree ray per valid sample, from the axis at the sample's height in the sample's direction, against
// the mesh: the first hit's distance is the surface's radius there. A ray may slip past the mesh only
// where the sample lies on its border (a rim row, the ends of a partial turn, next to a hole): there the
// ray runs exactly along the mesh's boundary edge. Fill triangles are left out: they lie in the
// half-plane of a longitude or the plane of a height, edge-on to the rays of the samples there, so a ray
// in their plane has no single radius on them (the polygons on both sides do, and are measured).
RayCheck cast_rays(const Scan& scan, const Mesh& mesh, double tolerance, double slack) {
  RayCheck c;
  std::vector<int64_t> vi, vj;
  grid_coords(scan, mesh, &vi, &vj);
  std::vector<uint32_t> facing;
  for (size_t t = 0; t < mesh.tri.size(); t += 3) {
    const uint32_t a = mesh.tri[t], b = mesh.tri[t + 1], d = mesh.tri[t + 2];
    if ((vi[a] == vi[b] && vi[b] == vi[d]) || (vj[a] == vj[b] && vj[b] == vj[d])) {
      ++c.edge_on;
      continue;
    }
    facing.insert(facing.end(), {a, b, d});
  }
  core::RayScene scene;
  scene.add_triangles(mesh.xyz, facing);
  scene.commit();
  RTCScene handle = static_cast<RTCScene>(scene.handle());
  uint32_t first = scan.g.height, last = 0;
  for (uint32_t j = 0; j < scan.g.height; ++j)
    for (uint32_t i = 0; i < scan.g.width; ++i)
      if (scan.valid(i, j)) first = std::min(first, j), last = std::max(last, j);
  RTCIntersectContext context;
  const double dy = 1e-4 * scan.height_step, da = 1e-4 * scan.angle_step;
  auto cast = [&](double y, double a) {  // the distance to the first hit, or -1
    RTCRayHit rh{};
    rh.ray.org_x = 0;
    rh.ray.org_y = float(y);
    rh.ray.org_z = 0;
    rh.ray.dir_x = float(std::sin(a));
    rh.ray.dir_y = 0;
    rh.ray.dir_z = float(std::cos(a));
    rh.ray.tnear = 0;
    rh.ray.tfar = std::numeric_limits<float>::infinity();
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcInitIntersectContext(&context);
    rtcIntersect1(handle, &context, &rh);
    return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1.0 : double(rh.ray.tfar);
  };
  for (uint32_t j = 0; j < scan.g.height; ++j)
    for (uint32_t i = 0; i < scan.g.width; ++i) {
      if (!scan.valid(i, j)) continue;
      const double r = scan.g.z[uint64_t(j) * scan.g.width + i], a = i * scan.angle_step;
      ++c.rays;
      std::vector<double> hits{cast(scan.height(j), a)};
      if (hits[0] < 0) {
        // Every ray runs at the height of a row of vertices and in the half-plane of a column of them,
        // often through a vertex or along an edge, which in float it can slip past (rare); with fill
        // polygons it can also run through the gap they close, in their plane. The rays 1e-4 of
        // a row and a column off, on both sides, must both hit; they are measured instead.
        ++c.retried;
        hits = {cast(scan.height(j) + dy, a + da), cast(scan.height(j) - dy, a - da)};
      }
      if (hits[0] < 0 || (hits.size() == 2 && hits[1] < 0)) {
        ++c.misses;
        bool border = j == first || j == last || (!scan.closed() && (i == 0 || i + 1 == scan.g.width));
        for (int dj = -1; dj <= 1 && !border; ++dj)
          for (int di = -1; di <= 1; ++di) border = border || !scan.valid(int64_t(i) + di, int64_t(j) + dj);
        if (!border && ++c.misses_away_from_borders <= 3) ADD_FAILURE() << "ray " << i << " " << j << " missed";
        continue;
      }
      ++c.hits;
      for (double t : hits) {
        const double e = std::abs(t - r);
        c.max_error = std::max(c.max_error, e);
        if (e > tolerance + slack && ++c.over <= 3) ADD_FAILURE() << "ray " << i << " " << j << ": " << t << " against " << r;
      }
    }
  return c;
}

struct EdgeCheck {
  uint64_t vertices = 0, duplicate_positions = 0, edges = 0, nonmanifold = 0, misoriented = 0;
  uint64_t open_edges = 0, open_edges_inside = 0;  // used once; inside: not on a rim, partial-turn end or hole
  uint64_t seam_edges = 0, seam_open = 0;           // edges along longitude 0 (closed turns)
  uint64_t inward = 0;                              // triangles facing the axis
};

// Edges of the read-back mesh: manifold (each undirected edge used at most twice, each directed edge at
// most once: consistent winding), open only on the rims and hole borders, one vertex per position, and
// every triangle facing away from the axis (but fill triangles, edge-on to it).
EdgeCheck check_edges(const Scan& scan, const Mesh& m) {
  EdgeCheck c;
  c.vertices = m.xyz.size() / 3;
  std::set<std::array<float, 3>> seen;
  for (size_t v = 0; v < m.xyz.size(); v += 3)
    if (!seen.insert({m.xyz[v], m.xyz[v + 1], m.xyz[v + 2]}).second) ++c.duplicate_positions;
  std::vector<int64_t> vi, vj;
  grid_coords(scan, m, &vi, &vj);
  uint32_t first = scan.g.height, last = 0;
  for (uint32_t j = 0; j < scan.g.height; ++j)
    for (uint32_t i = 0; i < scan.g.width; ++i)
      if (scan.valid(i, j)) first = std::min(first, j), last = std::max(last, j);
  auto cell_has_hole = [&](int64_t ci, int64_t cj) {  // the cell with NW corner (ci, cj)
    return !scan.valid(ci, cj) || !scan.valid(ci + 1, cj) || !scan.valid(ci, cj + 1) || !scan.valid(ci + 1, cj + 1);
  };
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (size_t t = 0; t < m.tri.size(); t += 3) {
    for (int k = 0; k < 3; ++k) ++directed[{m.tri[t + size_t(k)], m.tri[t + size_t((k + 1) % 3)]}];
    const uint32_t a = m.tri[t], b = m.tri[t + 1], d = m.tri[t + 2];
    if ((vi[a] == vi[b] && vi[b] == vi[d]) || (vj[a] == vj[b] && vj[b] == vj[d])) continue;  // fill: edge-on
    // Facing: the normal against the direction from the axis to the centroid (edge-on fill triangles skipped).
    const float* p[3] = {&m.xyz[3 * m.tri[t]], &m.xyz[3 * m.tri[t + 1]], &m.xyz[3 * m.tri[t + 2]]};
    const double u[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double w[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const double cx = (p[0][0] + p[1][0] + p[2][0]) / 3, cz = (p[0][2] + p[1][2] + p[2][2]) / 3;
    const double dot = n[0] * cx + n[2] * cz, len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * std::hypot(cx, cz);
    if (dot < -1e-6 * len && ++c.inward <= 3) ADD_FAILURE() << "inward triangle at column " << vi[m.tri[t]] << ", row " << vj[m.tri[t]];
  }
  std::map<std::pair<uint32_t, uint32_t>, int> undirected;
  for (const auto& [e, n] : directed) {
    if (n > 1 && ++c.misoriented <= 3) ADD_FAILURE() << "edge used twice in one direction at column " << vi[e.first] << ", row " << vj[e.first];
    undirected[{std::min(e.first, e.second), std::max(e.first, e.second)}] += n;
  }
  for (const auto& [e, n] : undirected) {
    ++c.edges;
    const int64_t ia = vi[e.first], ja = vj[e.first], ib = vi[e.second], jb = vj[e.second];
    const bool seam = scan.closed() && ia == 0 && ib == 0;
    c.seam_edges += seam;
    if (n > 2) ++c.nonmanifold;
    if (n != 1) continue;
    ++c.open_edges;
    c.seam_open += seam;
    bool border = false;
    if (ja == jb) {  // along a row: a rim, or a cell above or below it touches a hole
      border = ja == first || ja == last;
      for (int64_t i = std::min(ia, ib); i < std::max(ia, ib) && !border; ++i)
        border = cell_has_hole(i, ja - 1) || cell_has_hole(i, ja);
    } else if (ia == ib) {  // along a column: a partial turn's end, or a cell beside it touches a hole
      border = !scan.closed() && (ia == 0 || ia == scan.g.width - 1);
      for (int64_t j = std::min(ja, jb); j < std::max(ja, jb) && !border; ++j)
        border = cell_has_hole(ia - 1, j) || cell_has_hole(ia, j);
    }
    if (!border) ++c.open_edges_inside;
  }
  return c;
}

// Runs `grid --cylindrical` and returns its summary.json.
json run_grid(const test::TempDir& tmp, const std::string& input, const std::string& out, std::vector<std::string> extra) {
  std::vector<std::string> args{"grid", input, "-o", out, "--cylindrical", "--json"};
  args.insert(args.end(), extra.begin(), extra.end());
  const test::CliRun r = test::run_cli(args, tmp);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  if (r.exit_code != 0) return json::object();
  return json::parse(test::read_file(out + "/summary.json"));
}

std::string asc(uint32_t w, uint32_t h, double cellsize, const std::vector<double>& r) {
  std::string s = fmt::format("ncols {}\nnrows {}\nxllcenter 0\nyllcenter 0\ncellsize {}\nNODATA_value -9999\n", w, h, cellsize);
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) s += fmt::format("{:.9g}{}", r[uint64_t(j) * w + i], i + 1 < w ? ' ' : '\n');
  return s;
}

Scan load(const std::string& path, double z_scale, double height_step) {
  Scan s;
  s.g = io::read_height_grid(path, io::GridReadOptions{z_scale, 0});
  s.angle_step = 2 * std::numbers::pi / s.g.width;
  s.height_step = height_step > 0 ? height_step : s.g.spacing;
  return s;
}

// A cylinder of radius 10, 16 columns (22.5 degrees each): a chord across k columns lies inside the arc
// by 10 (1 - cos(k · 11.25°)) at its middle, so interpolating radii in the (longitude, height) domain
// would call one polygon per 90 degrees exact. Measured along the rays, two columns miss the middle
// sample by 10 (1 - cos 22.5°) = 0.761 and three by 1.52: at tolerance 1 every polygon spans two
// columns and the full height, and at 0.5 one column.
TEST(GridCylinder, ChordsLieInsideTheArc) {
  test::TempDir tmp;
  const std::string in = tmp.write("cyl.asc", asc(16, 5, 2, std::vector<double>(16 * 5, 10.0)));
  for (const double tol : {1.0, 0.5}) {
    const json s = run_grid(tmp, in, tmp.file(fmt::format("out{}", tol)), {"--tolerance", fmt::format("{}", tol)});
    ASSERT_FALSE(s.empty());
    EXPECT_EQ(s["polygons"], tol == 1.0 ? 8 : 16);
    EXPECT_EQ(s["triangles"], tol == 1.0 ? 16 : 32);
    EXPECT_EQ(s["vertices"], tol == 1.0 ? 16 : 32);  // the seam's column once
    EXPECT_NEAR(s["max_radius_error"].get<double>(), tol == 1.0 ? 10 * (1 - std::cos(std::numbers::pi / 8)) : 0.0, 1e-5);
    EXPECT_EQ(s["cylinder"]["closed"], true);
    const Scan scan = load(in, 1, 0);
    const Mesh m = read_glb(tmp.file(fmt::format("out{}/grid.glb", tol)));
    const RayCheck rc = cast_rays(scan, m, tol, 1e-5);
    EXPECT_EQ(rc.over, 0u);
    EXPECT_EQ(rc.misses_away_from_borders, 0u);
    const EdgeCheck ec = check_edges(scan, m);
    EXPECT_EQ(ec.duplicate_positions, 0u);
    EXPECT_EQ(ec.open_edges_inside, 0u);
    EXPECT_EQ(ec.nonmanifold + ec.misoriented + ec.inward, 0u);
    EXPECT_EQ(ec.seam_edges, 1u);  // the seam: one edge from the top row to the bottom, shared
    EXPECT_EQ(ec.seam_open, 0u);
  }
}

// Fine detail just west of the seam (a bump in the last columns) against a smooth surface east of it:
// the polygons at longitude 0 are large, those at 360 degrees small, so the seam is full of T-junctions.
// Extra vertices and fill polygons close them across the seam: no open edge but the rims.
TEST(GridCylinder, SeamTJunctionsAreClosed) {
  test::TempDir tmp;
  const uint32_t w = 64, h = 33;
  std::vector<double> r(uint64_t(w) * h);
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) {
      const double a = 2 * std::numbers::pi * i / w, y = double(j) / (h - 1);
      const double bump = i >= w - 6 ? 0.4 * std::sin(7 * y * std::numbers::pi) * std::sin(double(w - i) / 6 * std::numbers::pi) : 0;
      r[uint64_t(j) * w + i] = 20 + 2 * std::cos(a) + y + bump;
    }
  const std::string in = tmp.write("seam.asc", asc(w, h, 0.5, r));
  const Scan scan = load(in, 1, 0);
  for (const char* gaps : {"extra-vertices", "fill", "none"}) {
    const std::string out = tmp.file(std::string("out-") + gaps);
    const json s = run_grid(tmp, in, out, {"--tolerance", "0.02", "--gaps", gaps});
    ASSERT_FALSE(s.empty());
    const Mesh m = read_glb(out + "/grid.glb");
    const RayCheck rc = cast_rays(scan, m, 0.02, 1e-5);
    EXPECT_EQ(rc.over, 0u) << gaps << ": max " << rc.max_error;
    EXPECT_LE(s["max_radius_error"].get<double>(), 0.02 + 1e-5);
    const EdgeCheck ec = check_edges(scan, m);
    EXPECT_EQ(ec.duplicate_positions, 0u) << gaps;
    EXPECT_EQ(ec.nonmanifold + ec.misoriented + ec.inward, 0u) << gaps;
    EXPECT_GT(ec.seam_edges, 1u) << gaps;  // the seam is cut by the small polygons' corners
    if (std::string(gaps) == "none") {
      EXPECT_GT(s["cracks"].get<uint64_t>(), 0u);
      EXPECT_GT(ec.seam_open, 0u);  // the cracks the thesis' plain method leaves, at the seam too
    } else {
      EXPECT_EQ(s["cracks"], 0u);
      EXPECT_EQ(rc.misses_away_from_borders, 0u) << gaps;
      EXPECT_EQ(ec.open_edges_inside, 0u) << gaps;
      EXPECT_EQ(ec.seam_open, 0u) << gaps;
    }
  }
}

// Thesis §II.B: the scanned volume is taller than the subject, so the top and bottom rows hold no
// return; they are trimmed (and reported), rows with no return inside stay as holes, and the heights do
// not move.
TEST(GridCylinder, EmptyTopAndBottomRowsAreTrimmed) {
  test::TempDir tmp;
  const uint32_t w = 12, h = 9;
  std::vector<double> r(uint64_t(w) * h, 5.0);
  for (uint32_t i = 0; i < w; ++i) {
    r[i] = 0;                              // row 0: no return (0)
    r[w + i] = -9999;                      // row 1: NODATA
    r[uint64_t(h - 1) * w + i] = -9999;    // the last row
    r[uint64_t(4) * w + i] = i == 3 ? 0 : 5 + 0.1 * i;  // a hole inside stays
  }
  const std::string in = tmp.write("trim.asc", asc(w, h, 3, r));
  const json s = run_grid(tmp, in, tmp.file("out"), {"--tolerance", "0.001"});
  ASSERT_FALSE(s.empty());
  EXPECT_EQ(s["cylinder"]["trimmed_rows_top"], 2);
  EXPECT_EQ(s["cylinder"]["trimmed_rows_bottom"], 1);
  EXPECT_EQ(s["cylinder"]["rows"], 6);
  EXPECT_GT(s["hole_cells"].get<uint64_t>(), 0u);
  const Mesh m = read_glb(tmp.file("out/grid.glb"));
  float lo = INFINITY, hi = -INFINITY;
  for (size_t v = 1; v < m.xyz.size(); v += 3) lo = std::min(lo, m.xyz[v]), hi = std::max(hi, m.xyz[v]);
  EXPECT_FLOAT_EQ(hi, 3.0f * (h - 1 - 2));  // row 2's height, as in the untrimmed file
  EXPECT_FLOAT_EQ(lo, 3.0f * 1);            // row 7's
  const Scan scan = load(in, 1, 0);
  const RayCheck rc = cast_rays(scan, m, 0.001, 1e-5);
  EXPECT_EQ(rc.over, 0u);
  EXPECT_EQ(rc.misses_away_from_borders, 0u);
  const EdgeCheck ec = check_edges(scan, m);
  EXPECT_EQ(ec.open_edges_inside + ec.nonmanifold + ec.misoriented + ec.inward + ec.duplicate_positions, 0u);
}

// A partial turn (--angle-step below 360 / columns) stays open at both ends; --axis z writes the axis
// along Z in grid.obj while grid.glb keeps it on glTF's up axis.
TEST(GridCylinder, PartialTurnAndAxis) {
  test::TempDir tmp;
  const uint32_t w = 10, h = 4;
  std::vector<double> r(uint64_t(w) * h);
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) r[uint64_t(j) * w + i] = 7 + 0.3 * j + 0.2 * (i % 3);
  const std::string in = tmp.write("part.asc", asc(w, h, 1, r));
  const json s = run_grid(tmp, in, tmp.file("out"), {"--tolerance", "0.01", "--angle-step", "10", "--axis", "z"});
  ASSERT_FALSE(s.empty());
  EXPECT_EQ(s["cylinder"]["closed"], false);
  EXPECT_EQ(s["cylinder"]["axis"], "z");
  Scan scan = load(in, 1, 0);
  scan.angle_step = 10 * std::numbers::pi / 180;
  const Mesh m = read_glb(tmp.file("out/grid.glb"));
  const RayCheck rc = cast_rays(scan, m, 0.01, 1e-5);
  EXPECT_EQ(rc.over, 0u);
  EXPECT_EQ(rc.misses_away_from_borders, 0u);
  const EdgeCheck ec = check_edges(scan, m);
  EXPECT_EQ(ec.open_edges_inside + ec.nonmanifold + ec.misoriented + ec.inward + ec.duplicate_positions, 0u);
  // grid.obj: axis z, longitude 0 at +X. Vertex (0, 0) (top row, column 0) is at (7, 0, 3).
  const std::string obj = test::read_file(tmp.file("out/grid.obj"));
  EXPECT_NE(obj.find("\nv 7 0 3"), std::string::npos) << obj.substr(0, 400);
}

TEST(GridCylinder, Errors) {
  test::TempDir tmp;
  const std::string good = tmp.write("good.asc", asc(8, 3, 1, std::vector<double>(24, 4.0)));
  auto run = [&](std::vector<std::string> args) { return test::run_cli(args, tmp); };
  const std::string out = tmp.file("out");
  // Usage (64).
  EXPECT_EQ(run({"grid", good, "-o", out, "--tolerance", "1", "--cylindrical", "--angle-step", "50"}).exit_code, 64);  // 8 x 50 > 360
  EXPECT_EQ(run({"grid", good, "-o", out, "--tolerance", "1", "--height-step", "2"}).exit_code, 64);  // needs --cylindrical
  EXPECT_EQ(run({"grid", good, "-o", out, "--tolerance", "1", "--cylindrical", "--axis", "w"}).exit_code, 64);
  EXPECT_EQ(run({"grid", good, "-o", out, "--tolerance", "1", "--cylindrical", "--spacing", "2"}).exit_code, 64);
  EXPECT_EQ(run({"grid", good, "-o", out, "--tolerance", "1", "--cylindrical", "--height-step", "-1"}).exit_code, 64);
  const test::CliRun png = run({"grid", test::source_dir() + "/tests/data/grids/hill-terrain-rgb.png", "-o", out, "--tolerance", "1", "--cylindrical"});
  EXPECT_EQ(png.exit_code, 64);
  EXPECT_NE(png.err.find("Terrain-RGB"), std::string::npos) << png.err;
  const std::string two = tmp.write("two.asc", asc(2, 3, 1, std::vector<double>(6, 4.0)));  // 180 degrees a column
  EXPECT_EQ(run({"grid", two, "-o", out, "--tolerance", "1", "--cylindrical"}).exit_code, 64);
  // Malformed (65), with the line or byte offset.
  const std::string bad_asc = tmp.write("bad.asc", "ncols 4\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n5 x 7 8\n");
  const test::CliRun a = run({"grid", bad_asc, "-o", out, "--tolerance", "1", "--cylindrical"});
  EXPECT_EQ(a.exit_code, 65);
  EXPECT_NE(a.err.find("bad.asc:7:"), std::string::npos) << a.err;
  const std::string bad_pgm = tmp.write("bad.pgm", std::string("P5\n4 4\n65535\n") + std::string(20, '\x01'));
  const test::CliRun p = run({"grid", bad_pgm, "-o", out, "--tolerance", "1", "--cylindrical"});
  EXPECT_EQ(p.exit_code, 65);
  EXPECT_NE(p.err.find("byte"), std::string::npos) << p.err;
  const std::string empty = tmp.write("empty.asc", asc(8, 3, 1, std::vector<double>(24, 0.0)));
  const test::CliRun e = run({"grid", empty, "-o", out, "--tolerance", "1", "--cylindrical"});
  EXPECT_EQ(e.exit_code, 65);
  EXPECT_NE(e.err.find("no sample has a return"), std::string::npos) << e.err;
  std::vector<double> neg(24, 4.0);
  neg[10] = -2;
  const std::string negative = tmp.write("neg.asc", asc(8, 3, 1, neg));
  const test::CliRun n = run({"grid", negative, "-o", out, "--tolerance", "1", "--cylindrical"});
  EXPECT_EQ(n.exit_code, 65);
  EXPECT_NE(n.err.find("row 2, column 3"), std::string::npos) << n.err;
  std::vector<double> one_row(24, 0.0);
  for (int i = 8; i < 16; ++i) one_row[size_t(i)] = 3;
  const std::string single = tmp.write("single.asc", asc(8, 3, 1, one_row));
  EXPECT_EQ(run({"grid", single, "-o", out, "--tolerance", "1", "--cylindrical"}).exit_code, 65);
}

// The shipped sample: a 128 x 128 scan of the CC0 teddy bear (tests/data/grids/LICENSE-teddy-bear.md),
// 16-bit PGM; every gap mode and split rule, growth and merge, on the rays and the edges.
TEST(GridCylinder, ShippedTeddyBearScan) {
  test::TempDir tmp;
  const std::string in = test::source_dir() + "/tests/data/grids/teddy-bear-cyl-128.pgm";
  const std::string pgm = test::read_file(in);
  const std::smatch m = [&] {
    std::smatch x;
    std::regex_search(pgm, x, std::regex("value x ([0-9.e+-]+).*height step ([0-9.e+-]+)"));
    return x;
  }();
  ASSERT_EQ(m.size(), 3u) << "the PGM comment names the radius scale and height step";
  const std::string z_scale = m[1], height_step = m[2];
  const Scan scan = load(in, std::stod(z_scale), std::stod(height_step));
  double rmax = 0;
  for (uint64_t k = 0; k < scan.g.z.size(); ++k) rmax = std::max(rmax, double(scan.g.z[k]));
  const std::vector<std::vector<std::string>> variants{
      {"--gaps", "extra-vertices"},
      {"--gaps", "fill", "--split", "center", "--divide", "2"},
      {"--gaps", "extra-vertices", "--merge"},
      {"--gaps", "fill", "--method", "growth"},
      {"--gaps", "extra-vertices", "--split", "curvature"},
      {"--gaps", "none", "--split", "first"},
  };
  for (const double tol : {0.2, 1.0}) {
    for (const auto& v : variants) {
      std::vector<std::string> args{"--tolerance", fmt::format("{}", tol), "--z-scale", z_scale, "--height-step", height_step};
      args.insert(args.end(), v.begin(), v.end());
      const std::string out = tmp.file("out");
      const json s = run_grid(tmp, in, out, args);
      ASSERT_FALSE(s.empty());
      const std::string what = fmt::format("tolerance {} {}", tol, fmt::join(v, " "));
      EXPECT_LE(s["max_radius_error"].get<double>(), tol + 1e-6 * rmax) << what;  // float rounding of the vertices
      const Mesh mesh = read_glb(out + "/grid.glb");
      const RayCheck rc = cast_rays(scan, mesh, tol, 2e-6 * rmax);
      EXPECT_EQ(rc.over, 0u) << what << ": max " << rc.max_error;
      EXPECT_GT(rc.hits, rc.rays * 9 / 10) << what;
      const EdgeCheck ec = check_edges(scan, mesh);
      EXPECT_EQ(ec.duplicate_positions + ec.nonmanifold + ec.misoriented + ec.inward, 0u) << what;
      if (v[1] != "none") {
        EXPECT_EQ(rc.misses_away_from_borders, 0u) << what;
        EXPECT_EQ(ec.open_edges_inside, 0u) << what;
        EXPECT_EQ(ec.seam_open, 0u) << what;
      }
      EXPECT_GT(s["cylinder"]["trimmed_rows_top"].get<int>() + s["cylinder"]["trimmed_rows_bottom"].get<int>(), 0) << what;
      // Only samples in no drawable cell (all four cells around them touch a hole) are met by no ray.
      EXPECT_EQ(s["uncovered_samples"], 2) << what;
    }
  }
  // Stopped by a polygon count, polygons are coarse and their triangles steep (planes crossing the axis
  // between their rows): every ray still meets the surface once.
  const std::string out = tmp.file("target");
  const json s = run_grid(tmp, in, out, {"--target-polygons", "500", "--z-scale", z_scale, "--height-step", height_step});
  ASSERT_FALSE(s.empty());
  EXPECT_EQ(s["uncovered_samples"], 2);
  const RayCheck rc = cast_rays(scan, read_glb(out + "/grid.glb"), 1e9, 0);
  EXPECT_EQ(rc.misses_away_from_borders, 0u);
}

// The thesis' main data from real models: Nefertiti, the ogre and the bunny scanned by
// tools/scan_cylindrical at 512 x 512 (as the Cyberware scanner did), then subdivided at a few
// tolerances and gap modes; every valid sample's ray checked against the mesh read back.
TEST(GridCylinder, ScansOfRealBusts) {
  LODSTREAM_REQUIRE_SHARED_DATA(data);
#ifndef LODSTREAM_SCAN_TOOL
  GTEST_SKIP() << "skipped: tools/scan_cylindrical is not built (LODSTREAM_BUILD_TOOLS=OFF)";
#else
  test::TempDir tmp;
  struct Model {
    const char* file;
    const char* axis;
  };
  for (const Model& model : {Model{"scans/nefertiti.obj", "z"}, Model{"scans/ogre.obj", "y"}, Model{"scans/stanford-bunny.obj", "y"}}) {
    const std::string base = tmp.file("scan");
    const std::string tool = LODSTREAM_SCAN_TOOL;
    std::vector<std::string> args{tool, data + "/" + model.file, base, "--axis", model.axis};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const std::string log = tmp.file("scan.log");
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid;
    ASSERT_EQ(posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << model.file;
    const std::string printed = test::read_file(log);
    std::smatch m;
    ASSERT_TRUE(std::regex_search(printed, m, std::regex("--height-step ([0-9.e+-]+) \\(PGM: --z-scale ([0-9.e+-]+)\\)"))) << printed;
    const std::string height_step = m[1], z_scale = m[2];
    const Scan pgm = load(base + ".pgm", std::stod(z_scale), std::stod(height_step));
    const Scan asc_scan = load(base + ".asc", 1, 0);
    ASSERT_EQ(pgm.g.width, 512u);
    ASSERT_EQ(pgm.g.height, 512u);
    double rmax = 0;
    for (float r : asc_scan.g.z) rmax = std::max(rmax, double(r));
    struct Run {
      double tol_fraction;  // of the largest radius
      const char* gaps;
      bool use_asc;
      bool merge;
    };
    for (const Run& run : {Run{0.002, "extra-vertices", false, false}, Run{0.01, "fill", false, false},
                           Run{0.001, "extra-vertices", false, true}, Run{0.01, "extra-vertices", true, false},
                           Run{0.002, "none", true, false}}) {
      const double tol = run.tol_fraction * rmax;
      const Scan& scan = run.use_asc ? asc_scan : pgm;
      std::vector<std::string> a{"--tolerance", fmt::format("{:.9g}", tol), "--gaps", run.gaps, "--axis", model.axis};
      if (run.merge) a.push_back("--merge");
      if (!run.use_asc) a.insert(a.end(), {"--z-scale", z_scale, "--height-step", height_step});
      const std::string out = tmp.file("out");
      const json s = run_grid(tmp, run.use_asc ? base + ".asc" : base + ".pgm", out, a);
      ASSERT_FALSE(s.empty());
      const std::string what = fmt::format("{} tolerance {} {}{} {}", model.file, tol, run.gaps, run.merge ? " merge" : "", run.use_asc ? "asc" : "pgm");
      const Mesh mesh = read_glb(out + "/grid.glb");
      const RayCheck rc = cast_rays(scan, mesh, tol, 2e-6 * rmax);
      EXPECT_EQ(rc.over, 0u) << what << ": max " << rc.max_error;
      EXPECT_LE(s["max_radius_error"].get<double>(), tol + 1e-6 * rmax) << what;  // float rounding of the vertices
      const EdgeCheck ec = check_edges(scan, mesh);
      EXPECT_EQ(ec.duplicate_positions + ec.nonmanifold + ec.misoriented + ec.inward, 0u) << what;
      if (std::string(run.gaps) != "none") {
        EXPECT_EQ(rc.misses_away_from_borders, 0u) << what;
        EXPECT_EQ(ec.open_edges_inside, 0u) << what;
        EXPECT_EQ(ec.seam_open, 0u) << what;
      }
      EXPECT_GT(s["cylinder"]["trimmed_rows_top"].get<int>(), 0) << what;
      EXPECT_GT(s["cylinder"]["trimmed_rows_bottom"].get<int>(), 0) << what;
      std::printf("%s: %llu polygons, %llu triangles, max radius error %.4g, %llu rays\n", what.c_str(),
                  static_cast<unsigned long long>(s["polygons"].get<uint64_t>()),
                  static_cast<unsigned long long>(s["triangles"].get<uint64_t>()), rc.max_error,
                  static_cast<unsigned long long>(rc.rays));
    }
  }
#endif
}

}  // namespace
}  // namespace lodstream

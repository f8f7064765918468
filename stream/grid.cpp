// `grid`: read a height grid, subdivide it (core/adaptive_subdivision.h), measure the drawn triangles
// against every sample, and write them (OBJ, PLY, GLB; the polygons to OBJ and PLY with
// GridOptions::polygons) and summary.json (last).
// With --cylindrical the grid holds a cylindrical scan's radii (DeHaemer 1989 §II.B): its empty top and
// bottom rows are trimmed, a full turn gets its first column repeated at 360 degrees for the subdivision
// (core::CylinderFrame::wrap) and folded back onto column 0 here, and the mesh is the 3D one.
#include <array>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/adaptive_subdivision.h"
#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "io/grid_reader.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"
#include "io/polygon_writer.h"
#include "lodstream/lodstream.h"
#include "stream/job.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream {

namespace {

using nlohmann::ordered_json;

const char* name(GridSplit s) {
  switch (s) {
    case GridSplit::center: return "center";
    case GridSplit::first: return "first";
    case GridSplit::greatest: return "greatest";
    case GridSplit::curvature: return "curvature";
    case GridSplit::random: return "random";
  }
  return "?";
}
const char* name(GridGaps g) {
  return g == GridGaps::none ? "none" : g == GridGaps::extra_vertices ? "extra-vertices" : "fill";
}
const char* name(GridMethod m) { return m == GridMethod::subdivision ? "subdivision" : "growth"; }

void check_options(const GridOptions& o) {
  auto usage = [](const std::string& m) { fail(Status::usage, m); };
  if (o.output_dir.empty()) usage("an output directory is required (-o DIR)");
  if (!std::isfinite(o.tolerance)) usage("--tolerance must be a finite number");
  if (o.tolerance < 0 && o.target_polygons == 0) usage("give --tolerance or --target-polygons");
  if (o.divide != 2 && o.divide != 4) usage("--divide must be 4 or 2");
  if (o.method == GridMethod::growth && o.tolerance < 0) usage("--method growth needs --tolerance");
  if (o.method == GridMethod::growth && o.target_polygons) usage("--method growth takes no --target-polygons");
  if (o.merge && o.tolerance < 0) usage("--merge needs --tolerance");
  if (o.cylindrical) {
    if (!(o.height_step >= 0) || !std::isfinite(o.height_step)) usage("--height-step must be a finite number > 0");
    if (!(o.angle_step >= 0) || !std::isfinite(o.angle_step)) usage("--angle-step must be a finite number of degrees > 0");
    if (o.spacing != 0) usage("--spacing is for height grids: give a cylindrical grid's --height-step");
  } else if (o.height_step != 0 || o.angle_step != 0) {
    usage("--height-step and --angle-step need --cylindrical");
  }
}

const char* name(GridAxis a) { return a == GridAxis::x ? "x" : a == GridAxis::y ? "y" : "z"; }

// A cylindrical scan ready for the subdivision (core::CylinderFrame): the rows with a return, and with a
// full turn column 0 repeated as the last column.
struct CylinderGrid {
  uint32_t columns = 0, rows = 0, width = 0;  // width: columns, + 1 with wrap
  uint32_t trimmed_top = 0, trimmed_bottom = 0;
  double angle_step_degrees = 0;
  std::vector<float> z;
  std::vector<uint8_t> valid;  // 0: no return (0, NODATA)
  core::CylinderFrame frame;
};

CylinderGrid prepare_cylinder(const std::string& input, const io::HeightGrid& g, const GridOptions& go) {
  if (g.format == "terrain-rgb-png")
    fail(Status::usage, fmt::format("{}: --cylindrical reads radii from a PGM or ESRI ASCII grid, not a Terrain-RGB PNG", input));
  CylinderGrid c;
  c.columns = g.width;
  auto has_return = [&](uint64_t s) { return (g.valid.empty() || g.valid[s]) && g.z[s] > 0; };
  for (uint32_t j = 0; j < g.height; ++j)
    for (uint32_t i = 0; i < g.width; ++i) {
      const uint64_t s = uint64_t(j) * g.width + i;
      if ((g.valid.empty() || g.valid[s]) && g.z[s] < 0)
        fail(Status::bad_data, fmt::format("{}: row {}, column {} (from 1, top row first): negative radius {}", input, j + 1, i + 1, g.z[s]));
    }
  // Thesis §II.B: the scanned volume is taller than the subject, so the top and bottom rows hold no
  // return; they are trimmed (rows inside the subject with no return stay, as holes).
  auto row_empty = [&](uint32_t j) {
    for (uint32_t i = 0; i < g.width; ++i)
      if (has_return(uint64_t(j) * g.width + i)) return false;
    return true;
  };
  uint32_t top = 0, bottom = g.height;
  while (top < bottom && row_empty(top)) ++top;
  while (bottom > top && row_empty(bottom - 1)) --bottom;
  if (top == bottom) fail(Status::bad_data, fmt::format("{}: no sample has a return (every radius is 0 or NODATA)", input));
  c.trimmed_top = top;
  c.trimmed_bottom = g.height - bottom;
  c.rows = bottom - top;
  if (c.rows < 2)
    fail(Status::bad_data, fmt::format("{}: one row has a return once the empty rows are trimmed: no cell to draw (at least 2 rows)", input));

  const double turn = 360;
  c.angle_step_degrees = go.angle_step > 0 ? go.angle_step : turn / c.columns;
  const double covered = c.angle_step_degrees * c.columns;
  if (covered > turn * (1 + 1e-9))
    fail(Status::usage, fmt::format("--angle-step {}: {} columns cover {} degrees, more than a turn (360)", c.angle_step_degrees, c.columns, covered));
  if (c.angle_step_degrees >= 180)
    fail(Status::usage, fmt::format("{}: an angle step of {} degrees per column: less than 180 needed (at least 3 columns for a turn)", input, c.angle_step_degrees));
  c.frame.wrap = covered >= turn * (1 - 1e-9);
  // A full turn uses exactly 2 pi / columns, so that column `columns` is column 0 again.
  c.frame.angle_step = c.frame.wrap ? 2 * std::numbers::pi / c.columns : c.angle_step_degrees * std::numbers::pi / 180;
  if (c.frame.wrap) c.angle_step_degrees = turn / c.columns;
  c.frame.height_step = go.height_step > 0 ? go.height_step : g.spacing;
  // Heights as the file places its rows (io::HeightGrid::y with the height step), so trimming moves nothing.
  c.frame.y_bottom = g.origin_y + double(g.height - bottom) * c.frame.height_step;
  c.width = c.columns + (c.frame.wrap ? 1 : 0);
  c.z.resize(uint64_t(c.width) * c.rows);
  c.valid.resize(c.z.size());
  for (uint32_t j = 0; j < c.rows; ++j)
    for (uint32_t i = 0; i < c.width; ++i) {
      const uint64_t from = uint64_t(j + top) * g.width + (i == c.columns ? 0 : i), to = uint64_t(j) * c.width + i;
      c.valid[to] = has_return(from);
      c.z[to] = c.valid[to] ? g.z[from] : 0;
    }
  return c;
}

// World axes of the local frame (c, s, axis) of core::CylinderFrame: a cyclic permutation, so the frame
// stays right-handed and the triangles keep facing outwards.
std::array<int, 3> world_axes(GridAxis axis) {
  const int a = axis == GridAxis::x ? 0 : axis == GridAxis::y ? 1 : 2;
  return {(a + 1) % 3, (a + 2) % 3, a};
}

// Unit normal (local frame) of sample (i, j) of a cylindrical grid from its neighbours' points: the
// longitude difference (wrapping on a full turn) crossed with the height difference, one-sided at the
// rims, at the ends of a partial turn and next to holes; the radial direction when both are missing.
void cylinder_normal(const core::GridSamples& g, const CylinderGrid& c, uint32_t i, uint32_t j, double* n) {
  auto ok = [&](int64_t a, int64_t b) {
    if (c.frame.wrap) a = (a + c.columns) % c.columns;
    return a >= 0 && b >= 0 && a < c.columns && b < c.rows && c.valid[uint64_t(b) * c.width + a];
  };
  auto point = [&](int64_t a, int64_t b, double* p) {
    if (c.frame.wrap) a = (a + c.columns) % c.columns;
    core::cylinder_point(g, uint32_t(uint64_t(b) * c.width + a), p);
  };
  auto diff = [&](int64_t a0, int64_t b0, int64_t a1, int64_t b1, double* d) {  // point(a1, b1) - point(a0, b0)
    double p[3], q[3];
    const bool lo = ok(a0, b0), hi = ok(a1, b1);
    if (!lo) a0 = i, b0 = j;
    if (!hi) a1 = i, b1 = j;
    point(a0, b0, p);
    point(a1, b1, q);
    for (int k = 0; k < 3; ++k) d[k] = q[k] - p[k];
  };
  double du[3], dv[3];
  diff(int64_t(i) - 1, j, int64_t(i) + 1, j, du);  // eastward (growing longitude)
  diff(i, int64_t(j) + 1, i, int64_t(j) - 1, dv);  // upward
  n[0] = du[1] * dv[2] - du[2] * dv[1];
  n[1] = du[2] * dv[0] - du[0] * dv[2];
  n[2] = du[0] * dv[1] - du[1] * dv[0];
  double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!(len > 0)) {
    point(i, j, n);
    n[2] = 0;
    len = std::sqrt(n[0] * n[0] + n[1] * n[1]);
  }
  for (int k = 0; k < 3; ++k) n[k] /= len;
}

// Unit normal of sample s from central differences in world units (one-sided at borders and NODATA).
void sample_normal(const io::HeightGrid& g, uint32_t i, uint32_t j, float* n) {
  auto ok = [&](int64_t a, int64_t b) {
    return a >= 0 && b >= 0 && a < g.width && b < g.height && (g.valid.empty() || g.valid[uint64_t(b) * g.width + a]);
  };
  auto zat = [&](int64_t a, int64_t b) { return double(g.z[uint64_t(b) * g.width + a]); };
  auto slope = [&](int64_t a0, int64_t b0, int64_t a1, int64_t b1) {  // dz per sample step from (a0,b0) to (a1,b1)
    const bool lo = ok(a0, b0), hi = ok(a1, b1);
    if (lo && hi) return (zat(a1, b1) - zat(a0, b0)) / 2;
    if (hi) return zat(a1, b1) - zat(i, j);
    if (lo) return zat(i, j) - zat(a0, b0);
    return 0.0;
  };
  const double dx = slope(int64_t(i) - 1, j, int64_t(i) + 1, j) / g.spacing;
  const double dy = slope(i, int64_t(j) + 1, i, int64_t(j) - 1) / g.spacing;  // y grows northward, j southward
  const double len = std::sqrt(dx * dx + dy * dy + 1);
  n[0] = float(-dx / len);
  n[1] = float(-dy / len);
  n[2] = float(1 / len);
}

}  // namespace

Result grid(const std::string& input, const GridOptions& go, const Options& options, GridReport* out) {
  return stream::guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    check_options(go);
    stream::Progress progress(options);
    GridReport report;
    report.input = input;

    const io::HeightGrid g = stream::run_stage(&report.stages, "read", [&](StageStats&) {
      progress.report("read", 0);
      io::HeightGrid h = io::read_height_grid(input, io::GridReadOptions{go.z_scale, go.spacing});
      progress.report("read", 1);
      return h;
    });
    if (g.width < 2 || g.height < 2)
      fail(Status::bad_data, fmt::format("{}: a {} x {} grid has no cell to draw (at least 2 x 2 samples)", input, g.width, g.height));
    report.format = g.format;
    report.width = g.width;
    report.height = g.height;
    report.spacing = g.spacing;
    const uint64_t n = uint64_t(g.width) * g.height;
    report.valid_samples = g.valid.empty() ? n : uint64_t(std::count(g.valid.begin(), g.valid.end(), uint8_t{1}));

    core::GridSamples samples{g.width, g.height, g.spacing, g.z, g.valid};
    CylinderGrid cyl;
    if (go.cylindrical) {
      cyl = prepare_cylinder(input, g, go);
      samples = core::GridSamples{cyl.width, cyl.rows, cyl.frame.height_step, cyl.z, cyl.valid, &cyl.frame};
      report.valid_samples = 0;
      for (uint64_t s = 0; s < cyl.z.size(); ++s) report.valid_samples += cyl.valid[s] && s % cyl.width < cyl.columns;
      report.trimmed_rows_top = cyl.trimmed_top;
      report.trimmed_rows_bottom = cyl.trimmed_bottom;
      report.angle_step = cyl.angle_step_degrees;
      report.height_step = cyl.frame.height_step;
      report.closed = cyl.frame.wrap;
    }
    core::SubdivisionOptions so;
    so.tolerance = go.tolerance >= 0 ? go.tolerance : std::numeric_limits<double>::infinity();
    so.split = static_cast<core::SplitRule>(go.split);  // the public enums list the same values in the same order
    so.divide = go.divide;
    so.gaps = static_cast<core::GapMode>(go.gaps);
    so.target_polygons = go.target_polygons;
    so.method = go.method == GridMethod::growth ? core::Method::growth : core::Method::subdivision;
    so.seed = go.seed;
    so.merge = go.merge;
    core::Subdivision sub = stream::run_stage(&report.stages, "subdivide", [&](StageStats&) {
      return core::subdivide(samples, so, [&](double f) { progress.report("subdivide", f); });
    });

    // The indexed mesh (vertices: the samples the polygons use, in sample order), timed as its own stage:
    // it is part of the meshing a peer's time includes (Martini's getMesh and Delatin return indexed
    // vertices), so tools/bench_grid.sh adds it to "subdivide". Normals are left out of it (peers compute none).
    io::PolygonMesh poly;
    core::LodMesh tri;
    std::vector<uint32_t> used;  // vertex -> sample
    if (go.cylindrical) stream::run_stage(&report.stages, "index", [&](StageStats&) {
      // As below, in 3D: the wrap column's ids fold onto column 0's, so the seam's vertices are shared.
      constexpr uint32_t kUnused = UINT32_MAX;
      const uint64_t m = uint64_t(samples.width) * samples.height;
      auto fold = [&](uint32_t s) { return cyl.frame.wrap && s % cyl.width == cyl.columns ? s - cyl.columns : s; };
      std::vector<uint32_t> vid(m, kUnused);
      for (uint32_t s : sub.rings) vid[fold(s)] = 0;
      const std::array<int, 3> axes = world_axes(go.axis);
      for (uint32_t s = 0; s < m; ++s) {
        if (vid[s] == kUnused) continue;
        vid[s] = uint32_t(used.size());
        used.push_back(s);
        double p[3];
        core::cylinder_point(samples, s, p);
        float w[3];
        for (int k = 0; k < 3; ++k) w[axes[size_t(k)]] = float(p[k]);
        poly.positions.insert(poly.positions.end(), w, w + 3);
      }
      poly.offsets = std::move(sub.ring_offsets);
      poly.indices = std::move(sub.rings);
      for (uint32_t& s : poly.indices) s = vid[fold(s)];
      tri.triangles.reserve(sub.triangles.size());
      for (uint32_t s : sub.triangles) tri.triangles.push_back(vid[fold(s)]);
    });
    else stream::run_stage(&report.stages, "index", [&](StageStats&) {
      // One pass over a sample-sized map instead of sorting the ring entries.
      constexpr uint32_t kUnused = UINT32_MAX;
      std::vector<uint32_t> vid(n, kUnused);
      uint64_t vertices = 0;
      for (uint32_t s : sub.rings)
        if (vid[s] == kUnused) vid[s] = 0, ++vertices;
      used.reserve(vertices);
      poly.positions.reserve(3 * vertices);
      for (uint32_t j = 0; j < g.height; ++j)
        for (uint32_t i = 0; i < g.width; ++i) {
          const uint64_t s = uint64_t(j) * g.width + i;
          if (vid[s] == kUnused) continue;
          vid[s] = uint32_t(used.size());
          used.push_back(uint32_t(s));
          poly.positions.insert(poly.positions.end(), {float(g.x(i)), float(g.y(j)), g.z[s]});
        }
      // The rings are not needed as sample ids after this: their storage becomes the mesh's (no copy).
      poly.offsets = std::move(sub.ring_offsets);
      poly.indices = std::move(sub.rings);
      for (uint32_t& s : poly.indices) s = vid[s];
      tri.triangles.reserve(sub.triangles.size());
      for (uint32_t s : sub.triangles) tri.triangles.push_back(vid[s]);
    });
    poly.normals.resize(3 * used.size());
    if (go.cylindrical) {
      const std::array<int, 3> axes = world_axes(go.axis);
      for (size_t v = 0; v < used.size(); ++v) {
        double nl[3];
        cylinder_normal(samples, cyl, used[v] % cyl.width, used[v] / cyl.width, nl);
        for (int k = 0; k < 3; ++k) poly.normals[3 * v + size_t(axes[size_t(k)])] = float(nl[k]);
      }
    } else {
      for (size_t v = 0; v < used.size(); ++v) sample_normal(g, used[v] % g.width, used[v] / g.width, &poly.normals[3 * v]);
    }
    tri.positions = poly.positions;
    tri.normals = poly.normals;
    // grid.obj and grid.ply hold `tri` in the --axis frame; grid.glb holds `glb_tri`.
    core::LodMesh rotated;
    const core::LodMesh* glb_tri = &tri;
    if (go.cylindrical && go.axis != GridAxis::y) {
      // glTF is Y-up: grid.glb holds the mesh with the cylinder's axis on Y (the frame --axis y gives), a
      // rotation of the --axis frame (both are cyclic permutations of the local one).
      rotated = tri;
      glb_tri = &rotated;
      const std::array<int, 3> from = world_axes(go.axis), to = world_axes(GridAxis::y);
      for (std::vector<float>* a : {&rotated.positions, &rotated.normals})
        for (size_t v = 0; v < a->size(); v += 3) {
          float w[3];
          for (int k = 0; k < 3; ++k) w[to[size_t(k)]] = (*a)[v + size_t(from[size_t(k)])];
          std::copy(w, w + 3, a->begin() + std::ptrdiff_t(v));
        }
    }

    const core::VerticalError err = stream::run_stage(&report.stages, "measure", [&](StageStats&) {
      progress.report("measure", 0);
      // Cylinders: on the vertices as written (float), along each sample's ray from the axis.
      const core::VerticalError e = core::vertical_error(samples, sub.triangles, go.cylindrical);
      progress.report("measure", 1);
      return e;
    });

    report.hole_cells = sub.hole_cells;
    report.polygons = poly.polygon_count();
    report.fill_polygons = sub.fill_polygons;
    report.fill_vertices = poly.offsets.back() - poly.offsets[sub.polygons.size()];  // fill rings come last
    report.vertices = used.size();
    report.draw_vertices = poly.indices.size();
    report.bytes = 24 * report.vertices + 12 * report.polygons + 4 * report.draw_vertices;
    report.triangles = tri.triangle_count();
    report.obj_ply_faces = go.polygons ? "polygons" : "triangles";
    report.max_error = err.max;
    report.rms_error = err.rms;
    report.measured_samples = err.samples;
    report.uncovered_samples = err.uncovered;
    report.t_junctions = sub.t_junctions;
    report.gaps = sub.gaps;
    report.cracks = sub.cracks;
    report.max_gap = sub.max_gap;
    report.trials = sub.trials;
    report.verify_splits = sub.verify_splits;
    report.merges = sub.merges;

    stream::make_output_dir(go.output_dir);
    const std::string generator = std::string("lodstream ") + LODSTREAM_VERSION;
    const std::string tol_text = go.tolerance >= 0 ? fmt::format("{}", go.tolerance) : std::string("none");
    const std::vector<std::string> comments{
        generator, fmt::format("grid {} ({} x {}), method {}, tolerance {}, split {}, divide {}, gaps {}, target {}{}",
                               input, g.width, g.height, name(go.method), tol_text, name(go.split), go.divide,
                               name(go.gaps), go.target_polygons, go.merge ? ", merge" : "") +
                       (go.cylindrical ? fmt::format(", cylindrical axis {}, angle step {} degrees, height step {}", name(go.axis),
                                                     cyl.angle_step_degrees, cyl.frame.height_step)
                                       : std::string()),
        go.polygons ? "faces: the polygons (the tolerance holds for grid.glb's triangles, not a viewer's own)"
                    : "faces: the drawn triangles, as in grid.glb"};
    // OBJ and PLY get the GLB's triangles by default: the tolerance holds for them, not for the fans a
    // viewer would make of the n-gons (on the Fuji tile 6.75 m at a tolerance of 1 m, README).
    stream::run_stage(&report.stages, "write", [&](StageStats&) {
      if (go.write_obj) {
        if (go.polygons)
          io::write_polygon_obj(go.output_dir + "/grid.obj", poly, comments);
        else
          io::write_obj(go.output_dir + "/grid.obj", tri, comments);
        report.files.push_back("grid.obj");
      }
      progress.report("write", 0.3);
      if (go.write_ply) {
        if (go.polygons)
          io::write_polygon_ply(go.output_dir + "/grid.ply", poly, comments);
        else
          io::write_ply(go.output_dir + "/grid.ply", tri, comments);
        report.files.push_back("grid.ply");
      }
      progress.report("write", 0.6);
      if (go.write_glb) {
        const io::GlbLevel level{glb_tri, "grid", 0.0};
        io::write_glb(go.output_dir + "/grid.glb", std::span<const io::GlbLevel>(&level, 1), generator);
        report.files.push_back("grid.glb");
      }
      progress.report("write", 1);
    });
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report.peak_rss_bytes = stream::peak_rss_bytes();

    ordered_json j;
    j["generator"] = generator;
    j["input"] = {{"path", input}, {"format", g.format}, {"width", g.width}, {"height", g.height},
                  {"spacing", g.spacing}, {"samples", n}, {"valid_samples", report.valid_samples}};
    j["options"] = {{"method", name(go.method)},
                    {"tolerance", go.tolerance >= 0 ? ordered_json(go.tolerance) : ordered_json(nullptr)},
                    {"split", name(go.split)},
                    {"divide", go.divide},
                    {"gaps", name(go.gaps)},
                    {"target_polygons", go.target_polygons},
                    {"seed", go.seed},
                    {"merge", go.merge},
                    {"polygons", go.polygons},
                    {"z_scale", go.z_scale},
                    {"spacing", go.spacing}};
    j["polygons"] = report.polygons;
    j["rect_polygons"] = sub.polygons.size();
    j["triangles"] = report.triangles;
    j["obj_ply_faces"] = report.obj_ply_faces;
    j["vertices"] = report.vertices;
    j["draw_vertices"] = report.draw_vertices;
    j["bytes"] = report.bytes;
    j["fill_polygons"] = report.fill_polygons;
    j["fill_vertices"] = report.fill_vertices;
    j["max_error"] = report.max_error;
    j["rms_error"] = report.rms_error;
    j["measured_samples"] = report.measured_samples;
    j["uncovered_samples"] = report.uncovered_samples;
    j["hole_cells"] = report.hole_cells;
    j["t_junctions"] = report.t_junctions;
    j["gaps"] = report.gaps;
    j["cracks"] = report.cracks;
    j["max_gap"] = report.max_gap;
    j["trials"] = report.trials;
    j["verify_splits"] = report.verify_splits;
    j["merges"] = report.merges;
    if (go.cylindrical) {
      // max_error and rms_error above are these radius errors (along each sample's ray from the axis,
      // measured on the written float vertices); also under their own names.
      j["max_radius_error"] = report.max_error;
      j["rms_radius_error"] = report.rms_error;
      j["cylinder"] = {{"axis", name(go.axis)},
                       {"columns", cyl.columns},
                       {"rows", cyl.rows},
                       {"angle_step_degrees", cyl.angle_step_degrees},
                       {"height_step", cyl.frame.height_step},
                       {"closed", cyl.frame.wrap},
                       {"trimmed_rows_top", cyl.trimmed_top},
                       {"trimmed_rows_bottom", cyl.trimmed_bottom}};
    }
    j["files"] = report.files;
    ordered_json stages = ordered_json::array();
    for (const StageStats& s : report.stages)
      stages.push_back(stream::stage_json(s));
    j["stages"] = stages;
    j["seconds"] = report.seconds;
    j["peak_rss_bytes"] = report.peak_rss_bytes;
    io::write_file_atomic(go.output_dir + "/summary.json", j.dump(2) + "\n", io::Sync::durable);
    if (out) *out = std::move(report);
  });
}

}  // namespace lodstream

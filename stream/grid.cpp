// `grid`: read a height grid, subdivide it (core/adaptive_subdivision.h), measure the drawn triangles
// against every sample, and write the polygons (OBJ, PLY), the triangles (GLB) and summary.json (last).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/adaptive_subdivision.h"
#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "io/grid_reader.h"
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
    stream::run_stage(&report.stages, "index", [&](StageStats&) {
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
    for (size_t v = 0; v < used.size(); ++v) sample_normal(g, used[v] % g.width, used[v] / g.width, &poly.normals[3 * v]);
    tri.positions = poly.positions;
    tri.normals = poly.normals;

    const core::VerticalError err = stream::run_stage(&report.stages, "measure", [&](StageStats&) {
      progress.report("measure", 0);
      const core::VerticalError e = core::vertical_error(samples, sub.triangles);
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
                               name(go.gaps), go.target_polygons, go.merge ? ", merge" : "")};
    stream::run_stage(&report.stages, "write", [&](StageStats&) {
      if (go.write_obj) {
        io::write_polygon_obj(go.output_dir + "/grid.obj", poly, comments);
        report.files.push_back("grid.obj");
      }
      progress.report("write", 0.3);
      if (go.write_ply) {
        io::write_polygon_ply(go.output_dir + "/grid.ply", poly, comments);
        report.files.push_back("grid.ply");
      }
      progress.report("write", 0.6);
      if (go.write_glb) {
        const io::GlbLevel level{&tri, "grid", 0.0};
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
                    {"z_scale", go.z_scale},
                    {"spacing", go.spacing}};
    j["polygons"] = report.polygons;
    j["rect_polygons"] = sub.polygons.size();
    j["triangles"] = report.triangles;
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
    j["files"] = report.files;
    ordered_json stages = ordered_json::array();
    for (const StageStats& s : report.stages)
      stages.push_back({{"name", s.name}, {"seconds", s.seconds}, {"peak_rss_bytes", s.peak_rss_bytes}});
    j["stages"] = stages;
    j["seconds"] = report.seconds;
    j["peak_rss_bytes"] = report.peak_rss_bytes;
    io::write_file_atomic(go.output_dir + "/summary.json", j.dump(2) + "\n", io::Sync::durable);
    if (out) *out = std::move(report);
  });
}

}  // namespace lodstream

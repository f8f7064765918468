// `simplify`: the LOD pipeline of ../shared/DESIGN.md, stage by stage: ingest -> grade (weld, grade, sort
// into the weight index) -> cluster (every level in one ordered pass) -> emit and write each level ->
// manifest.json. Each stage leaves its result in the work directory with a stamp of what it was made from,
// and a later run with the same inputs and options reuses it.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "core/floating_cell.h"
#include "core/grade.h"
#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"
#include "lodstream/lodstream.h"
#include "stream/cluster_stage.h"
#include "stream/disk_space.h"
#include "stream/emit_stage.h"
#include "stream/grade_stage.h"
#include "stream/ingest.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream {

namespace {

using nlohmann::ordered_json;
using stream::guarded;
using stream::run_stage;

// Part of every stage stamp; bumped when a work file changes format (2: the weight index keeps the store's
// precision; 3: the weight index is the order and, for the mean, the grades; bit-packed cluster maps; cell
// info by representative), so that a work directory from an older build is redone rather than misread.
constexpr int kStampVersion = 3;
constexpr uint64_t kCoarsestTarget = 4000;  // "a few thousand" triangles at the coarsest default level
constexpr unsigned kMaxLevels = 32;
constexpr unsigned kMaxSearchPasses = 12;
constexpr double kTargetTolerance = 0.15;

const char* name(Grading g) { return g == Grading::lowtan ? "lowtan" : "rossignac"; }
const char* name(Clustering c) { return c == Clustering::floating ? "floating" : "uniform"; }
const char* name(CellShape c) { return c == CellShape::cube ? "cube" : "sphere"; }
const char* name(CellVariant v) { return v == CellVariant::nearest ? "nearest" : "heaviest"; }
const char* name(Representative r) {
  return r == Representative::center ? "center" : r == Representative::mean ? "mean" : "quadric";
}

// Exact text for a double (hex float), for stamps.
std::string exact(double v) { return fmt::format("{:a}", v); }

void check_options(const SimplifyOptions& s) {
  auto usage = [](const std::string& m) { fail(Status::usage, m); };
  if (s.output_dir.empty()) usage("an output directory is required (-o DIR)");
  if (!s.cell_sizes.empty() && !s.target_triangles.empty()) usage("give --cell-sizes or --target-triangles, not both");
  for (size_t i = 0; i < s.cell_sizes.size(); ++i) {
    const double c = s.cell_sizes[i];
    if (!(c >= core::kMinCellSize && c <= core::kMaxCellSize)) usage(fmt::format("--cell-sizes: {} is not a usable cell size", c));
    if (i > 0 && !(c > s.cell_sizes[i - 1])) usage("--cell-sizes must be strictly increasing");
  }
  for (size_t i = 0; i < s.target_triangles.size(); ++i) {
    if (s.target_triangles[i] == 0) usage("--target-triangles: targets must be positive");
    if (i > 0 && !(s.target_triangles[i] < s.target_triangles[i - 1]))
      usage("--target-triangles must be strictly decreasing (finest level first)");
  }
  const size_t levels = !s.cell_sizes.empty()         ? s.cell_sizes.size()
                        : !s.target_triangles.empty() ? s.target_triangles.size()
                        : s.levels                    ? s.levels
                                                      : default_levels;
  if (levels < 1 || levels > kMaxLevels) usage(fmt::format("--levels must be between 1 and {}", kMaxLevels));
  if (!(s.fov_degrees > 0 && s.fov_degrees < 180)) usage("--fov must be between 0 and 180 degrees");
  if (s.resolution == 0) usage("--resolution must be positive");
  if (!(s.pixels_per_cell > 0 && std::isfinite(s.pixels_per_cell))) usage("--pixels-per-cell must be positive");
  if (!(s.crease_degrees >= 0 && s.crease_degrees <= 180)) usage("--crease must be between 0 and 180 degrees");
  if (!s.write_ply && !s.write_obj && !s.write_glb) usage("nothing to write: enable at least one of PLY, OBJ, GLB");
}

core::ClusterOptions cluster_options(const SimplifyOptions& s) {
  core::ClusterOptions o;
  o.clustering = s.clustering == Clustering::floating ? core::Clustering::floating : core::Clustering::uniform;
  o.shape = s.cell == CellShape::cube ? core::CellShape::cube : core::CellShape::sphere;
  o.choice = s.variant == CellVariant::nearest ? core::CellChoice::nearest : core::CellChoice::heaviest;
  return o;
}

double diagonal(const stream::Bbox& b) {
  if (b.empty) return 0;
  double d2 = 0;
  for (int k = 0; k < 3; ++k) d2 += (b.max[k] - b.min[k]) * (b.max[k] - b.min[k]);
  return std::sqrt(d2);
}

// Every coordinate must be within the clusterer's range for the finest level (core/floating_cell.h).
void check_cell_sizes(std::span<const double> sizes, const stream::Bbox& box) {
  for (double c : sizes) {
    if (!(c >= core::kMinCellSize && c <= core::kMaxCellSize)) fail(Status::usage, fmt::format("cell size {} is out of range", c));
    for (int k = 0; k < 3; ++k) {
      const double extent = std::max(std::abs(box.min[k]), std::abs(box.max[k]));
      if (!(extent < core::kMaxSquaresPerAxis * (c / 2)))
        fail(Status::usage, fmt::format("cell size {} is too small for coordinates as large as {}", c, extent));
    }
  }
}

// Estimated output triangles at cell size c: a triangle of area a much smaller than a cell is merged with
// others into about kCellsPerArea·a/c² triangles (a surface cut into cells of side c gives about 1.5·A/c²
// cells and twice as many triangles); one larger than that stays about one triangle.
constexpr double kCellsPerArea = 3.0;
double estimated_triangles(const stream::AreaHistogram& h, double c) {
  double t = 0;
  for (int b = 0; b < stream::kAreaBins; ++b)
    if (h.count[b]) t += std::min(static_cast<double>(h.count[b]), kCellsPerArea * h.area[b] / (c * c));
  return t;
}

// Default cell sizes: targets falling geometrically from the input's triangle count to a few thousand, and
// for each the size whose estimated triangle count (above) meets it, by bisection on log c. `targets`
// receives the targets.
std::vector<double> default_cell_sizes(unsigned levels, uint64_t triangles, const stream::AreaHistogram& h, double diag,
                                       std::vector<double>* targets) {
  std::vector<double> sizes;
  const double t0 = static_cast<double>(std::max<uint64_t>(triangles, 1));
  // Small inputs halve at least once per level, so that every target is below the input's count.
  const double coarsest = std::min(static_cast<double>(kCoarsestTarget), t0 / std::pow(2.0, levels));
  const double ratio = std::pow(coarsest / t0, 1.0 / levels);
  double area = 0;
  for (double a : h.area) area += a;
  for (unsigned l = 0; l < levels; ++l) {
    const double target = std::max(1.0, t0 * std::pow(ratio, l + 1));
    targets->push_back(target);
    double c;
    if (area > 0 && target >= t0) {
      // No cell size brings the count below the input's (one triangle): the triangles' own scale.
      c = std::sqrt(area / t0);
    } else if (area > 0) {
      double lo = std::log(std::sqrt(area / t0)) - 40, hi = std::log(std::sqrt(area)) + 10;
      for (int i = 0; i < 100; ++i) {
        const double mid = (lo + hi) / 2;
        (estimated_triangles(h, std::exp(mid)) > target ? lo : hi) = mid;
      }
      c = std::exp(hi);
    } else {
      c = diag > 0 ? diag / std::sqrt(target) : 1.0;
    }
    if (!sizes.empty() && !(c > sizes.back())) c = sizes.back() * 2;
    sizes.push_back(c);
  }
  return sizes;
}

// Default levels (SimplifyOptions::levels), counted before they are made. A level's count is its triangles;
// for an input without triangles, or whose triangles no cell size keeps (each has two corners at one
// position), its edges and points. `count(sizes, triangles_only)` clusters and emits at `sizes` and returns
// their counts, exactly as the emit stage will make them (with `triangles_only`, the triangles only, by the
// cheaper count-only emit), so what is decided here depends on the input and options only.
// 1. The finest level must count something. If at its estimated size it counts nothing, its size is
//    searched below the estimate: quartered until it counts at least its target (the estimate's) or
//    reaches `smallest`, then bisected on log c; of the sizes that count anything, the one whose count is
//    nearest the target in ratio is kept (within kTargetTolerance ends the search).
// 2. Unless exactly as many levels were asked for (`exact`), levels are kept finest first while their counts
//    fall: a level that counts nothing, or no fewer than the last level kept, is left out. So no level is
//    empty or repeats its finer neighbour, and `notice` says when fewer levels are made than asked.
struct DefaultLevels {
  std::vector<double> sizes;
  std::string notice;
};
using CountFn = std::function<std::vector<stream::EmitCounts>(const std::vector<double>&, bool)>;
DefaultLevels settle_default_levels(std::vector<double> sizes, std::span<const double> targets, bool exact,
                                    bool has_triangles, double smallest, const CountFn& count) {
  bool by_triangles = has_triangles;
  std::vector<stream::EmitCounts> counts = count(sizes, by_triangles);
  if (by_triangles && counts[0].triangles == 0) {
    const double target = targets[0];
    double lo = 0, hi = sizes[0], best = 0, best_err = INFINITY;
    for (unsigned pass = 0; pass < kMaxSearchPasses && best_err > std::log1p(kTargetTolerance); ++pass) {
      // invariant: sizes >= hi count fewer than the target; sizes <= lo (when lo > 0) at least the target
      const double c = lo > 0 ? std::sqrt(lo * hi) : std::max(hi / 4, smallest);
      if (!(c < hi && c > lo)) break;
      const uint64_t got = count({c}, true)[0].triangles;
      if (got > 0 && std::abs(std::log(static_cast<double>(got) / target)) < best_err) {
        best_err = std::abs(std::log(static_cast<double>(got) / target));
        best = c;
      }
      (static_cast<double>(got) >= target ? lo : hi) = c;
    }
    if (best > 0) {
      sizes[0] = best;
      counts = count(sizes, true);
    } else {
      by_triangles = false;
      counts = count(sizes, false);
    }
  }
  if (exact) return {sizes, {}};
  auto measure = [&](const stream::EmitCounts& c) { return by_triangles ? c.triangles : c.edges + c.points; };
  DefaultLevels d;
  uint64_t last = UINT64_MAX;
  std::string list;
  for (size_t l = 0; l < sizes.size(); ++l) {
    const uint64_t n = measure(counts[l]);
    list += fmt::format("{}{}", l ? ", " : "", n);
    if (n > 0 && n < last) d.sizes.push_back(sizes[l]), last = n;
  }
  if (d.sizes.empty()) d.sizes.push_back(sizes[0]);  // not reached: every primitive leaves at least a point
  if (d.sizes.size() < sizes.size())
    d.notice = fmt::format("made {} level{}, not the {} asked: a level with no {}, or no fewer than the level before, "
                           "is left out ({} per level at the estimated cell sizes: {})",
                           d.sizes.size(), d.sizes.size() == 1 ? "" : "s", sizes.size(),
                           by_triangles ? "triangles" : "edges or points", by_triangles ? "triangles" : "edges and points", list);
  return d;
}

ordered_json source_json(const stream::StoreMeta& m) {
  return {{"path", m.source.path}, {"bytes", m.source.bytes}, {"mtime_ns", m.source.mtime_ns}, {"format", m.format}};
}

// A stage's stamp: reused when it exists, holds `key`, and every listed file exists.
bool stamp_matches(const std::string& path, const ordered_json& key, ordered_json* value) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return false;
  try {
    ordered_json j = ordered_json::parse(io::read_small_file(path));
    if (j.at("key") != key) return false;
    for (const auto& f : j.at("files"))
      if (!std::filesystem::exists(f.get<std::string>(), ec)) return false;
    *value = j.at("value");
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

void write_stamp(const std::string& path, const ordered_json& key, const std::vector<std::string>& files,
                 const ordered_json& value) {
  stream::kill_point(std::filesystem::path(path).filename().string());
  io::write_file_atomic(path, ordered_json{{"key", key}, {"files", files}, {"value", value}}.dump(1) + "\n");
}

}  // namespace

Result simplify(const std::string& input, const SimplifyOptions& so, const Options& options, SimplifyReport* out) {
  return guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    check_options(so);
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    stream::WorkDir work(options.work_dir);
    if (options.check_disk_space) stream::check_simplify_space(input, so, work.path());
    const std::string store_dir = work.subdir("store");
    const core::ClusterOptions copts = cluster_options(so);
    SimplifyReport report;
    report.input = input;

    tbb::task_arena arena(static_cast<int>(plan.threads));
    arena.execute([&] {
      bool reused = false;
      const stream::StoreMeta meta =
          stream::run_ingest_stage(input, store_dir, plan, work, progress, &report.stages, &report.scene, &reused);
      if (meta.primitives() == 0)
        fail(Status::bad_data, input + ": nothing to simplify (no triangles, lines or points)");

      // Grade and sort.
      const std::string canonical_path = work.file("weld.map");
      const std::string prefix = work.file("");
      // The grades are kept on disk only for the mean representative, the one stage that sums them.
      const bool keep_grades = so.representative == Representative::mean;
      const std::string order_path = stream::order_path(prefix);
      const std::string grades_path = keep_grades ? stream::grades_path(prefix) : std::string();
      const ordered_json grade_key{{"version", kStampVersion},
                                   {"source", source_json(meta)},
                                   {"grading", name(so.grading)},
                                   {"grades", keep_grades}};
      const stream::GradeSummary grade = run_stage(&report.stages, "grade", [&](StageStats& st) {
        ordered_json v;
        if (stamp_matches(work.file("grade.json"), grade_key, &v)) {
          st.reused = true;
          stream::GradeSummary g;
          g.records = v.at("records");
          g.distinct_positions = v.at("distinct_positions");
          g.surface_area = v.at("surface_area");
          g.ranges = v.at("ranges");
          g.areas.count = v.at("area_counts").get<std::vector<uint64_t>>();
          g.areas.area = v.at("area_sums").get<std::vector<double>>();
          return g;
        }
        std::filesystem::remove(work.file("grade.json"));
        std::filesystem::remove(canonical_path);
        std::filesystem::remove(stream::grades_path(prefix));
        for (const char* old : {"weights.idx", "weld.u32"}) std::filesystem::remove(work.file(old));  // an older version's
        const stream::GradeSummary g = stream::grade_and_sort(
            store_dir, meta, so.grading == Grading::lowtan ? core::Grading::lowtan : core::Grading::rossignac, plan,
            work, progress, canonical_path, order_path, grades_path, so.grade_range_vertices);
        std::vector<std::string> files{order_path};
        if (keep_grades) files.push_back(grades_path);
        if (g.distinct_positions < meta.vertices) files.push_back(canonical_path);
        write_stamp(work.file("grade.json"), grade_key, files,
                    {{"records", g.records}, {"distinct_positions", g.distinct_positions},
                     {"surface_area", g.surface_area}, {"ranges", g.ranges},
                     {"area_counts", g.areas.count}, {"area_sums", g.areas.area}});
        return g;
      });
      report.vertices_graded = grade.records;
      report.distinct_positions = grade.distinct_positions;
      report.surface_area = grade.surface_area;
      report.grade_ranges = grade.ranges;
      const std::string canonical = grade.distinct_positions < meta.vertices ? canonical_path : std::string();

      const stream::EmitOptions count_only{so.representative, so.crease_degrees, true, true};
      stream::EmitScratch scratch;
      const stream::CellInfoKind info_kind = stream::cell_info_kind(so.representative);
      const ordered_json cluster_base{{"grade", grade_key},
                                      {"clustering", name(so.clustering)},
                                      {"cell", name(so.cell)},
                                      {"variant", name(so.variant)},
                                      {"cell_info", name(so.representative)}};
      // Clusters at `sizes` unless the stamp says it is done; returns cells per level.
      auto cluster = [&](const std::vector<double>& sizes, StageStats* st) {
        ordered_json key = cluster_base;
        std::vector<std::string> hex;
        for (double c : sizes) hex.push_back(exact(c));
        key["cell_sizes"] = hex;
        ordered_json v;
        if (stamp_matches(work.file("cluster.json"), key, &v)) {
          if (st) st->reused = true;
          return v.at("cells").get<std::vector<uint64_t>>();
        }
        std::filesystem::remove(work.file("cluster.json"));
        check_cell_sizes(sizes, meta.bbox);
        std::vector<double> bounds;
        if (!meta.bbox.empty) {
          bounds.assign(meta.bbox.min.begin(), meta.bbox.min.end());
          bounds.insert(bounds.end(), meta.bbox.max.begin(), meta.bbox.max.end());
        }
        stream::check_cluster_estimate(grade.areas, grade.records, meta.vertices, meta.single_precision, bounds, sizes,
                                       plan.stage_bytes);
        const stream::WeightIndex index{order_path,
                                        grades_path,
                                        store_dir + (meta.single_precision ? "/positions.f32" : "/positions.f64"),
                                        grade.records,
                                        meta.vertices,
                                        meta.single_precision};
        const stream::ClusterSummary cs =
            stream::cluster_levels(index, bounds, sizes, copts, info_kind, plan.stage_bytes, work, progress, prefix);
        std::vector<std::string> files;
        for (size_t l = 0; l < sizes.size(); ++l) {
          files.push_back(stream::cells_path(prefix, l));
          files.push_back(stream::cell_info_path(prefix, l));
        }
        write_stamp(work.file("cluster.json"), key, files, {{"cells", cs.cells}});
        return cs.cells;
      };

      // Emits every level at `sizes` with `cells` cells, handing each finished mesh to `sink` (level index,
      // mesh), in groups that share a pass over the input as far as the memory plan allows
      // (stream::emit_group_end); the grouping changes no byte. Each mesh is written as soon as it is
      // finished, so no finished mesh is held while the next levels are emitted.
      auto emit_all = [&](const std::vector<double>& sizes, const std::vector<uint64_t>& cells,
                          const stream::EmitOptions& eo, const std::function<void(size_t, core::LodMesh&)>& sink) {
        // Every level is checked before the first is written, so that a level that cannot fit stops the run
        // before any output file appears.
        for (size_t l = 0; l < sizes.size(); ++l)
          stream::check_emit_budget(cells, l, meta.vertices, meta.primitives(), plan.stage_bytes, 0, eo);
        std::vector<stream::EmitCounts> counts;
        for (size_t first = 0; first < sizes.size();) {
          const size_t end = stream::emit_group_end(cells, first, meta.vertices, meta.primitives(), plan.stage_bytes, 0, eo);
          std::vector<stream::EmitLevel> group;
          for (size_t l = first; l < end; ++l) group.push_back({l, cells[l], sizes[l]});
          const std::vector<stream::EmitCounts> c =
              stream::emit_levels(store_dir, meta, canonical, prefix, group, grade.records, copts, eo, progress, scratch,
                                  [&](size_t i, core::LodMesh& mesh) { sink(first + i, mesh); });
          counts.insert(counts.end(), c.begin(), c.end());
          first = end;
        }
        return counts;
      };

      // Cell sizes: given, searched for, or the default estimate (settled on small inputs).
      std::vector<double> sizes = so.cell_sizes;
      std::vector<double> estimated_targets;
      if (sizes.empty()) {
        const unsigned levels = !so.target_triangles.empty() ? static_cast<unsigned>(so.target_triangles.size())
                                : so.levels                   ? so.levels
                                                              : default_levels;
        // An input without triangles aims its levels at its segments and points.
        sizes = default_cell_sizes(levels, meta.triangles ? meta.triangles : meta.primitives(), grade.areas, diagonal(meta.bbox),
                                   &estimated_targets);
      }
      report.levels_asked = static_cast<unsigned>(sizes.size());
      // Checked where the estimate aims below kCoarsestTarget, where a few cells more or less decide a count.
      if (so.cell_sizes.empty() && so.target_triangles.empty() &&
          static_cast<double>(meta.triangles) < std::ldexp(static_cast<double>(kCoarsestTarget), static_cast<int>(sizes.size()))) {
        run_stage(&report.stages, "levels", [&](StageStats&) {
          const stream::EmitOptions counting{so.representative, so.crease_degrees, false, false};
          double extent = 0;
          for (int k = 0; k < 3; ++k) extent = std::max({extent, std::abs(meta.bbox.min[k]), std::abs(meta.bbox.max[k])});
          const DefaultLevels d = settle_default_levels(
              sizes, estimated_targets, so.levels != 0, meta.triangles > 0,
              std::max(core::kMinCellSize, 4 * extent / core::kMaxSquaresPerAxis),
              [&](const std::vector<double>& s, bool triangles_only) {
                return emit_all(s, cluster(s, nullptr), triangles_only ? count_only : counting, [](size_t, core::LodMesh&) {});
              });
          sizes = d.sizes;
          report.notice = d.notice;
        });
      }
      if (!so.target_triangles.empty()) {
        run_stage(&report.stages, "search", [&](StageStats&) {
          const auto ts = std::chrono::steady_clock::now();
          const size_t n = sizes.size();
          std::vector<double> lo(n, 0), hi(n, 0), best(sizes);
          std::vector<double> best_err(n, INFINITY);
          for (unsigned pass = 0; pass < kMaxSearchPasses; ++pass) {
            const std::vector<uint64_t> cells = cluster(sizes, nullptr);
            ++report.search_iterations;
            bool all_ok = true;
            std::vector<double> next(sizes);
            const std::vector<stream::EmitCounts> counts = emit_all(sizes, cells, count_only, [](size_t, core::LodMesh&) {});
            for (size_t l = 0; l < n; ++l) {
              const stream::EmitCounts& c = counts[l];
              const double t = static_cast<double>(so.target_triangles[l]);
              const double got = std::max(static_cast<double>(c.triangles), 0.5);
              const double err = std::abs(std::log(got / t));
              if (err < best_err[l]) best_err[l] = err, best[l] = sizes[l];
              if (std::abs(got - t) <= kTargetTolerance * t) continue;
              all_ok = false;
              if (got > t) lo[l] = std::max(lo[l], sizes[l]);  // cells too small
              else hi[l] = hi[l] > 0 ? std::min(hi[l], sizes[l]) : sizes[l];
              // Triangle counts fall about as c^-2; bisect (geometrically) when that step leaves the bracket.
              double step = sizes[l] * std::sqrt(got / t);
              if ((lo[l] > 0 && !(step > lo[l])) || (hi[l] > 0 && !(step < hi[l])))
                step = lo[l] > 0 && hi[l] > 0 ? std::sqrt(lo[l] * hi[l]) : (lo[l] > 0 ? lo[l] * 2 : hi[l] / 2);
              next[l] = step;
            }
            if (all_ok) break;
            for (size_t l = 1; l < n; ++l)
              if (!(next[l] > next[l - 1])) next[l] = next[l - 1] * (1 + 1e-6);
            if (next == sizes) break;
            sizes = next;
          }
          sizes = best;
          for (size_t l = 1; l < n; ++l)
            if (!(sizes[l] > sizes[l - 1])) sizes[l] = sizes[l - 1] * (1 + 1e-9);
          report.search_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
        });
      }

      const std::vector<uint64_t> cells = run_stage(&report.stages, "cluster", [&](StageStats& st) { return cluster(sizes, &st); });

      // Emit and write. Each level's PLY and OBJ files and its part of the GLB are written as soon as the
      // emit stage finishes the level (the three side by side); the write stage then assembles the GLB
      // (io::GlbBuilder), so that no two levels' meshes are ever held together.
      stream::make_output_dir(so.output_dir);
      stream::remove_summary(so.output_dir + "/manifest.json");
      const double tan_half = std::tan(so.fov_degrees * M_PI / 360);
      const double diag = diagonal(meta.bbox);
      for (size_t l = 0; l < sizes.size(); ++l) {
        LevelStats ls;
        ls.cell_size = sizes[l];
        ls.cells = cells[l];
        ls.target_triangles = so.target_triangles.empty() ? 0 : so.target_triangles[l];
        ls.switch_distance = sizes[l] * so.resolution / (2 * so.pixels_per_cell * tan_half);
        ls.screen_coverage = diag > 0 ? diag / (2 * ls.switch_distance * tan_half) : 0;
        report.levels.push_back(ls);
      }
      const std::string generator = std::string("lodstream ") + LODSTREAM_VERSION;
      std::unique_ptr<io::GlbBuilder> glb;
      // The GLB's binary data is gathered beside it in the output directory (a .partial name, which a rerun
      // writes again), not in the work directory: it is output, as large as the GLB, and counts against the
      // outputs' room (stream/disk_space.cpp).
      if (so.write_glb)
        glb = std::make_unique<io::GlbBuilder>(so.output_dir + "/lods.glb", so.output_dir + "/lods.glb.bin.partial", generator);
      auto write_level = [&](size_t l, core::LodMesh& mesh) {
        LevelStats& ls = report.levels[l];
        ls.vertices = mesh.vertex_count();
        const std::vector<std::string> comments{
            generator, fmt::format("level {} of {}, cell size {}", l, sizes.size(), sizes[l]),
            fmt::format("clustering {} {} {}, representative {}, grading {}", name(so.clustering), name(so.cell),
                        name(so.variant), name(so.representative), name(so.grading))};
        const std::string stem = fmt::format("lod{}", l);
        tbb::task_group files;
        if (so.write_ply) files.run([&] { io::write_ply(so.output_dir + "/" + stem + ".ply", mesh, comments); });
        if (so.write_obj) files.run([&] { io::write_obj(so.output_dir + "/" + stem + ".obj", mesh, comments); });
        // MSFT_screencoverage: level l is shown while the coverage is at least the coverage at which the next
        // level takes over; the last level down to one pixel.
        if (glb) {
          const double lower = l + 1 < sizes.size() ? report.levels[l + 1].screen_coverage : 1.0 / so.resolution;
          files.run([&] { glb->add({&mesh, stem, lower}); });
        }
        files.wait();
        if (so.write_ply) ls.files.push_back(stem + ".ply");
        if (so.write_obj) ls.files.push_back(stem + ".obj");
        if (so.write_obj && !meta.materials.empty()) ls.files.push_back(stem + ".mtl");
      };
      stream::EmitOptions emit_options{so.representative, so.crease_degrees, true, false};
      emit_options.grades_path = grades_path;
      emit_options.colors = meta.colors;
      run_stage(&report.stages, "emit", [&](StageStats&) {
        const std::vector<stream::EmitCounts> counts = emit_all(sizes, cells, emit_options, write_level);
        for (size_t l = 0; l < sizes.size(); ++l) {
          LevelStats& ls = report.levels[l];
          const stream::EmitCounts& c = counts[l];
          ls.triangles = c.triangles;
          ls.edges = c.edges;
          ls.points = c.points;
          ls.edges_on_triangles = c.edges_on_triangles;
          ls.points_covered = c.points_covered;
        }
        scratch = stream::EmitScratch();
      });
      run_stage(&report.stages, "write", [&](StageStats&) {
        if (glb) glb->finish();
        glb.reset();
        progress.report("write", 1);
      });
    });
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report.peak_rss_bytes = stream::peak_rss_bytes();
    report.work_dir = stream::work_dir_usage(work.path(), report.scene.file_bytes);

    // manifest.json, last: its presence means the output directory is complete.
    ordered_json m;
    m["generator"] = std::string("lodstream ") + LODSTREAM_VERSION;
    m["input"] = {{"path", input},
                  {"absolute_path", std::filesystem::absolute(input).lexically_normal().string()},
                  {"format", report.scene.format},
                  {"bytes", report.scene.file_bytes},
                  {"vertices", report.scene.vertices},
                  {"triangles", report.scene.triangles},
                  {"lines", report.scene.lines},
                  {"points", report.scene.points},
                  {"bbox", {{"min", report.scene.bbox_min}, {"max", report.scene.bbox_max}}},
                  {"distinct_positions", report.distinct_positions},
                  {"vertices_graded", report.vertices_graded},
                  {"surface_area", report.surface_area}};
    m["options"] = {{"grading", name(so.grading)},
                    {"clustering", name(so.clustering)},
                    {"cell", name(so.cell)},
                    {"variant", name(so.variant)},
                    {"representative", name(so.representative)},
                    {"crease_degrees", so.crease_degrees},
                    {"fov_degrees", so.fov_degrees},
                    {"resolution", so.resolution},
                    {"pixels_per_cell", so.pixels_per_cell}};
    ordered_json levels = ordered_json::array();
    for (size_t l = 0; l < report.levels.size(); ++l) {
      const LevelStats& ls = report.levels[l];
      ordered_json j{{"level", l},
                     {"cell_size", ls.cell_size},
                     {"cells", ls.cells},
                     {"vertices", ls.vertices},
                     {"triangles", ls.triangles},
                     {"edges", ls.edges},
                     {"points", ls.points},
                     {"eliminated", {{"edges_on_triangles", ls.edges_on_triangles}, {"points_covered", ls.points_covered}}},
                     {"switch_distance", ls.switch_distance},
                     {"screen_coverage", ls.screen_coverage},
                     {"files", ls.files}};
      if (ls.target_triangles) j["target_triangles"] = ls.target_triangles;
      levels.push_back(j);
    }
    m["levels"] = levels;
    m["levels_asked"] = report.levels_asked;
    m["levels_made"] = report.levels.size();
    if (!report.notice.empty()) m["notice"] = report.notice;
    if (so.write_glb) m["glb"] = "lods.glb";
    if (!so.target_triangles.empty())
      m["search"] = {{"passes", report.search_iterations}, {"seconds", report.search_seconds}};
    ordered_json stages = ordered_json::array();
    for (const StageStats& s : report.stages)
      stages.push_back({{"name", s.name}, {"seconds", s.seconds}, {"peak_rss_bytes", s.peak_rss_bytes}, {"reused", s.reused}});
    m["stages"] = stages;
    m["seconds"] = report.seconds;
    m["peak_rss_bytes"] = report.peak_rss_bytes;
    m["work_dir"] = stream::work_dir_json(report.work_dir);
    stream::kill_point("manifest.json");
    io::write_file_atomic(so.output_dir + "/manifest.json", m.dump(2) + "\n", io::Sync::durable);
    *out = std::move(report);
  });
}

}  // namespace lodstream

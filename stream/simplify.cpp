// `simplify`: the LOD pipeline of ../shared/DESIGN.md, stage by stage: ingest -> grade (weld, grade, sort
// into the weight index) -> cluster (every level in one ordered pass) -> emit and write each level ->
// manifest.json. Each stage leaves its result in the work directory with a stamp of what it was made from,
// and a later run with the same inputs and options reuses it.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include "core/floating_cell.h"
#include "core/grade.h"
#include "core/mesh.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "io/obj_writer.h"
#include "io/ply_writer.h"
#include "lodstream/lodstream.h"
#include "stream/cluster_shares.h"
#include "stream/cluster_stage.h"
#include "stream/disk_space.h"
#include "stream/emit_regions.h"
#include "stream/emit_stage.h"
#include "stream/grade_shares.h"
#include "stream/grade_stage.h"
#include "stream/ingest.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/labels_stage.h"
#include "stream/level_files.h"
#include "stream/memory.h"
#include "stream/position_gather.h"
#include "stream/progress.h"
#include "stream/ingest_range.h"
#include "stream/block_bounds.h"
#include "stream/cluster_merge.h"
#include "stream/shard.h"
#include "stream/vertex_cells.h"
#include "stream/wide_units.h"
#include "stream/tiles.h"
#include "stream/units.h"
#include "stream/work_dir.h"

namespace lodstream {

namespace {

using nlohmann::ordered_json;
using stream::guarded;
using stream::run_stage;
using stream::source_json;
using stream::stamp_matches;
using stream::stamped_share;
using stream::take_units;
using stream::write_stamp;

// Part of every stage stamp; bumped when a work file changes format (2: the weight index keeps the store's
// precision; 3: the weight index is the order and, for the mean, the grades; bit-packed cluster maps; cell
// info by representative; 4: the grade stage's area histogram summed block by block, as its units sum it;
// 5: the grade stamp says whether the records' positions in weight order were written, as the grading
// shares' merge writes them: stream/position_gather.h), so that a work directory from an older build is
// redone rather than misread.
constexpr int kStampVersion = 5;
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

// Silhouette labels and the error bound (README "Silhouette labels").
void check_silhouette_options(const SimplifyOptions& s) {
  auto usage = [](const std::string& m) { fail(Status::usage, m); };
  if (!(s.silhouette_interval >= 0 && std::isfinite(s.silhouette_interval)))
    usage("--silhouette-interval must be 0 (off) or a positive number of pixels");
  if (!(s.silhouette_factor > 0 && s.silhouette_factor < 1)) usage("--silhouette-factor must be between 0 and 1");
  if (s.silhouette_views == 0) usage("--silhouette-views must be at least 1");
  if (s.silhouette_resolution < 8 || s.silhouette_resolution > 8192) usage("--silhouette-resolution must be between 8 and 8192");
  if (!(s.max_error_px >= 0 && std::isfinite(s.max_error_px))) usage("--max-error-px must be 0 (off) or a positive number of pixels");
  if (s.max_error_px > 0 && !s.target_triangles.empty()) usage("give --max-error-px or --target-triangles, not both");
  if (s.max_error_px > 0 && s.max_error_views == 0) usage("--max-error-views must be at least 1");
  if (s.max_error_px > 0 && s.resolution > 8192) usage("--max-error-px measures at --resolution, which must then be at most 8192");
}

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
  if (s.tile_triangles < 2) usage("--tile-triangles must be at least 2");
  if (!(s.crease_degrees >= 0 && s.crease_degrees <= 180)) usage("--crease must be between 0 and 180 degrees");
  if (!s.write_ply && !s.write_obj && !s.write_glb && !s.write_tiles)
    usage("nothing to write: enable at least one of PLY, OBJ, GLB, 3D Tiles");
  if (s.tiles_transform.size() != 0 && s.tiles_transform.size() != 3 && s.tiles_transform.size() != 16)
    usage("--tiles-transform takes 16 numbers (a column-major 4x4 matrix) or 3 (longitude, latitude, height)");
  for (double v : s.tiles_transform)
    if (!std::isfinite(v)) usage("--tiles-transform: numbers must be finite");
  check_silhouette_options(s);
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

// The 3D Tiles builder (stream/tiles.h) of `--tiles`: fed region by region by the emit stage's region
// sink, in the scene cube the regions are cut in (stream/emit_regions.h).
stream::TilesOptions tiles_options(const SimplifyOptions& so, const stream::StoreMeta& meta, size_t levels,
                                  const std::string& generator) {
  stream::TilesOptions to;
  to.dir = so.output_dir + "/tiles";
  to.levels = static_cast<unsigned>(levels);
  to.thick = so.tile_lines == SimplifyOptions::TileLines::triangles;
  to.pixels_per_cell = so.pixels_per_cell;
  to.encoding = so.tile_encoding == SimplifyOptions::TileEncoding::plain       ? io::TileEncoding::plain
                : so.tile_encoding == SimplifyOptions::TileEncoding::quantized ? io::TileEncoding::quantized
                                                                               : io::TileEncoding::meshopt;
#ifndef LODSTREAM_HAVE_MESHOPT
  if (to.encoding == io::TileEncoding::meshopt) to.encoding = io::TileEncoding::quantized;
#endif
  if (!meta.bbox.empty)
    for (int k = 0; k < 3; ++k)
      to.scene_magnitude = std::max({to.scene_magnitude, std::abs(meta.bbox.min[k]), std::abs(meta.bbox.max[k])});
  const core::SceneCube cube = stream::scene_cube_of(meta);
  std::copy(cube.min, cube.min + 3, to.cube_min);
  to.cube_side = cube.side;
  to.transform = so.tiles_transform.size() == 3
                     ? stream::enu_transform(so.tiles_transform[0], so.tiles_transform[1], so.tiles_transform[2])
                     : so.tiles_transform;
  if (so.tiles_z_up) to.transform = stream::z_up_transform(to.transform);
  to.generator = generator;
  return to;
}
std::unique_ptr<stream::TilesetBuilder> make_tiles_builder(const SimplifyOptions& so, const stream::StoreMeta& meta,
                                                           size_t levels, const std::string& generator) {
  return std::make_unique<stream::TilesetBuilder>(tiles_options(so, meta, levels, generator));
}

// The comments of level l's files.
std::vector<std::string> level_comments(const SimplifyOptions& so, const std::string& generator, size_t l, size_t levels,
                                        double cell_size) {
  return {generator, fmt::format("level {} of {}, cell size {}", l, levels, cell_size),
          fmt::format("clustering {} {} {}, representative {}, grading {}", name(so.clustering), name(so.cell),
                      name(so.variant), name(so.representative), name(so.grading))};
}

// A shared stage of a sharded run whose work is units that every process takes part in: reused when its
// stamp matches `key`; else the work directory's lock (`lock`, held) is let go while run() takes part in
// the units, and back under the lock the first process stamps the stage with run()'s value (the units'
// figures). Returns whether it was reused.
template <class Run>
bool stage_in_units(const std::string& stamp, const ordered_json& key, const std::vector<std::string>& files,
                    std::unique_ptr<stream::ShardLock>& lock, const std::string& work_dir, Run&& run) {
  ordered_json v;
  if (stamp_matches(stamp, key, &v)) return true;
  lock.reset();
  const ordered_json value = run();
  lock = std::make_unique<stream::ShardLock>(work_dir);
  if (!stamp_matches(stamp, key, &v)) write_stamp(stamp, key, files, {{"units", value}});
  return false;
}

// Silhouette p95 (pixels) of each level file seen from its switching distance, by `report`'s own rule on
// `views` views: the one place simplify measures a level, so that it always agrees with report.
std::vector<double> measure_silhouette_p95(const std::string& original, const std::vector<std::string>& files,
                                           const std::vector<double>& distances, const SimplifyOptions& so,
                                           const Options& options, const std::string& work_dir, const std::string& out_dir) {
  ReportOptions ro;
  ro.output_dir = out_dir;
  ro.original = original;
  ro.lods = files;
  ro.switch_distances = distances;
  ro.views = so.max_error_views;
  ro.resolution = so.resolution;
  ro.fov_degrees = so.fov_degrees;
  ro.samples = 4096;  // Hausdorff samples, not used here
  ro.html_views = 0;
  Options o = options;
  o.work_dir = work_dir;
  o.check_disk_space = false;
  o.progress = nullptr;
  Report rep;
  const Result r = report(ro, o, &rep);
  if (!r.ok()) fail(r.status, "--max-error-px: measuring the levels: " + r.message);
  std::vector<double> p95;
  for (const ReportLevel& l : rep.runs.at(0).levels) p95.push_back(l.silhouette.p95);
  return p95;
}

// --max-error-px: each level keeps the switching distance of its first cell size, and a level's mesh
// depends on its own cell size and factor only, so each level is searched on its own, all levels in the
// same passes (one clustering, emit and measurement each). A level above the bound first halves its fine
// factor (with labels, down to 1/8), then its cell size is searched in a bracket: `lo` the largest size
// measured within the bound, `hi` the smallest above it; a failing size steps down in proportion to
// E / p95 (p95 in pixels grows about as the cell size at a fixed distance; by 10 % to 4× a pass) or
// bisects the bracket on log c, and a size within the bound bisects towards `hi` while hi/lo > 1.25 (the
// first size is never exceeded). The silhouette p95 is a square root of an integer (1, 1.41, 2, ...) and
// not monotone in c, hence the bracket. Sizes stay strictly increasing (a finer level is lowered below
// the next); the sizes kept are each level's `lo` (its first size when none met the bound), measured
// once more when they differ from the last pass, so that the figures are those of the sizes used.
// Emits the levels at the given cell sizes, writing level l as a PLY at the l-th path.
using EmitFn = std::function<void(const std::vector<double>&, const std::vector<std::string>&)>;
ordered_json bound_silhouette_error(const std::string& input, const SimplifyOptions& so, const Options& options,
                                    const stream::WorkDir& work, std::vector<double>& sizes, std::vector<double>& factors,
                                    std::vector<double>& distances, SimplifyReport& report, const EmitFn& emit) {
  const size_t n = sizes.size();
  const double tan_half = std::tan(so.fov_degrees * M_PI / 360);
  distances.clear();
  for (double c : sizes) distances.push_back(c * so.resolution / (2 * so.pixels_per_cell * tan_half));
  factors.assign(n, so.silhouette_factor);
  const bool labels = so.silhouette_interval > 0;
  const std::string dir = work.subdir("max-error");
  ordered_json passes = ordered_json::array();
  auto measure = [&] {
    for (size_t l = n - 1; l > 0; --l)
      if (!(sizes[l - 1] < sizes[l])) sizes[l - 1] = sizes[l] * (1 - 1e-6);
    std::vector<std::string> files(n);
    for (size_t l = 0; l < n; ++l) files[l] = fmt::format("{}/lod{}.ply", dir, l);
    emit(sizes, files);
    std::vector<double> p95 = measure_silhouette_p95(input, files, distances, so, options, work.subdir("max-error-work"), dir + "/report");
    ++report.error_passes;
    passes.push_back({{"cell_sizes", sizes}, {"factors", labels ? ordered_json(factors) : ordered_json()}, {"p95_px", p95}});
    return p95;
  };
  const std::vector<double> first(sizes);
  std::vector<double> lo(n, 0), hi(n, 0), lo_factor(factors);
  std::vector<double> p95;
  for (unsigned pass = 0; pass < kMaxSearchPasses; ++pass) {
    p95 = measure();
    bool done = true;
    std::vector<double> next(sizes);
    for (size_t l = 0; l < n; ++l) {
      if (p95[l] <= so.max_error_px) {
        if (sizes[l] > lo[l]) lo[l] = sizes[l], lo_factor[l] = factors[l];
        if (hi[l] > 0 && hi[l] / lo[l] > 1.25) next[l] = std::sqrt(lo[l] * hi[l]), done = false;
        continue;
      }
      done = false;
      if (labels && factors[l] > 0.125 && lo[l] == 0 && hi[l] == 0) {
        factors[l] /= 2;
        continue;
      }
      hi[l] = hi[l] > 0 ? std::min(hi[l], sizes[l]) : sizes[l];
      next[l] = lo[l] > 0 ? std::sqrt(lo[l] * hi[l]) : sizes[l] * std::clamp(so.max_error_px / p95[l], 0.25, 0.9);
    }
    if (done) break;
    sizes = next;
  }
  std::vector<double> kept(n);
  for (size_t l = 0; l < n; ++l) {
    kept[l] = lo[l] > 0 ? lo[l] : first[l];
    if (lo[l] > 0) factors[l] = lo_factor[l];
  }
  if (kept != passes.back()["cell_sizes"].get<std::vector<double>>() ||
      (labels && factors != passes.back()["factors"].get<std::vector<double>>())) {
    sizes = kept;
    p95 = measure();
  }
  bool met = true;
  for (double v : p95) met = met && v <= so.max_error_px;
  ordered_json out{{"target_px", so.max_error_px}, {"views", so.max_error_views}, {"met", met},
                   {"passes", passes}, {"p95_px", p95}};
  if (!met) report.notice += (report.notice.empty() ? "" : "; ") +
                             fmt::format("--max-error-px {}: not met (p95 per level after {} passes: {})", so.max_error_px,
                                         passes.size(), fmt::join(p95, ", "));
  return out;
}

// The silhouette labels stage (stream/labels_stage.h), when labels are on: reused when its stamp matches.
// Returns its stamp key (null when labels are off), part of the cluster stage's key.
ordered_json run_labels_stage(const SimplifyOptions& so, const std::string& store_dir, const stream::StoreMeta& meta,
                              uint64_t records, const std::string& order_path, const std::string& ordered_positions_path,
                              const std::string& labels_path, const ordered_json& grade_key, const stream::MemoryPlan& plan,
                              uint64_t chunk_cap, stream::Progress& progress, const stream::WorkDir& work,
                              SimplifyReport* report) {
  if (so.silhouette_interval <= 0) return nullptr;
  const ordered_json key{{"grade", grade_key},
                         {"views", so.silhouette_views},
                         {"resolution", so.silhouette_resolution},
                         {"fov", exact(so.fov_degrees)}};
  run_stage(&report->stages, "labels", [&](StageStats& st) {
    ordered_json v;
    if (stamp_matches(work.file("labels.json"), key, &v)) {
      st.reused = true;
      report->labelled_vertices = v.at("labelled");
      return;
    }
    std::filesystem::remove(work.file("labels.json"));
    const stream::LabelSummary sum = stream::compute_labels(
        store_dir, meta, order_path, records,
        {so.silhouette_views, so.silhouette_resolution, so.fov_degrees}, plan.stage_bytes, chunk_cap, progress, labels_path,
        ordered_positions_path);
    report->labelled_vertices = sum.labelled;
    report->label_chunks = sum.chunks;
    report->label_view_groups = sum.view_groups;
    write_stamp(work.file("labels.json"), key, {labels_path}, {{"labelled", sum.labelled}});
  });
  return key;
}

// Stages 2 and 3, grade and sort (stream/grade_stage.h), unless the stamp says they are done. In a sharded
// run they may run as N shares (stream/grade_shares.h): a grading share task (--shard-grade I/N) takes
// part in the weld's units and the weld map's (the lock released), makes the shares' plan (under the work
// directory's lock, which `lock` holds), releases the lock and runs its share; any later process of the
// run finds the plan, runs the shares no task ran (each under its own lock) and takes part in their
// merge's units (the lock released again); the first back under the lock stamps the stage. Returns false
// for a share task, whose run ends after its share.
struct GradeStageInput {
  const SimplifyOptions& so;
  const stream::StoreMeta& meta;
  const stream::MemoryPlan& plan;
  const stream::WorkDir& work;
  std::string store_dir, prefix, canonical_path, order_path, grades_path, positions_path;
  ordered_json key;
  bool sharded;
};


// The weld's units, as one grading share takes part (take_units). Returns every unit's run and its pairs.
std::vector<std::pair<std::string, uint64_t>> run_weld_units(const stream::GradeShareInput& gs, unsigned count, unsigned index,
                                                             const ordered_json& key, stream::Progress& progress) {
  const unsigned units = std::min(count, stream::kMaxWeldUnits);
  ordered_json unit_key = key;
  unit_key["weld_units"] = units;
  const std::vector<ordered_json> values = take_units(
      stream::weld_units_dir(gs.prefix), units, index, [&](unsigned u) { return stream::weld_unit_stamp(gs.prefix, u); },
      unit_key, [&](unsigned u) {
        const stream::WeldUnitResult r = stream::run_weld_unit(gs, u, units, progress);
        return std::pair(std::vector<std::string>{stream::weld_unit_run(gs.prefix, u)},
                         ordered_json{{"distinct", r.distinct}, {"welded", r.welded}});
      });
  std::vector<std::pair<std::string, uint64_t>> runs;
  for (unsigned u = 0; u < units; ++u) runs.emplace_back(stream::weld_unit_run(gs.prefix, u), values[u].at("welded").get<uint64_t>());
  return runs;
}

// The weld map's units, as one grading share takes part (take_units) once every weld unit has run (the
// map started once); returns the map's path, or nothing when no vertex is welded.
std::string run_weld_map_units(const stream::GradeShareInput& gs, unsigned count, unsigned index, const ordered_json& key,
                               const std::vector<std::pair<std::string, uint64_t>>& weld_runs) {
  uint64_t welded = 0;
  for (const auto& run : weld_runs) welded += run.second;
  if (welded == 0) return {};
  const unsigned units = std::min(count, stream::kMaxWeldUnits);
  ordered_json unit_key = key;
  unit_key["weld_map_units"] = units;
  unit_key["welded"] = welded;
  const std::string path = stream::start_weld_map_once(gs, welded, unit_key);
  take_units(
      stream::weld_map_units_dir(gs.prefix), units, index, [&](unsigned u) { return stream::weld_map_unit_stamp(gs.prefix, u); },
      unit_key, [&](unsigned u) {
        stream::run_weld_map_unit(gs, weld_runs, u, units);
        return std::pair(std::vector<std::string>{path}, ordered_json{});
      });
  return path;
}

// The block pass's units, as one grading share takes part (take_units) once the weld map is whole (the
// masks' file sized once); returns their count.
unsigned run_block_units(const stream::GradeShareInput& gs, unsigned count, unsigned index, const ordered_json& key,
                         const std::string& weld_map, stream::Progress& progress) {
  const unsigned units = std::min(count, stream::kMaxBlockUnits);
  ordered_json unit_key = key;
  unit_key["block_units"] = units;
  unit_key["count"] = count;
  stream::start_block_units_once(gs, unit_key);
  take_units(
      stream::block_units_dir(gs.prefix), units, index, [&](unsigned u) { return stream::block_unit_stamp(gs.prefix, u); }, unit_key,
      [&](unsigned u) {
        const std::string areas = stream::run_block_unit(gs, weld_map, count, u, units, progress);
        return std::pair(std::vector<std::string>{areas}, ordered_json{});
      });
  return units;
}

stream::GradeSummary grade_from_stamp(const ordered_json& v) {
  stream::GradeSummary g;
  g.records = v.at("records");
  g.distinct_positions = v.at("distinct_positions");
  g.surface_area = v.at("surface_area");
  g.ranges = v.at("ranges");
  g.areas.count = v.at("area_counts").get<std::vector<uint64_t>>();
  g.areas.area = v.at("area_sums").get<std::vector<double>>();
  g.ordered_positions = v.at("ordered_positions");
  return g;
}

// The merge of the grading shares' runs (share s holds records[s]) as units (stream/grade_shares.h), which
// every process that needs the weight index takes part in (from `index` on: a clustering share's or a
// task's), the work directory's lock (`lock`) let go meanwhile. The merge's plan is made once, under the
// lock, from the runs alone, so every process that reads it sees the same cuts. Returns, under the lock
// again, the plan whose units have all run, or nothing when another process has stamped the stage
// meanwhile.
std::optional<stream::GradeMergePlan> run_grade_merge_units(const GradeStageInput& in, const stream::GradeShareInput& gs,
                                                            const ordered_json& share_key, const std::vector<uint64_t>& records,
                                                            unsigned index, std::unique_ptr<stream::ShardLock>& lock,
                                                            stream::Progress& progress) {
  const unsigned units = std::min(static_cast<unsigned>(records.size()), stream::kMaxGradeMergeUnits);
  const bool grades = !in.grades_path.empty();
  const ordered_json unit_key{{"shares", share_key}, {"records", records}, {"units", units}};
  auto take_merge_units = [&](const stream::GradeMergePlan& mp) {
    take_units(stream::grade_merge_dir(in.prefix), units, index, [&](unsigned u) { return stream::grade_merge_stamp(in.prefix, u); },
               unit_key, [&](unsigned u) {
                 return std::pair(std::vector<std::string>{},
                                  ordered_json{{"records", stream::run_grade_merge_unit(gs, mp, u, progress)}});
               });
  };
  const stream::GradeMergePlan first = stream::shared_grade_merge_plan(gs, records, units, grades, share_key);
  lock.reset();
  take_merge_units(first);
  lock = std::make_unique<stream::ShardLock>(in.work.path());
  ordered_json v;
  if (stamp_matches(in.work.file("grade.json"), in.key, &v)) return std::nullopt;
  // Again under the lock: a plan made afresh, and its units run here, when a process died finishing the last one.
  const stream::GradeMergePlan mp = stream::shared_grade_merge_plan(gs, records, units, grades, share_key);
  take_merge_units(mp);
  return mp;
}

bool grade_stage(const GradeStageInput& in, stream::Progress& progress, std::unique_ptr<stream::ShardLock>& lock, StageStats& st,
                 stream::GradeSummary* out, SimplifyReport* report) {
  const SimplifyOptions& so = in.so;
  const std::string stamp = in.work.file("grade.json");
  ordered_json v;
  if (stamp_matches(stamp, in.key, &v)) {
    st.reused = true;
    *out = grade_from_stamp(v);
    return so.grade_share_count == 0;
  }
  std::filesystem::remove(stamp);
  std::filesystem::remove(in.canonical_path);
  std::filesystem::remove(stream::grades_path(in.prefix));
  std::filesystem::remove(in.positions_path);
  for (const char* old : {"weights.idx", "weld.u32"}) std::filesystem::remove(in.work.file(old));  // an older version's
  const core::Grading mode = so.grading == Grading::lowtan ? core::Grading::lowtan : core::Grading::rossignac;
  const bool keep_grades = !in.grades_path.empty();
  auto write_grade_stamp = [&](const stream::GradeSummary& g) {
    std::vector<std::string> files{in.order_path};
    if (g.ordered_positions) files.push_back(in.positions_path);
    if (keep_grades) files.push_back(in.grades_path);
    if (g.distinct_positions < in.meta.vertices) files.push_back(in.canonical_path);
    write_stamp(stamp, in.key, files,
                {{"records", g.records}, {"distinct_positions", g.distinct_positions}, {"surface_area", g.surface_area},
                 {"ranges", g.ranges}, {"area_counts", g.areas.count}, {"area_sums", g.areas.area},
                 {"ordered_positions", g.ordered_positions}});
  };
  const unsigned count = so.grade_share_count ? so.grade_share_count
                         : in.sharded         ? stream::grade_shares_planned(in.prefix, in.key)
                                              : 0;
  if (count == 0) {
    *out = stream::grade_and_sort(in.store_dir, in.meta, mode, in.plan, in.work, progress, in.canonical_path, in.order_path,
                                  in.grades_path, so.grade_range_vertices);
    write_grade_stamp(*out);
    return true;
  }
  const stream::GradeShareInput gs{in.store_dir, &in.meta, mode, in.plan, in.prefix, &in.work, so.grade_range_vertices};
  stream::PlanUnits plan_units;
  if (so.grade_share_count > 0 && stream::grade_shares_planned(in.prefix, in.key) != count) {
    // The weld, its map and the block pass as units every grading share takes part in (stream/grade_shares.h),
    // the lock let go meanwhile.
    lock.reset();
    if (stream::store_needs_weld(in.meta)) {
      plan_units.weld_runs = run_weld_units(gs, count, so.grade_share_index, in.key, progress);
      plan_units.weld_map = run_weld_map_units(gs, count, so.grade_share_index, in.key, plan_units.weld_runs);
    }
    plan_units.block_units = run_block_units(gs, count, so.grade_share_index, in.key, plan_units.weld_map, progress);
    plan_units.block_dir = stream::block_units_dir(in.prefix);
    lock = std::make_unique<stream::ShardLock>(in.work.path());
  }
  const stream::GradePlan gp = stream::shared_grade_plan(gs, count, in.key, progress, plan_units);  // under the lock
  ordered_json share_key = in.key;
  share_key["count"] = count;
  // A share's stamp: its ranges and records.
  auto run_share = [&](unsigned s) {
    return stamped_share(stream::grade_shares_dir(in.prefix), s, stream::grade_share_stamp(in.prefix, s), share_key,
                         so.grade_share_count > 0 ? fmt::format("grade-share-{}", s) : std::string(), [&] {
                           const uint64_t records = stream::run_grade_share(gs, gp, s, count, progress);
                           const auto [first, end] = stream::grade_share_ranges(gp, s, count);
                           return std::pair(std::vector<std::string>{stream::grade_share_run(in.prefix, s)},
                                            ordered_json{{"ranges", {first, end}}, {"records", records}});
                         });
  };
  if (so.grade_share_count > 0) {
    lock.reset();  // the stages before are done: the other shares may run now
    report->grade_share = run_share(so.grade_share_index).dump();
    return false;
  }
  std::vector<uint64_t> records;
  for (unsigned s = 0; s < count; ++s) records.push_back(run_share(s).at("records"));
  const unsigned index = so.cluster_share_count > 0 ? so.cluster_share_index : so.shard_count > 0 ? so.shard_index : 0;
  const std::optional<stream::GradeMergePlan> mp = run_grade_merge_units(in, gs, share_key, records, index, lock, progress);
  if (!mp) {  // another process finished the merge
    if (!stamp_matches(stamp, in.key, &v)) fail(Status::internal, stamp + ": the grading merge's units are done, the stage is not");
    *out = grade_from_stamp(v);
    return true;
  }
  *out = stream::finish_grade_merge(gs, gp, *mp, in.order_path, in.grades_path, in.positions_path, in.canonical_path);
  write_grade_stamp(*out);
  // The shares are spent once the stage is stamped (the weld map is a link to the plan's). The merge's
  // units' stamps stay until the cluster stage is stamped: a process may still be reading them.
  std::filesystem::remove_all(stream::grade_shares_dir(in.prefix));
  std::filesystem::remove_all(stream::weld_units_dir(in.prefix));
  std::filesystem::remove_all(stream::block_units_dir(in.prefix));
  return true;
}

// A sharded run's options (stream/shard.h).
void check_shard_options(const SimplifyOptions& so, const Options& options) {
  if (options.work_dir.empty()) fail(Status::usage, "--shard and --shard-prepare need --work DIR, a directory every task shares");
  if (so.shard_count > 0 && so.shard_index >= so.shard_count)
    fail(Status::usage, fmt::format("--shard {}/{}: the index must be below the count", so.shard_index, so.shard_count));
  if (so.max_error_px > 0) fail(Status::usage, "--max-error-px is not available with --shard");
  if (so.cluster_share_count > 0 && so.cluster_share_index >= so.cluster_share_count)
    fail(Status::usage, fmt::format("--shard-cluster {}/{}: the index must be below the count", so.cluster_share_index,
                                    so.cluster_share_count));
  if (so.grade_share_count > 0 && so.grade_share_index >= so.grade_share_count)
    fail(Status::usage, fmt::format("--shard-grade {}/{}: the index must be below the count", so.grade_share_index,
                                    so.grade_share_count));
  if (so.grade_share_count > 0 && (so.cluster_share_count > 0 || so.shard_count > 0 || so.shard_prepare))
    fail(Status::usage, "--shard-grade runs a grading share alone: not with --shard, --shard-prepare or --shard-cluster");
}

// A range ingest task (stream/ingest_range.h): parses its byte range of the input into the work
// directory's segments, for the prepare job's join; no lock (the tasks run at once).
void run_ingest_range(const std::string& input, const SimplifyOptions& so, const Options& options,
                      SimplifyReport* out) {
  if (options.work_dir.empty()) fail(Status::usage, "--shard-ingest needs --work DIR, a directory every task shares");
  if (so.ingest_index >= so.ingest_count)
    fail(Status::usage, fmt::format("--shard-ingest {}/{}: the index must be below the count", so.ingest_index, so.ingest_count));
  const stream::MemoryPlan plan = stream::plan_memory(options);
  stream::Progress progress(options);
  stream::WorkDir work(options.work_dir);
  SimplifyReport report;
  report.input = input;
  tbb::task_arena arena(static_cast<int>(plan.threads));
  arena.execute([&] {
    stream::run_stage(&report.stages, "ingest-range", [&](StageStats&) {
      const stream::RangeStats r = stream::ingest_range(input, work, so.ingest_index, so.ingest_count, plan, progress);
      report.scene.path = input;
      report.scene.file_bytes = r.parsed_end - r.parsed_begin;
      return 0;
    });
  });
  *out = std::move(report);
}

// A task's summary, OUTDIR/shards/task-I.json (stream/shard.h): its manifest as one machine would write it
// (the level counts its own), what merge needs to write the outputs, and its key.
void write_shard_task(const SimplifyOptions& so, const SimplifyReport& report, const ordered_json& manifest,
                      const ordered_json& tiles, const ordered_json& store) {
  const std::string generator = manifest.at("generator");
  ordered_json merge{{"write_ply", so.write_ply}, {"write_obj", so.write_obj}, {"write_glb", so.write_glb},
                     {"resolution", so.resolution}, {"comments", ordered_json::array()}, {"store", store}};
  for (size_t l = 0; l < report.levels.size(); ++l)
    merge["comments"].push_back(level_comments(so, generator, l, report.levels.size(), report.levels[l].cell_size));
  ordered_json key{{"count", so.shard_count}, {"input", manifest.at("input")}, {"options", manifest.at("options")},
                   {"tile_triangles", so.tile_triangles}, {"merge", merge}};
  for (const LevelStats& ls : report.levels) key["levels"].push_back({exact(ls.cell_size), ls.cells});
  key["tiles"] = tiles;
  stream::write_shard_task(so.output_dir, so.shard_index, key, manifest);
}

}  // namespace

Result simplify(const std::string& input, const SimplifyOptions& so, const Options& options, SimplifyReport* out) {
  return guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    check_options(so);
    if (so.ingest_count > 0) return run_ingest_range(input, so, options, out);
    const stream::MemoryPlan plan = stream::plan_memory(options);
    stream::Progress progress(options);
    // A task of a sharded run (stream/shard.h) holds the work directory's lock through the shared stages.
    const bool sharded = so.shard_count > 0 || so.shard_prepare || so.cluster_share_count > 0 || so.grade_share_count > 0;
    if (sharded) check_shard_options(so, options);
    std::unique_ptr<stream::ShardLock> shard_lock;
    if (sharded) shard_lock = std::make_unique<stream::ShardLock>(options.work_dir);
    stream::WorkDir work(options.work_dir);
    if (options.check_disk_space && !so.shard_prepare && !so.cluster_share_count && !so.grade_share_count)
      stream::check_simplify_space(input, so, work.path(), sharded);
    const std::string store_dir = work.subdir("store");
    const core::ClusterOptions copts = cluster_options(so);
    SimplifyReport report;
    report.input = input;
    ordered_json error_json;  // --max-error-px: the passes and figures, for the manifest
    ordered_json shard_tiles;  // a sharded run's 3D Tiles options, for merge
    ordered_json shard_store;  // a sharded run's material table and colour flag, for merge's level files
    uint64_t primitives_read = 0;  // a sharded task's emit: the input primitives its passes read
    stream::PagedMapFigures paged_figures;  // a sharded task's paged maps (stream/paged_vertex_map.h)
    std::vector<std::array<uint32_t, 3>> shard_runs;  // and its run of each level's regions (stream/shard.h)

    tbb::task_arena arena(static_cast<int>(plan.threads));
    arena.execute([&] {
      bool reused = false;
      const stream::StoreMeta meta =
          stream::run_ingest_stage(input, store_dir, plan, work, progress, &report.stages, &report.scene, &reused,
                                   sharded ? stream::ingest_ranges_dir(work) : std::string());
      if (meta.primitives() == 0)
        fail(Status::bad_data, input + ": nothing to simplify (no triangles, lines or points)");

      // Grade and sort.
      const std::string canonical_path = work.file("weld.map");
      const std::string prefix = work.file("");
      // The grades are kept on disk only for the mean representative, the one stage that sums them.
      const bool keep_grades = so.representative == Representative::mean;
      const std::string order_path = stream::order_path(prefix);
      const std::string grades_path = keep_grades ? stream::grades_path(prefix) : std::string();
      const std::string positions_path = stream::ordered_positions_path(prefix, meta.single_precision);
      const ordered_json grade_key{{"version", kStampVersion},
                                   {"source", source_json(meta)},
                                   {"grading", name(so.grading)},
                                   {"grades", keep_grades}};
      const GradeStageInput gin{so,           meta,        plan,           work,      store_dir, prefix, canonical_path,
                                order_path,   grades_path, positions_path, grade_key, sharded};
      stream::GradeSummary grade;
      if (!run_stage(&report.stages, "grade", [&](StageStats& st) { return grade_stage(gin, progress, shard_lock, st, &grade, &report); }))
        return;  // a grading share task: done
      report.vertices_graded = grade.records;
      report.distinct_positions = grade.distinct_positions;
      report.surface_area = grade.surface_area;
      report.grade_ranges = grade.ranges;
      const std::string canonical = grade.distinct_positions < meta.vertices ? canonical_path : std::string();
      const std::string labels_path = work.file("labels.f32");
      // The records' positions in weight order, while they are not spent (position_gather.h).
      auto ordered_positions = [&] { return grade.ordered_positions ? stream::live_ordered_positions(positions_path) : std::string(); };
      const ordered_json labels_key = run_labels_stage(so, store_dir, meta, grade.records, order_path, ordered_positions(),
                                                       labels_path, grade_key, plan, options.chunk_bytes, progress, work, &report);

      const stream::EmitOptions count_only{so.representative, so.crease_degrees, true, true};
      stream::EmitScratch scratch;
      const stream::CellInfoKind info_kind = stream::cell_info_kind(so.representative);
      const ordered_json cluster_base{{"grade", grade_key},
                                      {"clustering", name(so.clustering)},
                                      {"cell", name(so.cell)},
                                      {"variant", name(so.variant)},
                                      {"cell_info", name(so.representative)}};
      // Clusters at `sizes` unless the stamp says it is done; returns cells per level.
      // Silhouette labels: per level, the fine cell size and the label under which a vertex is near the
      // outline (fine_factors and switch_distances when set for these sizes, else the options' factor and
      // the distance the size gives).
      std::vector<double> fine_factors, switch_distances;
      auto fine_cells = [&](const std::vector<double>& sizes) {
        std::unique_ptr<stream::FineCells> f;
        if (so.silhouette_interval <= 0) return f;
        f = std::make_unique<stream::FineCells>();
        f->labels_path = labels_path;
        const double tan_half = std::tan(so.fov_degrees * M_PI / 360);
        for (size_t l = 0; l < sizes.size(); ++l) {
          const bool given = fine_factors.size() == sizes.size();
          f->sizes.push_back(sizes[l] * (given ? fine_factors[l] : so.silhouette_factor));
          const double d = given ? switch_distances[l] : sizes[l] * so.resolution / (2 * so.pixels_per_cell * tan_half);
          f->near.push_back(so.silhouette_interval * 2 * d * tan_half / so.resolution);
        }
        return f;
      };
      // The clustering as N shares (stream/cluster_shares.h): a share task runs its share and returns no
      // cells (the run stops after the stage); the shared stage runs the shares no task ran and merges them.
      const unsigned cluster_shares = so.cluster_share_count ? so.cluster_share_count : sharded ? so.cluster_shares : 0;
      const unsigned unit_index = so.shard_count > 0 ? so.shard_index : 0;  // the first unit this process takes
      // Per level: its cells by vertex came with the cluster shares' merge (kept in the cluster stage's stamp,
      // so that a process that reuses the stage writes the others only: processes that disagreed on the
      // levels would restart each other's cells-by-vertex units).
      std::vector<char> vertex_cells_written;
      auto vertex_cells_from_stamp = [&](const ordered_json& v) {
        vertex_cells_written.clear();
        if (v.contains("vertex_cells"))
          for (const auto& b : v.at("vertex_cells")) vertex_cells_written.push_back(b.get<bool>());
      };
      ordered_json merge_units;                // the clustering merge's units' figures (stream/cluster_merge.h), for the stamp
      auto cluster_by_shares = [&](const ordered_json& key, const std::vector<double>& sizes, const stream::FineCells* fine,
                                   const stream::WeightIndex& index, const std::vector<double>& bounds) {
        stream::ClusterShareInput in{index, bounds, sizes, copts, info_kind, fine, plan.stage_bytes, options.chunk_bytes,
                                     prefix, &work};
        in.vertex_cells = true, in.canonical_path = canonical;  // the tasks read them (stream/vertex_cells.h)
        // The shares' decisions freed as the merge's map is written, the positions in weight order after its
        // sums (stream/cluster_merge.h).
        in.spend_decisions = true;
        const stream::ClusterShares shares = stream::shared_cluster_plan(in, cluster_shares, key, progress);  // under the lock
        ordered_json share_key = key;
        share_key["shares"] = shares.json();
        share_key["vertex_cells"] = in.vertex_cells;
        in.key = share_key;  // the centers units' stamps (levels split by records): the stage's inputs and the plan
        const std::string dir = work.subdir("cluster-shares");
        auto run_share = [&](unsigned s) {
          return stamped_share(dir, s, stream::cluster_share_stamp(prefix, s), share_key,
                               so.cluster_share_count > 0 ? fmt::format("cluster-share-{}", s) : std::string(), [&] {
                                 return std::pair(stream::cluster_share_files(in, shares, s),
                                                  ordered_json{{"levels", stream::run_cluster_share(in, shares, s, progress)}});
                               })
              .at("levels");
        };
        if (so.cluster_share_count > 0) {
          shard_lock.reset();  // the stages before are done: the other shares may run now
          report.cluster_share = run_share(so.cluster_share_index).dump();
          return std::vector<uint64_t>();
        }
        // Every share's figures (a share no process finished runs here); the merge's key.
        std::vector<ordered_json> figures;
        auto run_shares = [&] {
          figures.clear();
          for (unsigned s = 0; s < shares.count; ++s) figures.push_back(run_share(s));
          return ordered_json{{"shares", share_key}, {"figures", figures}};
        };
        ordered_json merge_key = run_shares();
        // Shares whose decisions a merge under another key spent (a build's half-done merge): run them again.
        if (stream::forget_shares_spent_elsewhere(in, shares, merge_key)) merge_key = run_shares();
        // The split levels' maps as units (stream/cluster_merge.h) that every process here takes part in, the
        // work directory's lock let go meanwhile (a prepare array's jobs, tasks that reach the stage).
        shard_lock.reset();
        const stream::SplitMerge merged = stream::merge_split_levels(in, shares, merge_key, unit_index, progress);
        merge_units = merged.units;
        if (const ordered_json c = stream::cluster_centers_figures(in, shares); !c.empty()) merge_units["centers_passes"] = c;
        shard_lock = std::make_unique<stream::ShardLock>(options.work_dir);
        ordered_json v;
        if (stamp_matches(work.file("cluster.json"), key, &v)) {  // another process finished the stage meanwhile
          vertex_cells_from_stamp(v);
          return v.at("cells").get<std::vector<uint64_t>>();
        }
        stream::ClusterSummary cs = stream::merge_cluster_shares(in, shares, figures, merged.cells, progress);
        vertex_cells_written = cs.vertex_cells;
        return cs.cells;
      };
      // by_shares: the stage of the final sizes, which a sharded run with cluster shares clusters by them.
      auto cluster = [&](const std::vector<double>& sizes, StageStats* st, bool by_shares = false) {
        const bool in_shares = by_shares && cluster_shares > 0;
        ordered_json key = cluster_base;
        std::vector<std::string> hex;
        for (double c : sizes) hex.push_back(exact(c));
        key["cell_sizes"] = hex;
        const std::unique_ptr<stream::FineCells> fine = fine_cells(sizes);
        if (fine) {
          std::vector<std::string> fh, nh;
          for (size_t l = 0; l < sizes.size(); ++l) fh.push_back(exact(fine->sizes[l])), nh.push_back(exact(fine->near[l]));
          key["labels"] = labels_key;
          key["fine_sizes"] = fh;
          key["near"] = nh;
        }
        ordered_json v;
        if (stamp_matches(work.file("cluster.json"), key, &v)) {
          if (st) st->reused = true;
          vertex_cells_from_stamp(v);
          return v.at("cells").get<std::vector<uint64_t>>();
        }
        std::filesystem::remove(work.file("cluster.json"));
        check_cell_sizes(sizes, meta.bbox);
        std::vector<double> bounds;
        if (!meta.bbox.empty) {
          bounds.assign(meta.bbox.min.begin(), meta.bbox.min.end());
          bounds.insert(bounds.end(), meta.bbox.max.begin(), meta.bbox.max.end());
        }
        if (!in_shares)  // a share holds a share's cells; its whole levels check as they run
          stream::check_cluster_estimate(grade.areas, grade.records, meta.vertices, meta.single_precision, bounds, sizes,
                                         plan.stage_bytes, options.chunk_bytes);
        const stream::WeightIndex index{order_path,
                                        grades_path,
                                        stream::positions_column_path(store_dir, meta),
                                        grade.records,
                                        meta.vertices,
                                        meta.single_precision,
                                        ordered_positions()};
        stream::ClusterSummary cs;
        if (in_shares) {
          cs.cells = cluster_by_shares(key, sizes, fine.get(), index, bounds);
          if (so.cluster_share_count > 0) return cs.cells;  // a share task: no stamp of the whole stage
        } else {
          cs = stream::cluster_levels(index, bounds, sizes, copts, info_kind, plan.stage_bytes, work, progress, prefix,
                                      fine.get(), options.chunk_bytes);
        }
        std::vector<std::string> files;
        for (size_t l = 0; l < sizes.size(); ++l) {
          files.push_back(stream::cells_path(prefix, l));
          files.push_back(stream::cell_info_path(prefix, l));
        }
        ordered_json value{{"cells", cs.cells}};
        if (!merge_units.is_null()) value["merge_units"] = merge_units;
        if (in_shares)
          for (char b : vertex_cells_written) value["vertex_cells"].push_back(b != 0);
        write_stamp(work.file("cluster.json"), key, files, value);
        // The shares are spent once the stage is stamped (the whole levels' maps are links to their files).
        // (The records' positions in weight order are spent by the clustering merge, after its sums.)
        if (in_shares) std::filesystem::remove_all(stream::cluster_shares_dir(prefix));
        std::filesystem::remove_all(stream::grade_merge_dir(prefix));  // the grading merge's units' stamps (grade_stage)
        return cs.cells;
      };

      // Emits every level at `sizes` with `cells` cells. Counting (eo.count_only): whole levels, in groups that
      // share a pass over the input as far as the memory plan allows (stream::emit_group_end). Otherwise
      // region by region (stream/emit_regions.h): `sink(level, region info, part)` gets every region's part,
      // level by level, each level's in region order, and `level_done(level)` follows its last part. Levels
      // that fit whole share passes as when counting; the others are emitted in batches of regions. Neither
      // the grouping nor the batches change a byte.
      using PartSink = std::function<void(size_t, const stream::RegionInfo&, stream::RegionPart&)>;
      auto emit_all = [&](const std::vector<double>& sizes, const std::vector<uint64_t>& cells, const stream::EmitOptions& options_in,
                          const PartSink& sink, const std::function<void(size_t)>& level_done) {
        // What is resident before the levels are emitted (code and libraries touched so far, pages the heap
        // kept from earlier stages) beyond what the memory plan sets aside for the process (budget less
        // stage_bytes) counts against the stage: the plan gets the rest. On the 193 M-triangle city at
        // --memory 1G, a whole run came to emit with about 70 MiB more resident than a rerun of emit alone,
        // and went over. The plan changes how levels are grouped and batched, never a byte.
        // A 32nd of the stage stays spare for what the model of emit's memory misses, and at least 64 MiB
        // from a 256 MiB stage up: part of what it misses has a fixed size (bursts of the threads' block
        // tables; at --memory 1G the 193 M-triangle city's whole runs peaked at 1019 and 1035 MiB with a
        // 32nd, 30 MiB, spare, and at 991 MiB with 64 MiB).
        const uint64_t set_aside = plan.budget - plan.stage_bytes, resident = stream::resident_bytes();
        const uint64_t spare = plan.stage_bytes >= (256 << 20) ? std::max<uint64_t>(plan.stage_bytes / 32, 64 << 20)
                                                               : plan.stage_bytes / 32;
        const uint64_t budget = plan.stage_bytes - spare -
                                std::min(resident > set_aside ? resident - set_aside : 0, plan.stage_bytes / 2);
        // The thickness passes hold what the plan counts for them (stream::emit_corner_bytes of this budget).
        stream::EmitOptions eo = options_in;
        eo.corner_bytes = stream::emit_corner_bytes(budget);
        std::vector<stream::EmitCounts> counts(sizes.size());
        if (eo.count_only) {
          for (size_t l = 0; l < sizes.size(); ++l)
            stream::check_emit_budget(cells, l, meta.vertices, meta.primitives(), budget, 0, eo);
          for (size_t first = 0; first < sizes.size();) {
            const size_t end = stream::emit_group_end(cells, first, meta.vertices, meta.primitives(), budget, 0, eo);
            std::vector<stream::EmitLevel> group;
            for (size_t l = first; l < end; ++l) group.push_back({l, cells[l], sizes[l]});
            const std::vector<stream::EmitCounts> c = stream::emit_levels(
                store_dir, meta, canonical, prefix, group, grade.records, copts, eo, progress, scratch, [](size_t, stream::RegionPart&) {});
            std::copy(c.begin(), c.end(), counts.begin() + static_cast<ptrdiff_t>(first));
            first = end;
          }
          return counts;
        }
        const core::SceneCube cube = stream::scene_cube_of(meta);
        // With tiles, the side of coarser levels' regions is also bounded (stream/tiles.h tile_side_bounds).
        const std::vector<core::SideBound> sides =
            so.write_tiles ? stream::tile_side_bounds(sizes, cells, cube.side) : std::vector<core::SideBound>();
        const std::vector<stream::LevelCut> cuts = stream::cut_levels(prefix, cells, cube, so.tile_triangles / 2, so.representative,
                                                                      meta.single_precision, sides);
        // Every level is planned before the first is written, so that a level that cannot fit stops the run
        // before any output file appears.
        std::vector<stream::EmitLevelPlan> plans;
        for (size_t l = 0; l < sizes.size(); ++l)
          plans.push_back(stream::plan_emit_level(l, cells[l], *std::max_element(cuts[l].cells.begin(), cuts[l].cells.end()),
                                                  meta.vertices, meta.primitives(), budget, eo));
        auto info = [&](size_t l, uint32_t r) {
          stream::RegionInfo i;
          i.level = l, i.key = cuts[l].regions[r], i.cell_size = sizes[l], i.cells = cuts[l].cells[r];
          core::region_box(cube, i.key, i.box_min, i.box_max);
          return i;
        };
        // Before each level or group: the previous group's packed map dropped (a smaller map would otherwise
        // reuse its larger capacity, all of it resident) and the heap's free pages returned; what is still
        // resident beyond what it was when the budget was set counts against the group (on the 1 B-triangle
        // city at --memory 4G, 741 MiB were resident besides the maps when the group after the batched
        // finest level began, against 220 MiB at emit's start).
        auto held_since_start = [&] {
          scratch = stream::EmitScratch();
          stream::release_free_memory();
          const uint64_t now = stream::resident_bytes();
          return now > resident ? now - resident : 0;
        };
        auto add = [&](size_t l, const stream::EmitCounts& c) {
          counts[l].triangles += c.triangles, counts[l].edges += c.edges, counts[l].points += c.points;
          counts[l].edges_on_triangles += c.edges_on_triangles, counts[l].points_covered += c.points_covered;
        };
        for (size_t first = 0; first < sizes.size();) {
          const uint64_t held = held_since_start();
          if (plans[first].batched) {
            const size_t l = first++;
            // Planned again with what is held now (the batches change no byte); the plan made before the
            // first level, which stopped the run if the level could not fit at all, stays when this one
            // would not fit.
            if (held > 0 && held < budget) {
              bool fits = true;
              const stream::EmitLevelPlan now = stream::plan_emit_level(
                  l, cells[l], *std::max_element(cuts[l].cells.begin(), cuts[l].cells.end()), meta.vertices, meta.primitives(),
                  budget - held, eo, &fits);
              if (fits) plans[l] = now;
            }
            stream::write_representatives(store_dir, meta, canonical, prefix, l, cells[l], sizes[l], grade.records, copts,
                                          eo.representative, plans[l].reps_range_cells, progress, scratch);
            const stream::CellRegions regions = stream::load_cell_regions(prefix, l, cells[l], cube, cuts[l], so.representative, meta.single_precision);
            // The batches are routed kRouteBatches at a time (two passes over the input), and each batch then
            // reads only the words of the input its routes name.
            const std::vector<std::pair<uint32_t, uint32_t>> batches = stream::region_batches(cuts[l], plans[l].batch_cells);
            for (size_t b0 = 0; b0 < batches.size(); b0 += stream::kRouteBatches) {
              const std::span<const std::pair<uint32_t, uint32_t>> routed(
                  batches.data() + b0, std::min(stream::kRouteBatches, batches.size() - b0));
              stream::BatchRoutes routes;
              stream::EmitLevel level{l, cells[l], sizes[l], &cuts[l], &regions, 0, 0, true};
              stream::route_batches(store_dir, meta, canonical, prefix, level, routed, grade.records, copts, progress, scratch, routes);
              for (size_t i = 0; i < routed.size(); ++i) {
                level.first_region = routed[i].first, level.end_region = routed[i].second;
                level.routes = &routes, level.route_bit = static_cast<unsigned>(i);
                const std::vector<stream::EmitCounts> c = stream::emit_levels(
                    store_dir, meta, canonical, prefix, std::span<const stream::EmitLevel>(&level, 1), grade.records, copts, eo,
                    progress, scratch, [&](size_t, stream::RegionPart& part) { sink(l, info(l, part.region), part); });
                add(l, c[0]);
              }
            }
            std::filesystem::remove(stream::representatives_path(prefix, l));
            level_done(l);
            continue;
          }
          // Beside the group's working memory, its levels' per-cell tables (stream::kLevelBytesPerCell).
          uint64_t tables = 0;
          for (size_t l = first; l < sizes.size(); ++l) tables += stream::kLevelBytesPerCell * cells[l];
          size_t end = stream::emit_group_end(cells, first, meta.vertices, meta.primitives(), budget, tables + held, eo);
          end = static_cast<size_t>(std::find_if(plans.begin() + static_cast<ptrdiff_t>(first), plans.begin() + static_cast<ptrdiff_t>(end),
                                                 [](const stream::EmitLevelPlan& p) { return p.batched; }) -
                                    plans.begin());
          std::vector<stream::CellRegions> regions;
          std::vector<stream::EmitLevel> group;
          for (size_t l = first; l < end; ++l)
            regions.push_back(stream::load_cell_regions(prefix, l, cells[l], cube, cuts[l], so.representative, meta.single_precision));
          for (size_t l = first; l < end; ++l)
            group.push_back({l, cells[l], sizes[l], &cuts[l], &regions[l - first], 0,
                             static_cast<uint32_t>(cuts[l].regions.size()), false});
          const std::vector<stream::EmitCounts> c =
              stream::emit_levels(store_dir, meta, canonical, prefix, group, grade.records, copts, eo, progress, scratch,
                                  [&](size_t i, stream::RegionPart& part) { sink(first + i, info(first + i, part.region), part); });
          for (size_t l = first; l < end; ++l) add(l, c[l - first]), level_done(l);
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
                return emit_all(s, cluster(s, nullptr), triangles_only ? count_only : counting,
                                [](size_t, const stream::RegionInfo&, stream::RegionPart&) {}, [](size_t) {});
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
            const std::vector<stream::EmitCounts> counts = emit_all(sizes, cells, count_only, nullptr, nullptr);
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

      if (so.max_error_px > 0)
        run_stage(&report.stages, "error", [&](StageStats&) {
          error_json = bound_silhouette_error(input, so, options, work, sizes, fine_factors, switch_distances, report,
                                              [&](const std::vector<double>& s, const std::vector<std::string>& paths) {
                                                stream::EmitOptions eo{so.representative, so.crease_degrees, true, false};
                                                eo.work = &work, eo.chunk_bytes = options.chunk_bytes;
                                                const std::vector<uint64_t> cells = cluster(s, nullptr);
                                                stream::OpenLevels levels(work, "error-level", cells);
                                                emit_all(
                                                    s, cells, eo,
                                                    [&](size_t l, const stream::RegionInfo&, stream::RegionPart& part) { levels.add(l, part); },
                                                    [&](size_t l) { levels.take(l)->write_ply(paths[l], {}); });
                                              });
        });

      const std::vector<uint64_t> cells =
          run_stage(&report.stages, "cluster", [&](StageStats& st) { return cluster(sizes, &st, true); });
      if (so.cluster_share_count > 0) return;  // a share task (or a share whose stage another task finished)
      stream::ShardEmitInput shard_input;
      if (sharded) {
        stream::EmitOptions shard_emit;
        shard_emit.representative = so.representative, shard_emit.crease_degrees = so.crease_degrees;
        shard_emit.work = &work, shard_emit.chunk_bytes = options.chunk_bytes;
        shard_emit.paged_figures = &paged_figures;
        shard_input = {store_dir, canonical, prefix, &meta, grade.records, copts, shard_emit, plan.stage_bytes, so.tile_triangles,
                       sizes, cells, so.write_tiles};
        // The store's block boxes (stream/block_bounds.h) and every level's cells by vertex
        // (stream/vertex_cells.h: the tasks' packed maps). No representative is written ahead: a task forms
        // its cells' own (stream::EmitOptions::own_representatives).
        // Both as units (stream/units.h) that every process here takes part in, the lock let go meanwhile
        // (stage_in_units), N of them (one a cluster share, else the budget's).
        const unsigned unit_count = std::max(1u, cluster_shares);
        run_stage(&report.stages, "bounds", [&](StageStats& st) {
          const std::string path = stream::block_bounds_path(prefix);
          const ordered_json key{{"version", kStampVersion}, {"source", source_json(meta)}};
          st.reused = stage_in_units(work.file("block-bounds.json"), key, {path}, shard_lock, options.work_dir, [&] {
            return stream::write_block_bounds_in_units(store_dir, meta, path, prefix + "block-bounds-units/", unit_count, unit_index,
                                                       key, progress);
          });
        });
        // What the stages below are made from: the clustering and its levels.
        ordered_json levels_key = cluster_base;
        levels_key["cells"] = cells;
        for (double c : sizes) levels_key["cell_sizes"].push_back(exact(c));
        run_stage(&report.stages, "vertex-cells", [&](StageStats& st) {
          const ordered_json& key = levels_key;
          std::vector<std::string> files;
          for (size_t l = 0; l < cells.size(); ++l) files.push_back(stream::vertex_cells_path(prefix, l));
          st.reused = stage_in_units(work.file("shard-vertex-cells.json"), key, files, shard_lock, options.work_dir, [&] {
            std::vector<size_t> levels;  // else written by its cluster share
            std::vector<stream::VertexCellsSource> sources;  // the clustering merge's pairs, where they are
            for (size_t l = 0; l < cells.size(); ++l)
              if (l >= vertex_cells_written.size() || !vertex_cells_written[l]) {
                levels.push_back(l);
                sources.push_back({stream::vertex_pairs_paths(prefix, l)});
              }
            return stream::write_vertex_cells_in_units(prefix, canonical, meta.vertices, grade.records, levels, cells, sources, unit_count,
                                                       unit_index, key, plan.stage_bytes, progress);
          });
        });
        // Every cells-by-vertex unit is done (the stage is stamped): no process reads the pairs again.
        stream::remove_vertex_pairs(prefix);
        // The wide levels' pass A (stream/wide_units.h), as units that every task takes part in, N of them:
        // a task's, since which levels are wide depends on the task count (a prepare job leaves it to them).
        if (so.shard_count > 0 && !so.shard_prepare)
          run_stage(&report.stages, "wide-units", [&](StageStats& st) {
            ordered_json key = levels_key;
            key["source"] = source_json(meta);
            key["representative"] = name(so.representative);
            key["tiles"] = so.write_tiles;
            key["tile_triangles"] = so.tile_triangles;
            key["tasks"] = so.shard_count;
            key["format"] = 3;  // the units' files (stream/emit_stage.cpp write_classified)
            std::atomic<uint64_t> read{0};
            shard_input.cuts = stream::shard_cuts(shard_input);  // the units' and the emit's
            st.reused = stage_in_units(work.file("wide-units.json"), key, {}, shard_lock, options.work_dir, [&] {
              return stream::run_wide_units(shard_input, so.shard_index, so.shard_count, key, progress, scratch, read);
            });
            primitives_read += read.load();
            shard_input.wide_units = true;
            scratch = stream::EmitScratch();  // the units' packed map: the task's emit counts its own
          });
        shard_lock.reset();
        if (so.shard_prepare) return;
        if (so.write_tiles)
          shard_tiles = stream::tiles_options_json(tiles_options(so, meta, sizes.size(), std::string("lodstream ") + LODSTREAM_VERSION));
        shard_store = {{"materials", ordered_json::array()}, {"colors", meta.colors}};
        for (const core::Material& mat : meta.materials) shard_store["materials"].push_back(stream::material_json(mat));
      }

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
        ls.switch_distance = switch_distances.size() == sizes.size() ? switch_distances[l]
                                                                     : sizes[l] * so.resolution / (2 * so.pixels_per_cell * tan_half);
        if (const std::unique_ptr<stream::FineCells> fine = fine_cells(sizes))
          ls.fine_cell_size = fine->sizes[l], ls.near_outline = fine->near[l];
        if (!error_json.is_null()) ls.measured_p95_px = error_json["p95_px"][l].get<double>();
        ls.screen_coverage = diag > 0 ? diag / (2 * ls.switch_distance * tan_half) : 0;
        report.levels.push_back(ls);
      }
      const std::string generator = std::string("lodstream ") + LODSTREAM_VERSION;
      std::unique_ptr<io::GlbBuilder> glb;
      // The GLB's binary data is gathered beside it in the output directory (a .partial name, which a rerun
      // writes again), not in the work directory: it is output, as large as the GLB, and counts against the
      // outputs' room (stream/disk_space.cpp).
      if (so.write_glb && !sharded)
        glb = std::make_unique<io::GlbBuilder>(so.output_dir + "/lods.glb", so.output_dir + "/lods.glb.bin.partial", generator);
      // Each level's parts are welded into its files (stream/level_files.h) as they come; the level's PLY and
      // OBJ files and its part of the GLB are written after its last part (the three side by side).
      // Their scratch files are in the output directory (stream/level_files.h: the levels' data in the
      // making, counted with the outputs, stream/disk_space.cpp), not in the work directory.
      stream::OpenLevels open_levels(stream::OpenLevels::OutputScratch{so.output_dir}, "lod", cells, meta.materials, meta.colors);
      // The region sink of the 3D Tiles output (stream/emit_regions.h): every region of every level becomes a
      // tile as it is emitted (stream/tiles.h); tileset.json is written after the last.
      std::unique_ptr<stream::TilesetBuilder> tiles;
      if (so.write_tiles && !sharded) tiles = make_tiles_builder(so, meta, sizes.size(), generator);
      stream::RegionSink region_sink;
      if (tiles)
        region_sink = [&](size_t l, const stream::RegionInfo& info, const core::LodMesh& part) {
          tiles->add(l, {info.key.depth, info.key.x, info.key.y, info.key.z, info.cell_size, info.cells}, part);
        };
      auto add_part = [&](size_t l, const stream::RegionInfo& info, stream::RegionPart& part) {
        if (region_sink) region_sink(l, info, part.mesh);
        open_levels.add(l, part);
      };
      auto write_level = [&](size_t l) {
        const std::unique_ptr<stream::LevelFiles> level = open_levels.take(l);
        stream::kill_point(fmt::format("lod{}.scratch", l));  // tests/test_crash.cpp: killed with the level's scratch complete
        LevelStats& ls = report.levels[l];
        ls.vertices = level->vertices();
        const std::vector<std::string> comments = level_comments(so, generator, l, sizes.size(), sizes[l]);
        const std::string stem = fmt::format("lod{}", l);
        // MSFT_screencoverage: level l is shown while the coverage is at least the coverage at which the next
        // level takes over; the last level down to one pixel.
        const double lower = l + 1 < sizes.size() ? report.levels[l + 1].screen_coverage : 1.0 / so.resolution;
        ls.files = stream::write_level_outputs(*level, so.output_dir, stem, comments, so.write_ply, so.write_obj, glb.get(), lower);
      };
      stream::EmitOptions emit_options{so.representative, so.crease_degrees, true, false};
      emit_options.grades_path = grades_path;
      emit_options.colors = meta.colors;
      emit_options.materials = !meta.materials.empty();
      emit_options.work = &work, emit_options.chunk_bytes = options.chunk_bytes;
      run_stage(&report.stages, "emit", [&](StageStats&) {
        const std::vector<stream::EmitCounts> counts =
            sharded ? stream::emit_shard(shard_input, so.shard_index, so.shard_count, so.output_dir, progress, scratch, &primitives_read,
                                         &shard_runs)
                    : emit_all(sizes, cells, emit_options, add_part, write_level);
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
      if (!sharded) run_stage(&report.stages, "write", [&](StageStats&) {
        if (glb) glb->finish();
        glb.reset();
        progress.report("write", 1);
      });
      if (so.write_tiles && !sharded)
        run_stage(&report.stages, "tiles", [&](StageStats&) {
          const stream::TilesSummary t = tiles->finish();
          tiles.reset();
          report.tiles = {t.tiles, t.content_tiles, t.bytes, t.triangles, t.max_triangles};
          progress.report("tiles", 1);
        });
    });
    if (so.shard_prepare || so.cluster_share_count > 0 || so.grade_share_count > 0) {
      *out = std::move(report);
      return;
    }
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
    if (so.silhouette_interval > 0)
      m["options"]["silhouette"] = {{"interval_px", so.silhouette_interval}, {"factor", so.silhouette_factor},
                                    {"views", so.silhouette_views}, {"resolution", so.silhouette_resolution},
                                    {"labelled_vertices", report.labelled_vertices}};
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
      if (ls.fine_cell_size > 0) j["silhouette"] = {{"fine_cell_size", ls.fine_cell_size}, {"near_outline", ls.near_outline}};
      if (ls.measured_p95_px >= 0) j["silhouette_p95_px"] = ls.measured_p95_px;
      levels.push_back(j);
    }
    m["levels"] = levels;
    m["levels_asked"] = report.levels_asked;
    m["levels_made"] = report.levels.size();
    if (!report.notice.empty()) m["notice"] = report.notice;
    if (so.write_glb) m["glb"] = "lods.glb";
    if (so.max_error_px > 0) m["max_error"] = error_json;
    if (so.write_tiles)
      m["tiles"] = {{"tileset", "tiles/tileset.json"},
                    {"tile_triangles", so.tile_triangles},
                    {"tile_lines", so.tile_lines == SimplifyOptions::TileLines::triangles ? "triangles" : "lines"},
                    {"tile_encoding", so.tile_encoding == SimplifyOptions::TileEncoding::plain       ? "plain"
                                      : so.tile_encoding == SimplifyOptions::TileEncoding::quantized ? "quantized"
                                                                                                     : "meshopt"},
                    {"up", so.tiles_z_up ? "z" : "y"},
                    {"tiles", report.tiles.tiles},
                    {"content_tiles", report.tiles.content_tiles},
                    {"bytes", report.tiles.bytes},
                    {"triangles", report.tiles.triangles},
                    {"max_triangles", report.tiles.max_triangles}};
    if (!so.target_triangles.empty())
      m["search"] = {{"passes", report.search_iterations}, {"seconds", report.search_seconds}};
    ordered_json stages = ordered_json::array();
    for (const StageStats& s : report.stages)
      stages.push_back(stream::stage_json(s));
    m["stages"] = stages;
    m["seconds"] = report.seconds;
    m["peak_rss_bytes"] = report.peak_rss_bytes;
    m["work_dir"] = stream::work_dir_json(report.work_dir);
    if (sharded) {
      m["input_primitives_read"] = primitives_read;
      m["paged_map"] = {{"maps", paged_figures.maps},
                        {"pages", paged_figures.pages},
                        {"pages_read", paged_figures.pages_read},
                        {"reads", paged_figures.reads},
                        {"drops", paged_figures.drops},
                        {"largest_group_pages", paged_figures.largest_group},
                        {"largest_bytes", paged_figures.largest_bytes}};
      m["regions"] = shard_runs;
      write_shard_task(so, report, m, shard_tiles, shard_store);
      *out = std::move(report);
      return;
    }
    stream::kill_point("manifest.json");
    io::write_file_atomic(so.output_dir + "/manifest.json", m.dump(2) + "\n", io::Sync::durable);
    *out = std::move(report);
  });
}

}  // namespace lodstream

// `lodstream report`: how far off, in pixels, each level of detail is where a renderer would show it
// (../shared/DESIGN.md "Error report").
//
// For every original (ingested into the scene store, reused from a simplify work directory when it is the
// same file), traced out of core: the store is cut into chunks (stream/store_chunks.h) that fit what
// --memory leaves, one chunk in core. Its samples and view targets are drawn in two passes over the chunks
// (stream/report_samples.h).
// For every level:
// 1. read the LOD file, draw its samples, and the original → level Hausdorff distances against its scene
//    (its triangles, and its thick edges and points as flat curves and discs, whose radii do not enter
//    the distances);
// 2. chunk-outer passes over the original: each chunk's Embree scene (its triangles; its lines and points,
//    drawn one pixel wide, in a small second scene per level distance) is built once per pass, every
//    level's samples are lowered to their distance to it (level → original Hausdorff), and every view of
//    the levels of the pass accumulates its image; then it is freed;
// 3. views: K directions on a Fibonacci sphere, view k aimed at the k-th of K points sampled uniformly
//    by area on the original's surface, the camera at the level's switching distance from that point;
//    the level ray cast into H × H images under the same pixel rule as the original (core/view_cast.h:
//    centre ray, else any of k × k rays; thick edges at their true width), compared with the original's:
//    silhouette error and thin-feature share from exact
//    distance transforms of the original's coverage (core/silhouette_error.h); depth and normal error
//    where both cover.
// Levels whose distance comes from their Hausdorff max take one more pass (distances first). What stays
// between chunks: the samples and their distances so far, and for the levels of a pass the original's
// view images (depth, normal, kind, centre: 18 bytes a pixel); levels are grouped into passes so that these take
// at most half of what --memory leaves. A level too large for the rest is traced in chunks as well.
// Everything drawn at random comes from counter-based streams of --seed (views, targets, samples), every
// sum is formed in a fixed order, distances are minima over chunks and a pixel keeps the hit of lowest
// (distance, primitive order) over chunks (core/nearest_hit.h), so the figures are the same for any
// thread count, memory budget or chunking. A task of a sharded report traces a range of the original's and
// of each level's primitives for every view, and the merge composites the tasks' images in range order
// (core::composite_view), or else a share of the views against the whole original (stream/report_shard.h).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/ray_scene.h"
#include "core/silhouette_error.h"
#include "core/primitive_color.h"
#include "core/status.h"
#include "core/surface_sampling.h"
#include "core/view_cast.h"
#include "io/file_writer.h"
#include "io/lod_reader.h"
#include "io/report_html.h"
#include <fmt/format.h>
#include "lodstream/lodstream.h"
#include "stream/ingest.h"
#include "stream/ingest_range.h"
#include "stream/disk_space.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/report_samples.h"
#include "stream/report_shard.h"
#include "stream/scene_store.h"
#include "stream/shard.h"
#include "stream/store_access.h"
#include "stream/chunk_scene.h"
#include "stream/store_chunks.h"
#include "stream/work_dir.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using stream::run_stage;

constexpr stream::ChunkCosts kChunkCosts = stream::kChunkSceneCosts;

// Resident bytes of the process now (/proc/self/statm), 0 where unknown.
uint64_t resident_bytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long long size = 0, resident = 0;
  const int got = std::fscanf(f, "%llu %llu", &size, &resident);
  std::fclose(f);
  return got == 2 ? resident * 4096ull : 0;
}

struct LevelSpec {
  std::string file;
  double cell_size = 0;
  double switch_distance = 0;  // 0 = derive from the Hausdorff max
};

struct RunSpec {
  std::string name;
  std::string original;
  double fov_degrees = 60;
  std::vector<LevelSpec> levels;
};

bool exists_file(const std::string& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

std::vector<RunSpec> resolve_runs(const ReportOptions& ro) {
  std::vector<RunSpec> runs;
  if (!ro.runs.empty() && !ro.lods.empty()) fail(Status::usage, "give simplify output directories or --lod files, not both");
  if (ro.runs.empty() && ro.lods.empty()) fail(Status::usage, "nothing to report: give a simplify output directory or --original with --lod");
  if (ro.views == 0) fail(Status::usage, "--views must be at least 1");
  if (ro.resolution < 8 || ro.resolution > 8192) fail(Status::usage, "--resolution must be between 8 and 8192");
  if (!(ro.fov_degrees > 0 && ro.fov_degrees < 180)) fail(Status::usage, "--fov must be between 0 and 180 degrees");
  if (ro.supersample < 1 || ro.supersample > 16) fail(Status::usage, "--supersample must be between 1 and 16");
  if (!(ro.pixels_per_cell > 0)) fail(Status::usage, "--pixels-per-cell must be positive");
  for (const std::string& dir : ro.runs) {
    const std::string manifest_path = dir + "/manifest.json";
    std::error_code ec;
    if (!fs::exists(dir, ec)) fail(Status::no_input, dir + ": no such directory");
    if (!exists_file(manifest_path))
      fail(Status::no_input, dir + ": no manifest.json (not a complete simplify output directory)");
    nlohmann::json m;
    try {
      m = nlohmann::json::parse(io::read_small_file(manifest_path));
    } catch (const Failure&) {
      throw;
    } catch (const std::exception& e) {
      fail(Status::bad_data, manifest_path + ": not valid JSON (" + e.what() + ")");
    }
    RunSpec run;
    run.name = dir;
    try {
      std::string input = m.at("input").value("absolute_path", m.at("input").at("path").get<std::string>());
      run.original = ro.original.empty() ? input : ro.original;
      run.fov_degrees = m.at("options").at("fov_degrees").get<double>();
      for (const auto& level : m.at("levels")) {
        LevelSpec spec;
        spec.cell_size = level.at("cell_size").get<double>();
        spec.switch_distance = level.at("switch_distance").get<double>();
        std::string chosen;
        for (const auto& f : level.at("files")) {
          const std::string name = f.get<std::string>();
          if (name.size() > 4 && name.compare(name.size() - 4, 4, ".ply") == 0) chosen = name;
          if (chosen.empty() && name.size() > 4 && name.compare(name.size() - 4, 4, ".obj") == 0) chosen = name;
        }
        if (chosen.empty())
          fail(Status::usage, manifest_path + ": level " + std::to_string(run.levels.size()) +
                                  " has no PLY or OBJ file to measure (simplify without --no-ply)");
        spec.file = dir + "/" + chosen;
        if (!(spec.switch_distance > 0)) fail(Status::bad_data, manifest_path + ": a level has no positive switch_distance");
        run.levels.push_back(spec);
      }
    } catch (const Failure&) {
      throw;
    } catch (const std::exception& e) {
      fail(Status::bad_data, manifest_path + ": not a simplify manifest (" + e.what() + ")");
    }
    if (!exists_file(run.original))
      fail(Status::no_input, run.original + ": original of " + dir + " not found (give it with --original)");
    runs.push_back(std::move(run));
  }
  if (!ro.lods.empty()) {
    if (ro.original.empty()) fail(Status::usage, "--lod needs --original");
    if (!ro.switch_distances.empty() && ro.switch_distances.size() != ro.lods.size())
      fail(Status::usage, "--switch-distances needs one distance per --lod file");
    RunSpec run;
    run.name = fs::path(ro.original).filename().string();
    run.original = ro.original;
    run.fov_degrees = ro.fov_degrees;
    for (size_t i = 0; i < ro.lods.size(); ++i) {
      LevelSpec spec;
      spec.file = ro.lods[i];
      if (!ro.switch_distances.empty()) {
        spec.switch_distance = ro.switch_distances[i];
        if (!(spec.switch_distance > 0) || !std::isfinite(spec.switch_distance))
          fail(Status::usage, "--switch-distances must be positive");
      }
      run.levels.push_back(spec);
    }
    runs.push_back(std::move(run));
  }
  for (const RunSpec& run : runs)
    for (const LevelSpec& level : run.levels)
      if (!exists_file(level.file)) fail(Status::no_input, level.file + ": no such file");
  return runs;
}

// Nearest-rank statistics of a set of values (any order; reordered for the p95); the sum runs in the given
// order.
ErrorStats stats_of(std::span<float> values) {
  ErrorStats s;
  s.count = values.size();
  if (values.empty()) return s;
  double sum = 0, sum2 = 0, mx = 0;
  for (float v : values) {
    sum += v, sum2 += double(v) * v;
    mx = std::max(mx, double(v));
  }
  s.max = mx;
  s.mean = sum / double(values.size());
  s.rms = std::sqrt(sum2 / double(values.size()));
  const size_t rank = static_cast<size_t>(std::ceil(0.95 * double(values.size()))) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(rank), values.end());
  s.p95 = values[rank];
  return s;
}

// One direction of the Hausdorff distance (Metro): the max over every sample (faces, edges, vertices);
// mean, RMS and p95 over the face samples, which estimate the surface integral and do not depend on the
// sample count (vertex samples sit where a simplification is worst, so pooling them would bias the mean
// by N). Without face samples (a mesh of edges or points only), over every sample.
ErrorStats hausdorff_stats(std::vector<float>& d, size_t faces) {
  float mx = 0;
  for (float v : d) mx = std::max(mx, v);
  ErrorStats s = stats_of(std::span<float>(d.data(), faces > 0 ? faces : d.size()));
  s.max = mx;
  s.count = d.size();
  return s;
}

// ------------------------------------------------------------------------------------------- meshes

using Samples = stream::MeshSamples;

// How the original's chunks are sized, and kept within what the measure stage leaves them (`room`: a
// chunk's own arrays, its triangles' Embree scene and its wire scene together). Embree's bytes per
// triangle are first estimated, then measured on the first chunk large enough to tell (its memory
// monitor's peak, vertex copies aside) and the chunks still to come cut again by that figure, 5 % above
// it; a chunk whose build the monitor still refuses (its limit is what the room leaves beside the chunk's
// own arrays and its wire) is cut again smaller and built again. So no chunk takes more than the room,
// whatever the scene. The chunking never changes a figure (trace_original).
struct ChunkSizing {
  uint64_t room = 0;
  uint64_t cap = 0;               // --chunk-bytes, 0 = none
  double embree_triangle = 96;    // Embree's bytes per triangle (measured 82-94 on the city and the room)
  bool calibrated = false;
  bool colored = false;

  // Estimated bytes of a chunk per primitive and distinct vertex: Embree's and the chunk's own arrays.
  stream::ChunkCosts costs() const {
    const double rgb = colored ? 3 : 0;
    return {.triangle = embree_triangle + 12 + rgb, .line = kChunkCosts.line + 8 + rgb,
            .point = kChunkCosts.point + 4 + rgb, .vertex = colored ? 28.0 : 24.0};
  }
  uint64_t bytes() const { return cap ? std::min(cap, room) : room; }
};

// An original: its scene store, cut into chunks that each fit the memory left for tracing.
struct Original {
  std::string path;
  stream::StoreMeta meta;
  std::unique_ptr<stream::StoreChunks> chunks;
  Samples samples;              // Metro-style samples
  std::vector<float> targets;   // view targets
  double diagonal = 0;
  // A task by ranges: its samples as points (their distances' bounds, distance_bounds).
  std::unique_ptr<core::RayScene> sample_points;
};

stream::SampleOptions sample_options(const ReportOptions& ro) { return {ro.samples, ro.seed, ro.views}; }

void set_samples(Original* o, stream::OriginalSamples&& s) {
  o->samples.xyz = std::move(s.xyz), o->samples.faces = s.faces, o->targets = std::move(s.targets);
}

double bbox_diagonal(const stream::StoreMeta& meta) {
  const double d[3] = {meta.bbox.max[0] - meta.bbox.min[0], meta.bbox.max[1] - meta.bbox.min[1],
                       meta.bbox.max[2] - meta.bbox.min[2]};
  return std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

// Cuts the original into chunks of at most `sizing.bytes()` and draws its samples and view targets.
void load_original(const std::string& store_dir, const stream::StoreMeta& meta, const ReportOptions& ro,
                   const ChunkSizing& sizing, stream::Progress& progress, Original* o) {
  o->meta = meta;
  o->chunks = std::make_unique<stream::StoreChunks>(store_dir, meta);
  o->chunks->plan(sizing.costs(), sizing.bytes());
  progress.report("load", 0.1);
  set_samples(o, stream::draw_original_samples(store_dir, meta, sample_options(ro), *o->chunks, progress));
  o->diagonal = bbox_diagonal(meta);
  progress.report("load", 1);
}

// Distances from samples [first, end) to the nearest primitive of any of `scenes`, lowered into `d` (sample
// order).
void lower_closest_distances(const std::vector<float>& samples, std::span<const core::RayScene* const> scenes,
                             std::vector<float>& d, uint64_t first, uint64_t end) {
  tbb::parallel_for(tbb::blocked_range<size_t>(first, end, 512), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i)
      for (const core::RayScene* s : scenes)
        if (!s->empty()) d[i] = std::min(d[i], s->closest_distance(samples.data() + 3 * i, nullptr, d[i]));
  });
}


// ------------------------------------------------------------------------------------------- images

// Shaded render: grey by the cosine between normal and view axis; thick edges orange, points red. With
// colours (ViewImage::color), every primitive in its own colour, triangles shaded by the same cosine.
std::vector<uint8_t> shade(const core::ViewImage& v, const core::Camera& cam) {
  const uint64_t n = uint64_t{v.resolution} * v.resolution;
  std::vector<uint8_t> rgb(3 * n, 255);
  for (uint64_t p = 0; p < n; ++p) {
    if (!v.covered(p)) continue;
    const float* nn = &v.normal[3 * p];
    const double c = std::fabs(nn[0] * cam.forward[0] + nn[1] * cam.forward[1] + nn[2] * cam.forward[2]);
    const double g = 50 + 180 * c;
    double r = g, gg = g, b = g;
    if (!v.color.empty()) {
      const double f = v.kind[p] == uint8_t(core::PrimitiveKind::triangle) ? (50 + 205 * c) / 255 : 1.0;
      r = f * v.color[3 * p], gg = f * v.color[3 * p + 1], b = f * v.color[3 * p + 2];
      rgb[3 * p] = uint8_t(r), rgb[3 * p + 1] = uint8_t(gg), rgb[3 * p + 2] = uint8_t(b);
      continue;
    }
    if (v.kind[p] == uint8_t(core::PrimitiveKind::edge)) r = 235, gg = 140, b = 30;
    if (v.kind[p] == uint8_t(core::PrimitiveKind::point)) r = 220, gg = 30, b = 30;
    rgb[3 * p] = uint8_t(r), rgb[3 * p + 1] = uint8_t(gg), rgb[3 * p + 2] = uint8_t(b);
  }
  return rgb;
}

// Heat map: agreeing coverage light grey, mismatched pixels yellow (1 px) to red (8 px and more).
std::vector<uint8_t> heat(const core::ViewImage& o, const core::ViewImage& l, std::span<const float> distance) {
  const uint64_t n = uint64_t{o.resolution} * o.resolution;
  std::vector<uint8_t> rgb(3 * n, 255);
  for (uint64_t p = 0; p < n; ++p) {
    const bool a = o.covered(p), b = l.covered(p);
    if (a && b) {
      rgb[3 * p] = rgb[3 * p + 1] = rgb[3 * p + 2] = 215;
    } else if (a != b) {
      const double t = std::clamp((double(distance[p]) - 1) / 7, 0.0, 1.0);
      rgb[3 * p] = 255, rgb[3 * p + 1] = uint8_t(220 * (1 - t)), rgb[3 * p + 2] = 0;
      if (distance[p] >= 8) rgb[3 * p] = 170;
    }
  }
  return rgb;
}

// ------------------------------------------------------------------------------------------- one level

const char* kCsvHeader =
    "view,dir_x,dir_y,dir_z,target_x,target_y,target_z,eye_x,eye_y,eye_z,covered_pixels,mismatched_pixels,"
    "silhouette_max_px,silhouette_mean_px,both_pixels,depth_mean_px,normal_mean_deg,thin_pixels,thin_kept_pixels\n";

std::string fmt_csv_row(unsigned k, const double* dir, const double* target, const double* eye,
                        const core::SilhouetteStats& s, uint64_t both, double depth_mean, double normal_mean) {
  return fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", k, dir[0], dir[1], dir[2], target[0],
                     target[1], target[2], eye[0], eye[1], eye[2], s.covered_either, s.mismatched, s.max, s.mean,
                     both, depth_mean, normal_mean, s.thin, s.thin_kept);
}

struct LevelResult {
  ReportLevel level;
  std::vector<std::string> csv_rows;
  std::vector<io::HtmlView> views;
  uint64_t rays = 0, queries = 0;
  double ray_seconds = 0, query_seconds = 0;
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Where the measure stage's time goes (report.json performance.phases): wall and CPU seconds of the whole
// process while each part ran, summed over chunks and levels (the parts run one at a time, each on every
// thread).
enum Phase : int {
  kChunkRead, kChunkBuild, kWireBuild, kQueriesOnOriginal, kRaysOnOriginal,
  kLevelRead, kLevelBuild, kQueriesOnLevel, kRaysOnLevel, kCompare, kPhaseCount
};
constexpr const char* kPhaseNames[kPhaseCount] = {
    "chunk_read", "chunk_build", "wire_build", "queries_on_original", "rays_on_original",
    "level_read", "level_build", "queries_on_level", "rays_on_level", "compare"};
struct PhaseTimes {
  double wall[kPhaseCount] = {}, cpu[kPhaseCount] = {};
};
class PhaseTimer {
 public:
  PhaseTimer(PhaseTimes* times, Phase phase)
      : times_(times), phase_(phase), t0_(std::chrono::steady_clock::now()), cpu0_(stream::process_cpu_seconds()) {}
  ~PhaseTimer() {
    if (!times_) return;
    times_->wall[phase_] += seconds_since(t0_);
    times_->cpu[phase_] += stream::process_cpu_seconds() - cpu0_;
  }
  PhaseTimer(const PhaseTimer&) = delete;
  PhaseTimer& operator=(const PhaseTimer&) = delete;

 private:
  PhaseTimes* times_;
  Phase phase_;
  std::chrono::steady_clock::time_point t0_;
  double cpu0_;
};

// One level's measurement, in three phases around the original's chunk passes:
// 1. begin_level: read the level, draw its samples, original → level Hausdorff (its own scene);
// 2. chunk passes (trace_original): level → original distances, lowered chunk by chunk; the original's
//    image of each view, accumulated chunk by chunk;
// 3. finish_level: the level's own images, compared with the original's.
struct LevelWork {
  const RunSpec* run = nullptr;
  size_t index = 0;
  LevelResult out;
  Samples samples;                 // of the level
  std::vector<float> to_original;  // per sample: distance to the original's chunks traced so far
  bool distance_known = false;
  double distance = 0;             // camera distance of every view
  double tan_half = 0;
  unsigned views = 0;
  std::vector<core::Camera> cameras;
  std::vector<core::ViewImage> original_views;  // during the passes that trace its views
  uint64_t level_chunks = 1;                    // chunks the level itself was traced in
  // A task of a sharded report (stream/report_shard.h) measures views [view_first, view_end) and the
  // samples [from_first, from_end) of the original and [to_first, to_end) of the level (one machine: all),
  // and keeps its share of the raw values in `share` instead of forming the figures. A level whose distance
  // comes from its Hausdorff max needs every sample first: each task measures them all, and keeps its share.
  bool sharded = false;
  // A task of a report by primitive ranges: every view and sample, against its ranges of the original and
  // of the level (stream/report_shard.h).
  bool ranges = false;
  unsigned view_first = 0, view_end = 0;
  uint64_t from_first = 0, from_end = 0, to_first = 0, to_end = 0;
  stream::ReportLevelShare share;
  PhaseTimes* phases = nullptr;
  double pixel_at(double d, unsigned resolution) const { return 2 * d * tan_half / resolution; }
};

// Per-pixel bytes of a view image held between chunks: depth, normal, kind, centre; and RGB when the
// scene has colours (ViewImage::color).
constexpr uint64_t kViewPixelBytes = 4 + 12 + 1 + 1;
uint64_t view_pixel_bytes(bool colored) { return kViewPixelBytes + (colored ? 3 : 0); }

// What a renderer draws one pixel wide (an original's lines and points, a level's points and its edges of
// thickness 0), at the radii of core::one_pixel_radii for the pixel's width at the level's distance.
struct WireRadii {
  float line = 0, point = 0;
  WireRadii(double pixel, unsigned k) {
    const core::OnePixelRadii r = core::one_pixel_radii(pixel, k);
    line = r.line, point = r.point;
  }
};

// A level (or a chunk of it) as two scenes: its triangles (cast in packets) and its edges and points. Their
// order keeps the key order of the tie rule: triangles, then edges, then points.
struct LevelScene {
  std::unique_ptr<core::RayScene> triangles, wire;
  core::Box box;  // bounds of its primitives, edges and points widened by their radii
  std::vector<const core::RayScene*> list() const { return {triangles.get(), wire.get()}; }
};

// Bounds of the vertices `xyz`.
core::Box bounds_of(std::span<const float> xyz) {
  core::Box b;
  for (int c = 0; c < 3; ++c) b.min[c] = std::numeric_limits<double>::infinity(), b.max[c] = -b.min[c];
  for (size_t v = 0; v + 2 < xyz.size(); v += 3)
    for (int c = 0; c < 3; ++c) b.min[c] = std::min<double>(b.min[c], xyz[v + c]), b.max[c] = std::max<double>(b.max[c], xyz[v + c]);
  return b;
}

// `b` widened by `radius` (what a scene's segments and discs reach past their vertices).
core::Box widened(core::Box b, double radius) {
  for (int c = 0; c < 3; ++c) b.min[c] -= radius, b.max[c] += radius;
  return b;
}

// The colours a level's primitives are rendered in (RGB per triangle, edge, point), for a level with
// vertex colours or materials (else empty): its material's base colour times the mean of its vertices'
// colours.
struct PrimitiveColors {
  std::vector<uint8_t> triangles, edges, points;
};

PrimitiveColors primitive_colors(const core::LodMesh& m) {
  PrimitiveColors out;
  const bool colors = !m.colors.empty(), materials = !m.materials.empty();
  if (!colors && !materials) return out;
  auto fill = [&](const std::vector<uint32_t>& ids, int arity, const std::vector<uint32_t>& material, std::vector<uint8_t>& rgb) {
    const uint64_t n = ids.size() / static_cast<uint64_t>(arity);
    rgb.resize(3 * n);
    for (uint64_t i = 0; i < n; ++i) {
      const uint8_t* v[3];
      for (int j = 0; j < arity; ++j) v[j] = colors ? &m.colors[4 * uint64_t{ids[static_cast<uint64_t>(arity) * i + j]}] : nullptr;
      core::primitive_rgb(colors ? v : nullptr, arity, materials ? &m.materials[material[i]] : nullptr, &rgb[3 * i]);
    }
  };
  fill(m.triangles, 3, m.triangle_materials, out.triangles);
  fill(m.edges, 2, m.edge_materials, out.edges);
  fill(m.points, 1, m.point_materials, out.points);
  return out;
}

// Thick edges at their true width (radius T / 2), and points at the size of what they replace (radius
// size / 2, core/mesh.h), with no floor: a part of the original thinner than the rays can resolve is missed
// on both sides alike. An edge of thickness 0 (an original line kept as it is) and a point of size 0 or of
// no size (an input point, a level file without sizes) are drawn one pixel wide, as the original's are.
// `colors`: the primitives' colours, or empty spans.
struct PrimitiveColorSpans {
  std::span<const uint8_t> triangles, edges, points;
};
LevelScene build_level_scene(const core::LodMesh& mesh, const WireRadii& wire, uint64_t embree_limit,
                             const PrimitiveColorSpans& colors = {}) {
  auto vec = [](std::span<const uint8_t> s) { return std::vector<uint8_t>(s.begin(), s.end()); };
  LevelScene scene;
  scene.triangles = std::make_unique<core::RayScene>(embree_limit);
  scene.triangles->add_triangles(mesh.positions, mesh.triangles);
  if (!colors.triangles.empty()) scene.triangles->set_colors(vec(colors.triangles));
  scene.triangles->commit();
  scene.wire = std::make_unique<core::RayScene>(embree_limit);
  std::vector<float> radius(mesh.edge_count());
  for (size_t e = 0; e < radius.size(); ++e) radius[e] = mesh.thickness[e] > 0 ? mesh.thickness[e] / 2 : wire.line;
  scene.wire->add_segments(mesh.positions, mesh.edges, radius);
  if (!colors.edges.empty() && !mesh.edges.empty()) scene.wire->set_colors(vec(colors.edges));
  std::vector<float> point_radius(mesh.point_count(), wire.point);
  for (size_t p = 0; p < mesh.point_size.size(); ++p)
    if (mesh.point_size[p] > 0) point_radius[p] = mesh.point_size[p] / 2;
  scene.wire->add_points(mesh.positions, mesh.points, point_radius);
  if (!colors.points.empty() && !mesh.points.empty()) scene.wire->set_colors(vec(colors.points));
  scene.wire->commit();
  float reach = 0;
  for (float r : radius) reach = std::max(reach, r);
  for (float r : point_radius) reach = std::max(reach, r);
  scene.box = widened(bounds_of(mesh.positions), 1.01 * double(reach));
  return scene;
}

uint64_t primitive_count(const core::LodMesh& m) { return m.triangle_count() + m.edge_count() + m.point_count(); }

// A level too large for one scene is traced the same way as an original, in chunks: consecutive ranges of
// its primitives (triangles, then edges, then points: the order of build_level_scene's geometries, so the
// tie rule picks the same hit), each with its own vertices. A report task by ranges cuts only its range
// [range_first, range_end) of them (none when it is empty).
class LevelChunks {
 public:
  LevelChunks(const core::LodMesh& m, uint64_t bytes) : LevelChunks(m, bytes, 0, primitive_count(m)) {}
  LevelChunks(const core::LodMesh& m, uint64_t bytes, uint64_t range_first, uint64_t range_end)
      : m_(m), colors_(primitive_colors(m)) {
    const uint64_t prims = primitive_count(m);
    whole_ = range_first == 0 && range_end == prims;
    const double per_vertex = prims ? kChunkCosts.vertex * double(m.vertex_count()) / double(prims) : 0;
    const double cost[3] = {kChunkCosts.triangle + per_vertex, kChunkCosts.line + per_vertex, kChunkCosts.point + per_vertex};
    const uint64_t count[3] = {m.triangle_count(), m.edge_count(), m.point_count()};
    const auto kind_of = [&](uint64_t g) { return g < count[0] ? 0 : g < count[0] + count[1] ? 1 : 2; };
    if (range_first >= range_end) return;
    double total = 0;
    uint64_t base = 0;
    for (int k = 0; k < 3; base += count[k], ++k) {
      const uint64_t lo = std::max(range_first, base), hi = std::min(range_end, base + count[k]);
      if (lo < hi) total += cost[k] * double(hi - lo);
    }
    if (total <= double(bytes)) {
      ranges_.push_back({range_first, range_end});
      return;
    }
    uint64_t first = range_first;
    double used = 0;
    for (uint64_t g = range_first; g < range_end; ++g) {
      const int k = kind_of(g);
      if (g > first && used + cost[k] > double(bytes)) ranges_.push_back({first, g}), first = g, used = 0;
      used += cost[k];
    }
    ranges_.push_back({first, range_end});
  }
  size_t size() const { return ranges_.size(); }
  // The scene of chunk c; the whole level's for a level in one chunk.
  LevelScene scene(size_t c, const WireRadii& wire, uint64_t embree_limit) {
    auto slice = [](const std::vector<uint8_t>& rgb, uint64_t from, uint64_t n) {
      return rgb.empty() ? std::span<const uint8_t>() : std::span<const uint8_t>(rgb.data() + 3 * from, 3 * n);
    };
    if (ranges_.size() == 1 && whole_)
      return build_level_scene(m_, wire, embree_limit,
                               {slice(colors_.triangles, 0, m_.triangle_count()), slice(colors_.edges, 0, m_.edge_count()),
                                slice(colors_.points, 0, m_.point_count())});
    const auto [first, end] = ranges_[c];
    core::LodMesh part;
    if (local_.empty()) local_.assign(m_.vertex_count(), UINT32_MAX);
    std::vector<uint32_t> touched;
    // Appends the chunk's primitives of one column (global ids from `base`); returns the first one's index.
    const auto take = [&](const std::vector<uint32_t>& ids, uint64_t arity, uint64_t base, std::vector<uint32_t>& out) {
      const uint64_t n = ids.size() / arity;
      const uint64_t lo = std::max(first, base) - base, hi = std::min(end, base + n) - base;
      for (uint64_t i = lo; i < hi; ++i)
        for (uint64_t k = 0; k < arity; ++k) {
          const uint32_t v = ids[i * arity + k];
          if (local_[v] == UINT32_MAX) {
            local_[v] = static_cast<uint32_t>(part.positions.size() / 3);
            part.positions.insert(part.positions.end(), m_.positions.begin() + 3 * v, m_.positions.begin() + 3 * v + 3);
            touched.push_back(v);
          }
          out.push_back(local_[v]);
        }
      return lo;
    };
    const uint64_t t = m_.triangle_count(), e = m_.edge_count();
    PrimitiveColorSpans colors;
    if (first < t) {
      const uint64_t from = take(m_.triangles, 3, 0, part.triangles);
      colors.triangles = slice(colors_.triangles, from, part.triangles.size() / 3);
    }
    if (first < t + e && end > t) {
      const uint64_t from = take(m_.edges, 2, t, part.edges);
      part.thickness.assign(m_.thickness.begin() + static_cast<std::ptrdiff_t>(from),
                            m_.thickness.begin() + static_cast<std::ptrdiff_t>(from + part.edges.size() / 2));
      colors.edges = slice(colors_.edges, from, part.edges.size() / 2);
    }
    if (end > t + e) {
      const uint64_t from = take(m_.points, 1, t + e, part.points);
      colors.points = slice(colors_.points, from, part.points.size());
      if (!m_.point_size.empty())
        part.point_size.assign(m_.point_size.begin() + static_cast<std::ptrdiff_t>(from),
                               m_.point_size.begin() + static_cast<std::ptrdiff_t>(from + part.points.size()));
    }
    for (uint32_t v : touched) local_[v] = UINT32_MAX;
    return build_level_scene(part, wire, embree_limit, colors);
  }

 private:
  const core::LodMesh& m_;
  PrimitiveColors colors_;
  std::vector<std::pair<uint64_t, uint64_t>> ranges_;
  bool whole_ = true;  // the ranges cover every primitive
  std::vector<uint32_t> local_;  // store vertex -> chunk vertex, UINT32_MAX outside the chunk being made
};

// Bytes of a level in memory (its arrays), for the share of the budget its chunks get.
uint64_t mesh_bytes(const core::LodMesh& m) {
  return 4 * (m.positions.size() + m.normals.size() + m.triangles.size() + m.edges.size() + m.thickness.size() + m.points.size() + m.point_size.size());
}

// What is left of `bytes` once `held` is taken, at least 16 MiB (the memory monitor stays the guard).
uint64_t left_of(uint64_t bytes, uint64_t held) { return std::max<uint64_t>(bytes - std::min(bytes, held), 16ull << 20); }

// What a level's scenes may take when every view's image of it is held beside the level: `embree_limit`
// less the level's arrays and those images.
uint64_t level_scenes_room(const core::LodMesh& mesh, const LevelWork& w, const ReportOptions& ro, uint64_t embree_limit) {
  const uint64_t pixels = uint64_t{ro.resolution} * ro.resolution;
  return left_of(embree_limit, mesh_bytes(mesh) + pixels * view_pixel_bytes(!mesh.colors.empty() || !mesh.materials.empty()) * w.views);
}

// Estimated bytes of a level's chunk within `limit` (its Embree scene's guard): three quarters of it, the
// rest for the chunk's own copy of its part of the level (about a quarter of its scene's bytes).
uint64_t level_chunk_bytes(uint64_t limit, uint64_t chunk_cap) {
  return chunk_cap ? std::min(chunk_cap, limit / 4 * 3) : limit / 4 * 3;
}

// ------------------------------------------------------------------------------------------- ranges
// A report by primitive ranges (stream/report_shard.h): the tasks draw each original's samples and view
// targets as units they all take up (stream/report_samples.h); task I traces the I-th N-th of the
// original's primitives and of every level's.

// Every level has its switching distance: the tasks can share the work by primitive ranges.
bool every_distance_known(const std::vector<RunSpec>& runs) {
  for (const RunSpec& r : runs)
    for (const LevelSpec& l : r.levels)
      if (!(l.switch_distance > 0)) return false;
  return true;
}

// Where the tasks' sampling units of original g go (stream/report_samples.h).
std::string sample_units_dir(const stream::WorkDir& work, size_t g) {
  return work.file(g == 0 ? std::string("report-samples") : fmt::format("report-samples-{}", g));
}

// Samples as a scene of points (closest_distance: to the nearest one).
std::unique_ptr<core::RayScene> sample_point_scene(const std::vector<float>& xyz) {
  auto scene = std::make_unique<core::RayScene>();
  std::vector<uint32_t> ids(xyz.size() / 3);
  std::iota(ids.begin(), ids.end(), 0u);
  scene->add_points(xyz, ids, 1e-30f);
  scene->commit();
  return scene;
}

// A task by ranges starts each level sample's distance to the original at a bound no smaller than it: the
// distance to the nearest of the original's own samples (points on it), widened by their rounding (a
// sample point lies within a few ulps of its primitive: 2^-18 of the largest coordinate, with 2^-10 of the
// distance). Its chunks farther than that are culled at their root, so a task pays for the samples near
// its ranges rather than for every sample. The least distance over the tasks is one machine's: the task
// that holds the nearest primitive finds it below the bound (closest_distance's result does not depend on
// where its search starts), and no task reports less than it.
std::vector<float> distance_bounds(const std::vector<float>& samples, const core::RayScene& other_points,
                                   const std::vector<float>& other_samples) {
  float magnitude = 0;
  for (const std::vector<float>* xyz : {&samples, &other_samples})
    for (float c : *xyz) magnitude = std::max(magnitude, std::fabs(c));
  const double slack = double(magnitude) * 0x1p-18;
  std::vector<float> d(samples.size() / 3, std::numeric_limits<float>::infinity());
  if (other_points.empty()) return d;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, d.size(), 512), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const double u = other_points.closest_distance(samples.data() + 3 * i);
      d[i] = std::nextafter(static_cast<float>(u + u * 0x1p-10 + slack), std::numeric_limits<float>::infinity());
    }
  });
  return d;
}

// Task I's range of the original: its primitives' chunks; the samples and targets drawn by the tasks'
// sampling units, which it takes part in (with its index first).
void load_original_range(const std::string& store_dir, const stream::StoreMeta& meta, const ReportOptions& ro,
                         const ChunkSizing& sizing, const std::string& units_dir, stream::Progress& progress, Original* o) {
  o->meta = meta;
  set_samples(o, stream::draw_original_samples_in_units(store_dir, meta, sample_options(ro), units_dir, ro.shard_count,
                                                        ro.shard_index, sizing.bytes(), progress));
  const auto [first, end] = stream::share_of(meta.primitives(), ro.shard_index, ro.shard_count);
  o->chunks = std::make_unique<stream::StoreChunks>(store_dir, meta);
  o->chunks->plan_range(sizing.costs(), sizing.bytes(), first, end);
  o->diagonal = bbox_diagonal(meta);
  o->sample_points = sample_point_scene(o->samples.xyz);
  progress.report("load", 1);
}

// A task's shares of the level's views and samples (stream/report_shard.h); one machine's: all of them.
void set_shares(const Original& o, LevelWork& w, const ReportOptions& ro) {
  w.sharded = ro.shard_count > 0;
  const auto views = stream::share_of(w.views, ro.shard_index, w.ranges ? 0 : ro.shard_count);
  w.view_first = static_cast<unsigned>(views.first), w.view_end = static_cast<unsigned>(views.second);
  const unsigned count = w.distance_known && !w.ranges ? ro.shard_count : 0;
  std::tie(w.from_first, w.from_end) = stream::share_of(o.samples.xyz.size() / 3, ro.shard_index, count);
  std::tie(w.to_first, w.to_end) = stream::share_of(w.samples.xyz.size() / 3, ro.shard_index, count);
}

// What a task keeps of one direction's distances: its share (all of them were measured when the level's
// distance comes from its Hausdorff max).
std::vector<float> kept_share(const std::vector<float>& d, const ReportOptions& ro) {
  const auto [first, end] = stream::share_of(d.size(), ro.shard_index, ro.shard_count);
  return std::vector<float>(d.begin() + static_cast<std::ptrdiff_t>(first), d.begin() + static_cast<std::ptrdiff_t>(end));
}

// The level's view figures from the silhouette counts and the depth and normal errors of every view (in
// view order: the sums run in it).
void view_figures(ReportLevel& L, const core::SilhouetteCounts& total, std::vector<float>& depth_err, std::vector<float>& normal_err) {
  const core::SilhouetteStats s = core::silhouette_stats(total);
  L.silhouette.max = s.max, L.silhouette.p95 = s.p95, L.silhouette.mean = s.mean, L.silhouette.count = s.mismatched;
  double sum2 = 0;
  for (const core::SquaredDistanceCount& bin : total.histogram) sum2 += double(bin.squared) * double(bin.count);
  L.silhouette.rms = s.mismatched ? std::sqrt(sum2 / double(s.mismatched)) : 0;
  L.mismatched_pixels = s.mismatched;
  L.covered_pixels = s.covered_either;
  L.mismatch_fraction = s.mismatch_fraction;
  L.thin_pixels = s.thin, L.thin_kept_pixels = s.thin_kept, L.thin_kept_fraction = s.thin_kept_fraction;
  L.depth = stats_of(depth_err);
  L.normal = stats_of(normal_err);
}

// embree_limit: what the level's scene may take; chunk_cap: --chunk-bytes (0 = none), which cuts a level
// into chunks of at most that many bytes as it does the original.
void begin_level(const Original& o, LevelWork& w, const ReportOptions& ro, uint64_t embree_limit, uint64_t chunk_cap) {
  const auto t0 = std::chrono::steady_clock::now();
  const LevelSpec& spec = w.run->levels[w.index];
  ReportLevel& L = w.out.level;
  L.file = spec.file;
  L.cell_size = spec.cell_size;
  std::optional<PhaseTimer> read_time(std::in_place, w.phases, kLevelRead);
  const core::LodMesh mesh = io::read_lod_mesh(spec.file);
  L.vertices = mesh.vertex_count(), L.triangles = mesh.triangle_count(), L.edges = mesh.edge_count(),
  L.points = mesh.point_count();
  if (L.triangles + L.edges + L.points == 0) fail(Status::bad_data, spec.file + ": the level has no primitives");
  w.tan_half = std::tan(w.run->fov_degrees * M_PI / 360.0);
  w.distance_known = spec.switch_distance > 0;
  w.distance = w.distance_known ? spec.switch_distance : 1.0;
  w.views = std::min<unsigned>(ro.views, static_cast<unsigned>(o.targets.size() / 3));
  w.samples = stream::sample_mesh(mesh, ro.samples, ro.seed, stream::kStreamLodSamples);
  w.to_original.assign(w.samples.xyz.size() / 3, std::numeric_limits<float>::infinity());
  read_time.reset();
  set_shares(o, w, ro);
  if (w.ranges) {  // the original's samples meet the task's range of the level in trace_level_range
    PhaseTimer t(w.phases, kQueriesOnOriginal);
    w.to_original = distance_bounds(w.samples.xyz, *o.sample_points, o.samples.xyz);
    L.seconds += seconds_since(t0);
    return;
  }
  // Segment and point radii do not enter the point queries: any distance builds the same query scene.
  const uint64_t limit = left_of(embree_limit, mesh_bytes(mesh));
  LevelChunks chunks(mesh, level_chunk_bytes(limit, chunk_cap));
  w.level_chunks = chunks.size();
  std::vector<float> d(o.samples.xyz.size() / 3, std::numeric_limits<float>::infinity());
  for (size_t c = 0; c < chunks.size(); ++c) {
    std::optional<PhaseTimer> build_time(std::in_place, w.phases, kLevelBuild);
    const LevelScene scene = chunks.scene(c, WireRadii(w.pixel_at(w.distance, ro.resolution), ro.supersample), limit);
    build_time.reset();
    PhaseTimer query_time(w.phases, kQueriesOnLevel);
    const auto t_q = std::chrono::steady_clock::now();
    lower_closest_distances(o.samples.xyz, scene.list(), d, w.from_first, w.from_end);
    w.out.queries += w.from_end - w.from_first;
    w.out.query_seconds += seconds_since(t_q);
  }
  if (w.sharded) w.share.original_to_lod = kept_share(d, ro), w.share.original_faces = o.samples.faces;
  if (!w.sharded || !w.distance_known) L.original_to_lod = hausdorff_stats(d, o.samples.faces);
  L.seconds += seconds_since(t0);
}

// After every chunk lowered the level's distances: the two-sided figures, and the camera distance when none
// was given (where the Hausdorff max spans pixels_per_cell pixels, at least a tiny positive distance).
void finish_hausdorff(const Original& o, LevelWork& w, const ReportOptions& ro) {
  ReportLevel& L = w.out.level;
  if (w.sharded) {
    w.share.lod_to_original = w.ranges ? std::move(w.to_original) : kept_share(w.to_original, ro);
    w.share.lod_faces = w.samples.faces;
    if (w.distance_known) {  // the merge forms the figures from every task's share
      w.to_original = {};
      return;
    }
  }
  L.lod_to_original = hausdorff_stats(w.to_original, w.samples.faces);
  w.to_original = {};
  const ErrorStats& a = L.lod_to_original;
  const ErrorStats& b = L.original_to_lod;
  L.hausdorff_max = std::max(a.max, b.max);
  L.hausdorff_mean = std::max(a.mean, b.mean);
  L.hausdorff_rms = std::max(a.rms, b.rms);
  if (!w.distance_known) {
    w.distance = std::max(L.hausdorff_max * ro.resolution / (ro.pixels_per_cell * 2 * w.tan_half), o.diagonal * 1e-6);
    w.distance_known = true;
  }
  L.switch_distance = w.distance;
  L.pixel_size = w.pixel_at(w.distance, ro.resolution);
  if (o.diagonal > 0) {
    L.hausdorff_max_percent = 100 * L.hausdorff_max / o.diagonal;
    L.hausdorff_mean_percent = 100 * L.hausdorff_mean / o.diagonal;
  }
  L.hausdorff_max_pixels = L.hausdorff_max / L.pixel_size;
  L.hausdorff_mean_pixels = L.hausdorff_mean / L.pixel_size;
}

// View k: from the Fibonacci direction k, at the level's distance from the original's k-th target.
void view_geometry(const Original& o, const LevelWork& w, const ReportOptions& ro, unsigned k, double dir[3],
                   double target[3], double eye[3]) {
  core::fibonacci_direction(k, ro.views, dir);
  for (int c = 0; c < 3; ++c) target[c] = o.targets[3 * k + c], eye[c] = target[c] + dir[c] * w.distance;
}

void begin_views(const Original& o, LevelWork& w, const ReportOptions& ro) {
  w.cameras.clear();
  for (unsigned k = 0; k < w.views; ++k) {
    double dir[3], target[3], eye[3];
    view_geometry(o, w, ro, k, dir, target, eye);
    w.cameras.push_back(core::look_at(eye, target, w.run->fov_degrees, ro.resolution));
    w.cameras.back().supersample = ro.supersample;
  }
  w.original_views.assign(w.views, core::ViewImage{});
}

using stream::ChunkScene;

// A chunk's lines and points drawn one pixel wide (WireRadii) for a level's distance.
std::unique_ptr<core::RayScene> build_wire(const stream::ChunkGeometry& g, const WireRadii& wire, uint64_t embree_limit) {
  return stream::build_wire(g, wire.line, wire.point, embree_limit);
}

struct TraceTotals {
  uint64_t chunks = 0;              // chunk scenes built
  uint64_t embree_peak_bytes = 0;   // the largest chunk scene's peak, as Embree's memory monitor counts it
  uint64_t chunk_triangles = 0;     // triangles of that chunk
  uint64_t replans = 0;             // times the chunks still to come were cut again (ChunkSizing)
  PhaseTimes* phases = nullptr;
};

// The wire scene's estimated bytes (Embree's, as kChunkCosts counts them).
uint64_t wire_bytes(const stream::ChunkGeometry& g) {
  return static_cast<uint64_t>(kChunkCosts.line * double(g.lines.size() / 2) + kChunkCosts.point * double(g.points.size()));
}

// Reads and builds chunk `c` within the room, cutting the chunks from `c` on again while its build is
// refused (see ChunkSizing).
std::unique_ptr<ChunkScene> load_sized_chunk(const Original& o, size_t c, ChunkSizing& sizing, TraceTotals& totals) {
  for (;;) {
    stream::ChunkGeometry g;
    {
      PhaseTimer t(totals.phases, kChunkRead);
      o.chunks->read(c, &g, true);
    }
    const uint64_t own = stream::chunk_geometry_bytes(g) + wire_bytes(g);
    const uint64_t vertices = g.xyz.size() / 3, triangles = g.triangles.size() / 3;
    const uint64_t limit = left_of(sizing.room, own);
    std::unique_ptr<ChunkScene> chunk;
    {
      PhaseTimer t(totals.phases, kChunkBuild);
      chunk = stream::build_chunk_scene(std::move(g), limit);
    }
    if (chunk) {
      ++totals.chunks;
      const uint64_t peak = chunk->triangles->peak_embree_bytes();
      if (peak > totals.embree_peak_bytes) totals.embree_peak_bytes = peak, totals.chunk_triangles = chunk->triangle_count;
      if (!sizing.calibrated && triangles >= (1u << 16)) {
        sizing.calibrated = true;
        const double measured = 1.05 * double(peak - std::min(peak, 12 * vertices)) / double(triangles);
        if (measured > sizing.embree_triangle || measured < 0.97 * sizing.embree_triangle) {
          sizing.embree_triangle = measured;
          PhaseTimer t(totals.phases, kChunkRead);
          o.chunks->replan(c + 1, sizing.costs(), sizing.bytes());
          ++totals.replans;
        }
      }
      return chunk;
    }
    const stream::StoreChunk& sc = o.chunks->chunks()[c];
    if (sc.end - sc.first <= 1)
      fail(Status::usage, "a primitive of the original needs more memory for its ray-casting scene than --memory leaves");
    // It needed more than `limit` for its triangles: cut from here by at least that, and a quarter more.
    const double needed = triangles ? double(limit - std::min(limit, 12 * vertices)) / double(triangles) : 0;
    sizing.embree_triangle = std::max(1.25 * sizing.embree_triangle, 1.1 * needed);
    sizing.calibrated = true;
    PhaseTimer t(totals.phases, kChunkRead);
    o.chunks->replan(c, sizing.costs(), sizing.bytes());
    ++totals.replans;
  }
}

// Bytes a built chunk holds (its arrays and its Embree scene now).
uint64_t cached_bytes(const ChunkScene& chunk) {
  return stream::chunk_geometry_bytes(chunk.geometry) + chunk.triangles->embree_bytes();
}

// Estimated bytes of a level in one scene, beside its mesh: as an original's chunk (ChunkSizing::costs).
uint64_t level_scene_bytes(const ReportLevel& level, const ChunkSizing& sizing) {
  const stream::ChunkCosts c = sizing.costs();
  return static_cast<uint64_t>(c.triangle * double(level.triangles) + c.line * double(level.edges) +
                               c.point * double(level.points) + c.vertex * double(level.vertices));
}

// One pass over the original's chunks: each chunk's scene is built, the samples of `queries` levels are
// lowered to their distance to it, and the views of `viewed` levels accumulate its image; then it is
// freed. Every figure is the same for any chunking: distances are minima, and view pixels keep the hit
// with the lowest (distance, primitive order) over all chunks (core/nearest_hit.h), chunks being
// consecutive in the store's primitive order. With one chunk, its scene is kept in `cache` for the next pass.
void trace_original(const Original& o, const std::vector<LevelWork*>& queries, const std::vector<LevelWork*>& viewed,
                    const ReportOptions& ro, ChunkSizing& sizing, stream::Progress& progress,
                    std::unique_ptr<ChunkScene>& cache, TraceTotals& totals) {
  for (size_t c = 0; c < o.chunks->chunks().size(); ++c) {
    std::unique_ptr<ChunkScene> chunk = std::move(cache);
    if (!chunk) chunk = load_sized_chunk(o, c, sizing, totals);
    // The wire scenes take what the room leaves beside the chunk.
    const uint64_t wire_limit = left_of(sizing.room, stream::chunk_geometry_bytes(chunk->geometry) + chunk->triangles->embree_bytes());
    const bool wire = chunk->has_wire();
    if (!queries.empty()) {
      // Radii do not enter the point queries: one wire scene serves every level.
      std::unique_ptr<core::RayScene> lines;
      if (wire) {
        PhaseTimer t(totals.phases, kWireBuild);
        lines = build_wire(chunk->geometry, WireRadii(1.0, 1), wire_limit);
      }
      const core::RayScene* scenes[] = {chunk->triangles.get(), lines ? lines.get() : chunk->triangles.get()};
      for (LevelWork* w : queries) {
        PhaseTimer t(totals.phases, kQueriesOnOriginal);
        const auto t0 = std::chrono::steady_clock::now();
        lower_closest_distances(w->samples.xyz, std::span<const core::RayScene* const>(scenes, lines ? 2 : 1), w->to_original,
                                w->to_first, w->to_end);
        w->out.queries += w->to_end - w->to_first;
        w->out.query_seconds += seconds_since(t0);
        w->out.level.seconds += seconds_since(t0);
      }
    }
    // Rays that cannot reach the chunk's bounds are not cast: they would hit nothing in it.
    const core::Box chunk_box = viewed.empty() ? core::Box{} : bounds_of(chunk->geometry.xyz);
    for (LevelWork* w : viewed) {
      const auto t0 = std::chrono::steady_clock::now();
      const WireRadii radii(w->pixel_at(w->distance, ro.resolution), ro.supersample);
      std::unique_ptr<core::RayScene> lines;
      if (wire) {
        PhaseTimer t(totals.phases, kWireBuild);
        lines = build_wire(chunk->geometry, radii, wire_limit);
      }
      const core::RayScene* scenes[] = {chunk->triangles.get(), lines.get()};
      PhaseTimer t(totals.phases, kRaysOnOriginal);
      const core::Box box = widened(chunk_box, wire ? 1.01 * std::max(radii.line, radii.point) : 0.0);
      for (unsigned k = w->view_first; k < w->view_end; ++k)
        w->out.rays += core::cast_view(std::span<const core::RayScene* const>(scenes, lines ? 2 : 1), w->cameras[k],
                                       &w->original_views[k], true, core::project_box(box, w->cameras[k]));
      w->out.ray_seconds += seconds_since(t0);
      w->out.level.seconds += seconds_since(t0);
    }
    progress.report("measure", double(c + 1) / double(o.chunks->chunks().size()));
    if (o.chunks->chunks().size() == 1) cache = std::move(chunk);
  }
}

// What comparing a view needs beside its two images, reused from view to view.
struct CompareScratch {
  core::SilhouetteScratch silhouette;
  std::vector<float> distance_image;
};

// View k's images of the original and the level compared: its silhouette counts, depth and normal errors
// (appended to w.share), its CSV row and, for the first html_views views, its renders.
void compare_view(const Original& o, LevelWork& w, const ReportOptions& ro, unsigned k, const core::ViewImage& vo,
                  const core::ViewImage& vl, CompareScratch& scratch) {
  const unsigned h = ro.resolution;
  const uint64_t pixels = uint64_t{h} * h;
  double dir[3], target[3], eye[3];
  view_geometry(o, w, ro, k, dir, target, eye);
  const core::Camera& cam = w.cameras[k];
  scratch.distance_image.resize(pixels);
  core::SilhouetteCounts view;
  core::compare_silhouettes(vo.kind, vl.kind, int(h), int(h), scratch.silhouette, view, scratch.distance_image);
  core::add_silhouette_counts(w.share.silhouette, view);
  const core::SilhouetteStats vs = core::silhouette_stats(view);
  double depth_sum = 0, normal_sum = 0;
  uint64_t both = 0;
  for (uint64_t p = 0; p < pixels; ++p) {
    if (!vo.covered(p) || !vl.covered(p)) continue;
    const float px = static_cast<float>(cam.pixel_size(vo.depth[p]));
    const float de = px > 0 ? std::fabs(vo.depth[p] - vl.depth[p]) / px : 0.0f;
    const float* n0 = &vo.normal[3 * p];
    const float* n1 = &vl.normal[3 * p];
    const double c = std::clamp(double(n0[0]) * n1[0] + double(n0[1]) * n1[1] + double(n0[2]) * n1[2], -1.0, 1.0);
    const float ne = static_cast<float>(std::acos(c) * 180 / M_PI);
    w.share.depth_err.push_back(de), w.share.normal_err.push_back(ne);
    depth_sum += de, normal_sum += ne, ++both;
  }
  w.out.csv_rows.push_back(fmt_csv_row(k, dir, target, eye, vs, both, both ? depth_sum / both : 0, both ? normal_sum / both : 0));
  if (k < ro.html_views) {
    io::HtmlView hv;
    hv.view = k;
    hv.resolution = h;
    hv.original_rgb = shade(vo, cam);
    hv.lod_rgb = shade(vl, cam);
    hv.heat_rgb = heat(vo, vl, scratch.distance_image);
    w.out.views.push_back(std::move(hv));
  }
}

// The level's own images, compared with the original's view by view.
void finish_level(const Original& o, LevelWork& w, const ReportOptions& ro, uint64_t embree_limit, uint64_t chunk_cap) {
  const auto t0 = std::chrono::steady_clock::now();
  ReportLevel& L = w.out.level;
  std::optional<PhaseTimer> read_time(std::in_place, w.phases, kLevelRead);
  const core::LodMesh mesh = io::read_lod_mesh(w.run->levels[w.index].file);
  read_time.reset();
  const unsigned h = ro.resolution;
  const uint64_t pixels = uint64_t{h} * h;
  const WireRadii wire(w.pixel_at(w.distance, ro.resolution), ro.supersample);
  // In one chunk, each view is cast and compared in turn; in several, every view's image is accumulated
  // chunk by chunk first (the level's images then take as much memory as the original's).
  const uint64_t limit = level_scenes_room(mesh, w, ro, embree_limit);
  LevelChunks chunks(mesh, level_chunk_bytes(limit, chunk_cap));
  w.level_chunks = std::max<uint64_t>(w.level_chunks, chunks.size());
  std::vector<core::ViewImage> lod_views(chunks.size() > 1 ? w.views : 1);
  LevelScene lod;
  if (chunks.size() > 1) {
    for (size_t c = 0; c < chunks.size(); ++c) {
      {
        PhaseTimer t(w.phases, kLevelBuild);
        lod = chunks.scene(c, wire, limit);
      }
      const auto lod_scenes = lod.list();
      PhaseTimer t(w.phases, kRaysOnLevel);
      const auto t_r = std::chrono::steady_clock::now();
      for (unsigned k = w.view_first; k < w.view_end; ++k)
        w.out.rays += core::cast_view(lod_scenes, w.cameras[k], &lod_views[k], true, core::project_box(lod.box, w.cameras[k]));
      w.out.ray_seconds += seconds_since(t_r);
    }
    lod = {};
  } else {
    PhaseTimer t(w.phases, kLevelBuild);
    lod = chunks.scene(0, wire, limit);
  }
  CompareScratch scratch;
  // At most a value a pixel of every view of the share: reserved, so that neither grows by doubling.
  w.share.depth_err.reserve(pixels * (w.view_end - w.view_first)), w.share.normal_err.reserve(pixels * (w.view_end - w.view_first));
  for (unsigned k = w.view_first; k < w.view_end; ++k) {
    const core::Camera& cam = w.cameras[k];
    core::ViewImage& vl = lod.triangles ? lod_views[0] : lod_views[k];
    if (lod.triangles) {
      const auto lod_scenes = lod.list();
      PhaseTimer t(w.phases, kRaysOnLevel);
      const auto t_r = std::chrono::steady_clock::now();
      w.out.rays += core::cast_view(lod_scenes, cam, &vl, false, core::project_box(lod.box, cam));
      w.out.ray_seconds += seconds_since(t_r);
    }
    {
      PhaseTimer compare_time(w.phases, kCompare);
      compare_view(o, w, ro, k, w.original_views[k], vl, scratch);
    }
    w.original_views[k] = {};
    if (!lod.triangles) lod_views[k] = {};
  }
  w.original_views = {};
  lod_views = {};
  if (!w.sharded) {  // a task hands the counts and errors to the merge
    view_figures(L, w.share.silhouette, w.share.depth_err, w.share.normal_err);
    w.share = {};
  }
  L.seconds += seconds_since(t0);
}

// A task by ranges: its range of the level's primitives, cut into chunks that fit, traced into every view
// (the level's image of those primitives, written to `views` view by view), and every sample of the
// original lowered to its distance to them (w.share.original_to_lod).
void trace_level_range(const Original& o, LevelWork& w, const ReportOptions& ro, uint64_t embree_limit,
                       uint64_t chunk_cap, stream::ViewHitsWriter& views) {
  const auto t0 = std::chrono::steady_clock::now();
  std::optional<PhaseTimer> read_time(std::in_place, w.phases, kLevelRead);
  const core::LodMesh mesh = io::read_lod_mesh(w.run->levels[w.index].file);
  read_time.reset();
  const WireRadii wire(w.pixel_at(w.distance, ro.resolution), ro.supersample);
  const uint64_t limit = level_scenes_room(mesh, w, ro, embree_limit);
  const auto [first, end] = stream::share_of(primitive_count(mesh), ro.shard_index, ro.shard_count);
  LevelChunks chunks(mesh, level_chunk_bytes(limit, chunk_cap), first, end);
  w.level_chunks = std::max<uint64_t>(w.level_chunks, chunks.size());
  std::vector<core::ViewImage> images(w.views);
  // No bounds this way (distance_bounds): a level's range is small, and its queries cost less than the bounds.
  std::vector<float> d(o.samples.xyz.size() / 3, std::numeric_limits<float>::infinity());
  for (size_t c = 0; c < chunks.size(); ++c) {
    std::optional<PhaseTimer> build_time(std::in_place, w.phases, kLevelBuild);
    const LevelScene lod = chunks.scene(c, wire, limit);
    build_time.reset();
    const auto lod_scenes = lod.list();
    {
      PhaseTimer t(w.phases, kQueriesOnLevel);
      const auto t_q = std::chrono::steady_clock::now();
      lower_closest_distances(o.samples.xyz, lod_scenes, d, 0, d.size());
      w.out.queries += d.size();
      w.out.query_seconds += seconds_since(t_q);
    }
    PhaseTimer t(w.phases, kRaysOnLevel);
    const auto t_r = std::chrono::steady_clock::now();
    for (unsigned k = 0; k < w.views; ++k)
      w.out.rays += core::cast_view(lod_scenes, w.cameras[k], &images[k], true, core::project_box(lod.box, w.cameras[k]));
    w.out.ray_seconds += seconds_since(t_r);
  }
  for (unsigned k = 0; k < w.views; ++k) {
    views.add(images[k]);
    images[k] = {};
  }
  views.commit();
  w.share.original_to_lod = std::move(d), w.share.original_faces = o.samples.faces;
  w.share.targets = o.targets;
  w.out.level.seconds += seconds_since(t0);
}

// A task by ranges: the original's images of a level's views (its range of the original), written view by
// view and freed.
void write_original_views(LevelWork& w, const std::string& path) {
  stream::ViewHitsWriter views(path);
  for (core::ViewImage& image : w.original_views) {
    views.add(image);
    image = {};
  }
  views.commit();
  w.original_views = {};
}

nlohmann::ordered_json stats_json(const ErrorStats& s) {
  return {{"max", s.max}, {"p95", s.p95}, {"mean", s.mean}, {"rms", s.rms}, {"count", s.count}};
}

nlohmann::ordered_json report_json(const Report& rep, const ReportOptions& ro) {
  nlohmann::ordered_json j;
  j["generator"] = std::string("lodstream ") + LODSTREAM_VERSION;
  j["options"] = {{"views", ro.views}, {"resolution", ro.resolution}, {"seed", ro.seed}, {"samples", ro.samples},
                  {"pixels_per_cell", ro.pixels_per_cell}, {"supersample", ro.supersample}};
  j["units"] = {{"pixels", "pixels of the resolution × resolution report images, camera at the switching distance"},
                {"hausdorff", "scene units"},
                {"normal", "degrees"}};
  auto& runs = j["runs"] = nlohmann::ordered_json::array();
  for (const ReportRun& r : rep.runs) {
    nlohmann::ordered_json jr;
    jr["name"] = r.name;
    jr["original"] = {{"path", r.original}, {"triangles", r.original_triangles}, {"vertices", r.original_vertices},
                      {"bbox_diagonal", r.bbox_diagonal}};
    jr["fov_degrees"] = r.fov_degrees;
    auto& levels = jr["levels"] = nlohmann::ordered_json::array();
    for (size_t i = 0; i < r.levels.size(); ++i) {
      const ReportLevel& l = r.levels[i];
      levels.push_back({{"level", i},
                        {"file", l.file},
                        {"cell_size", l.cell_size},
                        {"vertices", l.vertices},
                        {"triangles", l.triangles},
                        {"edges", l.edges},
                        {"points", l.points},
                        {"switch_distance", l.switch_distance},
                        {"pixel_size", l.pixel_size},
                        {"silhouette", {{"max_px", l.silhouette.max}, {"p95_px", l.silhouette.p95},
                                        {"mean_px", l.silhouette.mean}, {"rms_px", l.silhouette.rms},
                                        {"mismatched_pixels", l.mismatched_pixels},
                                        {"covered_pixels", l.covered_pixels},
                                        {"mismatch_fraction", l.mismatch_fraction},
                                        {"thin_pixels", l.thin_pixels}, {"thin_kept_pixels", l.thin_kept_pixels},
                                        {"thin_kept_fraction", l.thin_kept_fraction}}},
                        {"depth_px", stats_json(l.depth)},
                        {"normal_degrees", stats_json(l.normal)},
                        {"hausdorff", {{"max", l.hausdorff_max}, {"mean", l.hausdorff_mean}, {"rms", l.hausdorff_rms},
                                       {"max_percent_diagonal", l.hausdorff_max_percent},
                                       {"mean_percent_diagonal", l.hausdorff_mean_percent},
                                       {"max_px", l.hausdorff_max_pixels}, {"mean_px", l.hausdorff_mean_pixels},
                                       {"lod_to_original", stats_json(l.lod_to_original)},
                                       {"original_to_lod", stats_json(l.original_to_lod)}}},
                        {"csv", l.csv},
                        {"seconds", l.seconds}});
    }
    runs.push_back(jr);
  }
  j["performance"] = {{"rays", rep.rays}, {"ray_seconds", rep.ray_seconds},
                      {"rays_per_second", rep.ray_seconds > 0 ? double(rep.rays) / rep.ray_seconds : 0.0},
                      {"point_queries", rep.point_queries}, {"query_seconds", rep.query_seconds},
                      {"queries_per_second", rep.query_seconds > 0 ? double(rep.point_queries) / rep.query_seconds : 0.0},
                      {"original_chunks", rep.original_chunks}, {"original_primitives", rep.original_primitives},
                      {"chunk_scenes", rep.chunk_scenes},
                      {"chunk_embree_peak_bytes", rep.chunk_embree_peak_bytes}, {"chunk_triangles", rep.chunk_triangles},
                      {"level_chunks", rep.level_chunks}, {"chunk_replans", rep.chunk_replans},
                      {"chunk_triangle_bytes", rep.chunk_triangle_bytes}};
  auto& phases = j["performance"]["phases"] = nlohmann::ordered_json::array();
  for (const StageStats& p : rep.phases)
    phases.push_back({{"name", p.name}, {"seconds", p.seconds}, {"cpu_seconds", p.cpu_seconds}});
  auto& stages = j["stages"] = nlohmann::ordered_json::array();
  for (const StageStats& s : rep.stages)
    stages.push_back(stream::stage_json(s));
  j["seconds"] = rep.seconds;
  j["peak_rss_bytes"] = rep.peak_rss_bytes;
  j["work_dir"] = stream::work_dir_json(rep.work_dir);
  return j;
}

std::string absolute(const std::string& p) {
  std::error_code ec;
  const fs::path a = fs::weakly_canonical(fs::absolute(p, ec), ec);
  return ec ? p : a.string();
}

// ------------------------------------------------------------------------------------------- shards

// The runs' originals, each once, as absolute paths, in the order of the runs: original G's store is
// WORK/store (G = 0) or WORK/store-G, its range segments stream::ingest_ranges_dir(work, G).
std::vector<std::string> distinct_originals(const std::vector<RunSpec>& runs) {
  std::vector<std::string> originals;
  for (const RunSpec& r : runs)
    if (std::find(originals.begin(), originals.end(), absolute(r.original)) == originals.end())
      originals.push_back(absolute(r.original));
  return originals;
}

// A range ingest task (stream/ingest_range.h): parses its byte range of every original into the work
// directory's segments, for the prepare job's join; no lock (the tasks run at once).
void run_report_ingest_range(const ReportOptions& ro, const std::vector<RunSpec>& runs, const Options& options,
                             const stream::MemoryPlan& plan, Report* out) {
  if (options.work_dir.empty()) fail(Status::usage, "--shard-ingest needs --work DIR, a directory every task shares");
  if (ro.ingest_index >= ro.ingest_count)
    fail(Status::usage, fmt::format("--shard-ingest {}/{}: the index must be below the count", ro.ingest_index, ro.ingest_count));
  stream::Progress progress(options);
  stream::WorkDir work(options.work_dir);
  const std::vector<std::string> originals = distinct_originals(runs);
  Report rep;
  tbb::task_arena arena(static_cast<int>(plan.threads));
  arena.execute([&] {
    stream::run_stage(&rep.stages, "ingest-range", [&](StageStats&) {
      for (size_t g = 0; g < originals.size(); ++g)
        stream::ingest_range(originals[g], work, ro.ingest_index, ro.ingest_count, plan, progress, g);
      return 0;
    });
  });
  *out = std::move(rep);
}

void check_report_shard(const ReportOptions& ro, const Options& options) {
  if (options.work_dir.empty()) fail(Status::usage, "--shard and --shard-prepare need --work DIR, a directory every task shares");
  if (ro.shard_count > 0 && ro.shard_index >= ro.shard_count)
    fail(Status::usage, fmt::format("--shard {}/{}: the index must be below the count", ro.shard_index, ro.shard_count));
}

// What the figures depend on: every task of one report has the same; the merge measures nothing and
// takes the options from it.
nlohmann::ordered_json report_options_json(const ReportOptions& ro) {
  return {{"runs", ro.runs}, {"original", ro.original}, {"lods", ro.lods}, {"switch_distances", ro.switch_distances},
          {"views", ro.views}, {"resolution", ro.resolution}, {"seed", ro.seed}, {"samples", ro.samples},
          {"fov_degrees", ro.fov_degrees}, {"pixels_per_cell", ro.pixels_per_cell}, {"html_views", ro.html_views},
          {"supersample", ro.supersample}};
}

ReportOptions report_options_from_json(const nlohmann::ordered_json& j) {
  ReportOptions ro;
  ro.runs = j.at("runs").get<std::vector<std::string>>();
  ro.original = j.at("original");
  ro.lods = j.at("lods").get<std::vector<std::string>>();
  ro.switch_distances = j.at("switch_distances").get<std::vector<double>>();
  ro.views = j.at("views"), ro.resolution = j.at("resolution"), ro.seed = j.at("seed"), ro.samples = j.at("samples");
  ro.fov_degrees = j.at("fov_degrees"), ro.pixels_per_cell = j.at("pixels_per_cell"), ro.html_views = j.at("html_views");
  ro.supersample = j.at("supersample");
  return ro;
}

// A task starting (again): its older summary no longer vouches for its shares; tasks of a report with more
// tasks are stale.
void begin_report_task(const ReportOptions& ro) {
  const std::string dir = stream::report_shards_dir(ro.output_dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail(Status::io_error, dir + ": cannot create: " + ec.message());
  fs::remove(stream::report_task_path(ro.output_dir, ro.shard_index), ec);
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    unsigned i;
    if (std::sscanf(e.path().filename().c_str(), "task-%u", &i) == 1 && i >= ro.shard_count) fs::remove(e.path(), ec);
  }
}

// Writes the task's shares (run by run, level by level), then its summary, task-I.json (durably, last).
void write_report_task(const ReportOptions& ro, const std::vector<RunSpec>& runs, bool by_ranges, const Report& rep,
                       const std::vector<std::vector<stream::ReportLevelShare>>& shares,
                       const std::vector<std::vector<std::vector<io::HtmlView>>>& views) {
  stream::ReportShareWriter writer(stream::report_levels_path(ro.output_dir, ro.shard_index));
  nlohmann::ordered_json jruns = nlohmann::ordered_json::array();
  for (size_t r = 0; r < runs.size(); ++r) {
    const ReportRun& rr = rep.runs[r];
    nlohmann::ordered_json levels = nlohmann::ordered_json::array();
    for (size_t l = 0; l < runs[r].levels.size(); ++l) {
      stream::ReportLevelShare share = shares[r][l];
      share.views = views[r][l];
      writer.add(share);
      const ReportLevel& L = rr.levels[l];
      levels.push_back({{"file", L.file}, {"cell_size", L.cell_size}, {"switch_distance", runs[r].levels[l].switch_distance},
                        {"vertices", L.vertices}, {"triangles", L.triangles}, {"edges", L.edges}, {"points", L.points},
                        {"seconds", L.seconds}});
    }
    jruns.push_back({{"name", rr.name}, {"original", rr.original}, {"fov_degrees", rr.fov_degrees},
                     {"original_triangles", rr.original_triangles}, {"original_vertices", rr.original_vertices},
                     {"bbox_diagonal", rr.bbox_diagonal}, {"levels", levels}});
  }
  writer.commit();
  nlohmann::ordered_json stages = nlohmann::ordered_json::array(), phases = nlohmann::ordered_json::array();
  for (const StageStats& s : rep.stages) stages.push_back(stream::stage_json(s));
  for (const StageStats& p : rep.phases) phases.push_back({{"name", p.name}, {"seconds", p.seconds}, {"cpu_seconds", p.cpu_seconds}});
  const nlohmann::ordered_json task{
      {"index", ro.shard_index},
      {"key", {{"count", ro.shard_count}, {"options", report_options_json(ro)},
               {"shared_by", by_ranges ? "ranges" : "views"}}},
      {"runs", jruns},
      {"performance",
       {{"rays", rep.rays}, {"ray_seconds", rep.ray_seconds}, {"point_queries", rep.point_queries},
        {"query_seconds", rep.query_seconds}, {"original_chunks", rep.original_chunks},
        {"original_primitives", rep.original_primitives}, {"chunk_scenes", rep.chunk_scenes},
        {"chunk_embree_peak_bytes", rep.chunk_embree_peak_bytes}, {"chunk_triangles", rep.chunk_triangles},
        {"level_chunks", rep.level_chunks}, {"phases", phases}}},
      {"stages", stages},
      {"seconds", rep.seconds},
      {"peak_rss_bytes", rep.peak_rss_bytes},
      {"work_dir", {{"bytes", rep.work_dir.bytes}, {"input_bytes", rep.work_dir.input_bytes}}}};
  stream::kill_point(fmt::format("report-task-{}.json", ro.shard_index));
  io::write_file_atomic(stream::report_task_path(ro.output_dir, ro.shard_index), task.dump(1) + "\n", io::Sync::durable);
}

// Every task's summary, checked to be one report's (stream::read_task_summaries).
std::vector<nlohmann::ordered_json> read_report_tasks(const std::string& output_dir) {
  return stream::read_task_summaries(stream::report_shards_dir(output_dir),
                                     {"report shares", "report task", "report", "other options or task count", "report"});
}

}  // namespace

Result report(const ReportOptions& ro, const Options& options, Report* out) {
  return stream::guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    const stream::MemoryPlan plan = stream::plan_memory(options);
    if (ro.output_dir.empty()) fail(Status::usage, "no output directory given (-o)");
    const std::vector<RunSpec> runs = resolve_runs(ro);
    if (ro.ingest_count > 0) return run_report_ingest_range(ro, runs, options, plan, out);
    stream::Progress progress(options);
    // A task of a sharded report (stream/report_shard.h) ingests the originals under the work directory's
    // lock, taken before the directory is opened (as simplify's tasks do, stream/shard.h).
    const bool sharded = ro.shard_count > 0 || ro.shard_prepare;
    if (sharded) check_report_shard(ro, options);
    // Tasks share the work by primitive ranges when every level has its distance, else by views.
    const bool by_ranges = sharded && every_distance_known(runs);
    std::unique_ptr<stream::ShardLock> shard_lock;
    if (sharded) shard_lock = std::make_unique<stream::ShardLock>(options.work_dir);
    stream::WorkDir work(options.work_dir);
    if (options.check_disk_space) {
      // A task by ranges hands the merge its covered pixels of every view of every level, of the original
      // and of the level (at most 25 bytes a pixel), and its distances.
      uint64_t task_bytes = 0;
      if (by_ranges && !ro.shard_prepare)
        for (const RunSpec& r : runs)
          task_bytes += r.levels.size() * (2ull * ro.views * ro.resolution * ro.resolution * 25 + 2 * 3 * ro.samples * 4);
      stream::check_report_space(distinct_originals(runs), work.path(), ro.output_dir, task_bytes);
    }
    stream::make_output_dir(ro.output_dir);
    stream::remove_summary(ro.output_dir + "/report.json");
    if (ro.shard_count > 0 && !ro.shard_prepare) begin_report_task(ro);
    Report rep;
    uint64_t input_bytes = 0;  // the originals'
    rep.runs.resize(runs.size());
    std::vector<std::vector<std::vector<io::HtmlView>>> views(runs.size());
    std::vector<std::vector<std::string>> csvs(runs.size());
    std::vector<std::vector<stream::ReportLevelShare>> shares(runs.size());  // a task's
    tbb::task_arena arena(static_cast<int>(plan.threads));
    arena.execute([&] {
      // One original at a time, each loaded once for every run that measures against it.
      const std::vector<std::string> originals = distinct_originals(runs);
      std::vector<std::string> run_original;  // each run's, as an absolute path
      for (const RunSpec& r : runs) run_original.push_back(absolute(r.original));
      for (size_t g = 0; g < originals.size(); ++g) {
        const std::string store_dir = work.subdir(g == 0 ? std::string("store") : "store-" + std::to_string(g));
        SceneInfo scene;
        bool reused = false;
        if (sharded && !shard_lock) shard_lock = std::make_unique<stream::ShardLock>(options.work_dir);
        const stream::StoreMeta meta =
            stream::run_ingest_stage(originals[g], store_dir, plan, work, progress, &rep.stages, &scene, &reused,
                                     sharded ? stream::ingest_ranges_dir(work, g) : std::string());
        shard_lock.reset();
        input_bytes += scene.file_bytes;
        if (ro.shard_prepare) continue;
        Original o;
        o.path = originals[g];
        std::vector<LevelWork> works;
        for (size_t r = 0; r < runs.size(); ++r)
          if (run_original[r] == o.path)
            for (size_t l = 0; l < runs[r].levels.size(); ++l) {
              works.emplace_back();
              works.back().run = &runs[r], works.back().index = l, works.back().ranges = by_ranges;
            }
        // Memory of the measure stage, every part that grows with the options or the scene counted:
        // - held throughout: what the process holds now (resident, mapped pages included), the samples
        //   and their distances (the original's and every level's: 3 × samples × 16 bytes each), each
        //   level's renders kept for report.html (3 RGB images a view), the comparison of one level (its
        //   depth and normal errors, 8 bytes a pixel of every view; its distance image and the
        //   distance transforms' scratch, 64 bytes a pixel), the reading of a chunk (a bit and a rank per
        //   16 store vertices, 3/16 byte; a mapped window of the positions, up to 64 MiB, and of a
        //   primitive column, up to 12 MiB), and a margin for the allocator (48 MiB, a sixteenth of
        //   smaller budgets); a task by ranges also holds the original's samples as points (about 120
        //   bytes a point, measured on the 48.6 M-triangle city: its Embree scene and query twin);
        // - the original's view images of a group of levels traced in one pass (18 bytes a pixel, 21
        //   with colours; at most half of what is left, or one level);
        // - the rest, for one chunk of the original at a time (ChunkSizing: its arrays, its Embree scenes)
        //   or, between passes, one level's scene.
        const bool colored = meta.colors || !meta.materials.empty();
        const uint64_t pixels = uint64_t{ro.resolution} * ro.resolution;
        const uint64_t view_bytes = uint64_t{ro.views} * pixels * view_pixel_bytes(colored);
        const uint64_t html_bytes = uint64_t{std::min(ro.html_views, ro.views)} * 3 * 3 * pixels;
        const uint64_t windows = std::min<uint64_t>(64ull << 20, meta.vertices * (meta.single_precision ? 12 : 24)) +
                                 std::min<uint64_t>(12ull << 20, meta.primitives() * 12);
        const uint64_t held = resident_bytes() + (works.size() + 1) * 3 * ro.samples * 16 + works.size() * html_bytes +
                              uint64_t{ro.views} * pixels * 8 + pixels * 64 + meta.vertices * 3 / 16 + windows +
                              std::min<uint64_t>(48ull << 20, plan.budget / 16) + (by_ranges ? 3 * ro.samples * 128 : 0);
        const uint64_t avail = plan.budget - std::min(plan.budget, held);
        const uint64_t levels_per_group = std::max<uint64_t>(1, avail / 2 / std::max<uint64_t>(1, view_bytes));
        const uint64_t group_bytes = std::min<uint64_t>(levels_per_group, works.size()) * view_bytes;
        const uint64_t embree_limit = left_of(avail, group_bytes);
        ChunkSizing sizing;
        sizing.room = embree_limit, sizing.cap = options.chunk_bytes, sizing.colored = colored;
        run_stage(&rep.stages, "load", [&](StageStats&) {
          if (by_ranges) load_original_range(store_dir, meta, ro, sizing, sample_units_dir(work, g), progress, &o);
          else load_original(store_dir, meta, ro, sizing, progress, &o);
        });
        PhaseTimes phases;
        run_stage(&rep.stages, "measure", [&](StageStats&) {
          for (LevelWork& w : works) w.phases = &phases, begin_level(o, w, ro, embree_limit, options.chunk_bytes);
          std::unique_ptr<ChunkScene> cache;
          TraceTotals totals;
          totals.phases = &phases;
          std::vector<LevelWork*> pending;  // levels whose samples have not met the original's chunks yet
          for (LevelWork& w : works) pending.push_back(&w);
          // Levels without a given distance need their Hausdorff max before their views.
          const bool unknown = std::any_of(works.begin(), works.end(), [](const LevelWork& w) { return !w.distance_known; });
          if (unknown) {
            trace_original(o, pending, {}, ro, sizing, progress, cache, totals);
            for (LevelWork* w : pending) finish_hausdorff(o, *w, ro);
            pending.clear();
          }
          for (size_t first = 0; first < works.size(); first += levels_per_group) {
            std::vector<LevelWork*> group;
            for (size_t i = first; i < std::min<size_t>(works.size(), first + levels_per_group); ++i) group.push_back(&works[i]);
            for (LevelWork* w : group) begin_views(o, *w, ro);
            trace_original(o, pending, group, ro, sizing, progress, cache, totals);
            for (LevelWork* w : pending) finish_hausdorff(o, *w, ro);
            pending.clear();
            // A task by ranges: where its images of level w's views go, of the original or of the level.
            const auto views_path = [&](const LevelWork* w, bool of_level) {
              return stream::report_views_path(ro.output_dir, ro.shard_index, static_cast<size_t>(w->run - runs.data()), w->index, of_level);
            };
            if (by_ranges)
              for (LevelWork* w : group) write_original_views(*w, views_path(w, false));
            for (LevelWork* w : group) {
              // A single chunk stays built between passes, unless the level's scene needs its room.
              if (cache && cached_bytes(*cache) + level_scene_bytes(w->out.level, sizing) > embree_limit) cache.reset();
              const uint64_t limit = left_of(embree_limit, cache ? cached_bytes(*cache) : 0);
              if (by_ranges) {
                stream::ViewHitsWriter level_views(views_path(w, true));
                trace_level_range(o, *w, ro, limit, options.chunk_bytes, level_views);
              } else {
                finish_level(o, *w, ro, limit, options.chunk_bytes);
              }
            }
          }
          rep.chunk_scenes += totals.chunks;
          rep.original_chunks += o.chunks->chunks().size();
          for (const stream::StoreChunk& c : o.chunks->chunks()) rep.original_primitives += c.end - c.first;
          rep.chunk_replans += totals.replans;
          rep.chunk_triangle_bytes = std::max(rep.chunk_triangle_bytes, sizing.embree_triangle);
          for (int p = 0; p < kPhaseCount; ++p) {
            StageStats st;
            st.name = kPhaseNames[p], st.seconds = phases.wall[p], st.cpu_seconds = phases.cpu[p];
            rep.phases.push_back(st);
          }
          for (const LevelWork& w : works) rep.level_chunks = std::max(rep.level_chunks, w.level_chunks);
          if (totals.embree_peak_bytes > rep.chunk_embree_peak_bytes)
            rep.chunk_embree_peak_bytes = totals.embree_peak_bytes, rep.chunk_triangles = totals.chunk_triangles;
          for (LevelWork& w : works) {
            const size_t r = static_cast<size_t>(w.run - runs.data()), l = w.index;
            ReportRun& rr = rep.runs[r];
            rr.name = runs[r].name;
            rr.original = runs[r].original;
            rr.original_triangles = meta.triangles;
            rr.original_vertices = meta.vertices;
            rr.bbox_diagonal = o.diagonal;
            rr.fov_degrees = runs[r].fov_degrees;
            views[r].resize(runs[r].levels.size());
            csvs[r].resize(runs[r].levels.size());
            rr.levels.resize(runs[r].levels.size());
            LevelResult& lr = w.out;
            lr.level.csv = runs.size() > 1 ? fmt::format("run{}-lod{}.csv", r, l) : fmt::format("lod{}.csv", l);
            if (w.sharded) {
              shares[r].resize(runs[r].levels.size());
              shares[r][l] = std::move(w.share);
              shares[r][l].csv_rows = lr.csv_rows;
            }
            std::string csv = kCsvHeader;
            for (const std::string& row : lr.csv_rows) csv += row;
            csvs[r][l] = std::move(csv);
            views[r][l] = std::move(lr.views);
            rep.rays += lr.rays, rep.point_queries += lr.queries;
            rep.ray_seconds += lr.ray_seconds, rep.query_seconds += lr.query_seconds;
            rr.levels[l] = std::move(lr.level);
          }
        });
      }
    });
    if (sharded) {
      rep.seconds = seconds_since(t0);
      rep.peak_rss_bytes = stream::peak_rss_bytes();
      rep.work_dir = stream::work_dir_usage(work.path(), input_bytes);
      if (!ro.shard_prepare) write_report_task(ro, runs, by_ranges, rep, shares, views);
      *out = std::move(rep);
      return;
    }
    run_stage(&rep.stages, "write", [&](StageStats&) {
      for (size_t r = 0; r < runs.size(); ++r)
        for (size_t l = 0; l < csvs[r].size(); ++l)
          io::write_file_atomic(ro.output_dir + "/" + rep.runs[r].levels[l].csv, csvs[r][l], io::Sync::durable);
      io::write_report_html(ro.output_dir + "/report.html", rep, ro, views);
    });
    rep.seconds = seconds_since(t0);
    rep.peak_rss_bytes = stream::peak_rss_bytes();
    rep.work_dir = stream::work_dir_usage(work.path(), input_bytes);
    // report.json last: its presence means the report is complete.
    stream::kill_point("report.json");
    io::write_file_atomic(ro.output_dir + "/report.json", report_json(rep, ro).dump(2) + "\n", io::Sync::durable);
    *out = std::move(rep);
  });
}

bool has_report_shards(const std::string& output_dir) {
  std::error_code ec;
  return fs::is_directory(stream::report_shards_dir(output_dir), ec);
}

// The merge of one level of a report by ranges (stream/report_shard.h): each sample's least distance over the
// tasks, then view by view the tasks' images composited in task order (the images of the original and of the
// level, as one machine casts them chunk by chunk) and compared as one machine compares them. Sets w's level
// figures, CSV rows (w.out.csv_rows) and renders (`renders`).
void merge_level_ranges(Original& o, LevelWork& w, const ReportOptions& ro, const std::string& output_dir,
                        const std::vector<std::unique_ptr<stream::ReportShareReader>>& readers, size_t run,
                        std::vector<io::HtmlView>& renders) {
  ReportLevel& L = w.out.level;
  std::vector<float> from_original;
  uint64_t original_faces = 0;
  stream::ReportLevelShare share;
  const auto lower = [&](std::vector<float>& into, const std::vector<float>& d, const std::string& path) {
    if (into.size() != d.size()) fail(Status::io_error, path + ": a report task's shares do not hold every sample");
    for (size_t i = 0; i < d.size(); ++i) into[i] = std::min(into[i], d[i]);
  };
  for (size_t t = 0; t < readers.size(); ++t) {
    readers[t]->next(&share);
    const std::string path = stream::report_levels_path(output_dir, static_cast<unsigned>(t));
    original_faces = share.original_faces, w.samples.faces = share.lod_faces;
    if (t == 0) {
      from_original = std::move(share.original_to_lod), w.to_original = std::move(share.lod_to_original);
      o.targets = std::move(share.targets);
    } else {
      lower(from_original, share.original_to_lod, path);
      lower(w.to_original, share.lod_to_original, path);
    }
  }
  L.original_to_lod = hausdorff_stats(from_original, original_faces);
  from_original = {};
  finish_hausdorff(o, w, ro);
  w.views = std::min<unsigned>(ro.views, static_cast<unsigned>(o.targets.size() / 3));
  begin_views(o, w, ro);
  std::vector<std::unique_ptr<stream::ViewHitsReader>> of_original, of_level;
  for (size_t t = 0; t < readers.size(); ++t) {
    const unsigned task = static_cast<unsigned>(t);
    of_original.push_back(std::make_unique<stream::ViewHitsReader>(stream::report_views_path(output_dir, task, run, w.index, false)));
    of_level.push_back(std::make_unique<stream::ViewHitsReader>(stream::report_views_path(output_dir, task, run, w.index, true)));
  }
  CompareScratch scratch;
  core::ViewImage vo, vl;
  for (unsigned k = 0; k < w.views; ++k) {
    core::clear_view(&vo, ro.resolution), core::clear_view(&vl, ro.resolution);
    for (size_t t = 0; t < readers.size(); ++t) of_original[t]->composite_next(&vo), of_level[t]->composite_next(&vl);
    compare_view(o, w, ro, k, vo, vl, scratch);
  }
  view_figures(L, w.share.silhouette, w.share.depth_err, w.share.normal_err);
  renders = std::move(w.out.views);
}

// The merge of one level of a report by views: every array in task order, one machine's sample and view
// order, and the figures formed from them. Sets w's level figures, CSV rows and renders, as
// merge_level_ranges.
void merge_level_views(const Original& o, LevelWork& w, const ReportOptions& ro,
                       const std::vector<std::unique_ptr<stream::ReportShareReader>>& readers,
                       std::vector<io::HtmlView>& renders) {
  ReportLevel& L = w.out.level;
  std::vector<float> from_original;
  uint64_t original_faces = 0;
  stream::ReportLevelShare share;
  for (const auto& reader : readers) {
    reader->next(&share);
    original_faces = share.original_faces, w.samples.faces = share.lod_faces;
    from_original.insert(from_original.end(), share.original_to_lod.begin(), share.original_to_lod.end());
    w.to_original.insert(w.to_original.end(), share.lod_to_original.begin(), share.lod_to_original.end());
    core::add_silhouette_counts(w.share.silhouette, share.silhouette);
    w.share.depth_err.insert(w.share.depth_err.end(), share.depth_err.begin(), share.depth_err.end());
    w.share.normal_err.insert(w.share.normal_err.end(), share.normal_err.begin(), share.normal_err.end());
    w.out.csv_rows.insert(w.out.csv_rows.end(), share.csv_rows.begin(), share.csv_rows.end());
    for (io::HtmlView& v : share.views) renders.push_back(std::move(v));
  }
  L.original_to_lod = hausdorff_stats(from_original, original_faces);
  finish_hausdorff(o, w, ro);
  view_figures(L, w.share.silhouette, w.share.depth_err, w.share.normal_err);
}

// The merge of a sharded report (stream/report_shard.h): every level's arrays are the tasks' shares in task
// order, which is one machine's sample and view order, and its figures are formed by the same functions.
Result merge_report(const std::string& output_dir, const Options& options, Report* out) {
  return stream::guarded([&] {
    using nlohmann::ordered_json;
    const auto t0 = std::chrono::steady_clock::now();
    stream::Progress progress(options);
    const std::vector<ordered_json> tasks = read_report_tasks(output_dir);
    const unsigned count = static_cast<unsigned>(tasks.size());
    ReportOptions ro = report_options_from_json(tasks[0].at("key").at("options"));
    ro.output_dir = output_dir;
    const bool by_ranges = tasks[0].at("key").value("shared_by", std::string("views")) == "ranges";
    stream::remove_summary(output_dir + "/report.json");
    const ordered_json& jruns = tasks[0].at("runs");
    std::vector<RunSpec> runs(jruns.size());
    Report rep;
    rep.runs.resize(runs.size());
    std::vector<std::vector<std::vector<io::HtmlView>>> views(runs.size());
    std::vector<std::vector<std::string>> csvs(runs.size());
    std::vector<std::unique_ptr<stream::ReportShareReader>> readers;
    for (unsigned t = 0; t < count; ++t)
      readers.push_back(std::make_unique<stream::ReportShareReader>(stream::report_levels_path(output_dir, t)));
    run_stage(&rep.stages, "merge", [&](StageStats&) {
      size_t done = 0, total_levels = 0;
      for (const ordered_json& jr : jruns) total_levels += jr.at("levels").size();
      for (size_t r = 0; r < runs.size(); ++r) {
        const ordered_json& jr = jruns[r];
        RunSpec& run = runs[r];
        run.name = jr.at("name"), run.original = jr.at("original"), run.fov_degrees = jr.at("fov_degrees");
        ReportRun& rr = rep.runs[r];
        rr.name = run.name, rr.original = run.original, rr.fov_degrees = run.fov_degrees;
        rr.original_triangles = jr.at("original_triangles"), rr.original_vertices = jr.at("original_vertices");
        rr.bbox_diagonal = jr.at("bbox_diagonal");
        for (const ordered_json& jl : jr.at("levels")) {
          LevelSpec spec;
          spec.file = jl.at("file"), spec.cell_size = jl.at("cell_size"), spec.switch_distance = jl.at("switch_distance");
          run.levels.push_back(spec);
        }
        Original o;
        o.diagonal = rr.bbox_diagonal;
        rr.levels.resize(run.levels.size());
        views[r].resize(run.levels.size());
        csvs[r].resize(run.levels.size());
        for (size_t l = 0; l < run.levels.size(); ++l) {
          const ordered_json& jl = jr.at("levels").at(l);
          LevelWork w;
          w.run = &run, w.index = l;
          ReportLevel& L = w.out.level;
          L.file = jl.at("file"), L.cell_size = jl.at("cell_size");
          L.vertices = jl.at("vertices"), L.triangles = jl.at("triangles"), L.edges = jl.at("edges"), L.points = jl.at("points");
          for (const ordered_json& t : tasks) L.seconds += t.at("runs").at(r).at("levels").at(l).at("seconds").get<double>();
          w.tan_half = std::tan(run.fov_degrees * M_PI / 360.0);
          w.distance_known = run.levels[l].switch_distance > 0;
          w.distance = w.distance_known ? run.levels[l].switch_distance : 1.0;
          if (by_ranges) merge_level_ranges(o, w, ro, output_dir, readers, r, views[r][l]);
          else merge_level_views(o, w, ro, readers, views[r][l]);
          L.csv = runs.size() > 1 ? fmt::format("run{}-lod{}.csv", r, l) : fmt::format("lod{}.csv", l);
          std::string csv = kCsvHeader;
          for (const std::string& row : w.out.csv_rows) csv += row;
          csvs[r][l] = std::move(csv);
          rr.levels[l] = std::move(L);
          progress.report("merge", double(++done) / double(total_levels));
        }
      }
    });
    readers.clear();
    run_stage(&rep.stages, "write", [&](StageStats&) {
      for (size_t r = 0; r < runs.size(); ++r)
        for (size_t l = 0; l < csvs[r].size(); ++l)
          io::write_file_atomic(ro.output_dir + "/" + rep.runs[r].levels[l].csv, csvs[r][l], io::Sync::durable);
      io::write_report_html(ro.output_dir + "/report.html", rep, ro, views);
    });
    // Performance: the tasks' counters summed (the original's chunks: the most any task cut it into).
    ordered_json shards = ordered_json::array();
    for (unsigned t = 0; t < count; ++t) {
      const ordered_json& tj = tasks[t];
      const ordered_json& p = tj.at("performance");
      rep.rays += p.at("rays").get<uint64_t>(), rep.ray_seconds += p.at("ray_seconds").get<double>();
      rep.point_queries += p.at("point_queries").get<uint64_t>(), rep.query_seconds += p.at("query_seconds").get<double>();
      rep.original_chunks = std::max(rep.original_chunks, p.at("original_chunks").get<uint64_t>());
      rep.original_primitives += p.at("original_primitives").get<uint64_t>();
      rep.chunk_scenes += p.at("chunk_scenes").get<uint64_t>();
      if (p.at("chunk_embree_peak_bytes").get<uint64_t>() > rep.chunk_embree_peak_bytes)
        rep.chunk_embree_peak_bytes = p.at("chunk_embree_peak_bytes"), rep.chunk_triangles = p.at("chunk_triangles");
      rep.level_chunks = std::max(rep.level_chunks, p.at("level_chunks").get<uint64_t>());
      rep.work_dir.bytes = std::max(rep.work_dir.bytes, tj.at("work_dir").at("bytes").get<uint64_t>());
      rep.work_dir.input_bytes = tj.at("work_dir").at("input_bytes");
      shards.push_back({{"index", t}, {"stages", tj.at("stages")}, {"seconds", tj.at("seconds")}, {"peak_rss_bytes", tj.at("peak_rss_bytes")},
                        {"original_primitives", p.at("original_primitives")}, {"phases", p.at("phases")}});
    }
    rep.seconds = seconds_since(t0);
    rep.peak_rss_bytes = stream::peak_rss_bytes();
    ordered_json j = report_json(rep, ro);
    j["shards"] = {{"count", count}, {"tasks", shards}};
    stream::kill_point("report.json");
    io::write_file_atomic(ro.output_dir + "/report.json", j.dump(2) + "\n", io::Sync::durable);
    // The shares have served: report.json now vouches for the outputs.
    std::error_code ec;
    fs::remove_all(stream::report_shards_dir(output_dir), ec);
    if (fs::is_empty(stream::shards_dir(output_dir), ec)) fs::remove(stream::shards_dir(output_dir), ec);
    *out = std::move(rep);
  });
}

}  // namespace lodstream

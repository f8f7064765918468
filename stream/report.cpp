// `lodstream report`: how far off, in pixels, each level of detail is where a renderer would show it
// (../shared/DESIGN.md "Error report").
//
// For every original (ingested into the scene store, reused from a simplify work directory when it is the
// same file), one Embree scene of its triangles is built once; its lines and points, which are drawn one
// pixel wide, go into a small second scene rebuilt for each level's distance. For every level:
// 1. read the LOD file, build its scene (thick edges as flat curves of radius max(T/2, half a pixel),
//    points as one-pixel discs);
// 2. two-sided Hausdorff distance: Metro-style samples of each mesh (core/surface_sampling.h), closest
//    points on the other by Embree point queries;
// 3. views: K directions on a Fibonacci sphere, view k aimed at the k-th of K points sampled uniformly
//    by area on the original's surface, the camera at the level's switching distance from that point;
//    original and LOD ray cast into H × H images; silhouette error from exact distance transforms of the
//    original's coverage (core/silhouette_error.h); depth and normal error where both cover.
// Everything drawn at random comes from counter-based streams of --seed (views, targets, samples), and
// every sum is formed in a fixed order, so the figures are the same for any thread count or memory budget.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/ray_scene.h"
#include "core/silhouette_error.h"
#include "core/status.h"
#include "core/surface_sampling.h"
#include "core/view_cast.h"
#include "io/file_writer.h"
#include "io/lod_reader.h"
#include "io/report_html.h"
#include <fmt/format.h>
#include "lodstream/lodstream.h"
#include "stream/ingest.h"
#include "stream/disk_space.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/store_access.h"
#include "stream/work_dir.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;
using stream::run_stage;

// Random streams of the seed (core/surface_sampling.h): one per use, so that changing one use never
// moves the numbers of another.
enum : uint64_t { kStreamTargets = 101, kStreamOriginalSamples = 102, kStreamLodSamples = 103 };

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

// Metro-style samples of a mesh given as arrays (positions, triangles, segments, points): face samples
// first, then edge and vertex samples.
struct Samples {
  std::vector<float> xyz;
  size_t faces = 0;  // the first `faces` samples are uniform by area
};

// With `targets`, also K view targets in the same two passes (the original is streamed once for both): points
// uniform by area on the triangles; with no triangles, uniform by length on the segments; with neither,
// the points themselves in turn.
Samples sample_mesh(std::span<const float> xyz, std::span<const uint32_t> triangles,
                    std::span<const uint32_t> segments, std::span<const uint32_t> points, uint64_t n, uint64_t seed,
                    uint64_t stream, unsigned k = 0, std::vector<float>* targets = nullptr) {
  core::SurfaceSampler sampler(n, seed, stream), aim(k, seed, kStreamTargets);
  const uint64_t vertex_count = xyz.size() / 3;
  std::vector<uint8_t> used(vertex_count, 0);
  for (auto ids : {triangles, segments, points})
    for (uint32_t v : ids) used[v] = 1;
  const float* p = xyz.data();
  auto corner = [&](std::span<const uint32_t> ids, size_t i) { return p + 3ull * ids[i]; };
  for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
    sampler.measure_triangle(corner(triangles, t), corner(triangles, t + 1), corner(triangles, t + 2));
    if (targets) aim.measure_triangle(corner(triangles, t), corner(triangles, t + 1), corner(triangles, t + 2));
  }
  for (size_t e = 0; e + 1 < segments.size(); e += 2) {
    sampler.measure_segment(corner(segments, e), corner(segments, e + 1));
    if (targets && triangles.empty()) aim.measure_segment(corner(segments, e), corner(segments, e + 1));
  }
  for (uint64_t v = 0; v < vertex_count; ++v)
    if (used[v]) sampler.measure_vertex();
  sampler.begin_sampling();
  aim.begin_sampling();
  std::vector<float> faces, edges, vertices, aim_faces, aim_edges, aim_unused;
  faces.reserve(3 * n), edges.reserve(3 * n), vertices.reserve(3 * std::min(n, vertex_count));
  for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
    sampler.sample_triangle(corner(triangles, t), corner(triangles, t + 1), corner(triangles, t + 2), faces, edges);
    if (targets)
      aim.sample_triangle(corner(triangles, t), corner(triangles, t + 1), corner(triangles, t + 2), aim_faces, aim_unused);
  }
  const bool aim_at_segments = targets && aim_faces.empty();
  for (size_t e = 0; e + 1 < segments.size(); e += 2) {
    sampler.sample_segment(corner(segments, e), corner(segments, e + 1), edges);
    if (aim_at_segments) aim.sample_segment(corner(segments, e), corner(segments, e + 1), aim_edges);
  }
  for (uint64_t v = 0; v < vertex_count; ++v)
    if (used[v]) sampler.sample_vertex(p + 3 * v, vertices);
  if (targets) {
    *targets = !aim_faces.empty() ? std::move(aim_faces) : std::move(aim_edges);
    if (targets->empty() && !points.empty())
      for (unsigned i = 0; i < k; ++i) targets->insert(targets->end(), corner(points, i % points.size()), corner(points, i % points.size()) + 3);
  }
  Samples out;
  out.faces = faces.size() / 3;
  faces.insert(faces.end(), edges.begin(), edges.end());
  faces.insert(faces.end(), vertices.begin(), vertices.end());
  out.xyz = std::move(faces);
  return out;
}

// An original, loaded once for all the levels measured against it.
struct Original {
  std::string path;
  stream::StoreMeta meta;
  std::unique_ptr<core::RayScene> triangles;  // its triangles (Embree holds the positions and indices)
  std::vector<float> own_xyz;                 // positions, when there are no triangles to hold them
  std::span<const float> xyz;
  std::span<const uint32_t> tris;
  std::vector<uint32_t> lines, points;        // drawn one pixel wide: a scene per level distance
  Samples samples;                            // Metro-style samples
  std::vector<float> targets;                 // view targets
  double diagonal = 0;
};

void load_original(const std::string& store_dir, const stream::StoreMeta& meta, const ReportOptions& ro,
                   uint64_t embree_limit, stream::Progress& progress, Original* o) {
  o->meta = meta;
  o->triangles = std::make_unique<core::RayScene>(embree_limit);
  const core::RayScene::TriangleBuffers buffers = o->triangles->add_triangles(meta.vertices, meta.triangles);
  std::span<float> xyz = buffers.xyz;
  if (meta.triangles == 0) {
    o->own_xyz.resize(3 * meta.vertices);
    xyz = o->own_xyz;
  }
  stream::StorePositions positions(store_dir, meta);
  positions.acquire();
  for (uint64_t v = 0; v < meta.vertices; ++v) {
    double p[3];
    positions.get(v, p);
    for (int k = 0; k < 3; ++k) xyz[3 * v + k] = static_cast<float>(p[k]);
    if ((v & 0xFFFFF) == 0) progress.report("load", 0.3 * double(v) / double(meta.vertices));
  }
  positions.release();
  stream::for_column_blocks(store_dir + "/triangles.u32", meta.triangles, 3, 1 << 20,
                            [&](uint64_t first, std::span<const uint32_t> ids) {
                              std::copy(ids.begin(), ids.end(), buffers.indices.begin() + 3 * first);
                              progress.report("load", 0.3 + 0.2 * double(first) / double(meta.triangles));
                            });
  stream::for_column_blocks(store_dir + "/lines.u32", meta.lines, 2, 1 << 20, [&](uint64_t, std::span<const uint32_t> ids) {
    o->lines.insert(o->lines.end(), ids.begin(), ids.end());
  });
  stream::for_column_blocks(store_dir + "/points.u32", meta.points, 1, 1 << 20, [&](uint64_t, std::span<const uint32_t> ids) {
    o->points.insert(o->points.end(), ids.begin(), ids.end());
  });
  o->xyz = xyz;
  o->tris = buffers.indices;
  o->triangles->commit();
  progress.report("load", 0.8);
  o->samples = sample_mesh(o->xyz, o->tris, o->lines, o->points, ro.samples, ro.seed, kStreamOriginalSamples,
                           ro.views, &o->targets);
  const double d[3] = {meta.bbox.max[0] - meta.bbox.min[0], meta.bbox.max[1] - meta.bbox.min[1],
                       meta.bbox.max[2] - meta.bbox.min[2]};
  o->diagonal = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  progress.report("load", 1);
}

// Distances from every sample to the nearest primitive of any of `scenes`, in sample order.
std::vector<float> closest_distances(const std::vector<float>& samples, std::span<const core::RayScene* const> scenes) {
  const size_t n = samples.size() / 3;
  std::vector<float> d(n, std::numeric_limits<float>::infinity());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 512), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i)
      for (const core::RayScene* s : scenes)
        if (!s->empty()) d[i] = std::min(d[i], s->closest_distance(samples.data() + 3 * i));
  });
  return d;
}

// ------------------------------------------------------------------------------------------- images

// Shaded render: grey by the cosine between normal and view axis; thick edges orange, points red.
std::vector<uint8_t> shade(const core::ViewImage& v, const core::Camera& cam) {
  const uint64_t n = uint64_t{v.resolution} * v.resolution;
  std::vector<uint8_t> rgb(3 * n, 255);
  for (uint64_t p = 0; p < n; ++p) {
    if (!v.covered(p)) continue;
    const float* nn = &v.normal[3 * p];
    const double c = std::fabs(nn[0] * cam.forward[0] + nn[1] * cam.forward[1] + nn[2] * cam.forward[2]);
    const double g = 50 + 180 * c;
    double r = g, gg = g, b = g;
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
    "silhouette_max_px,silhouette_mean_px,both_pixels,depth_mean_px,normal_mean_deg\n";

std::string fmt_csv_row(unsigned k, const double* dir, const double* target, const double* eye,
                        const core::SilhouetteStats& s, uint64_t both, double depth_mean, double normal_mean) {
  return fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", k, dir[0], dir[1], dir[2], target[0],
                     target[1], target[2], eye[0], eye[1], eye[2], s.covered_either, s.mismatched, s.max, s.mean,
                     both, depth_mean, normal_mean);
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

LevelResult measure_level(const Original& o, const RunSpec& run, size_t index, const ReportOptions& ro,
                          uint64_t embree_limit, stream::Progress& progress) {
  const auto t_level = std::chrono::steady_clock::now();
  const LevelSpec& spec = run.levels[index];
  LevelResult out;
  ReportLevel& L = out.level;
  L.file = spec.file;
  L.cell_size = spec.cell_size;
  const core::LodMesh mesh = io::read_lod_mesh(spec.file);
  L.vertices = mesh.vertex_count(), L.triangles = mesh.triangle_count(), L.edges = mesh.edge_count(),
  L.points = mesh.point_count();
  if (L.triangles + L.edges + L.points == 0) fail(Status::bad_data, spec.file + ": the level has no primitives");
  const double tan_half = std::tan(run.fov_degrees * M_PI / 360.0);
  auto pixel_at = [&](double d) { return 2 * d * tan_half / ro.resolution; };

  // Hausdorff first: without a given distance, the level is shown from where its max spans
  // pixels_per_cell pixels. Segment and point radii do not enter the point queries.
  const auto build = [&](double distance) {
    auto scene = std::make_unique<core::RayScene>(embree_limit);
    const float half_pixel = static_cast<float>(pixel_at(distance) / 2);
    scene->add_triangles(mesh.positions, mesh.triangles);
    std::vector<float> radius(mesh.edge_count());
    for (size_t e = 0; e < radius.size(); ++e) radius[e] = std::max(mesh.thickness[e] / 2, half_pixel);
    scene->add_segments(mesh.positions, mesh.edges, radius);
    scene->add_points(mesh.positions, mesh.points, half_pixel);
    scene->commit();
    return scene;
  };
  const auto build_wire = [&](double distance) {
    auto scene = std::make_unique<core::RayScene>(embree_limit);
    const float half_pixel = static_cast<float>(pixel_at(distance) / 2);
    scene->add_segments(o.xyz, o.lines, std::vector<float>(o.lines.size() / 2, half_pixel));
    scene->add_points(o.xyz, o.points, half_pixel);
    scene->commit();
    return scene;
  };
  const std::string stage = "level " + std::to_string(index);
  double distance = spec.switch_distance > 0 ? spec.switch_distance : 1.0;
  std::unique_ptr<core::RayScene> lod = build(distance), wire = build_wire(distance);
  progress.report(stage.c_str(), 0.05);
  const auto t_q = std::chrono::steady_clock::now();
  const Samples lod_samples =
      sample_mesh(mesh.positions, mesh.triangles, mesh.edges, mesh.points, ro.samples, ro.seed, kStreamLodSamples);
  {
    const core::RayScene* to_original[] = {o.triangles.get(), wire.get()};
    std::vector<float> d = closest_distances(lod_samples.xyz, to_original);
    L.lod_to_original = hausdorff_stats(d, lod_samples.faces);
  }
  {
    const core::RayScene* to_lod[] = {lod.get()};
    std::vector<float> d = closest_distances(o.samples.xyz, to_lod);
    L.original_to_lod = hausdorff_stats(d, o.samples.faces);
  }
  out.queries = lod_samples.xyz.size() / 3 + o.samples.xyz.size() / 3;
  out.query_seconds = seconds_since(t_q);
  progress.report(stage.c_str(), 0.3);
  const ErrorStats& a = L.lod_to_original;
  const ErrorStats& b = L.original_to_lod;
  L.hausdorff_max = std::max(a.max, b.max);
  L.hausdorff_mean = std::max(a.mean, b.mean);
  L.hausdorff_rms = std::max(a.rms, b.rms);
  if (spec.switch_distance <= 0) {
    // Shown from where the Hausdorff max spans pixels_per_cell pixels (at least a tiny positive distance).
    distance = std::max(L.hausdorff_max * ro.resolution / (ro.pixels_per_cell * 2 * tan_half), o.diagonal * 1e-6);
    lod = build(distance);
    wire = build_wire(distance);
  }
  L.switch_distance = distance;
  L.pixel_size = pixel_at(distance);
  if (o.diagonal > 0) {
    L.hausdorff_max_percent = 100 * L.hausdorff_max / o.diagonal;
    L.hausdorff_mean_percent = 100 * L.hausdorff_mean / o.diagonal;
  }
  L.hausdorff_max_pixels = L.hausdorff_max / L.pixel_size;
  L.hausdorff_mean_pixels = L.hausdorff_mean / L.pixel_size;

  // Views.
  const unsigned h = ro.resolution;
  const uint64_t pixels = uint64_t{h} * h;
  core::SilhouetteCounts total;
  core::SilhouetteScratch scratch;
  std::vector<float> depth_err, normal_err, distance_image(pixels);
  core::ViewImage vo, vl;
  const core::RayScene* original_scenes[] = {o.triangles.get(), wire.get()};
  const core::RayScene* lod_scenes[] = {lod.get()};
  const unsigned views = std::min<unsigned>(ro.views, static_cast<unsigned>(o.targets.size() / 3));
  for (unsigned k = 0; k < views; ++k) {
    double dir[3], target[3], eye[3];
    core::fibonacci_direction(k, ro.views, dir);
    for (int c = 0; c < 3; ++c) target[c] = o.targets[3 * k + c], eye[c] = target[c] + dir[c] * distance;
    const core::Camera cam = core::look_at(eye, target, run.fov_degrees, h);
    const auto t_r = std::chrono::steady_clock::now();
    out.rays += core::cast_view(original_scenes, cam, &vo);
    out.rays += core::cast_view(lod_scenes, cam, &vl);
    out.ray_seconds += seconds_since(t_r);
    core::SilhouetteCounts view;
    core::compare_silhouettes(vo.kind, vl.kind, int(h), int(h), scratch, view, distance_image);
    core::add_silhouette_counts(total, view);
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
      depth_err.push_back(de), normal_err.push_back(ne);
      depth_sum += de, normal_sum += ne, ++both;
    }
    out.csv_rows.push_back(fmt_csv_row(k, dir, target, eye, vs, both, both ? depth_sum / both : 0,
                                       both ? normal_sum / both : 0));
    if (k < ro.html_views) {
      io::HtmlView hv;
      hv.view = k;
      hv.resolution = h;
      hv.original_rgb = shade(vo, cam);
      hv.lod_rgb = shade(vl, cam);
      hv.heat_rgb = heat(vo, vl, distance_image);
      out.views.push_back(std::move(hv));
    }
    progress.report(stage.c_str(), 0.3 + 0.7 * double(k + 1) / views);
  }
  const core::SilhouetteStats s = core::silhouette_stats(total);
  L.silhouette.max = s.max, L.silhouette.p95 = s.p95, L.silhouette.mean = s.mean, L.silhouette.count = s.mismatched;
  double sum2 = 0;
  for (const core::SquaredDistanceCount& bin : total.histogram) sum2 += double(bin.squared) * double(bin.count);
  L.silhouette.rms = s.mismatched ? std::sqrt(sum2 / double(s.mismatched)) : 0;
  L.mismatched_pixels = s.mismatched;
  L.covered_pixels = s.covered_either;
  L.mismatch_fraction = s.mismatch_fraction;
  L.depth = stats_of(depth_err);
  L.normal = stats_of(normal_err);
  L.seconds = seconds_since(t_level);
  return out;
}

nlohmann::ordered_json stats_json(const ErrorStats& s) {
  return {{"max", s.max}, {"p95", s.p95}, {"mean", s.mean}, {"rms", s.rms}, {"count", s.count}};
}

nlohmann::ordered_json report_json(const Report& rep, const ReportOptions& ro) {
  nlohmann::ordered_json j;
  j["generator"] = std::string("lodstream ") + LODSTREAM_VERSION;
  j["options"] = {{"views", ro.views}, {"resolution", ro.resolution}, {"seed", ro.seed}, {"samples", ro.samples},
                  {"pixels_per_cell", ro.pixels_per_cell}};
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
                                        {"mismatch_fraction", l.mismatch_fraction}}},
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
                      {"queries_per_second", rep.query_seconds > 0 ? double(rep.point_queries) / rep.query_seconds : 0.0}};
  auto& stages = j["stages"] = nlohmann::ordered_json::array();
  for (const StageStats& s : rep.stages)
    stages.push_back({{"name", s.name}, {"seconds", s.seconds}, {"peak_rss_bytes", s.peak_rss_bytes}, {"reused", s.reused}});
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

}  // namespace

Result report(const ReportOptions& ro, const Options& options, Report* out) {
  return stream::guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    const stream::MemoryPlan plan = stream::plan_memory(options);
    if (ro.output_dir.empty()) fail(Status::usage, "no output directory given (-o)");
    const std::vector<RunSpec> runs = resolve_runs(ro);
    stream::Progress progress(options);
    stream::WorkDir work(options.work_dir);
    if (options.check_disk_space) {
      std::vector<std::string> originals;
      for (const RunSpec& r : runs)
        if (std::find(originals.begin(), originals.end(), absolute(r.original)) == originals.end())
          originals.push_back(absolute(r.original));
      stream::check_report_space(originals, work.path());
    }
    stream::make_output_dir(ro.output_dir);
    stream::remove_summary(ro.output_dir + "/report.json");
    Report rep;
    uint64_t input_bytes = 0;  // the originals'
    rep.runs.resize(runs.size());
    std::vector<std::vector<std::vector<io::HtmlView>>> views(runs.size());
    std::vector<std::vector<std::string>> csvs(runs.size());
    // Embree's monitor counts what it reserves, which is more than becomes resident (build scratch is
    // reserved in large blocks), so the whole budget is its guard; the measured VmHWM is what the contract caps.
    const uint64_t original_limit = plan.budget;
    tbb::task_arena arena(static_cast<int>(plan.threads));
    arena.execute([&] {
      // One original at a time, each loaded once for every run that measures against it.
      std::vector<std::string> originals, run_original;  // distinct originals; each run's, as absolute paths
      for (const RunSpec& r : runs) {
        run_original.push_back(absolute(r.original));
        if (std::find(originals.begin(), originals.end(), run_original.back()) == originals.end())
          originals.push_back(run_original.back());
      }
      for (size_t g = 0; g < originals.size(); ++g) {
        const std::string store_dir = work.subdir(g == 0 ? std::string("store") : "store-" + std::to_string(g));
        SceneInfo scene;
        bool reused = false;
        const stream::StoreMeta meta =
            stream::run_ingest_stage(originals[g], store_dir, plan, work, progress, &rep.stages, &scene, &reused);
        input_bytes += scene.file_bytes;
        Original o;
        o.path = originals[g];
        run_stage(&rep.stages, "load", [&](StageStats&) { load_original(store_dir, meta, ro, original_limit, progress, &o); });
        const uint64_t lod_limit = std::max<uint64_t>(64ull << 20, original_limit - std::min(original_limit, o.triangles->embree_bytes()));
        run_stage(&rep.stages, "measure", [&](StageStats&) {
          for (size_t r = 0; r < runs.size(); ++r) {
            if (run_original[r] != o.path) continue;
            ReportRun& rr = rep.runs[r];
            rr.name = runs[r].name;
            rr.original = runs[r].original;
            rr.original_triangles = meta.triangles;
            rr.original_vertices = meta.vertices;
            rr.bbox_diagonal = o.diagonal;
            rr.fov_degrees = runs[r].fov_degrees;
            views[r].resize(runs[r].levels.size());
            for (size_t l = 0; l < runs[r].levels.size(); ++l) {
              LevelResult lr = measure_level(o, runs[r], l, ro, lod_limit, progress);
              lr.level.csv = runs.size() > 1 ? fmt::format("run{}-lod{}.csv", r, l) : fmt::format("lod{}.csv", l);
              std::string csv = kCsvHeader;
              for (const std::string& row : lr.csv_rows) csv += row;
              csvs[r].push_back(std::move(csv));
              views[r][l] = std::move(lr.views);
              rep.rays += lr.rays, rep.point_queries += lr.queries;
              rep.ray_seconds += lr.ray_seconds, rep.query_seconds += lr.query_seconds;
              rr.levels.push_back(std::move(lr.level));
            }
          }
        });
      }
    });
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

}  // namespace lodstream

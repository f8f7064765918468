// Silhouette labels (core/silhouette_labels.h, Mata et al. 2006 §3) and what simplify does with them:
// - a known outline: a square plate, whose outline from every view is its boundary; every label is
//   checked against the exact distance, in each view's image plane, from the vertex's projection to the
//   projected square, converted at the vertex's depth and minimised over the views;
// - cells of two sizes in one level (core/floating_cell.h): no lost vertex, ids in creation order, the
//   per-square bound, the same ids by assign and assign_block, and each grid equal to a clusterer run on
//   its vertices alone;
// - the labels file and every output byte the same for any --threads and --memory;
// - --max-error-px meets its bound on the sample room, and report confirms it on the same views.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <unordered_map>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/floating_cell.h"
#include "core/ray_scene.h"
#include "core/silhouette_labels.h"
#include "core/status.h"
#include "core/view_cast.h"
#include "lodstream/lodstream.h"
#include "test_util.h"

namespace lodstream {
namespace {

namespace fs = std::filesystem;

// A square plate [-1, 1]² at z = 0, n × n quads.
struct Plate {
  std::vector<float> xyz;
  std::vector<uint32_t> triangles;
  int n = 0;
};
Plate make_plate(int n) {
  Plate p;
  p.n = n;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      p.xyz.insert(p.xyz.end(), {-1.0f + 2.0f * i / n, -1.0f + 2.0f * j / n, 0.0f});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      p.triangles.insert(p.triangles.end(), {a, b, d, a, d, c});
    }
  return p;
}

// Image-plane position (pixels, continuous, as view_cast places pixel centers at integer + 0.5) of q.
std::array<double, 3> project(const core::Camera& cam, const double q[3]) {
  double v[3];
  for (int k = 0; k < 3; ++k) v[k] = q[k] - cam.eye[k];
  const double z = v[0] * cam.forward[0] + v[1] * cam.forward[1] + v[2] * cam.forward[2];
  const double sx = (v[0] * cam.right[0] + v[1] * cam.right[1] + v[2] * cam.right[2]) / z;
  const double sy = (v[0] * cam.up[0] + v[1] * cam.up[1] + v[2] * cam.up[2]) / z;
  const double h = cam.resolution, s = h / (2 * cam.tan_half_fov);
  return {sx * s + h / 2, h / 2 - sy * s, z};
}

// The exact label of a plate point in one view: the distance from its projection to the projected
// square's boundary (the projection is convex and holds the point), in scene units at the point's depth.
double exact_label(const core::Camera& cam, const double q[3]) {
  const double corners[4][3] = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  std::array<double, 3> c[4];
  for (int k = 0; k < 4; ++k) c[k] = project(cam, corners[k]);
  const std::array<double, 3> p = project(cam, q);
  double best = INFINITY;
  for (int k = 0; k < 4; ++k) {
    const auto& a = c[k];
    const auto& b = c[(k + 1) % 4];
    const double ex = b[0] - a[0], ey = b[1] - a[1], len = std::hypot(ex, ey);
    if (len == 0) return 0;
    best = std::min(best, std::fabs((p[0] - a[0]) * ey - (p[1] - a[1]) * ex) / len);
  }
  return best * cam.pixel_size(p[2]);
}

TEST(SilhouetteLabels, PlateFacingTheCameraHasItsBoundaryAsOutline) {
  const Plate plate = make_plate(16);
  core::RayScene scene;
  scene.add_triangles(plate.xyz, plate.triangles);
  scene.commit();
  const double eye[3] = {0, 0, 4}, target[3] = {0, 0, 0};
  const core::Camera cam = core::look_at(eye, target, 60, 256);
  core::ViewImage image;
  const core::RayScene* scenes[] = {&scene};
  core::cast_view(scenes, cam, &image);
  std::vector<uint32_t> squared(256 * 256);
  core::outline_distances(image.kind, 256, squared);
  std::vector<float> labels(plate.xyz.size() / 3, core::kNoLabel);
  core::lower_labels(cam, squared, plate.xyz, labels);
  const double px = cam.pixel_size(4);
  for (size_t v = 0; v < labels.size(); ++v) {
    const double x = plate.xyz[3 * v], y = plate.xyz[3 * v + 1];
    const double expected = 1 - std::max(std::fabs(x), std::fabs(y));  // facing the camera: scene units
    EXPECT_NEAR(labels[v], expected, 1.5 * px) << "vertex " << v << " at " << x << ", " << y;
    if (expected == 0) {
      EXPECT_LE(labels[v], 1.0001 * px) << "a boundary vertex is on the outline";
    }
  }
}

TEST(SilhouetteLabels, PlateOverManyViewsMatchesTheExactMinimum) {
  const Plate plate = make_plate(8);
  core::RayScene scene;
  scene.add_triangles(plate.xyz, plate.triangles);
  scene.commit();
  const unsigned views = 12, h = 256;
  const double center[3] = {0, 0, 0}, radius = std::sqrt(2.0);
  std::vector<float> labels(plate.xyz.size() / 3, core::kNoLabel);
  std::vector<double> exact(labels.size(), INFINITY), slack(labels.size(), 0);
  for (unsigned k = 0; k < views; ++k) {
    const core::Camera cam = core::label_camera(k, views, center, radius, 60, h);
    core::ViewImage image;
    const core::RayScene* scenes[] = {&scene};
    core::cast_view(scenes, cam, &image);
    std::vector<uint32_t> squared(h * h);
    core::outline_distances(image.kind, h, squared);
    core::lower_labels(cam, squared, plate.xyz, labels);
    for (size_t v = 0; v < labels.size(); ++v) {
      const double q[3] = {plate.xyz[3 * v], plate.xyz[3 * v + 1], plate.xyz[3 * v + 2]};
      exact[v] = std::min(exact[v], exact_label(cam, q));
      slack[v] = std::max(slack[v], 1.5 * cam.pixel_size(project(cam, q)[2]));
    }
  }
  int boundary = 0;
  for (size_t v = 0; v < labels.size(); ++v) {
    EXPECT_NEAR(labels[v], exact[v], slack[v]) << "vertex " << v;
    const double x = plate.xyz[3 * v], y = plate.xyz[3 * v + 1];
    if (std::max(std::fabs(x), std::fabs(y)) == 1) {
      ++boundary;
      EXPECT_LE(labels[v], slack[v]) << "boundary vertex " << v << " is on the outline in every view";
    }
  }
  EXPECT_EQ(boundary, 4 * 8);
  // The center is well inside in some view (not every view is edge-on): its label is not 0.
  EXPECT_GT(labels[labels.size() / 2], 0.05);
}

// ---- cells of two sizes ----

using P = std::array<double, 3>;

std::vector<P> cloud(size_t n, uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<P> pts(n);
  for (P& p : pts) p = {u(rng), u(rng), u(rng)};
  return pts;
}

TEST(FineCells, InvariantsWithTwoSizesInALevel) {
  const std::vector<P> pts = cloud(20000, 7);
  std::mt19937 rng(3);
  std::vector<uint32_t> masks(pts.size());
  for (uint32_t& m : masks) m = rng() & 3;  // level 0 and level 1 each: near or not
  const double sizes[] = {0.05, 0.12}, fine[] = {0.02, 0.06};
  for (const core::ClusterOptions opt : {core::ClusterOptions{core::Clustering::floating, core::CellShape::cube, core::CellChoice::nearest},
                                         core::ClusterOptions{core::Clustering::floating, core::CellShape::sphere, core::CellChoice::heaviest},
                                         core::ClusterOptions{core::Clustering::uniform, core::CellShape::cube, core::CellChoice::nearest}}) {
    core::Clusterer one(sizes, opt, {}, core::Clusterer::kMaxDenseSquares, fine);
    std::vector<std::vector<uint32_t>> cells(2, std::vector<uint32_t>(pts.size()));
    std::vector<uint32_t> out(2);
    for (size_t v = 0; v < pts.size(); ++v) {
      one.assign(uint32_t(v), pts[v], out, masks[v]);
      cells[0][v] = out[0], cells[1][v] = out[1];
    }
    // The same by blocks, with bounds (dense and packed grids).
    const double bounds[] = {0, 0, 0, 1, 1, 1};
    core::Clusterer block(sizes, opt, bounds, core::Clusterer::kMaxDenseSquares, fine);
    std::vector<uint32_t> ids(pts.size());
    std::vector<double> xyz;
    for (size_t v = 0; v < pts.size(); ++v) ids[v] = uint32_t(v), xyz.insert(xyz.end(), pts[v].begin(), pts[v].end());
    std::vector<uint32_t> bc(2 * pts.size());
    block.assign_block(ids, xyz, bc, masks);
    for (int l = 0; l < 2; ++l) {
      EXPECT_EQ(std::vector<uint32_t>(bc.begin() + l * pts.size(), bc.begin() + (l + 1) * pts.size()), cells[l]);
      EXPECT_EQ(block.cell_count(l), one.cell_count(l));
      // No lost vertex, ids 0, 1, 2, ... in order of creation, each cell in one grid only.
      uint32_t next = 0;
      std::vector<int> grid_of(one.cell_count(l), -1);
      std::vector<size_t> center(one.cell_count(l));
      for (size_t v = 0; v < pts.size(); ++v) {
        const uint32_t c = cells[l][v];
        ASSERT_LT(c, one.cell_count(l));
        ASSERT_LE(c, next);
        if (c == next) ++next, center[c] = v;
        const int g = masks[v] >> l & 1;
        if (grid_of[c] < 0) grid_of[c] = g;
        ASSERT_EQ(grid_of[c], g) << "a cell mixes the two grids";
        // Inside the cell of its grid's size (cube test; spheres fit in it; uniform: the same square).
        const double half = (g ? fine[l] : sizes[l]) / 2;
        if (opt.clustering == core::Clustering::floating) {
          for (int a = 0; a < 3; ++a) ASSERT_LE(std::fabs(pts[v][a] - pts[center[c]][a]), half);
        }
      }
      EXPECT_EQ(next, one.cell_count(l));
      const uint32_t bound = opt.shape == core::CellShape::sphere ? core::kMaxSphereCellsPerSquare : core::kMaxCubeCellsPerSquare;
      EXPECT_LE(one.max_cells_per_square(l), bound);
      EXPECT_GE(one.max_cells_per_square(l), 1u);
      EXPECT_EQ(one.fine_cell_size(l), fine[l]);
      // Each grid is the clustering of its own vertices alone, at its own size.
      for (int g = 0; g < 2; ++g) {
        const double size = g ? fine[l] : sizes[l];
        core::Clusterer alone(std::span<const double>(&size, 1), opt);
        std::vector<uint32_t> mine, theirs;
        std::vector<uint32_t> o1(1);
        for (size_t v = 0; v < pts.size(); ++v)
          if (int(masks[v] >> l & 1) == g) {
            alone.assign(uint32_t(v), pts[v], o1);
            mine.push_back(o1[0]), theirs.push_back(cells[l][v]);
          }
        // Same partition: renumber both in order of first appearance.
        auto renumber = [](const std::vector<uint32_t>& c) {
          std::vector<uint32_t> first_seen(c.size());
          std::unordered_map<uint32_t, uint32_t> m;
          for (size_t i = 0; i < c.size(); ++i) first_seen[i] = m.emplace(c[i], uint32_t(m.size())).first->second;
          return first_seen;
        };
        EXPECT_EQ(renumber(mine), renumber(theirs)) << "level " << l << " grid " << g;
      }
    }
  }
}

TEST(FineCells, RejectsAFineSizeNotBelowTheLevels) {
  const double sizes[] = {0.1}, bad[] = {0.1};
  EXPECT_THROW(core::Clusterer(sizes, {}, {}, core::Clusterer::kMaxDenseSquares, bad), Failure);
}

// ---- through simplify ----

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

SimplifyOptions labelled(const std::string& out) {
  SimplifyOptions so;
  so.output_dir = out;
  so.levels = 3;
  so.silhouette_interval = 3;
  so.silhouette_factor = 0.5;
  so.silhouette_views = 6;
  so.silhouette_resolution = 128;
  so.write_glb = false;
  return so;
}

TEST(SilhouetteSimplify, LabelsAndOutputsAreTheSameForAnyThreadsAndMemory) {
  test::TempDir tmp;
  std::string first_labels, first_level;
  int run = 0;
  // 24 views of 256² take 33 MB: at 64 MiB they are traced in several groups; --chunk-bytes 1 MiB cuts
  // the room into several chunks.
  for (const auto& [threads, memory, chunk] :
       {std::tuple<unsigned, uint64_t, uint64_t>{1, 0, 0}, {2, 64ull << 20, 0}, {0, 80ull << 20, 1ull << 20}}) {
    Options o;
    o.threads = threads;
    o.memory_bytes = memory;
    o.chunk_bytes = chunk;
    o.work_dir = tmp.file("work" + std::to_string(run));
    const std::string out = tmp.file("out" + std::to_string(run));
    SimplifyReport rep;
    SimplifyOptions so = labelled(out);
    so.silhouette_resolution = 256;
    so.silhouette_views = 24;
    const Result r = simplify(sample_room(), so, o, &rep);
    ASSERT_TRUE(r.ok()) << r.message;
    EXPECT_GT(rep.labelled_vertices, 0u);
    if (memory == 64ull << 20) {
      EXPECT_GT(rep.label_view_groups, 1u) << "the views were meant to be traced in groups";
    }
    if (chunk) {
      EXPECT_GT(rep.label_chunks, rep.label_view_groups) << "the room was meant to be traced in chunks";
    }
    ASSERT_GT(rep.levels.at(0).fine_cell_size, 0);
    const std::string labels = slurp(o.work_dir + "/labels.f32"), level = slurp(out + "/lod0.ply");
    ASSERT_FALSE(labels.empty());
    if (run == 0) first_labels = labels, first_level = level;
    EXPECT_EQ(labels, first_labels) << "threads " << threads << " memory " << memory;
    EXPECT_EQ(level, first_level) << "threads " << threads << " memory " << memory;
    ++run;
  }
}

TEST(SilhouetteSimplify, LabelsMakeMoreCellsNearTheOutline) {
  test::TempDir tmp;
  Options o;
  SimplifyOptions with = labelled(tmp.file("with")), without = with;
  without.output_dir = tmp.file("without");
  without.silhouette_interval = 0;
  with.cell_sizes = without.cell_sizes = {0.05, 0.1, 0.2};
  SimplifyReport a, b;
  ASSERT_TRUE(simplify(sample_room(), with, o, &a).ok());
  ASSERT_TRUE(simplify(sample_room(), without, o, &b).ok());
  for (size_t l = 0; l < 3; ++l) EXPECT_GT(a.levels[l].cells, b.levels[l].cells) << "level " << l;
}

TEST(MaxErrorPx, MeetsItsBoundAndReportConfirmsIt) {
  test::TempDir tmp;
  Options o;
  SimplifyOptions so;
  so.output_dir = tmp.file("out");
  so.levels = 2;
  so.resolution = 256;
  so.max_error_px = 1.5;
  so.max_error_views = 4;
  so.write_glb = false;
  SimplifyReport rep;
  const Result r = simplify(sample_room(), so, o, &rep);
  ASSERT_TRUE(r.ok()) << r.message;
  const nlohmann::json m = nlohmann::json::parse(slurp(so.output_dir + "/manifest.json"));
  ASSERT_TRUE(m.contains("max_error"));
  EXPECT_TRUE(m["max_error"]["met"].get<bool>()) << m["max_error"].dump();
  EXPECT_GE(m["max_error"]["passes"].size(), 1u);
  // report, on the same views and resolution, measures the levels as written.
  ReportOptions ro;
  ro.output_dir = tmp.file("report");
  ro.runs = {so.output_dir};
  ro.views = so.max_error_views;
  ro.resolution = so.resolution;
  ro.samples = 4096;
  ro.html_views = 0;
  Report report_out;
  const Result rr = report(ro, o, &report_out);
  ASSERT_TRUE(rr.ok()) << rr.message;
  for (size_t l = 0; l < report_out.runs.at(0).levels.size(); ++l) {
    const double p95 = report_out.runs[0].levels[l].silhouette.p95;
    EXPECT_LE(p95, so.max_error_px) << "level " << l;
    EXPECT_EQ(p95, m["levels"][l]["silhouette_p95_px"].get<double>()) << "level " << l;
  }
}

}  // namespace
}  // namespace lodstream

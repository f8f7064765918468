// lodstream command-line interface: a thin layer over lodstream/lodstream.h.
// Exit codes are the library's Status values (sysexits.h): 0, 64 usage, 65 bad data, 66 no input,
// 70 internal, 74 I/O, 130 cancelled.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lodstream/lodstream.h"
#include "server/serve.h"
#include "tools/slurm_cli.h"

namespace {

std::atomic<bool> g_interrupted{false};
extern "C" void on_sigint(int) { g_interrupted.store(true); }

enum class ProgressMode { automatic, bar, json, none };

struct ProgressState {
  ProgressMode mode = ProgressMode::none;
  // Test-only (LODSTREAM_TEST_STOP_AFTER_PROGRESS set): after each NDJSON line the process stops itself
  // (SIGSTOP), so that tests/test_crash.cpp can kill it at exactly that line or let it go on (SIGCONT).
  bool stop_after_line = false;
  std::mutex mutex;
  std::string last_stage;
  int last_percent = -1;
  std::chrono::steady_clock::time_point last_time{};
  bool bar_open = false;
};

bool on_progress(void* user, const char* stage, double fraction) {
  auto* st = static_cast<ProgressState*>(user);
  if (st->mode == ProgressMode::none) return !g_interrupted.load();
  std::lock_guard lock(st->mutex);
  const int percent = static_cast<int>(fraction * 100.0);
  const bool new_stage = st->last_stage != stage;
  if (!new_stage && percent == st->last_percent) return !g_interrupted.load();
  const auto now = std::chrono::steady_clock::now();
  // The bar redraws at most every 100 ms; NDJSON has one line per percent step.
  if (st->mode == ProgressMode::bar && !new_stage && percent < 100 && now - st->last_time < std::chrono::milliseconds(100))
    return !g_interrupted.load();
  st->last_time = now;
  st->last_percent = percent;
  if (st->mode == ProgressMode::json) {
    std::fprintf(stderr, "%s\n", nlohmann::json{{"stage", stage}, {"fraction", fraction}}.dump().c_str());
    std::fflush(stderr);
    if (st->stop_after_line) std::raise(SIGSTOP);
  } else {
    if (new_stage && st->bar_open) std::fputc('\n', stderr);
    const int width = 30, filled = percent * width / 100;
    std::fprintf(stderr, "\r%-12s [%s%s] %3d%%", stage, std::string(static_cast<size_t>(filled), '#').c_str(),
                 std::string(static_cast<size_t>(width - filled), ' ').c_str(), percent);
    st->bar_open = true;
  }
  st->last_stage = stage;
  std::fflush(stderr);
  return !g_interrupted.load();
}


std::string human_bytes(uint64_t b) {
  if (b >= (1ull << 30)) return fmt::format("{:.2f} GiB", static_cast<double>(b) / (1ull << 30));
  if (b >= (1ull << 20)) return fmt::format("{:.1f} MiB", static_cast<double>(b) / (1ull << 20));
  if (b >= (1ull << 10)) return fmt::format("{:.1f} KiB", static_cast<double>(b) / (1ull << 10));
  return fmt::format("{} B", b);
}

std::string grouped(uint64_t n) {
  const std::string digits = std::to_string(n);
  std::string s;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s += ',';
    s += digits[i];
  }
  return s;
}

std::string work_dir_text(const lodstream::WorkDirUsage& u) {
  std::string s = human_bytes(u.bytes);
  if (u.input_bytes) s += fmt::format(" ({:.2f}x the input)", static_cast<double>(u.bytes) / static_cast<double>(u.input_bytes));
  return s;
}

nlohmann::ordered_json info_json(const lodstream::SceneInfo& in) {
  nlohmann::ordered_json stages = nlohmann::ordered_json::array();
  for (const auto& s : in.stages)
    stages.push_back({{"name", s.name}, {"seconds", s.seconds}, {"peak_rss_bytes", s.peak_rss_bytes}, {"reused", s.reused}});
  return {{"path", in.path},
          {"format", in.format},
          {"file_bytes", in.file_bytes},
          {"vertex_records", in.vertex_records},
          {"vertices", in.vertices},
          {"vertices_welded", in.vertices_welded},
          {"unused_vertices", in.unused_vertices},
          {"polygons", in.polygons},
          {"triangles", in.triangles},
          {"degenerate", in.degenerate},
          {"degenerate_segments", in.degenerate_segments},
          {"face_segments", in.face_segments},
          {"polygons_concave", in.polygons_concave},
          {"polygons_fallback", in.polygons_fallback},
          {"lines", in.lines},
          {"points", in.points},
          {"objects", in.objects},
          {"skipped_statements", in.skipped_statements},
          {"bbox", {{"min", in.bbox_min}, {"max", in.bbox_max}}},
          {"seconds", in.seconds},
          {"peak_rss_bytes", in.peak_rss_bytes},
          {"stages", stages},
          {"work_dir", nlohmann::ordered_json::parse(lodstream::work_dir_json(in.work_dir))}};
}

void print_info(const lodstream::SceneInfo& in) {
  std::printf("file         %s (%s, %s)\n", in.path.c_str(), in.format.c_str(), human_bytes(in.file_bytes).c_str());
  std::printf("vertices     %s stored, %s after welding by exact position", grouped(in.vertices).c_str(),
              grouped(in.vertices_welded).c_str());
  if (in.vertex_records != in.vertices) std::printf(" (%s vertex records in the file)", grouped(in.vertex_records).c_str());
  if (in.unused_vertices) std::printf(", %s unused", grouped(in.unused_vertices).c_str());
  std::printf("\n");
  std::printf("triangles    %s from %s polygons, %s degenerate dropped", grouped(in.triangles).c_str(),
              grouped(in.polygons).c_str(), grouped(in.degenerate).c_str());
  if (in.polygons_concave) std::printf(", %s concave polygons", grouped(in.polygons_concave).c_str());
  if (in.polygons_fallback) std::printf(", %s without a plane or self-intersecting (fan)", grouped(in.polygons_fallback).c_str());
  std::printf("\nlines        %s", grouped(in.lines).c_str());
  if (in.face_segments) std::printf(" (%s from faces naming two vertices)", grouped(in.face_segments).c_str());
  if (in.degenerate_segments) std::printf(" (%s zero-length dropped)", grouped(in.degenerate_segments).c_str());
  std::printf("\npoints       %s\n", grouped(in.points).c_str());
  std::printf("objects      %s\n", grouped(in.objects).c_str());
  if (in.skipped_statements) std::printf("skipped      %s records not used (texture coordinates, normals, materials, ...)\n", grouped(in.skipped_statements).c_str());
  std::printf("bbox         min (%g, %g, %g)  max (%g, %g, %g)\n", in.bbox_min[0], in.bbox_min[1], in.bbox_min[2],
              in.bbox_max[0], in.bbox_max[1], in.bbox_max[2]);
  for (const auto& s : in.stages)
    std::printf("stage        %-10s %8.3f s  peak %s%s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str(),
                s.reused ? "  (reused from work directory)" : "");
  std::printf("total        %.3f s, peak %s\n", in.seconds, human_bytes(in.peak_rss_bytes).c_str());
  std::printf("work dir     %s\n", work_dir_text(in.work_dir).c_str());
}

void print_simplify(const lodstream::SimplifyReport& r, const std::string& out_dir) {
  std::printf("input        %s (%s): %s triangles, %s lines, %s points; %s positions graded\n", r.input.c_str(),
              r.scene.format.c_str(), grouped(r.scene.triangles).c_str(), grouped(r.scene.lines).c_str(),
              grouped(r.scene.points).c_str(), grouped(r.vertices_graded).c_str());
  std::printf("%-6s %12s %12s %12s %10s %10s %14s  %s\n", "level", "cell size", "triangles", "vertices", "edges", "points",
              "switch dist", "files");
  for (size_t l = 0; l < r.levels.size(); ++l) {
    const auto& lv = r.levels[l];
    std::string files;
    for (const auto& f : lv.files) files += (files.empty() ? "" : " ") + f;
    std::printf("%-6zu %12.6g %12s %12s %10s %10s %14.6g  %s\n", l, lv.cell_size, grouped(lv.triangles).c_str(),
                grouped(lv.vertices).c_str(), grouped(lv.edges).c_str(), grouped(lv.points).c_str(), lv.switch_distance,
                files.c_str());
  }
  if (r.search_iterations)
    std::printf("search       %u clustering passes, %.3f s\n", r.search_iterations, r.search_seconds);
  if (r.tiles.tiles)
    std::printf("tiles        %s tiles (%s with content), %s triangles, at most %s a tile, %s; tiles/tileset.json\n",
                grouped(r.tiles.tiles).c_str(), grouped(r.tiles.content_tiles).c_str(), grouped(r.tiles.triangles).c_str(),
                grouped(r.tiles.max_triangles).c_str(), human_bytes(r.tiles.bytes).c_str());
  for (const auto& s : r.stages)
    std::printf("stage        %-10s %8.3f s  peak %s%s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str(),
                s.reused ? "  (reused from work directory)" : "");
  std::printf("total        %.3f s, peak %s; wrote %s/manifest.json\n", r.seconds, human_bytes(r.peak_rss_bytes).c_str(),
              out_dir.c_str());
  std::printf("work dir     %s\n", work_dir_text(r.work_dir).c_str());
}

void print_grid(const lodstream::GridReport& r, const std::string& out_dir) {
  std::printf("input        %s (%s): %u x %u samples, %s valid, spacing %g\n", r.input.c_str(), r.format.c_str(), r.width,
              r.height, grouped(r.valid_samples).c_str(), r.spacing);
  std::printf("polygons     %s (%s fill polygons, %s fill vertex references); %s hole cells\n", grouped(r.polygons).c_str(),
              grouped(r.fill_polygons).c_str(), grouped(r.fill_vertices).c_str(), grouped(r.hole_cells).c_str());
  std::printf("vertices     %s retained, %s sent; %s triangles drawn; %s bytes\n", grouped(r.vertices).c_str(),
              grouped(r.draw_vertices).c_str(), grouped(r.triangles).c_str(), grouped(r.bytes).c_str());
  std::printf("error        max %.6g, RMS %.6g over %s samples (%s uncovered)\n", r.max_error, r.rms_error,
              grouped(r.measured_samples).c_str(), grouped(r.uncovered_samples).c_str());
  std::printf("faces        grid.obj and grid.ply hold the %s\n",
              r.obj_ply_faces == "polygons" ? "polygons (n-gons)" : "drawn triangles (as grid.glb)");
  std::printf("junctions    %s T-junctions, %s with a gap (max %.6g), %s open cracks\n", grouped(r.t_junctions).c_str(),
              grouped(r.gaps).c_str(), r.max_gap, grouped(r.cracks).c_str());
  if (r.angle_step > 0)
    std::printf("cylinder     %.6g degrees and %g units per step, %s; %u empty rows trimmed at the top, %u at the bottom; errors are radii\n",
                r.angle_step, r.height_step, r.closed ? "a full turn, seam closed" : "a partial turn", r.trimmed_rows_top,
                r.trimmed_rows_bottom);
  for (const auto& s : r.stages)
    std::printf("stage        %-10s %8.3f s  peak %s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str());
  std::printf("total        %.3f s, peak %s; wrote %s/summary.json\n", r.seconds, human_bytes(r.peak_rss_bytes).c_str(),
              out_dir.c_str());
}

// An index option I/N (`name`: its flag: --shard, --shard-ingest, --shard-grade, --shard-cluster), or I and N
// from the environment (--shard-from-env); prints the error and returns false when it cannot be read.
bool read_index_option(const char* name, const std::string& text, bool from_env, unsigned* index, unsigned* count) {
  std::string error;
  if (from_env) {
    if (lodstream::shard_from_env(index, count, &error)) return true;
  } else {
    char slash = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%u%c%u%c", index, &slash, count, &extra) == 3 && slash == '/' && *count > 0 && *index < *count)
      return true;
    error = std::string(name) + ": '" + text + "' is not I/N with 0 <= I < N";
  }
  std::fprintf(stderr, "lodstream: %s\n", error.c_str());
  return false;
}

void print_report(const lodstream::Report& r, const std::string& out_dir) {
  for (const auto& run : r.runs) {
    std::printf("run          %s: original %s, %s triangles\n", run.name.c_str(), run.original.c_str(),
                grouped(run.original_triangles).c_str());
    std::printf("%-6s %12s %12s %26s %10s %10s %12s %24s\n", "level", "triangles", "switch dist", "silhouette max/p95/mean px",
                "mismatch", "thin kept", "normal p95", "Hausdorff max/mean %diag");
    for (size_t l = 0; l < run.levels.size(); ++l) {
      const auto& v = run.levels[l];
      const std::string sil = fmt::format("{:.3g} / {:.3g} / {:.3g}", v.silhouette.max, v.silhouette.p95, v.silhouette.mean);
      const std::string hd = fmt::format("{:.3g} / {:.3g}", v.hausdorff_max_percent, v.hausdorff_mean_percent);
      std::printf("%-6zu %12s %12.6g %26s %9.3f%% %9.1f%% %11.3g° %24s\n", l, grouped(v.triangles).c_str(), v.switch_distance,
                  sil.c_str(), 100 * v.mismatch_fraction, 100 * v.thin_kept_fraction, v.normal.p95, hd.c_str());
    }
  }
  std::printf("rays         %s in %.3f s (%.3g M/s); %s point queries in %.3f s (%.3g M/s)\n", grouped(r.rays).c_str(),
              r.ray_seconds, r.ray_seconds > 0 ? r.rays / r.ray_seconds / 1e6 : 0.0, grouped(r.point_queries).c_str(),
              r.query_seconds, r.query_seconds > 0 ? r.point_queries / r.query_seconds / 1e6 : 0.0);
  for (const auto& s : r.stages)
    std::printf("stage        %-10s %8.3f s  peak %s%s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str(),
                s.reused ? "  (reused from work directory)" : "");
  std::printf("total        %.3f s, peak %s; wrote %s/report.json and report.html\n", r.seconds,
              human_bytes(r.peak_rss_bytes).c_str(), out_dir.c_str());
  std::printf("work dir     %s\n", work_dir_text(r.work_dir).c_str());
}

// How every subcommand ends: the progress bar's line closed; on failure the one-line error and its exit
// status; else the JSON file the job wrote (when `json_file` is given: --json) or the text summary.
template <class Print>
int finish(const lodstream::Result& r, const ProgressState& progress, const std::string& json_file, Print&& print) {
  if (progress.bar_open) std::fputc('\n', stderr);
  if (!r.ok()) {
    std::fprintf(stderr, "lodstream: %s\n", r.message.c_str());
    return static_cast<int>(r.status);
  }
  if (!json_file.empty()) {
    std::ifstream in(json_file);
    std::printf("%s\n", nlohmann::ordered_json::parse(in).dump().c_str());
  } else {
    print();
  }
  return 0;
}

// "a,b,c" -> values; false on any unreadable item.
template <class T>
bool parse_list(const std::string& text, std::vector<T>* out) {
  out->clear();
  size_t at = 0;
  while (at <= text.size()) {
    const size_t comma = std::min(text.find(',', at), text.size());
    const std::string item = text.substr(at, comma - at);
    try {
      size_t used = 0;
      if constexpr (std::is_floating_point_v<T>) {
        const double v = std::stod(item, &used);
        out->push_back(v);
      } else {
        if (!item.empty() && item[0] == '-') return false;
        const unsigned long long v = std::stoull(item, &used);
        out->push_back(static_cast<T>(v));
      }
      if (used != item.size()) return false;
    } catch (const std::exception&) {
      return false;
    }
    at = comma + 1;
  }
  return !out->empty();
}

// Transparent huge pages for the allocator's large blocks (glibc's tunable glibc.malloc.hugetlb=1: its
// mmap'd and heap memory is madvise'd MADV_HUGEPAGE, which the kernel's default THP mode, "madvise",
// waits for). The stages allocate and fill arrays of hundreds of MiB (a weld's keys, a task's packed
// maps); in 4 KiB pages a page fault every 4 KiB, and the unmapping, took about a third of a grading
// share's CPU on a virtual machine (the 193 M-triangle city's first grading share of 8: 37.5-46.2 s,
// 69-84 CPU-s; with the tunable 23.3-27.4 s, 43-50 CPU-s). glibc reads its tunables only when a process
// starts, so the CLI sets the tunable and executes itself again, once: a GLIBC_TUNABLES that names
// glibc.malloc.hugetlb already (this second start, or the user's own choice, e.g. =0 to opt out) is
// left alone, and where the executable cannot be run again the process goes on as it is. The bytes
// written do not depend on it; jobs that this process starts (the job server's, Slurm's) inherit it.
void use_huge_pages(char** argv) {
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (tunables && std::strstr(tunables, "glibc.malloc.hugetlb")) return;
  const std::string set = tunables && *tunables ? std::string(tunables) + ":glibc.malloc.hugetlb=1" : "glibc.malloc.hugetlb=1";
  if (::setenv("GLIBC_TUNABLES", set.c_str(), 1) != 0) return;
  ::execv("/proc/self/exe", argv);
}

// Test-only (LODSTREAM_TEST_HUGE_PAGES set): prints the GLIBC_TUNABLES this process runs with and whether
// a fresh 64 MiB block of the allocator may be backed by huge pages (its mapping's THPeligible in
// /proc/self/smaps), then exits; tests/test_cli.cpp checks use_huge_pages by it.
int print_huge_pages() {
  const size_t bytes = size_t{64} << 20;
  char* block = static_cast<char*>(std::malloc(bytes));
  if (!block) return 70;
  block[0] = 1;
  const auto at = reinterpret_cast<unsigned long>(block);
  std::ifstream smaps("/proc/self/smaps");
  std::string line, eligible = "unknown";
  bool inside = false;
  while (std::getline(smaps, line)) {
    unsigned long lo = 0, hi = 0;
    if (std::sscanf(line.c_str(), "%lx-%lx", &lo, &hi) == 2) inside = lo <= at && at < hi;
    else if (inside && line.rfind("THPeligible:", 0) == 0) eligible = line.substr(line.find_last_of(" \t") + 1);
  }
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  std::printf("tunables=%s thp_eligible=%s\n", tunables ? tunables : "", eligible.c_str());
  std::free(block);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  use_huge_pages(argv);
  if (std::getenv("LODSTREAM_TEST_HUGE_PAGES")) return print_huge_pages();
  CLI::App app{"lodstream: out-of-core levels of detail for huge CAD and architectural scenes"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "lodstream 0.1.0");

  lodstream::Options options;
  std::string memory_text, chunk_text, progress_text = "auto";
  auto add_common = [&](CLI::App* cmd) {
    cmd->add_option("--threads", options.threads, "Worker threads (0 = all cores)");
    cmd->add_option("--memory", memory_text, "Cap on peak resident memory, e.g. 1G (default: half of RAM)");
    cmd->add_option("--chunk-bytes", chunk_text, "Input bytes per parse chunk (default: from --memory)");
    cmd->add_option("--work", options.work_dir, "Work directory, kept for inspection and resuming (default: temporary)");
    cmd->add_option("--progress", progress_text, "Progress on stderr: auto (bar on a terminal), bar, json (NDJSON), none")
        ->check(CLI::IsMember({"auto", "bar", "json", "none"}));
  };
  bool no_space_check = false;
  auto add_space_check = [&](CLI::App* cmd) {
    cmd->add_flag("--no-space-check", no_space_check,
                  "Start even when the free disk space looks too small for the estimated work directory and outputs");
  };

  CLI::App* info_cmd = app.add_subcommand("info", "Ingest a scene and print its statistics");
  std::string input;
  bool json = false;
  info_cmd->add_option("FILE", input, "Input scene (.obj, .ply, .stl, .glb, .gltf)")->required();
  info_cmd->add_flag("--json", json, "Print one JSON object instead of text");
  add_common(info_cmd);
  add_space_check(info_cmd);

  CLI::App* simplify_cmd = app.add_subcommand("simplify", "Build a chain of levels of detail (Low & Tan vertex clustering)");
  lodstream::SimplifyOptions so;
  std::string grading = "lowtan", clustering = "floating", cell = "cube", variant = "nearest", rep = "quadric";
  std::string sizes_text, targets_text;
  bool obj = false, no_glb = false, no_ply = false;
  simplify_cmd->add_option("INPUT", input, "Input scene (.obj, .ply, .stl, .glb, .gltf)")->required();
  simplify_cmd->add_option("-o,--output", so.output_dir, "Output directory (created if missing)")->required();
  simplify_cmd->add_option("--grading", grading, "Vertex grade: lowtan (cos(θ/2)·Lmax) or rossignac (Lmax/θ)")
      ->check(CLI::IsMember({"lowtan", "rossignac"}));
  simplify_cmd->add_option("--clustering", clustering, "floating (Low & Tan) or uniform (Rossignac & Borrel grid at the origin)")
      ->check(CLI::IsMember({"floating", "uniform"}));
  simplify_cmd->add_option("--cell", cell, "Floating cell shape: cube or sphere")->check(CLI::IsMember({"cube", "sphere"}));
  simplify_cmd->add_option("--variant", variant, "Cell a vertex joins when several contain it: nearest or heaviest")
      ->check(CLI::IsMember({"nearest", "heaviest"}));
  simplify_cmd->add_option("--representative", rep, "Cell representative: center, mean (grade-weighted) or quadric")
      ->check(CLI::IsMember({"center", "mean", "quadric"}));
  simplify_cmd->add_option("--levels", so.levels, "Exactly N levels when no sizes or targets are given (default: up to 5, while counts fall)")
      ->check(CLI::Range(1u, 32u));
  simplify_cmd->add_option("--cell-sizes", sizes_text, "Cell sizes a,b,... in scene units, finest first");
  simplify_cmd->add_option("--target-triangles", targets_text, "Triangle counts t1,t2,... to aim at (searched, ±15%)");
  simplify_cmd->add_option("--crease", so.crease_degrees, "Crease angle for normals, degrees (default 30)");
  simplify_cmd->add_option("--tile-triangles", so.tile_triangles,
                           "Regions (and 3D Tiles) of a level hold at most N/2 of its cells, about N triangles (default 200000)");
  simplify_cmd->add_option("--fov", so.fov_degrees, "Vertical field of view for switching distances, degrees (default 60)");
  simplify_cmd->add_option("--resolution", so.resolution, "Image height in pixels for switching distances (default 1080)");
  simplify_cmd->add_option("--pixels-per-cell", so.pixels_per_cell, "X of Low & Tan §4: cell width in pixels at the switch (default 5)");
  simplify_cmd->add_option("--silhouette-interval", so.silhouette_interval,
                           "Mata et al. distance interval D: vertices within D pixels of an outline get finer cells (0 = off, the default)");
  simplify_cmd->add_option("--silhouette-factor", so.silhouette_factor,
                           "Mata et al. error factor f: near the outline, cells are f times the level's size (default 0.5)");
  simplify_cmd->add_option("--silhouette-views", so.silhouette_views, "Views the silhouette labels are taken from (default 16)");
  simplify_cmd->add_option("--silhouette-resolution", so.silhouette_resolution, "Pixels per side of a label view (default 512)");
  simplify_cmd->add_option("--max-error-px", so.max_error_px,
                           "Lower each level's cells until its silhouette p95 at its switching distance is at most E pixels (0 = off)");
  simplify_cmd->add_option("--max-error-views", so.max_error_views, "Views --max-error-px measures on (default 8)");
  simplify_cmd->add_flag("--obj", obj, "Also write lodN.obj");
  simplify_cmd->add_flag("--no-ply", no_ply, "Do not write lodN.ply");
  simplify_cmd->add_flag("--no-glb", no_glb, "Do not write lods.glb");
  simplify_cmd->add_flag("--json", json, "Print the manifest's summary as one JSON object");
  std::string tile_lines = "triangles", tiles_transform_text;
  simplify_cmd->add_flag("--tiles", so.write_tiles, "Also write 3D Tiles 1.1: tiles/tileset.json and one GLB per tile");
  simplify_cmd->add_option("--tile-lines", tile_lines, "Edges and points in tiles: triangles (thick, default) or lines (glTF LINES/POINTS)")
      ->check(CLI::IsMember({"triangles", "lines"}));
  std::string tile_encoding = "meshopt";
  simplify_cmd->add_option("--tile-encoding", tile_encoding,
                           "Tile GLBs: meshopt (quantized and EXT_meshopt_compression, default), quantized (KHR_mesh_quantization) or plain (floats)")
      ->check(CLI::IsMember({"meshopt", "quantized", "plain"}));
  std::string tiles_up = "y";
  simplify_cmd->add_option("--tiles-up", tiles_up, "The input's up axis for tiles: y (glTF's, default) or z (rotated upright)")
      ->check(CLI::IsMember({"y", "z"}));
  simplify_cmd->add_option("--tiles-transform", tiles_transform_text,
                           "Tileset root transform: 16 numbers (4x4, column-major) or lon,lat,height (degrees, metres)");
  std::string shard_text;
  bool shard_from_env = false;
  simplify_cmd->add_option("--shard", shard_text, "Run task I of N over a shared --work DIR (then `lodstream merge OUTDIR`)");
  simplify_cmd->add_flag("--shard-from-env", shard_from_env,
                         "--shard from SLURM_ARRAY_TASK_ID/COUNT, JOB_COMPLETION_INDEX or AWS_BATCH_JOB_ARRAY_INDEX (count: LODSTREAM_SHARD_COUNT)");
  simplify_cmd->add_flag("--shard-prepare", so.shard_prepare, "Run the stages every task shares (ingest to cluster) over --work DIR, then stop (with --shard I/N: "
                         "the I-th of N such jobs, which share the clustering merge's units)");
  std::string shard_ingest_text;
  simplify_cmd->add_option("--shard-ingest", shard_ingest_text,
                           "Parse byte range I of N of the input into --work DIR, then stop (--shard-prepare joins the N ranges)");
  std::string shard_grade_text;
  simplify_cmd->add_option("--shard-grade", shard_grade_text,
                           "Run share I of N of the grading and the weight index's sort over --work DIR, then stop (the stages "
                           "before it first, unless another task ran them; any later step merges the shares)");
  std::string shard_cluster_text;
  simplify_cmd->add_option("--shard-cluster", shard_cluster_text,
                           "Run share I of N of the clustering over --work DIR, then stop (the stages before it first, unless "
                           "another task ran them; then --cluster-shards N merges the shares)");
  simplify_cmd->add_option("--cluster-shards", so.cluster_shares,
                           "With --shard or --shard-prepare: cluster by merging N --shard-cluster shares (running any no task ran)")
      ->check(CLI::Range(1u, 100000u));
  add_common(simplify_cmd);
  add_space_check(simplify_cmd);

  CLI::App* merge_cmd = app.add_subcommand("merge", "Write a sharded simplify's outputs from its tasks' parts (OUTDIR/shards)");
  std::string merge_dir;
  merge_cmd->add_option("OUTDIR", merge_dir, "The output directory the tasks wrote to")->required();
  merge_cmd->add_flag("--json", json, "Print the manifest's summary as one JSON object");
  merge_cmd->add_option("--threads", options.threads, "Worker threads (0 = all cores)");
  merge_cmd->add_option("--progress", progress_text, "Progress on stderr: auto (bar on a terminal), bar, json (NDJSON), none")
      ->check(CLI::IsMember({"auto", "bar", "json", "none"}));

  CLI::App* slurm_cmd = app.add_subcommand("slurm", "Run simplify or report as Slurm jobs: lodstream slurm simplify|report IN -o OUT --shards N [--wait] ...");
  slurm_cmd->prefix_command();

  CLI::App* report_cmd = app.add_subcommand(
      "report", "Measure each level's error in pixels at its switching distance (Embree ray casts, Hausdorff)");
  lodstream::ReportOptions ro;
  std::string distances_text;
  report_cmd->add_option("OUTDIR", ro.runs, "simplify output directories (several: side by side)");
  report_cmd->add_option("-o,--output", ro.output_dir, "Report directory (default: the one simplify directory given)");
  report_cmd->add_option("--original", ro.original, "The original scene (default: the manifest's input)");
  report_cmd->add_option("--lod", ro.lods, "A LOD file (.ply, .obj) of --original, finest first; repeat for each");
  report_cmd->add_option("--switch-distances", distances_text, "With --lod: camera distance d1,d2,... per LOD");
  report_cmd->add_option("--views", ro.views, "View directions per level (default 32)");
  report_cmd->add_option("--resolution", ro.resolution, "Image width and height in pixels (default 512)");
  report_cmd->add_option("--seed", ro.seed, "Seed of view targets and surface samples (default 1)");
  report_cmd->add_option("--samples", ro.samples, "Hausdorff samples of each kind (vertex, edge, face) per direction (default 250000)");
  report_cmd->add_option("--fov", ro.fov_degrees, "With --lod: field of view, degrees (default 60)");
  report_cmd->add_option("--pixels-per-cell", ro.pixels_per_cell,
                         "With --lod and no distances: the Hausdorff max spans this many pixels at the switch (default 5)");
  report_cmd->add_option("--html-views", ro.html_views, "Views per level rendered into report.html (default 3)");
  report_cmd->add_option("--supersample", ro.supersample,
                         "k: a pixel is covered when its centre ray or any of k x k rays over it hits, for original and level alike (1-16, default 3)");
  report_cmd->add_flag("--json", json, "Print report.json instead of the table");
  add_common(report_cmd);
  add_space_check(report_cmd);
  std::string report_shard_text;
  bool report_shard_from_env = false;
  report_cmd->add_option("--shard", report_shard_text,
                         "Measure task I of N's share (an N-th of every original's and level's primitives) over a shared --work DIR "
                         "(then `lodstream merge -o's DIR`)");
  report_cmd->add_flag("--shard-from-env", report_shard_from_env,
                       "--shard from SLURM_ARRAY_TASK_ID/COUNT, JOB_COMPLETION_INDEX or AWS_BATCH_JOB_ARRAY_INDEX (count: LODSTREAM_SHARD_COUNT)");
  report_cmd->add_flag("--shard-prepare", ro.shard_prepare,
                       "Ingest the originals into --work DIR for the tasks, then stop");
  std::string report_shard_ingest_text;
  report_cmd->add_option("--shard-ingest", report_shard_ingest_text,
                         "Parse byte range I of N of every original into --work DIR, then stop (--shard-prepare joins the N ranges)");

  CLI::App* grid_cmd = app.add_subcommand("grid", "Fit polygons to a height grid by adaptive subdivision (DeHaemer 1989)");
  lodstream::GridOptions go;
  std::string split = "greatest", gaps = "extra-vertices", method = "subdivision";
  bool no_obj = false;
  grid_cmd->add_option("INPUT", input, "Height grid (Terrain-RGB PNG, PGM, ESRI ASCII .asc)")->required();
  grid_cmd->add_option("-o,--output", go.output_dir, "Output directory (created if missing)")->required();
  grid_cmd->add_option("--tolerance", go.tolerance, "Largest vertical distance of a sample from the drawn surface (z units)");
  grid_cmd->add_option("--split", split, "Where a failing polygon splits: center, first, greatest, curvature, random")
      ->check(CLI::IsMember({"center", "first", "greatest", "curvature", "random"}));
  grid_cmd->add_option("--divide", go.divide, "Split into 4, or 2 across the longer side (default 4)")->check(CLI::IsMember({2u, 4u}));
  grid_cmd->add_option("--gaps", gaps, "Edge gaps: none (cracks remain), extra-vertices, fill (fill polygons)")
      ->check(CLI::IsMember({"none", "extra-vertices", "fill"}));
  grid_cmd->add_option("--target-polygons", go.target_polygons, "Refine greatest error first until N polygons");
  grid_cmd->add_option("--method", method, "subdivision or growth (polygon growth, slow)")
      ->check(CLI::IsMember({"subdivision", "growth"}));
  grid_cmd->add_option("--seed", go.seed, "Seed of --split random (default 1)");
  grid_cmd->add_flag("--merge", go.merge, "Then merge polygons sharing a whole side while their union passes (not in the thesis)");
  grid_cmd->add_option("--z-scale", go.z_scale, "PGM: height = sample value x this (default 1)");
  grid_cmd->add_option("--spacing", go.spacing, "Sample distance, overriding the file's (default: file, or 1)");
  CLI::Option* cyl_flag = grid_cmd->add_flag("--cylindrical", go.cylindrical,
                                             "The grid holds a cylindrical scan's radii (0 or NODATA: no return); a 3D mesh");
  grid_cmd->add_option("--height-step", go.height_step, "Cylindrical: scene units per row (default: the file's cell size, or 1)")->needs(cyl_flag);
  grid_cmd->add_option("--angle-step", go.angle_step, "Cylindrical: degrees per column (default 360 / columns: a full turn)")->needs(cyl_flag);
  std::string axis = "y";
  grid_cmd->add_option("--axis", axis, "Cylindrical: the axis, x, y (default) or z")->check(CLI::IsMember({"x", "y", "z"}))->needs(cyl_flag);
  grid_cmd->add_flag("--no-obj", no_obj, "Do not write grid.obj");
  grid_cmd->add_flag("--no-ply", no_ply, "Do not write grid.ply");
  grid_cmd->add_flag("--no-glb", no_glb, "Do not write grid.glb");
  grid_cmd->add_flag(
      "--polygons", go.polygons,
      "grid.obj and grid.ply hold the n-gons, not the drawn triangles (a viewer's triangulation of "
      "them may leave the tolerance)");
  grid_cmd->add_flag("--json", json, "Print summary.json instead of the table");
  add_common(grid_cmd);

  CLI::App* serve_cmd = app.add_subcommand("serve", "Run jobs over HTTP (OGC API - Processes), each in a child process");
  lodstream::serve::ServeOptions serve;
  std::string upload_text;
  serve_cmd->add_option("--bind", serve.bind, "HOST:PORT to listen on (default 127.0.0.1:8080; port 0: any free port)");
  serve_cmd->add_option("--data-root", serve.data_root, "Directory whose files jobs may read")->required();
  serve_cmd->add_option("--jobs-dir", serve.jobs_dir, "Directory of job state, work directories and outputs")->required();
  serve_cmd->add_option("--token-file", serve.token_file, "File holding a token every request must send (Authorization: Bearer)");
  serve_cmd->add_option("--max-jobs", serve.max_jobs, "Jobs running at once (default 1)")->check(CLI::Range(1u, 256u));
  serve_cmd->add_option("--memory", memory_text, "The running jobs' --memory caps add up to at most this (default: half of RAM)");
  serve_cmd->add_option("--job-threads", serve.job_threads, "Each job's --threads (default 0: all cores)");
  serve_cmd->add_option("--max-upload", upload_text, "Largest upload, e.g. 2G (default 1G)");
  serve_cmd->add_option("--timeout", serve.timeout_seconds, "Seconds a client may stay silent while sending or receiving (default 10)")
      ->check(CLI::Range(1, 3600));
  serve_cmd->add_option("--request-timeout", serve.request_timeout_seconds,
                        "Seconds a request's line and headers may take; bodies in and out must then keep up --min-rate (default 30)")
      ->check(CLI::Range(1, 3600));
  serve_cmd->add_option("--min-rate", serve.min_rate, "Bytes a second a request's body and response must average (default 1024)")
      ->check(CLI::Range(uint64_t{1}, uint64_t{1} << 40));

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "lodstream: %s (see lodstream --help)\n", e.what());
    return static_cast<int>(lodstream::Status::usage);
  }
  if (!memory_text.empty() && !lodstream::parse_size(memory_text, &options.memory_bytes)) {
    std::fprintf(stderr, "lodstream: --memory: cannot read '%s' as a size (e.g. 1G, 512M)\n", memory_text.c_str());
    return static_cast<int>(lodstream::Status::usage);
  }
  if (!chunk_text.empty() && (!lodstream::parse_size(chunk_text, &options.chunk_bytes) || options.chunk_bytes == 0)) {
    std::fprintf(stderr, "lodstream: --chunk-bytes: cannot read '%s' as a positive size\n", chunk_text.c_str());
    return static_cast<int>(lodstream::Status::usage);
  }

  if (slurm_cmd->parsed()) {
    char self[4096];
    const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
    return lodstream::cli::run_slurm(n > 0 ? std::string(self, static_cast<size_t>(n)) : std::string(argv[0]), slurm_cmd->remaining());
  }

  if (serve_cmd->parsed()) {
    if (!upload_text.empty() && !lodstream::parse_size(upload_text, &serve.max_upload_bytes)) {
      std::fprintf(stderr, "lodstream: --max-upload: cannot read '%s' as a size\n", upload_text.c_str());
      return static_cast<int>(lodstream::Status::usage);
    }
    serve.memory_bytes = options.memory_bytes;
    return lodstream::serve::run(serve);
  }

  options.check_disk_space = !no_space_check;
  ProgressState progress;
  progress.mode = progress_text == "json"   ? ProgressMode::json
                  : progress_text == "bar"  ? ProgressMode::bar
                  : progress_text == "none" ? ProgressMode::none
                  : isatty(STDERR_FILENO)   ? ProgressMode::bar
                                            : ProgressMode::none;
  progress.stop_after_line = progress.mode == ProgressMode::json && std::getenv("LODSTREAM_TEST_STOP_AFTER_PROGRESS");
  options.progress = on_progress;
  options.progress_user = &progress;
  std::signal(SIGINT, on_sigint);
  std::signal(SIGTERM, on_sigint);

  if (simplify_cmd->parsed()) {
    if (!sizes_text.empty() && !parse_list(sizes_text, &so.cell_sizes)) {
      std::fprintf(stderr, "lodstream: --cell-sizes: cannot read '%s' as a list of numbers\n", sizes_text.c_str());
      return static_cast<int>(lodstream::Status::usage);
    }
    if (!targets_text.empty() && !parse_list(targets_text, &so.target_triangles)) {
      std::fprintf(stderr, "lodstream: --target-triangles: cannot read '%s' as a list of counts\n", targets_text.c_str());
      return static_cast<int>(lodstream::Status::usage);
    }
    so.grading = grading == "lowtan" ? lodstream::Grading::lowtan : lodstream::Grading::rossignac;
    so.clustering = clustering == "floating" ? lodstream::Clustering::floating : lodstream::Clustering::uniform;
    so.cell = cell == "cube" ? lodstream::CellShape::cube : lodstream::CellShape::sphere;
    so.variant = variant == "nearest" ? lodstream::CellVariant::nearest : lodstream::CellVariant::heaviest;
    so.representative = rep == "center" ? lodstream::Representative::center
                        : rep == "mean" ? lodstream::Representative::mean
                                        : lodstream::Representative::quadric;
    so.write_obj = obj;
    so.write_ply = !no_ply;
    so.write_glb = !no_glb;
    so.tiles_z_up = tiles_up == "z";
    so.tile_encoding = tile_encoding == "plain"       ? lodstream::SimplifyOptions::TileEncoding::plain
                       : tile_encoding == "quantized" ? lodstream::SimplifyOptions::TileEncoding::quantized
                                                      : lodstream::SimplifyOptions::TileEncoding::meshopt;
    so.tile_lines = tile_lines == "lines" ? lodstream::SimplifyOptions::TileLines::lines : lodstream::SimplifyOptions::TileLines::triangles;
    if (!tiles_transform_text.empty() && !parse_list(tiles_transform_text, &so.tiles_transform)) {
      std::fprintf(stderr, "lodstream: --tiles-transform: cannot read '%s' as a list of numbers\n", tiles_transform_text.c_str());
      return static_cast<int>(lodstream::Status::usage);
    }
    const int usage = static_cast<int>(lodstream::Status::usage);
    if ((!shard_text.empty() || shard_from_env) &&
        !read_index_option("--shard", shard_text, shard_from_env, &so.shard_index, &so.shard_count))
      return usage;
    if (!shard_ingest_text.empty() && !read_index_option("--shard-ingest", shard_ingest_text, false, &so.ingest_index, &so.ingest_count))
      return usage;
    if (!shard_grade_text.empty() &&
        !read_index_option("--shard-grade", shard_grade_text, false, &so.grade_share_index, &so.grade_share_count))
      return usage;
    if (!shard_cluster_text.empty() &&
        !read_index_option("--shard-cluster", shard_cluster_text, false, &so.cluster_share_index, &so.cluster_share_count))
      return usage;
    const bool sharded =
        so.shard_count > 0 || so.shard_prepare || so.ingest_count > 0 || so.cluster_share_count > 0 || so.grade_share_count > 0;
    lodstream::SimplifyReport report;
    const lodstream::Result r = lodstream::simplify(input, so, options, &report);
    const int code = finish(r, progress, json && !sharded ? so.output_dir + "/manifest.json" : std::string(), [&] {
      if (!sharded) return print_simplify(report, so.output_dir);
      for (const auto& s : report.stages)
        std::printf("stage        %-15s %8.3f s  peak %s%s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str(),
                    s.reused ? "  (reused from work directory)" : "");
      if (so.ingest_count > 0)
        std::printf("range        %u of %u: %s bytes parsed into %s/ingest-ranges (then: --shard-prepare joins them)\n",
                    so.ingest_index, so.ingest_count, std::to_string(report.scene.file_bytes).c_str(), options.work_dir.c_str());
      else if (so.grade_share_count > 0)
        std::printf("grade        share %u of %u in %s/grade-shares%s (then: the next step merges them)\n", so.grade_share_index,
                    so.grade_share_count, options.work_dir.c_str(), report.grade_share.empty() ? ", the stage already done" : "");
      else if (so.cluster_share_count > 0)
        std::printf("cluster      share %u of %u in %s/cluster-shares%s (then: --cluster-shards %u merges them)\n", so.cluster_share_index,
                    so.cluster_share_count, options.work_dir.c_str(), report.cluster_share.empty() ? ", the stage already done" : "",
                    so.cluster_share_count);
      else if (so.shard_prepare) std::printf("prepared     %s for the tasks\n", options.work_dir.c_str());
      else std::printf("task         %u of %u: parts in %s/shards (then: lodstream merge %s)\n", so.shard_index, so.shard_count,
                       so.output_dir.c_str(), so.output_dir.c_str());
    });
    if (code == 0 && !report.notice.empty()) {
      std::fflush(stdout);  // after the table, when both go to one file
      std::fprintf(stderr, "notice: %s\n", report.notice.c_str());
    }
    return code;
  }

  if (merge_cmd->parsed() && lodstream::has_report_shards(merge_dir)) {
    lodstream::Report report;
    const lodstream::Result r = lodstream::merge_report(merge_dir, options, &report);
    return finish(r, progress, json ? merge_dir + "/report.json" : std::string(), [&] { print_report(report, merge_dir); });
  }
  if (merge_cmd->parsed()) {
    lodstream::SimplifyReport report;
    const lodstream::Result r = lodstream::merge(merge_dir, options, &report);
    return finish(r, progress, json ? merge_dir + "/manifest.json" : std::string(), [&] { print_simplify(report, merge_dir); });
  }

  if (grid_cmd->parsed()) {
    go.split = split == "center"     ? lodstream::GridSplit::center
               : split == "first"    ? lodstream::GridSplit::first
               : split == "greatest" ? lodstream::GridSplit::greatest
               : split == "curvature" ? lodstream::GridSplit::curvature
                                      : lodstream::GridSplit::random;
    go.gaps = gaps == "none" ? lodstream::GridGaps::none
              : gaps == "fill" ? lodstream::GridGaps::fill
                               : lodstream::GridGaps::extra_vertices;
    go.method = method == "growth" ? lodstream::GridMethod::growth : lodstream::GridMethod::subdivision;
    go.axis = axis == "x" ? lodstream::GridAxis::x : axis == "z" ? lodstream::GridAxis::z : lodstream::GridAxis::y;
    go.write_obj = !no_obj;
    go.write_ply = !no_ply;
    go.write_glb = !no_glb;
    lodstream::GridReport report;
    const lodstream::Result r = lodstream::grid(input, go, options, &report);
    return finish(r, progress, json ? go.output_dir + "/summary.json" : std::string(), [&] { print_grid(report, go.output_dir); });
  }

  if (report_cmd->parsed()) {
    if (!distances_text.empty() && !parse_list(distances_text, &ro.switch_distances)) {
      std::fprintf(stderr, "lodstream: --switch-distances: cannot read '%s' as a list of numbers\n", distances_text.c_str());
      return static_cast<int>(lodstream::Status::usage);
    }
    if (ro.output_dir.empty()) {
      if (ro.runs.size() != 1) {
        std::fprintf(stderr, "lodstream: report: give the report directory with -o (see lodstream report --help)\n");
        return static_cast<int>(lodstream::Status::usage);
      }
      ro.output_dir = ro.runs[0];
    }
    if ((!report_shard_text.empty() || report_shard_from_env) &&
        !read_index_option("--shard", report_shard_text, report_shard_from_env, &ro.shard_index, &ro.shard_count))
      return static_cast<int>(lodstream::Status::usage);
    if (!report_shard_ingest_text.empty() &&
        !read_index_option("--shard-ingest", report_shard_ingest_text, false, &ro.ingest_index, &ro.ingest_count))
      return static_cast<int>(lodstream::Status::usage);
    const bool sharded = ro.shard_count > 0 || ro.shard_prepare || ro.ingest_count > 0;
    lodstream::Report report;
    const lodstream::Result r = lodstream::report(ro, options, &report);
    return finish(r, progress, json && !sharded ? ro.output_dir + "/report.json" : std::string(), [&] {
      if (!sharded) return print_report(report, ro.output_dir);
      for (const auto& s : report.stages)
        std::printf("stage        %-15s %8.3f s  peak %s%s\n", s.name.c_str(), s.seconds, human_bytes(s.peak_rss_bytes).c_str(),
                    s.reused ? "  (reused from work directory)" : "");
      if (ro.ingest_count > 0)
        std::printf("range        %u of %u of the originals parsed into %s/ingest-ranges* (then: --shard-prepare joins them)\n",
                    ro.ingest_index, ro.ingest_count, options.work_dir.c_str());
      else if (ro.shard_prepare) std::printf("prepared     %s for the tasks\n", options.work_dir.c_str());
      else std::printf("task         %u of %u: shares in %s/shards/report (then: lodstream merge %s)\n", ro.shard_index, ro.shard_count,
                       ro.output_dir.c_str(), ro.output_dir.c_str());
    });
  }

  lodstream::SceneInfo info;
  const lodstream::Result r = lodstream::info(input, options, &info);
  return finish(r, progress, std::string(), [&] {
    if (json) std::printf("%s\n", info_json(info).dump().c_str());
    else print_info(info);
  });
}

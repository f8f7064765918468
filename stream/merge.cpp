// `merge`: the outputs of a sharded simplify (stream/shard.h) from its tasks' parts. The parts of a level
// are read run by run (each run of regions follows the previous one in region order), so
// the level files, the GLB and the tiles are given every region's part in the order one machine's emit
// stage gives them, and are written by the same code: the same bytes. What merge does grows with the
// output (the levels' parts are read once and written once), not with the input.
#include <algorithm>
#include <array>
#include <chrono>
#include <filesystem>
#include <map>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "lodstream/lodstream.h"
#include "stream/job.h"
#include "stream/kill_point.h"
#include "stream/level_files.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/shard.h"
#include "stream/tiles.h"
#include "stream/work_dir.h"

namespace lodstream {

namespace {

using nlohmann::ordered_json;

// Every task's summary, checked to be one run's (stream::read_task_summaries).
std::vector<ordered_json> read_tasks(const std::string& output_dir) {
  return stream::read_task_summaries(stream::shards_dir(output_dir),
                                     {"task parts", "task", "run", "other input, options or task count", "simplify"});
}

// The tasks in the order of their runs of level `level`'s regions (stream/shard.h shard_runs: a wide level
// is one task's whole), which is the order one machine writes the regions in.
// Tasks with no region of the level come anywhere (their parts are empty). Throws Failure(internal) unless
// the runs cover the level's regions once.
std::vector<unsigned> tasks_in_region_order(const std::vector<ordered_json>& tasks, size_t level, const std::string& output_dir) {
  std::vector<std::array<uint32_t, 3>> runs;
  for (const ordered_json& t : tasks) runs.push_back(t.at("manifest").at("regions").at(level).get<std::array<uint32_t, 3>>());
  std::vector<unsigned> order(tasks.size());
  for (unsigned t = 0; t < order.size(); ++t) order[t] = t;
  std::stable_sort(order.begin(), order.end(), [&](unsigned a, unsigned b) { return runs[a][0] < runs[b][0]; });
  uint32_t next = 0;
  for (unsigned t : order)
    if (runs[t][0] < runs[t][1]) {
      if (runs[t][0] != next || runs[t][2] != runs[order[0]][2])
        fail(Status::internal, output_dir + "/shards: the tasks' runs of level " + std::to_string(level) + "'s regions do not fit together");
      next = runs[t][1];
    }
  if (next != runs[order[0]][2])
    fail(Status::internal, output_dir + "/shards: the tasks' runs of level " + std::to_string(level) + " miss regions");
  return order;
}

}  // namespace

Result merge(const std::string& output_dir, const Options& options, SimplifyReport* out) {
  return stream::guarded([&] {
    const auto t0 = std::chrono::steady_clock::now();
    stream::Progress progress(options);
    const std::vector<ordered_json> tasks = read_tasks(output_dir);
    const ordered_json& key = tasks[0].at("key");
    const ordered_json& mi = key.at("merge");
    ordered_json m = tasks[0].at("manifest");
    m.erase("input_primitives_read");  // a task's own figures: the first goes under "shards"
    m.erase("regions");
    m.erase("paged_map");
    const size_t levels = m.at("levels").size();
    const unsigned count = static_cast<unsigned>(tasks.size());
    SimplifyReport report;
    stream::remove_summary(output_dir + "/manifest.json");

    const std::string generator = m.at("generator");
    std::unique_ptr<io::GlbBuilder> glb;
    if (mi.at("write_glb").get<bool>())
      glb = std::make_unique<io::GlbBuilder>(output_dir + "/lods.glb", output_dir + "/lods.glb.bin.partial", generator);
    std::unique_ptr<stream::TilesetBuilder> tiles;
    if (!key.at("tiles").is_null()) {
      stream::TilesOptions to = stream::tiles_options_from_json(key.at("tiles"));
      to.dir = output_dir + "/tiles";
      tiles = std::make_unique<stream::TilesetBuilder>(std::move(to));
    }
    // Scratch of the level files: beside the parts (they are output-sized, as the parts are).
    stream::WorkDir work(stream::shards_dir(output_dir) + "/merge");
    const bool ply = mi.at("write_ply"), obj = mi.at("write_obj");
    const unsigned resolution = mi.at("resolution");

    // The store's material table and colour flag: every part's mesh carries the table (as emit gives it).
    std::vector<core::Material> materials;
    for (const ordered_json& j : mi.at("store").at("materials")) materials.push_back(stream::material_from_json(j));
    const bool colors = mi.at("store").at("colors").get<bool>();

    stream::run_stage(&report.stages, "merge", [&](StageStats&) {
      for (size_t l = 0; l < levels; ++l) {
        ordered_json& lj = m["levels"][l];
        stream::LevelFiles level(work.scratch("level" + std::to_string(l)), lj.at("cells").get<uint64_t>(), materials, colors);
        uint64_t triangles = 0, edges = 0, points = 0, on_triangles = 0, covered = 0;
        unsigned merged = 0;
        for (unsigned t : tasks_in_region_order(tasks, l, output_dir)) {
          const ordered_json& tl = tasks[t].at("manifest").at("levels").at(l);
          triangles += tl.at("triangles").get<uint64_t>(), edges += tl.at("edges").get<uint64_t>();
          points += tl.at("points").get<uint64_t>();
          on_triangles += tl.at("eliminated").at("edges_on_triangles").get<uint64_t>();
          covered += tl.at("eliminated").at("points_covered").get<uint64_t>();
          stream::PartsReader parts(stream::shard_parts_path(output_dir, t, l));
          stream::StoredPart p;
          while (parts.next(&p)) {
            p.part.mesh.materials = materials;
            if (tiles)
              tiles->add(l, {p.info.key.depth, p.info.key.x, p.info.key.y, p.info.key.z, p.info.cell_size, p.info.cells},
                         p.part.mesh);
            level.add(p.part);
          }
          progress.report("merge", (l * count + ++merged + 0.0) / static_cast<double>(levels * count));
        }
        level.close();
        const std::vector<std::string> comments = mi.at("comments").at(l);
        const std::string stem = fmt::format("lod{}", l);
        const double lower = l + 1 < levels ? m["levels"][l + 1].at("screen_coverage").get<double>() : 1.0 / resolution;
        const std::vector<std::string> files = stream::write_level_outputs(level, output_dir, stem, comments, ply, obj, glb.get(), lower);
        lj["vertices"] = level.vertices();
        lj["triangles"] = triangles, lj["edges"] = edges, lj["points"] = points;
        lj["eliminated"] = {{"edges_on_triangles", on_triangles}, {"points_covered", covered}};
        lj["files"] = files;
      }
    });
    stream::run_stage(&report.stages, "write", [&](StageStats&) {
      if (glb) glb->finish();
      glb.reset();
    });
    if (tiles)
      stream::run_stage(&report.stages, "tiles", [&](StageStats&) {
        const stream::TilesSummary t = tiles->finish();
        tiles.reset();
        report.tiles = {t.tiles, t.content_tiles, t.bytes, t.triangles, t.max_triangles};
        m["tiles"]["tiles"] = t.tiles, m["tiles"]["content_tiles"] = t.content_tiles, m["tiles"]["bytes"] = t.bytes;
        m["tiles"]["triangles"] = t.triangles, m["tiles"]["max_triangles"] = t.max_triangles;
      });

    // The manifest: one machine's, with the merge's stages, and every task's under "shards".
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report.peak_rss_bytes = stream::peak_rss_bytes();
    ordered_json stages = ordered_json::array();
    for (const StageStats& s : report.stages)
      stages.push_back(stream::stage_json(s));
    ordered_json shards = ordered_json::array();
    for (unsigned t = 0; t < count; ++t) {
      const ordered_json& tm = tasks[t].at("manifest");
      shards.push_back({{"index", t}, {"stages", tm.at("stages")}, {"seconds", tm.at("seconds")}, {"peak_rss_bytes", tm.at("peak_rss_bytes")},
                        {"input_primitives_read", tm.value("input_primitives_read", uint64_t{0})}});
      if (tm.contains("paged_map")) shards.back()["paged_map"] = tm.at("paged_map");
    }
    m["stages"] = stages;
    m["seconds"] = report.seconds;
    m["peak_rss_bytes"] = report.peak_rss_bytes;
    m["shards"] = {{"count", count}, {"tasks", shards}};
    stream::kill_point("manifest.json");
    io::write_file_atomic(output_dir + "/manifest.json", m.dump(2) + "\n", io::Sync::durable);

    const ordered_json& in = m.at("input");
    report.input = in.at("path");
    report.scene.format = in.at("format");
    report.scene.triangles = in.at("triangles"), report.scene.lines = in.at("lines"), report.scene.points = in.at("points");
    report.vertices_graded = in.at("vertices_graded");
    for (const ordered_json& lj : m.at("levels")) {
      LevelStats ls;
      ls.cell_size = lj.at("cell_size"), ls.cells = lj.at("cells"), ls.vertices = lj.at("vertices");
      ls.triangles = lj.at("triangles"), ls.edges = lj.at("edges"), ls.points = lj.at("points");
      ls.switch_distance = lj.at("switch_distance"), ls.screen_coverage = lj.at("screen_coverage");
      ls.files = lj.at("files").get<std::vector<std::string>>();
      report.levels.push_back(std::move(ls));
    }
    report.levels_asked = m.at("levels_asked");
    if (m.contains("notice")) report.notice = m.at("notice");
    // The parts have served: the manifest now vouches for the outputs.
    std::error_code ec;
    std::filesystem::remove_all(stream::shards_dir(output_dir), ec);
    *out = std::move(report);
  });
}

}  // namespace lodstream

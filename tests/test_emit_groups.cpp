// Emit groups (stream/emit_stage.h): a level gives the same parts, to the bit, whether it is emitted alone,
// in one pass with other levels (packed cluster maps, shared corner and quadric work), or in batches of
// regions with their halos; and groups follow the memory model.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include "core/floating_cell.h"
#include "core/mesh.h"
#include "core/status.h"
#include "lodstream/lodstream.h"
#include "stream/emit_regions.h"
#include "stream/emit_stage.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "cli_harness.h"
#include "test_util.h"

namespace lodstream {
namespace {

void expect_same_mesh(const core::LodMesh& a, const core::LodMesh& b, const std::string& what) {
  EXPECT_EQ(a.positions, b.positions) << what;
  EXPECT_EQ(a.normals, b.normals) << what;
  EXPECT_EQ(a.triangles, b.triangles) << what;
  EXPECT_EQ(a.edges, b.edges) << what;
  EXPECT_EQ(a.thickness, b.thickness) << what;
  EXPECT_EQ(a.points, b.points) << what;
}

using Parts = std::vector<stream::RegionPart>;

// The sample room simplified with representative `rep` (two threads) into tmp's "work" and "out": the tests
// read the stages' files it leaves in the work directory.
Result simplify_room(const test::TempDir& tmp, Representative rep, Options& o, SimplifyOptions& so, SimplifyReport& report) {
  o.threads = 2;
  o.work_dir = tmp.file("work");
  so.output_dir = tmp.file("out");
  so.representative = rep;
  return simplify(test::source_dir() + "/tests/data/sample-room.ply", so, o, &report);
}

void expect_same_parts(const Parts& a, const Parts& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (size_t i = 0; i < a.size(); ++i) {
    const std::string w = what + ", region " + std::to_string(i);
    EXPECT_EQ(a[i].region, b[i].region) << w;
    expect_same_mesh(a[i].mesh, b[i].mesh, w);
    EXPECT_EQ(a[i].vertex_key, b[i].vertex_key) << w;
    EXPECT_EQ(a[i].owned_key, b[i].owned_key) << w;
    EXPECT_EQ(a[i].owned_positions, b[i].owned_positions) << w;
    EXPECT_EQ(a[i].owned_normals, b[i].owned_normals) << w;
  }
}

// Each level's parts come to the sink in group order, each level's in region order.
auto into(std::vector<Parts>& parts, size_t offset) {
  return [&parts, offset](size_t i, stream::RegionPart& part) {
    Parts& p = parts[offset + i];
    EXPECT_EQ(part.region, p.size());
    p.push_back(std::move(part));
  };
}

TEST(EmitGroups, SameMeshesAloneAndGrouped) {
  for (Representative rep : {Representative::center, Representative::quadric}) {
    test::TempDir tmp;
    Options o;
    SimplifyOptions so;
    SimplifyReport report;
    const Result r = simplify_room(tmp, rep, o, so, report);
    ASSERT_TRUE(r.ok()) << r.message;

    // The stages' files, as simplify left them in the work directory.
    const std::string store_dir = o.work_dir + "/store";
    stream::StoreMeta meta;
    ASSERT_TRUE(stream::read_store_meta(store_dir, &meta));
    const uint64_t records = nlohmann::json::parse(test::read_file(o.work_dir + "/grade.json"))["value"]["records"];
    const std::string weld = o.work_dir + "/weld.map";
    const std::string canonical = std::filesystem::exists(weld) ? weld : std::string();
    const std::string prefix = o.work_dir + "/";
    std::vector<uint64_t> cells;
    for (const LevelStats& ls : report.levels) cells.push_back(ls.cells);
    const core::SceneCube cube = stream::scene_cube_of(meta);
    const std::vector<stream::LevelCut> cuts = stream::cut_levels(prefix, cells, cube, 500, rep, meta.single_precision);
    std::vector<stream::CellRegions> regions;
    regions.reserve(report.levels.size());  // the levels point into it
    std::vector<stream::EmitLevel> levels;
    unsigned bits = 0;  // of levels 1 to 4
    for (size_t l = 0; l < report.levels.size(); ++l) {
      regions.push_back(stream::load_cell_regions(prefix, l, cells[l], cube, cuts[l], rep, meta.single_precision));
      levels.push_back({l, cells[l], report.levels[l].cell_size, &cuts[l], &regions[l], 0,
                        static_cast<uint32_t>(cuts[l].regions.size()), false});
      if (l > 0) bits += stream::emit_bits(report.levels[l].cells);
    }
    ASSERT_EQ(levels.size(), 5u);
    ASSERT_LE(bits, 64u);  // the room's levels 1 to 4 fit in one group
    ASSERT_GT(cuts[0].regions.size(), 4u);

    stream::Progress progress(o);
    stream::EmitScratch scratch;
    const core::ClusterOptions copts;
    const stream::EmitOptions eo{rep, so.crease_degrees, true, false};
    std::vector<Parts> alone(levels.size()), four(4), pair(2), batched(1), routed(1);
    for (size_t l = 0; l < levels.size(); ++l)
      stream::emit_levels(store_dir, meta, canonical, prefix, std::span(&levels[l], 1), records, copts, eo, progress,
                          scratch, into(alone, l));
    stream::emit_levels(store_dir, meta, canonical, prefix, std::span(levels).subspan(1), records, copts, eo, progress,
                        scratch, into(four, 0));
    const stream::EmitLevel skip[2] = {levels[3], levels[0]};  // any levels, in any order
    stream::emit_levels(store_dir, meta, canonical, prefix, skip, records, copts, eo, progress, scratch, into(pair, 0));
    // The finest level in batches of regions (each with its halo), its representatives written ahead.
    stream::write_representatives(store_dir, meta, canonical, prefix, 0, cells[0], levels[0].cell_size, records, copts, rep,
                                  cells[0] / 3 + 1, progress, scratch);
    const auto batches = stream::region_batches(cuts[0], cells[0] / 4);
    ASSERT_GE(batches.size(), 3u);
    for (const auto& [r0, r1] : batches) {
      stream::EmitLevel b = levels[0];
      b.first_region = r0, b.end_region = r1, b.batched = true;
      stream::emit_levels(store_dir, meta, canonical, prefix, std::span(&b, 1), records, copts, eo, progress, scratch,
                          into(batched, 0));
    }
    // Routed (stream::route_batches), in more batches than one routing holds: each batch reads only its
    // words of the input, and the map is built once for the routings and batches (EmitScratch).
    const auto small = stream::region_batches(cuts[0], cells[0] / 12);
    ASSERT_GT(small.size(), stream::kRouteBatches);
    size_t words_read = 0, words = 0;
    for (size_t b0 = 0; b0 < small.size(); b0 += stream::kRouteBatches) {
      const std::span<const std::pair<uint32_t, uint32_t>> group(small.data() + b0,
                                                                 std::min(stream::kRouteBatches, small.size() - b0));
      stream::BatchRoutes routes;
      stream::EmitLevel b = levels[0];
      b.batched = true;
      stream::route_batches(store_dir, meta, canonical, prefix, b, group, records, copts, progress, scratch, routes);
      ASSERT_EQ(routes.words[0].size(), (meta.triangles + 63) / 64);
      for (size_t i = 0; i < group.size(); ++i) {
        b.first_region = group[i].first, b.end_region = group[i].second, b.routes = &routes, b.route_bit = static_cast<unsigned>(i);
        for (uint8_t w : routes.words[0]) words_read += (w >> i) & 1;
        words += routes.words[0].size();
        stream::emit_levels(store_dir, meta, canonical, prefix, std::span(&b, 1), records, copts, eo, progress, scratch,
                            into(routed, 0));
      }
    }
    EXPECT_LT(words_read, words / 2) << "the batches' routes name most of the input";
    for (size_t l = 0; l < levels.size(); ++l) {
      EXPECT_EQ(alone[l].size(), cuts[l].regions.size());
      uint64_t triangles = 0;
      for (const stream::RegionPart& p : alone[l]) triangles += p.mesh.triangle_count();
      EXPECT_GT(triangles, 0u);
    }
    for (size_t l = 1; l < levels.size(); ++l)
      expect_same_parts(alone[l], four[l - 1], "level " + std::to_string(l) + " with levels 1 to 4");
    expect_same_parts(alone[3], pair[0], "level 3 with level 0");
    expect_same_parts(alone[0], pair[1], "level 0 with level 3");
    expect_same_parts(alone[0], batched[0], "level 0 in batches");
    expect_same_parts(alone[0], routed[0], "level 0 in routed batches");
  }
}

TEST(EmitGroups, GroupsFollowTheMemoryModel) {
  // The city scene's levels (34.8M stored vertices) under --memory 1G: the finest level alone, the
  // others together (also beside 250 MiB held by a caller).
  const std::vector<uint64_t> cells{2557792, 310283, 40817, 5424, 1012};
  const uint64_t vertices = 34781752, triangles = 48611194, budget = (1ull << 30) - (40ull << 20);
  const stream::EmitOptions quadric{Representative::quadric, 30, true, false};
  EXPECT_EQ(stream::emit_bits(2557792), 22u);
  EXPECT_EQ(stream::emit_bits(1), 1u);
  EXPECT_EQ(stream::emit_bits(255), 8u);
  EXPECT_EQ(stream::emit_bits(256), 9u);  // 256 cells and the all-ones "no cell"
  EXPECT_EQ(stream::emit_group_end(cells, 0, vertices, triangles, budget, 0, quadric), 1u);
  EXPECT_EQ(stream::emit_group_end(cells, 1, vertices, triangles, budget, 250ull << 20, quadric), 5u);
  // Unlimited memory: levels join while their records fit in 64 bits (22 + 19 + 16 = 57, + 13 > 64).
  EXPECT_EQ(stream::emit_group_end(cells, 0, vertices, triangles, UINT64_MAX / 2, 0, quadric), 3u);
  // No memory to spare: one level per pass.
  for (size_t l = 0; l < cells.size(); ++l) EXPECT_EQ(stream::emit_group_end(cells, l, vertices, triangles, 1, 0, quadric), l + 1);
}

TEST(EmitGroups, ALevelThatCannotFitStopsWithUsage) {
  // The city's finest level needs its map (22 bits × 34.8M vertices, 91 MiB), 320 bytes a cell (781 MiB),
  // 24 MiB of block buffers and, for the thickness passes, a 24th of the budget up to 40 MiB
  // (emit_corner_bytes): it fits in the stage's share of --memory 1G, not in that of 512M (915 MiB with
  // 20 MiB for those passes), nor beside 100 MiB that a caller holds when the budget is just what it needs.
  const std::vector<uint64_t> cells{2557792, 310283};
  const uint64_t vertices = 34781752, triangles = 48611194;
  const stream::EmitOptions quadric{Representative::quadric, 30, true, false};
  const uint64_t need =
      stream::emit_map_bytes(vertices, 22) + stream::emit_level_bytes(2557792, triangles, quadric) + (40ull << 20);
  EXPECT_EQ(need >> 20, 935u);
  EXPECT_NO_THROW(stream::check_emit_budget(cells, 0, vertices, triangles, (1ull << 30) - (40ull << 20), 0, quadric));
  EXPECT_NO_THROW(stream::check_emit_budget(cells, 0, vertices, triangles, need, 0, quadric));
  auto failure = [&](uint64_t budget, uint64_t resident) -> std::string {
    try {
      stream::check_emit_budget(cells, 0, vertices, triangles, budget, resident, quadric);
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::usage);
      return f.what();
    }
    ADD_FAILURE() << "no failure at " << budget << " with " << resident << " resident";
    return "";
  };
  const std::string at512 = failure((512ull << 20) - (40ull << 20), 0);
  EXPECT_NE(at512.find("level 0 (2557792 cells) needs about 915 MiB"), std::string::npos) << at512;
  EXPECT_NE(at512.find("--memory"), std::string::npos) << at512;
  const std::string beside = failure(need, 100ull << 20);
  EXPECT_NE(beside.find("what is already held"), std::string::npos) << beside;
  // Counting only, no quadrics: 240 bytes a cell.
  const stream::EmitOptions count_only{Representative::quadric, 30, true, true};
  EXPECT_NO_THROW(stream::check_emit_budget(cells, 0, vertices, triangles, need - 80 * 2557792, 0, count_only));
}


// A sharded task's regions of its level (stream/emit_regions.h CellRegions): loaded for a run of the cut,
// every cell of the run has the region the whole cut gives it and every other cell none, in a bit and a
// half a cell of the level and a region a cell of the run; the bits set from several threads at once
// (RankedBits::set_shared, as the halos and the uses are marked) are the bits set one at a time.
TEST(EmitGroups, ARunsCellRegionsAreTheWholeCutsInABitACell) {
  test::TempDir tmp;
  Options o;
  SimplifyOptions so;
  SimplifyReport report;
  const Result r = simplify_room(tmp, SimplifyOptions{}.representative, o, so, report);
  ASSERT_TRUE(r.ok()) << r.message;
  stream::StoreMeta meta;
  ASSERT_TRUE(stream::read_store_meta(o.work_dir + "/store", &meta));
  const std::string prefix = o.work_dir + "/";
  std::vector<uint64_t> cells;
  for (const LevelStats& ls : report.levels) cells.push_back(ls.cells);
  const core::SceneCube cube = stream::scene_cube_of(meta);
  const std::vector<stream::LevelCut> cuts = stream::cut_levels(prefix, cells, cube, 200, so.representative, meta.single_precision);
  ASSERT_GE(cuts[0].regions.size(), 4u);
  const stream::CellRegions whole = stream::load_cell_regions(prefix, 0, cells[0], cube, cuts[0], so.representative, meta.single_precision);
  EXPECT_TRUE(whole.in.bits.empty());
  EXPECT_EQ(whole.bytes(), stream::cell_regions_bytes(cells[0], cells[0]));
  // A run of the cut from its second region that holds cells to the one before its last (some regions of a
  // cut hold none).
  std::vector<uint32_t> full;
  for (uint32_t i = 0; i < cuts[0].regions.size(); ++i)
    if (cuts[0].cells[i] > 0) full.push_back(i);
  ASSERT_GE(full.size(), 3u);
  const uint32_t first = full[1], end = full.back();
  const stream::CellRegions run =
      stream::load_cell_regions(prefix, 0, cells[0], cube, cuts[0], so.representative, meta.single_precision, first, end);
  uint64_t in_run = 0;
  for (uint64_t c = 0; c < cells[0]; ++c) {
    const uint32_t w = whole.of(c);
    ASSERT_LT(w, cuts[0].regions.size());
    if (w >= first && w < end) {
      EXPECT_EQ(run.of(c), w) << "cell " << c;
      ++in_run;
    } else {
      EXPECT_EQ(run.of(c), UINT32_MAX) << "cell " << c;
    }
  }
  uint64_t expected = 0;
  for (uint32_t i = first; i < end; ++i) expected += cuts[0].cells[i];
  EXPECT_EQ(in_run, expected);
  EXPECT_GT(in_run, 0u);
  EXPECT_LT(in_run, cells[0]);
  EXPECT_EQ(run.region.size(), in_run);
  EXPECT_EQ(stream::cell_regions_bytes(cells[0], in_run), (cells[0] + 63) / 64 * 12 + 4 * in_run);
  EXPECT_LE(run.bytes(), stream::cell_regions_bytes(cells[0], in_run) + 64);

  stream::RankedBits one(100000), shared(100000);
  for (uint64_t i = 0; i < 100000; i += 3) one.set(i * 7 % 100000);
  tbb::parallel_for(uint64_t{0}, uint64_t{100000}, [&](uint64_t i) {
    if (i % 3 == 0) shared.set_shared(i * 7 % 100000), shared.set_shared(i * 7 % 100000);
  });
  EXPECT_EQ(shared.bits, one.bits);
}

}  // namespace
}  // namespace lodstream

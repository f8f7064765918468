// Sharded simplify (stream/shard.h) and merge, through the library, without a scheduler: the tasks run one
// after another on one work directory. Every output file must be one machine's bytes for any task count
// and any --memory (tasks in several batches), a missing task must stop the merge naming it, and the
// task ranges must cover every region once. tests/slurm_test.sh runs the same through Slurm.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lodstream/lodstream.h"
#include "cli_harness.h"
#include "core/octree_regions.h"
#include "io/file_writer.h"
#include "io/offset_file.h"
#include "stream/block_bounds.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_merge.h"
#include "stream/cluster_shares.h"
#include "stream/cluster_stage.h"
#include "stream/grade_shares.h"
#include "stream/position_gather.h"
#include "stream/ranked_bits.h"
#include "stream/chunk_scene.h"
#include "stream/report_samples.h"
#include "stream/scene_store.h"
#include "stream/shard.h"
#include "stream/paged_vertex_map.h"
#include "stream/vertex_cells.h"
#include "stream/wide_units.h"
#include "stream/vertex_pairs.h"
#include "test_util.h"

namespace lodstream {
namespace {

using test::TempDir;

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Every file under `dir` but manifest.json, by relative path.
// A file's bytes, which gtest prints as their size and hash only: printed whole (escaped) when two runs'
// outputs differed, the room's took the test process past the machine's 24 GB.
struct Bytes {
  std::string data;
  bool operator==(const Bytes& o) const { return data == o.data; }
};
void PrintTo(const Bytes& b, std::ostream* os) { *os << b.data.size() << " bytes, hash " << std::hash<std::string>{}(b.data); }

// Every output file of a run's directory but manifest.json, by its path there.
std::map<std::string, Bytes> outputs(const std::string& dir) {
  std::map<std::string, Bytes> f;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename() != "manifest.json")
      f[std::filesystem::relative(e.path(), dir).string()] = {slurp(e.path().string())};
  return f;
}

nlohmann::json manifest_without_timings(const std::string& dir) {
  nlohmann::json m = nlohmann::json::parse(slurp(dir + "/manifest.json"));
  for (const char* k : {"stages", "seconds", "peak_rss_bytes", "work_dir", "shards"}) m.erase(k);
  return m;
}

SimplifyOptions room_options(const std::string& out) {
  SimplifyOptions so;
  so.output_dir = out;
  so.tile_triangles = 6000;  // many regions per level, so that tasks split levels
  so.write_obj = true;
  so.write_tiles = true;
  return so;
}

// One machine's run on the work directory the tasks will share.
Options shared_work(const TempDir& dir) {
  Options o;
  o.work_dir = dir.file("work");
  o.check_disk_space = false;
  return o;
}

std::string sample_room() { return test::source_dir() + "/tests/data/sample-room.ply"; }

// Runs tasks `tasks` of `count` (then merge when `merge`) on `work`.
Result run_tasks(const std::string& out, const std::string& work, unsigned count, const std::vector<unsigned>& tasks,
                 uint64_t memory, bool merge_after, SimplifyReport* merged, const std::string& input = sample_room(),
                 Representative rep = SimplifyOptions().representative) {
  for (unsigned i : tasks) {
    SimplifyOptions so = room_options(out);
    so.shard_index = i, so.shard_count = count, so.representative = rep;
    Options o;
    o.work_dir = work;
    o.memory_bytes = memory;
    o.check_disk_space = false;
    SimplifyReport r;
    const Result res = simplify(input, so, o, &r);
    if (!res.ok()) return res;
  }
  if (!merge_after) return {};
  return merge(out, Options{}, merged);
}

// All `count` tasks, then the merge, on `work`: the outputs must be one machine's (in `one`).
void expect_all_tasks_give(const std::string& out, const std::string& work, unsigned count, Representative rep,
                           const std::string& one) {
  std::vector<unsigned> tasks(count);
  for (unsigned i = 0; i < count; ++i) tasks[i] = i;
  SimplifyReport merged;
  const Result res = run_tasks(out, work, count, tasks, 0, true, &merged, sample_room(), rep);
  ASSERT_TRUE(res.ok()) << res.message;
  EXPECT_EQ(outputs(out), outputs(one));
}

TEST(Shard, AnyTaskCountGivesOneMachinesBytes) {
  TempDir dir;
  const Options o = shared_work(dir);
  SimplifyReport one;
  ASSERT_TRUE(simplify(sample_room(), room_options(dir.file("one")), o, &one).ok());
  const auto want = outputs(dir.file("one"));
  uint64_t read_by_one = 0;  // the input primitives one task's passes read
  // 9 tasks: the levels of 8 regions or fewer are wide (stream/shard.h shard_runs), each whole in a task
  // of its own with no run of the finer levels' codes: the merge orders each level's tasks by their runs.
  for (unsigned n : {1u, 2u, 5u, 9u}) {
    SCOPED_TRACE("tasks " + std::to_string(n));
    const std::string out = dir.file("sharded-" + std::to_string(n));
    std::vector<unsigned> all;
    for (unsigned i = 0; i < n; ++i) all.push_back(i);
    SimplifyReport merged;
    const Result r = run_tasks(out, dir.file("work"), n, all, 0, true, &merged);
    ASSERT_TRUE(r.ok()) << r.message;
    EXPECT_EQ(outputs(out), want);
    EXPECT_EQ(manifest_without_timings(out), manifest_without_timings(dir.file("one")));
    // Every task's passes read only the blocks near its regions (stream/block_bounds.h): one task reads
    // the whole input in each pass; of five, each reads less than that and together less than five times it.
    const nlohmann::json m = nlohmann::json::parse(slurp(out + "/manifest.json"));
    uint64_t sum = 0, most = 0;
    for (const auto& t : m.at("shards").at("tasks")) {
      const uint64_t read = t.at("input_primitives_read");
      EXPECT_GT(read, 0u);
      sum += read, most = std::max(most, read);
    }
    if (n == 1) read_by_one = sum;
    if (n == 5) {
      EXPECT_LT(most, read_by_one);
      EXPECT_LT(sum, 4 * read_by_one);
    }
    EXPECT_FALSE(std::filesystem::exists(out + "/shards")) << "merge removes the parts";
    ASSERT_EQ(merged.levels.size(), one.levels.size());
    for (size_t l = 0; l < one.levels.size(); ++l) EXPECT_EQ(merged.levels[l].triangles, one.levels[l].triangles);
  }
}

TEST(Shard, TasksInBatchesUnderASmallBudgetGiveTheSameBytes) {
  TempDir dir;
  const Options o = shared_work(dir);
  SimplifyReport one;
  ASSERT_TRUE(simplify(sample_room(), room_options(dir.file("one")), o, &one).ok());
  // At the minimum budget a task's share of the finest level does not fit one batch (counted by the
  // model in stream/shard.cpp) and is emitted in several.
  SimplifyReport merged;
  const Result r = run_tasks(dir.file("small"), dir.file("work"), 2, {0, 1}, min_memory_bytes, true, &merged);
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_EQ(outputs(dir.file("small")), outputs(dir.file("one")));
}

// The paged map (stream/paged_vertex_map.h) of three levels' cells by vertex, written as the shared stages
// write them (pack_vertex_cells), at a capacity of a few pages: every group's records are the fields of
// every level at their shifts, groups past the held pages drop them, a group larger than the capacity is
// held whole, and a page not loaded, a cell out of range or a file of the wrong size are refused.
TEST(PagedMap, GroupsReadTheirPagesAndDropTheRest) {
  TempDir dir;
  const uint64_t vertices = 64 * 300 + 17;  // the last page partial
  const std::vector<uint64_t> cells = {1000, 5, 70000};
  std::vector<std::vector<uint32_t>> cell(cells.size(), std::vector<uint32_t>(vertices));
  std::vector<stream::PagedVertexMap::Level> levels;
  uint64_t seed = 12345;
  auto next = [&] { return seed = seed * 6364136223846793005ull + 1442695040888963407ull, seed >> 33; };
  unsigned shift = 0;
  for (size_t l = 0; l < cells.size(); ++l) {
    for (uint64_t v = 0; v < vertices; ++v) cell[l][v] = next() % 13 == 0 ? stream::kNoCell : static_cast<uint32_t>(next() % cells[l]);
    std::vector<uint64_t> words;
    stream::pack_vertex_cells(cell[l], stream::vertex_cell_bits(cells[l]), words);
    const std::string path = dir.file("level-" + std::to_string(l) + ".bits");
    io::write_file_atomic(path, std::string(reinterpret_cast<const char*>(words.data()), words.size() * 8));
    levels.push_back({path, cells[l], shift});
    shift += stream::vertex_cell_bits(cells[l]);
  }
  const unsigned bits = shift;
  auto expected = [&](uint64_t v) {
    uint64_t r = 0;
    for (size_t l = 0; l < cells.size(); ++l) {
      const unsigned b = stream::vertex_cell_bits(cells[l]);
      const uint64_t c = cell[l][v] == stream::kNoCell ? (uint64_t{1} << b) - 1 : cell[l][v];
      r |= c << levels[l].shift;
    }
    return r;
  };
  stream::PagedMapFigures figures;
  stream::PagedVertexMap map(levels, vertices, 8 * bits * 8, &figures);  // 8 pages
  ASSERT_EQ(map.bits(), bits);
  uint64_t checked = 0;
  for (int group = 0; group < 40; ++group) {
    // Runs of nearby vertices (consecutive pages) and a few far ones; every eighth group 20 pages' worth.
    std::vector<uint32_t> ids;
    const uint64_t base = next() % vertices;
    const int n = group % 8 == 7 ? 20 : 3;
    for (int k = 0; k < n; ++k) ids.push_back(static_cast<uint32_t>(k < n - 1 ? (base + 64 * k) % vertices : next() % vertices));
    ids.push_back(static_cast<uint32_t>(vertices - 1));
    map.want(ids);
    map.load();
    for (uint32_t v : ids) {
      ASSERT_EQ(map.get(v), expected(v)) << "vertex " << v << " of group " << group;
      ++checked;
    }
  }
  EXPECT_GT(checked, 100u);
  EXPECT_EQ(figures.maps, 1u);
  EXPECT_EQ(figures.pages, (vertices + 63) / 64);
  EXPECT_GT(figures.drops, 0u) << "groups past the 8 held pages drop them";
  EXPECT_GE(figures.largest_group, 20u);
  EXPECT_GE(figures.largest_bytes, 20u * bits * 8) << "a group larger than the capacity is held whole";
  EXPECT_GT(figures.pages_read, figures.reads / cells.size()) << "runs of consecutive pages are read at once";
  // A page no group loaded since the last drop.
  map.want(std::vector<uint32_t>(20, 0)), map.load();
  std::vector<uint32_t> far;
  for (uint32_t p = 100; p < 110; ++p) far.push_back(64 * p);
  map.want(far), map.load();  // 11 pages with page 0: past 8, so page 0 was dropped first
  try {
    map.get(0);
    ADD_FAILURE() << "a page not held must be refused";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::internal);
  }
  // A cell out of its level's range.
  {
    std::vector<uint32_t> bad = cell[1];
    bad[70] = 6;  // level 1 has 5 cells: 3 bits hold 6
    std::vector<uint64_t> words;
    stream::pack_vertex_cells(bad, stream::vertex_cell_bits(cells[1]), words);
    io::write_file_atomic(levels[1].path, std::string(reinterpret_cast<const char*>(words.data()), words.size() * 8));
    stream::PagedVertexMap m(levels, vertices, 1 << 20);
    m.want(std::vector<uint32_t>{0});
    m.load();  // page 0 holds vertices 0..63
    m.want(std::vector<uint32_t>{70});
    try {
      m.load();
      ADD_FAILURE() << "a cell out of range must be refused";
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::io_error);
      EXPECT_NE(std::string(f.what()).find("cell id out of range"), std::string::npos) << f.what();
    }
  }
  // A file of another size.
  try {
    stream::PagedVertexMap m(levels, vertices + 64, 1 << 20);
    ADD_FAILURE() << "a file of the wrong size must be refused";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::io_error);
  }
}

// `copies` copies of the sample room side by side along x, 10 m apart, each copy's vertices and faces after
// the previous copy's: a scene whose blocks of primitives each reach only their own copy's vertex ids.
std::string rooms_side_by_side(const TempDir& dir, int copies) {
  const std::string room = slurp(sample_room());
  const size_t body = room.find("end_header\n") + 11;
  const uint64_t vertices = 160266, faces = 141261;  // the header's counts (checked below)
  EXPECT_NE(room.find("element vertex 160266\n"), std::string::npos);
  EXPECT_NE(room.find("element face 141261\n"), std::string::npos);
  const char* v = room.data() + body;
  const char* f = v + 12 * vertices;
  std::string vs, fs;
  for (int c = 0; c < copies; ++c) {
    for (uint64_t i = 0; i < vertices; ++i) {
      float xyz[3];
      std::memcpy(xyz, v + 12 * i, 12);
      xyz[0] += 10.0f * static_cast<float>(c);
      vs.append(reinterpret_cast<const char*>(xyz), 12);
    }
    const char* p = f;
    for (uint64_t i = 0; i < faces; ++i) {
      const uint8_t n = static_cast<uint8_t>(*p++);
      fs.push_back(static_cast<char>(n));
      for (uint8_t k = 0; k < n; ++k, p += 4) {
        int32_t id;
        std::memcpy(&id, p, 4);
        id += static_cast<int32_t>(vertices) * c;
        fs.append(reinterpret_cast<const char*>(&id), 4);
      }
    }
    EXPECT_EQ(static_cast<size_t>(p - room.data()), room.size()) << "the room's faces end the file";
  }
  const std::string path = dir.file("rooms.ply");
  io::write_file_atomic(path, fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n"
                                          "property float y\nproperty float z\nelement face {}\n"
                                          "property list uchar int vertex_indices\nend_header\n",
                                          vertices * copies, faces * copies) +
                                  vs + fs);
  return path;
}

// Tasks whose paged maps hold a few pages (--chunk-bytes caps their capacity: a group's own pages and no
// more) drop and read pages again group after group, in pass A, the halo pass, pass Q, pass B and pass C's
// batches (on one thread, 4 blocks a group, over three rooms whose blocks reach only their own room's
// vertices, so that pass C's corners lie in pages pass B's last group did not hold): one machine's bytes.
TEST(Shard, TasksDroppingTheirMapsPagesGiveOneMachinesBytes) {
  TempDir dir;
  const std::string rooms = rooms_side_by_side(dir, 3);
  Options o = shared_work(dir);
  SimplifyReport one;
  ASSERT_TRUE(simplify(rooms, room_options(dir.file("one")), o, &one).ok());
  for (const unsigned count : {1u, 2u}) {
    for (const uint64_t chunk : {uint64_t{0}, uint64_t{16} << 10}) {
      SCOPED_TRACE(fmt::format("{} tasks, chunk bytes {}", count, chunk));
      const std::string name = fmt::format("{}-{}", count, chunk);
      const std::string out = dir.file("sharded-" + name), work = dir.file("work-" + name);
      for (unsigned i = 0; i < count; ++i) {
        SimplifyOptions so = room_options(out);
        so.shard_index = i, so.shard_count = count;
        Options to;
        to.work_dir = work, to.check_disk_space = false, to.chunk_bytes = chunk, to.threads = 1;
        SimplifyReport r;
        const Result res = simplify(rooms, so, to, &r);
        ASSERT_TRUE(res.ok()) << res.message;
      }
      SimplifyReport merged;
      ASSERT_TRUE(merge(out, Options{}, &merged).ok());
      EXPECT_EQ(outputs(out), outputs(dir.file("one")));
      const nlohmann::json m = nlohmann::json::parse(slurp(out + "/manifest.json"));
      uint64_t drops = 0, pages_read = 0, pages = 0;
      for (const auto& t : m.at("shards").at("tasks")) {
        const auto& p = t.at("paged_map");
        EXPECT_GT(p.at("maps").get<uint64_t>(), 0u);
        drops += p.at("drops").get<uint64_t>(), pages_read += p.at("pages_read").get<uint64_t>();
        pages = p.at("pages");
        EXPECT_LT(p.at("largest_group_pages").get<uint64_t>(), pages) << "a group reads some of the scene's pages";
      }
      EXPECT_EQ(pages, (3 * 160266 + 63) / 64u);
      if (chunk == 0) {
        EXPECT_EQ(drops, 0u) << "the rooms' maps fit the default capacity";
      } else {
        EXPECT_GT(drops, 0u);
        EXPECT_GT(pages_read, pages) << "pages dropped are read again";
      }
    }
  }
}

// The tasks look their vertices' cells up in the vertex-cells files (stream/vertex_cells.h), which the
// shared stages write by decoding the cluster maps (as units by vertex range). Written again in ranges of
// 4096 vertices (so that welded vertices find their canonical vertex's cell in an earlier range), and as
// 1, 3 and 7 units, they hold the same bytes; and tasks under
// center and mean representatives give one machine's bytes. No representative is written ahead: the tasks
// form their own (EmitOptions::own_representatives).
TEST(Shard, VertexCellsInRangesAgree) {
  TempDir dir;
  const Options o = shared_work(dir);
  SimplifyReport merged;
  const Result r = run_tasks(dir.file("sharded"), dir.file("work"), 2, {0, 1}, 0, true, &merged);
  ASSERT_TRUE(r.ok()) << r.message;
  const std::string prefix = dir.file("work") + "/";
  const uint64_t records = std::filesystem::file_size(prefix + "order.u32") / 4;
  const std::string weld = std::filesystem::exists(prefix + "weld.map") ? prefix + "weld.map" : std::string();
  EXPECT_FALSE(weld.empty()) << "the sample room has welded vertices";
  stream::Progress progress{Options{}};
  for (size_t l = 0; l < merged.levels.size(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    EXPECT_FALSE(std::filesystem::exists(stream::representatives_path(prefix, l)));
    const std::string path = stream::vertex_cells_path(prefix, l);
    const std::string from_map = slurp(path);
    stream::StoreMeta meta;
    ASSERT_TRUE(stream::read_store_meta(prefix + "store", &meta));
    const uint64_t vertices = meta.vertices;
    ASSERT_GT(vertices, 3 * 4096u);
    const unsigned bits = stream::vertex_cell_bits(merged.levels[l].cells);
    ASSERT_EQ(from_map.size(), stream::vertex_cells_bytes(vertices, merged.levels[l].cells));
    EXPECT_LT(from_map.size(), vertices * 4) << "packed to the level's " << bits << " bits a vertex, not a uint32";
    std::filesystem::remove(path);
    stream::write_vertex_cells(prefix, weld, vertices, records, l, merged.levels[l].cells, 4 * 4096, progress);
    EXPECT_TRUE(slurp(path) == from_map);
    // As units (the prepare jobs'), each by vertex range: 1, 3 and 7, run in reverse order (a welded
    // vertex's canonical vertex before its unit is found in the unit's own pass over the map, or in the
    // buckets of the pairs that hold it); each from the map and from its pairs by vertex range (as the
    // clustering merge's pairs units write them, here three units' files, in buckets of a few vertices since
    // the room is small).
    std::vector<std::string> pairs;
    {
      stream::CellMapReader map(stream::cells_path(prefix, l));
      std::vector<uint32_t> cells(records), ids(records);
      map.read(cells);
      map.finish(records, merged.levels[l].cells);
      // Every record's vertex holds its cell in the packed file.
      io::OffsetFile(stream::order_path(prefix), O_RDONLY).read(ids.data(), 4 * records, 0);
      uint64_t differ = 0;
      for (uint64_t rec = 0; rec < records; ++rec) differ += stream::packed_field(from_map.data(), ids[rec], bits) != cells[rec];
      EXPECT_EQ(differ, 0u) << "records whose vertex's field is not their cell";
      // The map entered at a record (the bits and the cells before it, as the merge's sums and pairs units
      // find them from the centers' bits) reads on as decoded from its start.
      uint64_t bit = 0, made = 0;
      for (uint64_t rec = 0; rec < records; ++rec) {
        if (rec == records / 3 || rec == records / 2 + 7 || rec == records - 1) {
          stream::CellMapReader entered(stream::cells_path(prefix, l), stream::MapEntry{bit, made});
          std::vector<uint32_t> rest(records - rec);
          entered.read(rest);
          entered.finish(records, merged.levels[l].cells);
          EXPECT_TRUE(std::equal(rest.begin(), rest.end(), cells.begin() + static_cast<std::ptrdiff_t>(rec))) << "entered at record " << rec;
        }
        bit += static_cast<uint64_t>(std::bit_width(made));
        made += cells[rec] == made;
      }
      for (uint64_t u = 0; u < 3; ++u) {
        const uint64_t lo = records * u / 3, hi = records * (u + 1) / 3;
        std::vector<uint64_t> counts(stream::kVertexPairBuckets, 0);
        stream::count_vertex_pairs(std::span<const uint32_t>(ids.data() + lo, hi - lo), vertices, counts);
        pairs.push_back(dir.file("pairs-" + std::to_string(u) + ".bin"));
        stream::VertexPairsWriter w(pairs.back(), vertices, lo, hi, merged.levels[l].cells, counts);
        for (uint64_t rec = lo; rec < hi; ++rec) w.add(ids[rec], cells[rec]);
        w.commit();
      }
    }
    EXPECT_GT(vertices >> stream::vertex_pair_shift(vertices), 31u) << "the pairs have many buckets";
    for (bool from_pairs : {false, true})
      for (unsigned units : {1u, 3u, 7u}) {
        SCOPED_TRACE("units " + std::to_string(units) + (from_pairs ? " from the pairs" : " from the map"));
        std::filesystem::remove(path);
        io::OffsetFile(path, O_WRONLY | O_CREAT | O_TRUNC).resize(from_map.size());
        stream::VertexCellsLevel level;
        level.map_path = stream::cells_path(prefix, l), level.path = path, level.cells = merged.levels[l].cells;
        if (from_pairs) level.pairs_paths = pairs;
        for (unsigned u = units; u-- > 0;)
          stream::write_vertex_cells_unit({level}, stream::order_path(prefix), weld, vertices, records, u, units, progress);
        EXPECT_TRUE(slurp(path) == from_map);
      }
    // Pairs read as another level's (cells of another width) are refused, as are pairs that miss a map
    // unit's file.
    EXPECT_THROW(stream::VertexPairs(pairs, vertices, records).for_each_in(0, vertices, 4 * merged.levels[l].cells + 4, [](uint32_t, uint32_t) {}),
                 Failure);
    pairs.pop_back();
    EXPECT_THROW(stream::VertexPairs(pairs, vertices, records), Failure);
  }

  // The store's block boxes, which the run wrote as units: one pass gives the same bytes, and so do 1, 3
  // and 7 units run in reverse order.
  {
    stream::StoreMeta meta;
    ASSERT_TRUE(stream::read_store_meta(prefix + "store", &meta));
    const std::string from_units = slurp(stream::block_bounds_path(prefix)), path = dir.file("bounds.f64");
    ASSERT_GT(from_units.size(), 3 * 48u);
    stream::write_block_bounds(prefix + "store", meta, path, progress);
    EXPECT_TRUE(slurp(path) == from_units);
    for (unsigned units : {1u, 3u, 7u}) {
      SCOPED_TRACE("bounds units " + std::to_string(units));
      io::OffsetFile(path, O_WRONLY | O_CREAT | O_TRUNC).resize(from_units.size());
      for (unsigned u = units; u-- > 0;) stream::write_block_bounds_unit(prefix + "store", meta, path, u, units, progress);
      EXPECT_TRUE(slurp(path) == from_units);
    }
  }

  for (Representative rep : {Representative::center, Representative::mean}) {
    SCOPED_TRACE(rep == Representative::center ? "center" : "mean");
    TempDir d;
    SimplifyOptions so = room_options(d.file("one"));
    so.representative = rep;
    SimplifyReport one;
    ASSERT_TRUE(simplify(sample_room(), so, shared_work(d), &one).ok());
    for (unsigned i = 0; i < 3; ++i) {
      SimplifyOptions t = room_options(d.file("sharded"));
      t.representative = rep, t.shard_index = i, t.shard_count = 3;
      SimplifyReport task;
      const Result tr = simplify(sample_room(), t, shared_work(d), &task);
      ASSERT_TRUE(tr.ok()) << tr.message;
    }
    SimplifyReport m;
    ASSERT_TRUE(merge(d.file("sharded"), Options{}, &m).ok());
    EXPECT_EQ(outputs(d.file("sharded")), outputs(d.file("one")));
  }
}

// The clustering as N shares (stream/cluster_shares.h) through the library: shares run as share tasks
// (one left out, which the prepare job runs itself), the prepare job merges them, N emit tasks and the
// merge then give one machine's bytes, for any N and representative.
TEST(ClusterShares, ShareTasksThenTasksGiveOneMachinesBytes) {
  for (Representative rep : {Representative::center, Representative::mean, Representative::quadric}) {
    SCOPED_TRACE(rep == Representative::center ? "center" : rep == Representative::mean ? "mean" : "quadric");
    TempDir dir;
    SimplifyOptions one_options = room_options(dir.file("one"));
    one_options.representative = rep;
    SimplifyReport one;
    ASSERT_TRUE(simplify(sample_room(), one_options, shared_work(dir), &one).ok());
    for (unsigned n : {1u, 2u, 4u}) {
      SCOPED_TRACE("shares " + std::to_string(n));
      const std::string work = dir.file("work-" + std::to_string(n)), out = dir.file("sharded-" + std::to_string(n));
      Options o;
      o.work_dir = work;
      o.check_disk_space = false;
      if (n == 4) {  // graded as shares first: the slabs are then selected from the records' positions in weight order
        for (unsigned i = 0; i < n; ++i) {
          SimplifyOptions so = room_options(out);
          so.representative = rep, so.grade_share_index = i, so.grade_share_count = n;
          SimplifyReport r;
          ASSERT_TRUE(simplify(sample_room(), so, o, &r).ok());
        }
      }
      for (unsigned i = 0; i < n; ++i) {
        if (n > 1 && i == 1) continue;  // a share no task ran
        SimplifyOptions so = room_options(out);
        so.representative = rep, so.cluster_share_index = i, so.cluster_share_count = n;
        SimplifyReport r;
        const Result res = simplify(sample_room(), so, o, &r);
        ASSERT_TRUE(res.ok()) << res.message;
        EXPECT_FALSE(r.cluster_share.empty());
        EXPECT_TRUE(std::filesystem::exists(stream::cluster_share_stamp(work + "/", i)));
        EXPECT_FALSE(std::filesystem::exists(work + "/cluster.json")) << "a share does not stamp the whole stage";
      }
      // The first cluster share merged the grading shares, writing the positions in weight order (the room's store holds floats).
      EXPECT_EQ(std::filesystem::exists(work + "/positions-w.f32"), n == 4);
      std::vector<size_t> whole_levels;  // and their cells by vertex, which their shares write (none here)
      if (n >= 3) {  // the room's coarsest levels are too coarse for the slabs: split by records (plan_cluster_shares)
        const nlohmann::json plan = nlohmann::json::parse(slurp(stream::cluster_shares_dir(work + "/") + "plan.json")).at("plan");
        std::vector<size_t> records_levels;
        for (size_t l = 0; l < plan.at("whole_share").size(); ++l) {
          EXPECT_EQ(plan.at("whole_share").at(l), -1) << "level " << l << " is clustered whole";
          if (plan.at("by_records").at(l) == 0) continue;
          records_levels.push_back(l);
          // Its centers, found once by whichever share came first.
          const nlohmann::json centers =
              nlohmann::json::parse(slurp(stream::cluster_shares_dir(work + "/") + fmt::format("centers/level-{}.json", l)));
          EXPECT_GT(centers.at("value").at("centers").get<uint64_t>(), 0u) << "level " << l;
        }
        ASSERT_FALSE(records_levels.empty()) << "the room's coarsest levels are too coarse for the slabs";
        EXPECT_EQ(plan.at("by_records").at(0), 0) << "the finest level splits by slabs";
        EXPECT_EQ(records_levels.back(), one.levels.size() - 1);
        for (size_t k = 1; k < plan.at("cuts").size(); ++k)
          EXPECT_NE(plan.at("cuts").at(k - 1), plan.at("cuts").at(k)) << "no empty slab: no share clusters whole levels only";
      }
      SimplifyOptions prepare = room_options(out);
      prepare.representative = rep, prepare.shard_prepare = true, prepare.cluster_shares = n;
      SimplifyReport pr;
      const Result pres = simplify(sample_room(), prepare, o, &pr);
      ASSERT_TRUE(pres.ok()) << pres.message;
      EXPECT_FALSE(std::filesystem::exists(stream::cluster_shares_dir(work + "/"))) << "the merge removes the spent shares";
      ASSERT_FALSE(one.levels.empty());
      for (size_t l = 0; l < one.levels.size(); ++l)
        EXPECT_TRUE(stream::vertex_pairs_paths(work + "/", l).empty()) << "level " << l << ": the pairs outlive the cells by vertex";
      if (n >= 3) {
        // A prepare job that reuses the cluster stage (here: the first one's, killed before the cells by vertex
        // were stamped) takes up the same units as the one that ran it, for the split levels only: had it
        // asked for every level, it would restart the first one's units under its feet (a unit stamp removed
        // while it was being written, and the first job failed: exit 74 in tests/slurm_test.sh).
        const std::string units = work + "/vertex-cells-units/", start = slurp(units + "start.json"),
                          unit0 = slurp(units + "vertex-cells-0.json");
        std::filesystem::remove(work + "/shard-vertex-cells.json");
        SimplifyReport again;
        ASSERT_TRUE(simplify(sample_room(), prepare, o, &again).ok());
        EXPECT_EQ(slurp(units + "start.json"), start) << "the second prepare job restarted the cells-by-vertex units";
        EXPECT_EQ(slurp(units + "vertex-cells-0.json"), unit0) << "the second prepare job ran a unit again";
        EXPECT_TRUE(std::filesystem::exists(work + "/shard-vertex-cells.json"));
      }
      // The whole levels' cells by vertex, as their shares wrote them, are the prepare job's own.
      for (size_t l : whole_levels) {
        const std::string path = stream::vertex_cells_path(work + "/", l), weld = work + "/weld.map";
        const std::string shares_made = slurp(path);
        std::filesystem::remove(path);
        stream::Progress progress{Options{}};
        stream::StoreMeta meta;
        ASSERT_TRUE(stream::read_store_meta(work + "/store", &meta));
        stream::write_vertex_cells(work + "/", std::filesystem::exists(weld) ? weld : std::string(), meta.vertices,
                                   std::filesystem::file_size(work + "/order.u32") / 4, l, one.levels[l].cells, 1 << 20, progress);
        EXPECT_TRUE(slurp(path) == shares_made) << "level " << l;
      }
      for (size_t l = 0; l < one.levels.size(); ++l) {
        EXPECT_TRUE(slurp(stream::cells_path(work + "/", l)) == slurp(stream::cells_path(dir.file("work") + "/", l))) << "level " << l;
        EXPECT_TRUE(slurp(stream::cell_info_path(work + "/", l)) == slurp(stream::cell_info_path(dir.file("work") + "/", l))) << "level " << l;
      }
      // A share task after the stage is done does nothing.
      SimplifyOptions late = room_options(out);
      late.representative = rep, late.cluster_share_index = 0, late.cluster_share_count = n;
      SimplifyReport lr;
      ASSERT_TRUE(simplify(sample_room(), late, o, &lr).ok());
      EXPECT_TRUE(lr.cluster_share.empty());
      expect_all_tasks_give(out, work, n, rep, dir.file("one"));
    }
  }
  SimplifyOptions bad = room_options(test::TempDir().file("out"));
  bad.cluster_share_index = 3, bad.cluster_share_count = 3;
  TempDir d;
  SimplifyReport r;
  EXPECT_EQ(simplify(sample_room(), bad, shared_work(d), &r).status, Status::usage);
}

// Grade and sort as N shares (stream/grade_shares.h), with ranges small enough that a share grades
// several, each from the blocks that touch it: the weight index, the weld map and the grades are one
// machine's bytes, and so is every output after them. A share no task ran is run by the next step; a
// share task after the stage is done does nothing.
// The records' positions in weight order that the grading shares' merge wrote in `work`
// (stream/position_gather.h): record i holds the store's bytes for vertex order[i]; one machine writes none.
void expect_ordered_positions(const std::string& work) {
  stream::StoreMeta meta;
  ASSERT_TRUE(stream::read_store_meta(work + "/store", &meta));
  const std::string column = slurp(stream::positions_column_path(work + "/store", meta)), order = slurp(work + "/order.u32");
  const std::string ordered = slurp(stream::ordered_positions_path(work + "/", meta.single_precision));
  const size_t stride = meta.single_precision ? 12 : 24;
  ASSERT_EQ(ordered.size(), order.size() / 4 * stride);
  ASSERT_FALSE(ordered.empty());
  for (size_t i = 0; i < order.size() / 4; ++i) {
    uint32_t v;
    std::memcpy(&v, order.data() + 4 * i, 4);
    ASSERT_EQ(ordered.compare(i * stride, stride, column, v * stride, stride), 0) << "record " << i;
  }
}

TEST(GradeShares, ShareTasksThenTasksGiveOneMachinesBytes) {
  for (Representative rep : {Representative::center, Representative::mean}) {
    SCOPED_TRACE(rep == Representative::center ? "center" : "mean");
    TempDir dir;
    SimplifyOptions one_options = room_options(dir.file("one"));
    one_options.representative = rep;
    SimplifyReport one;
    ASSERT_TRUE(simplify(sample_room(), one_options, shared_work(dir), &one).ok());
    const std::string one_work = dir.file("work") + "/";
    for (unsigned n : {1u, 3u, 5u}) {
      SCOPED_TRACE("shares " + std::to_string(n));
      const std::string work = dir.file("work-" + std::to_string(n)), out = dir.file("sharded-" + std::to_string(n));
      Options o;
      o.work_dir = work;
      o.check_disk_space = false;
      uint64_t records = 0;
      for (unsigned i = 0; i < n; ++i) {
        if (n > 1 && i == 1) continue;  // a share no task ran
        SimplifyOptions so = room_options(out);
        so.representative = rep, so.grade_share_index = i, so.grade_share_count = n, so.grade_range_vertices = 1000;
        SimplifyReport r;
        const Result res = simplify(sample_room(), so, o, &r);
        ASSERT_TRUE(res.ok()) << res.message;
        ASSERT_FALSE(r.grade_share.empty());
        records += nlohmann::json::parse(r.grade_share).at("records").get<uint64_t>();
        EXPECT_TRUE(std::filesystem::exists(stream::grade_share_stamp(work + "/", i)));
        EXPECT_FALSE(std::filesystem::exists(work + "/grade.json")) << "a share does not stamp the whole stage";
        EXPECT_FALSE(std::filesystem::exists(work + "/order.u32"));
      }
      EXPECT_GT(records, 0u);
      EXPECT_LE(records, one.vertices_graded);
      // The weld was made as units (one a share), whose runs the plan's maker wrote into the map.
      for (unsigned u = 0; u < n; ++u) {
        EXPECT_TRUE(std::filesystem::exists(stream::weld_unit_stamp(work + "/", u))) << u;
      }
      // The shares' plan has more ranges than shares (several a share).
      const nlohmann::json plan = nlohmann::json::parse(slurp(stream::grade_shares_dir(work + "/") + "plan.json"));
      EXPECT_GT(plan.at("plan").at("ranges").get<uint64_t>(), 2 * n);
      SimplifyOptions prepare = room_options(out);
      prepare.representative = rep, prepare.shard_prepare = true;
      SimplifyReport pr;
      const Result pres = simplify(sample_room(), prepare, o, &pr);
      ASSERT_TRUE(pres.ok()) << pres.message;
      EXPECT_EQ(pr.vertices_graded, one.vertices_graded);
      EXPECT_EQ(pr.distinct_positions, one.distinct_positions);
      EXPECT_EQ(pr.surface_area, one.surface_area) << "the areas are summed in the one machine's order";
      EXPECT_FALSE(std::filesystem::exists(stream::grade_shares_dir(work + "/"))) << "the merge removes the spent shares";
      EXPECT_FALSE(std::filesystem::exists(stream::weld_units_dir(work + "/"))) << "and the weld's units";
      EXPECT_TRUE(slurp(work + "/order.u32") == slurp(one_work + "order.u32"));
      EXPECT_TRUE(slurp(work + "/weld.map") == slurp(one_work + "weld.map"));
      EXPECT_FALSE(slurp(work + "/weld.map").empty());
      if (rep == Representative::mean) {
        EXPECT_TRUE(slurp(work + "/grades.f64") == slurp(one_work + "grades.f64"));
      }
      expect_ordered_positions(work);
      SimplifyOptions late = room_options(out);
      late.representative = rep, late.grade_share_index = 0, late.grade_share_count = n;
      SimplifyReport lr;
      ASSERT_TRUE(simplify(sample_room(), late, o, &lr).ok());
      EXPECT_TRUE(lr.grade_share.empty());
      expect_all_tasks_give(out, work, n, rep, dir.file("one"));
    }
  }
  SimplifyOptions bad = room_options(test::TempDir().file("out"));
  bad.grade_share_index = 2, bad.grade_share_count = 2;
  TempDir d;
  SimplifyReport r;
  EXPECT_EQ(simplify(sample_room(), bad, shared_work(d), &r).status, Status::usage);
  bad.grade_share_index = 0, bad.shard_prepare = true;
  EXPECT_EQ(simplify(sample_room(), bad, shared_work(d), &r).status, Status::usage);
}

// With silhouette labels (Mata et al.; every level then has a fine grid and is clustered whole), 3 grading
// shares and the prepare step give one machine's labels, cluster maps and cell infos: the labels stage and
// the whole levels read the records' positions in weight order, one machine reads them by id.
TEST(GradeShares, LabelsAndWholeLevelsFromTheOrderedPositionsAreOneMachines) {
  TempDir dir;
  auto with_labels = [](SimplifyOptions so) {
    so.silhouette_interval = 2;
    so.silhouette_views = 4;
    so.silhouette_resolution = 64;
    so.levels = 3;
    return so;
  };
  SimplifyReport one;
  ASSERT_TRUE(simplify(sample_room(), with_labels(room_options(dir.file("one"))), shared_work(dir), &one).ok());
  EXPECT_GT(one.labelled_vertices, 0u);
  const std::string one_work = dir.file("work") + "/", work = dir.file("work-3");
  EXPECT_FALSE(std::filesystem::exists(one_work + "positions-w.f32") || std::filesystem::exists(one_work + "positions-w.f64"));
  Options o;
  o.work_dir = work;
  o.check_disk_space = false;
  for (unsigned i = 0; i < 3; ++i) {
    SimplifyOptions so = with_labels(room_options(dir.file("sharded")));
    so.grade_share_index = i, so.grade_share_count = 3, so.grade_range_vertices = 1000;
    SimplifyReport r;
    const Result res = simplify(sample_room(), so, o, &r);
    ASSERT_TRUE(res.ok()) << res.message;
  }
  SimplifyOptions prepare = with_labels(room_options(dir.file("sharded")));
  prepare.shard_prepare = true;
  SimplifyReport pr;
  const Result pres = simplify(sample_room(), prepare, o, &pr);
  ASSERT_TRUE(pres.ok()) << pres.message;
  expect_ordered_positions(work);
  EXPECT_EQ(pr.labelled_vertices, one.labelled_vertices);
  EXPECT_TRUE(slurp(work + "/labels.f32") == slurp(one_work + "labels.f32"));
  for (size_t l = 0; l < 3; ++l) {
    EXPECT_TRUE(slurp(stream::cells_path(work + "/", l)) == slurp(stream::cells_path(one_work, l))) << l;
    EXPECT_TRUE(slurp(stream::cell_info_path(work + "/", l)) == slurp(stream::cell_info_path(one_work, l))) << l;
  }
}

// A share's run cut short after its stamp: the merge refuses with an I/O error naming the run, leaves
// no weight index and removes the share's stamp, so that the next step runs the share again.
TEST(GradeShares, MergeRefusesARunCutShort) {
  TempDir dir;
  SimplifyOptions one_options = room_options(dir.file("one"));
  SimplifyReport one;
  ASSERT_TRUE(simplify(sample_room(), one_options, shared_work(dir), &one).ok());
  const std::string work = dir.file("work-2");
  Options o;
  o.work_dir = work;
  o.check_disk_space = false;
  for (unsigned i = 0; i < 2; ++i) {
    SimplifyOptions so = room_options(dir.file("out"));
    so.grade_share_index = i, so.grade_share_count = 2;
    SimplifyReport r;
    ASSERT_TRUE(simplify(sample_room(), so, o, &r).ok());
  }
  const std::string run = stream::grade_share_run(work + "/", 1);
  std::filesystem::resize_file(run, std::filesystem::file_size(run) - 12);
  SimplifyOptions prepare = room_options(dir.file("out"));
  prepare.shard_prepare = true;
  SimplifyReport pr;
  const Result bad = simplify(sample_room(), prepare, o, &pr);
  EXPECT_EQ(bad.status, Status::io_error);
  EXPECT_NE(bad.message.find("share-1.run"), std::string::npos) << bad.message;
  EXPECT_FALSE(std::filesystem::exists(work + "/order.u32"));
  EXPECT_FALSE(std::filesystem::exists(work + "/grade.json"));
  EXPECT_FALSE(std::filesystem::exists(stream::grade_share_stamp(work + "/", 1)));
  EXPECT_TRUE(std::filesystem::exists(stream::grade_share_stamp(work + "/", 0)));
  ASSERT_TRUE(simplify(sample_room(), prepare, o, &pr).ok()) << "the next step runs the share again";
  EXPECT_TRUE(slurp(work + "/order.u32") == slurp(dir.file("work") + "/order.u32"));
}

// The grading merge as units (stream/grade_shares.h) on runs of many tied grades, one of them empty: any
// number of units, run in any order, write the bytes of a one-unit merge (the order, the grades and the
// records' positions in weight order, checked against the store's column), some
// units are empty (splitters repeat where a grade is shared by many records), and a plan already made is
// read back rather than made again.
TEST(GradeShares, MergeUnitsInAnyOrderWriteOneMergesBytes) {
  TempDir dir;
  stream::WorkDir work(dir.file("work"));
  const std::string prefix = work.path() + "/";
  std::filesystem::create_directories(stream::grade_shares_dir(prefix));
  const std::string store = dir.file("store");
  std::filesystem::create_directories(store);
  stream::StoreMeta meta;
  meta.single_precision = true;
  stream::MemoryPlan plan;
  plan.stage_bytes = 16 << 20;
  const stream::GradeShareInput in{store, &meta, core::Grading::lowtan, plan, prefix, &work, 0};
  stream::Progress progress{Options()};
  const stream::GradePlan gp;
  for (uint32_t n : {200000u, 100u}) {
    SCOPED_TRACE(fmt::format("{} records", n));
    // The store's column: vertex v at (v, v / 8, -v), floats.
    meta.vertices = n;
    std::vector<float> column;
    for (uint32_t v = 0; v < n; ++v) column.insert(column.end(), {float(v), float(v) / 8, -float(v)});
    std::ofstream(stream::positions_column_path(store, meta), std::ios::binary)
        .write(reinterpret_cast<const char*>(column.data()), static_cast<std::streamsize>(column.size() * 4));
    // 4 runs of ids dealt round-robin (run 2 gets none); grades of a few values, so ties are broken by id.
    std::vector<std::vector<stream::GradeRecord>> records(4);
    uint32_t seed = 12345;
    for (uint32_t id = 0; id < n; ++id) {
      seed = seed * 1664525u + 1013904223u;
      records[id % 3 == 2 ? 3 : id % 3].push_back({(seed >> 28) < 10 ? 0.25 * (seed >> 28) : 1e-3 * (seed >> 16), id});
    }
    std::vector<uint64_t> counts;
    for (unsigned s = 0; s < records.size(); ++s) {
      std::sort(records[s].begin(), records[s].end(), stream::WeightLess());
      std::ofstream(stream::grade_share_run(prefix, s), std::ios::binary)
          .write(reinterpret_cast<const char*>(records[s].data()), static_cast<std::streamsize>(records[s].size() * 12));
      counts.push_back(records[s].size());
    }
    ASSERT_EQ(counts[2], 0u);
    auto merged = [&](unsigned units, bool reverse, std::string* grades, std::string* positions) {
      const nlohmann::ordered_json key{{"test", units}, {"n", n}};
      const stream::GradeMergePlan mp = stream::shared_grade_merge_plan(in, counts, units, true, key);
      EXPECT_EQ(mp.units, units);
      EXPECT_EQ(mp.total(), n);
      unsigned empty = 0;
      for (unsigned u = 0; u < units; ++u) empty += mp.first(u + 1) == mp.first(u);
      if (units > n) {
        EXPECT_GT(empty, 0u) << "fewer samples than units: splitters repeat, units are empty";
      }
      if (units < n / 100) {
        EXPECT_EQ(empty, 0u);
      }
      for (unsigned k = 0; k < units; ++k) {
        const unsigned u = reverse ? units - 1 - k : k;
        EXPECT_EQ(stream::run_grade_merge_unit(in, mp, u, progress), mp.first(u + 1) - mp.first(u));
      }
      // Made once: read back from plan.json (its files untouched) while it is for the same key.
      EXPECT_EQ(stream::shared_grade_merge_plan(in, counts, units, true, key).cut, mp.cut);
      const std::string order = dir.file(fmt::format("order-{}.u32", units));
      const std::string grade_file = dir.file(fmt::format("grades-{}.f64", units));
      const std::string positions_file = dir.file(fmt::format("positions-{}.f32", units));
      EXPECT_EQ(stream::finish_grade_merge(in, gp, mp, order, grade_file, positions_file, "").records, n);
      *grades = slurp(grade_file);
      *positions = slurp(positions_file);
      return slurp(order);
    };
    std::string one_grades, grades, one_positions, positions;
    const std::string one = merged(1, false, &one_grades, &one_positions);
    std::vector<stream::GradeRecord> all;
    for (const auto& r : records) all.insert(all.end(), r.begin(), r.end());
    std::sort(all.begin(), all.end(), stream::WeightLess());
    ASSERT_EQ(one.size(), all.size() * 4);
    ASSERT_EQ(one_positions.size(), all.size() * 12);
    for (size_t i = 0; i < all.size(); ++i) {
      uint32_t id;
      std::memcpy(&id, one.data() + i * 4, 4);
      ASSERT_EQ(id, all[i].id) << i;
      float p[3];
      std::memcpy(p, one_positions.data() + i * 12, 12);
      ASSERT_EQ(p[0], float(id)) << i;
      ASSERT_EQ(p[1], float(id) / 8) << i;
      ASSERT_EQ(p[2], -float(id)) << i;
    }
    for (unsigned units : {2u, 7u, 256u}) {
      SCOPED_TRACE(units);
      EXPECT_TRUE(merged(units, units != 2, &grades, &positions) == one);
      EXPECT_TRUE(grades == one_grades);
      EXPECT_TRUE(positions == one_positions) << "each unit's records' positions, in place";
    }
  }
}

// The grading plan's block pass as units (stream/grade_stage.h, block_pass_unit) on a store of three
// blocks of triangles (sizes spread over many bins), two of segments and one of points: 2 and 5 units run
// backwards give plan_grading's own pass, every block's ranges and the area histogram to the bit (a
// block's areas are summed in triangle order, the blocks' in store order, whoever summed them); a unit's
// areas file cut short is refused.
// A store of a wavy 600 × 600 grid of vertices: about 717 K triangles, 300 K segments across it, 10 points.
stream::StoreMeta grid_store(const std::string& store) {
  std::filesystem::create_directories(store);
  stream::StoreWriter w(store, false);
  const uint32_t side = 600;  // (side - 1)^2 * 2 triangles
  std::vector<double> xyz;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) xyz.insert(xyz.end(), {x * (1 + 1e-3 * y), y + 1e-4 * x * x, std::sin(0.01 * x * y)});
  w.add_vertices(xyz);
  std::vector<uint32_t> tris, lines, points;
  for (uint32_t y = 0; y + 1 < side; ++y)
    for (uint32_t x = 0; x + 1 < side; ++x) {
      const uint32_t v = y * side + x;
      tris.insert(tris.end(), {v, v + 1, v + side, v + 1, v + side + 1, v + side});
    }
  for (uint32_t i = 0; i + 1 < 300000; ++i) lines.insert(lines.end(), {i, (i * 7919u) % (side * side)});
  for (uint32_t i = 0; i < 10; ++i) points.push_back(i * 1000);
  w.add_triangles(tris, {});
  w.add_lines(lines, {});
  w.add_points(points, {});
  return w.commit(stream::StoreMeta{});
}

TEST(GradeShares, BlockUnitsGiveTheBlockPassBits) {
  TempDir dir;
  const std::string store = dir.file("store");
  const stream::StoreMeta meta = grid_store(store);
  const std::array<uint64_t, 3> blocks = stream::grade_blocks(meta);
  ASSERT_EQ(blocks[0], 3u);
  ASSERT_EQ(blocks[1], 2u);
  stream::MemoryPlan plan;
  plan.stage_bytes = 64 << 20;
  stream::WorkDir work(dir.file("work"));
  stream::Progress progress{Options()};
  const stream::GradePlan one = stream::plan_grading(store, meta, plan, work, progress, dir.file("weld.map"), 0, 40, true);
  ASSERT_GT(one.ranges, 16u);
  EXPECT_FALSE(one.welded);
  for (unsigned units : {2u, 5u}) {
    SCOPED_TRACE(fmt::format("{} units", units));
    const std::string units_dir = dir.file(fmt::format("units-{}", units)) + "/";
    std::filesystem::create_directories(units_dir);
    io::OffsetFile(units_dir + "blocks.bin", O_WRONLY | O_CREAT | O_TRUNC)
        .resize((blocks[0] + blocks[1] + blocks[2]) * sizeof(stream::RangeMask));
    for (unsigned u = units; u-- > 0;)
      stream::block_pass_unit(store, meta, "", one.range, u, units, units_dir + "blocks.bin", units_dir + fmt::format("areas-{}.bin", u),
                              progress);
    stream::PlanUnits pu;
    pu.block_dir = units_dir, pu.block_units = units;
    const stream::GradePlan got = stream::plan_grading(store, meta, plan, work, progress, dir.file("weld.map"), 0, 40, true, pu);
    EXPECT_EQ(got.range, one.range);
    for (int kind = 0; kind < 3; ++kind) EXPECT_TRUE(got.block_ranges[kind] == one.block_ranges[kind]) << kind;
    EXPECT_EQ(got.areas.count, one.areas.count);
    EXPECT_EQ(0, std::memcmp(got.areas.area.data(), one.areas.area.data(), one.areas.area.size() * sizeof(double)));
  }
  // One range and no block pass: the grading's own sums, block by block, are the same bits.
  stream::MemoryPlan ample;
  ample.stage_bytes = uint64_t{1} << 30;
  stream::GradePlan single = stream::plan_grading(store, meta, ample, work, progress, dir.file("weld.map"), 0, 1, false);
  ASSERT_EQ(single.ranges, 1u);
  stream::GradeSorter sorter(work, "test", 16 << 20);
  stream::grade_ranges(store, meta, core::Grading::lowtan, single, dir.file("weld.map"), 0, 1, sorter, progress);
  EXPECT_EQ(0, std::memcmp(single.areas.area.data(), one.areas.area.data(), one.areas.area.size() * sizeof(double)));
  const std::string cut = dir.file("units-5/areas-1.bin");
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) - 16);
  stream::PlanUnits pu;
  pu.block_dir = dir.file("units-5") + "/", pu.block_units = 5;
  EXPECT_THROW(stream::plan_grading(store, meta, plan, work, progress, dir.file("weld.map"), 0, 40, true, pu), Failure);
}

// The clustering shares' input for the sample room's one-machine run `one` in the work directory `work`
// (float positions), at a 256 MiB budget; its prefix and work directory are the caller's.
stream::ClusterShareInput room_share_input(const std::string& work, const SimplifyReport& one, stream::CellInfoKind info) {
  stream::StoreMeta meta;
  if (!stream::read_store_meta(work + "store", &meta) || !meta.single_precision) ADD_FAILURE() << work << "store: no float store";
  stream::ClusterShareInput in;
  in.index = {stream::order_path(work), stream::grades_path(work), work + "store/positions.f32",
              std::filesystem::file_size(stream::order_path(work)) / 4, meta.vertices, meta.single_precision, ""};
  in.bounds.assign(meta.bbox.min.begin(), meta.bbox.min.end());
  in.bounds.insert(in.bounds.end(), meta.bbox.max.begin(), meta.bbox.max.end());
  for (const LevelStats& l : one.levels) in.sizes.push_back(l.cell_size);
  in.info = info;
  in.memory_bytes = 256 << 20;
  return in;
}

// One machine's run of the room in dir's work directory (into dir/one), and the shares' input over it.
stream::ClusterShareInput room_run_and_share_input(const TempDir& dir, Representative rep, SimplifyReport* one) {
  SimplifyOptions so = room_options(dir.file("one"));
  so.representative = rep;
  if (!simplify(sample_room(), so, shared_work(dir), one).ok()) ADD_FAILURE() << "one machine's run failed";
  return room_share_input(dir.file("work") + "/", *one, stream::cell_info_kind(rep));
}

// The shares through the stream API with a first halo of a quarter cell, so that their own vertices near
// the slabs' edges stay unsettled and the shares widen their halos: every level's map and info are still
// one machine's, and the merge refuses shares that do not add up.
TEST(ClusterShares, WideningSharesGiveOneMachinesMapsAndInfos) {
  TempDir dir;
  SimplifyReport one;
  stream::ClusterShareInput in = room_run_and_share_input(dir, Representative::mean, &one);
  const std::string work = dir.file("work") + "/";
  const std::string prefix = dir.file("shares") + "/";
  stream::WorkDir shares_work(dir.file("shares"));
  in.prefix = prefix, in.work = &shares_work;
  in.first_halo_cells = 0.25;
  stream::Progress progress{Options{}};
  stream::ClusterShares last_plan;
  std::vector<nlohmann::ordered_json> last_figures;
  for (const bool by_records : {true, false})
  for (unsigned n : {2u, 3u, 4u}) {
    SCOPED_TRACE("shares " + std::to_string(n) + (by_records ? ", coarse levels by records" : ", coarse levels whole"));
    std::filesystem::remove_all(stream::cluster_shares_dir(prefix));
    in.split_by_records = by_records;
    const stream::ClusterShares plan = stream::plan_cluster_shares(in, n, progress);
    EXPECT_EQ(std::count(plan.by_records.begin(), plan.by_records.end(), 1) > 0, by_records);
    EXPECT_EQ(std::count(plan.whole_share.begin(), plan.whole_share.end(), -1) == static_cast<long>(plan.whole_share.size()), by_records)
        << "a level too coarse for the slabs is split by records or clustered whole";
    ASSERT_EQ(plan.cuts.size(), n - 1);
    EXPECT_TRUE(std::is_sorted(plan.cuts.begin(), plan.cuts.end()));
    EXPECT_EQ(plan.whole_share.at(0), -1) << "the finest level splits";
    std::vector<nlohmann::ordered_json> figures;
    unsigned most_tries = 0;
    for (unsigned s = 0; s < n; ++s) {
      figures.push_back(stream::run_cluster_share(in, plan, s, progress));
      for (const auto& f : figures.back())
        if (f.contains("tries")) most_tries = std::max(most_tries, f.at("tries").get<unsigned>());
    }
    EXPECT_GT(most_tries, 1u) << "no share widened its halo";
    const stream::ClusterSummary cs = stream::merge_cluster_shares(in, plan, figures, progress);
    last_plan = plan, last_figures = figures;
    for (size_t l = 0; l < one.levels.size(); ++l) {
      EXPECT_EQ(cs.cells[l], one.levels[l].cells) << "level " << l;
      EXPECT_TRUE(slurp(stream::cells_path(prefix, l)) == slurp(stream::cells_path(work, l))) << "level " << l;
      EXPECT_TRUE(slurp(stream::cell_info_path(prefix, l)) == slurp(stream::cell_info_path(work, l))) << "level " << l;
    }
  }
  // The whole levels' shares (4 shares): levels 3 and 4 one a share when two slabs' selections fit the
  // budget; else share 1 has every whole level and three slabs remain, narrower, so level 2 is whole too
  // (plan_cluster_shares, slabs_fit).
  {
    stream::ClusterShareInput ample = in, scarce = in;
    ample.split_by_records = scarce.split_by_records = false;
    ample.memory_bytes = uint64_t{1} << 40;
    scarce.memory_bytes = in.index.vertices * 3 / 16 + in.index.vertices;  // a fortieth of the vertices each
    const stream::ClusterShares one_a_share = stream::plan_cluster_shares(ample, 4, progress);
    const stream::ClusterShares together = stream::plan_cluster_shares(scarce, 4, progress);
    EXPECT_EQ(one_a_share.whole_share, (std::vector<int>{-1, -1, -1, 1, 2}));
    EXPECT_EQ(together.whole_share, (std::vector<int>{-1, -1, 1, 1, 1})) << "level 2 is whole too in three slabs";
    EXPECT_EQ(one_a_share.cuts.at(0), one_a_share.cuts.at(2)) << "shares 1 and 2 have no slab";
    EXPECT_EQ(together.cuts.at(0), together.cuts.at(1)) << "share 1 has no slab";
    EXPECT_NE(together.cuts.at(1), together.cuts.at(2)) << "three slabs";
    // Split by records (the default): no whole level, four slabs, and levels 1 to 4 by records.
    ample.split_by_records = true;
    const stream::ClusterShares records = stream::plan_cluster_shares(ample, 4, progress);
    EXPECT_EQ(records.whole_share, (std::vector<int>{-1, -1, -1, -1, -1}));
    EXPECT_EQ(records.by_records, (std::vector<char>{0, 1, 1, 1, 1})) << "four slabs are narrower than three";
    EXPECT_NE(records.cuts.at(0), records.cuts.at(1));
    EXPECT_NE(records.cuts.at(1), records.cuts.at(2));
  }
  // A share's decisions cut short: the merge fails naming the shares' directory (the last plan's files, 4 shares).
  const std::string dec = stream::cluster_shares_dir(prefix) + "share-0-level-0.dec";
  std::filesystem::resize_file(dec, std::filesystem::file_size(dec) - 8);
  try {
    stream::merge_cluster_shares(in, last_plan, last_figures, progress);
    ADD_FAILURE() << "the merge took a share cut short";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::io_error);
    EXPECT_NE(std::string(f.what()).find("cluster-shares"), std::string::npos) << f.what();
  }
}

// The centers units of the levels split by records are stamped with the caller's key (the cluster stage's
// inputs): a second run at cell sizes 1 % larger, under another key, with the first run's centers units
// left in place, finds its own centers, and its maps are one pass's at those sizes.
TEST(ClusterShares, CentersUnitsAreKeyedByTheStage) {
  TempDir dir;
  SimplifyReport one;
  stream::ClusterShareInput in = room_run_and_share_input(dir, Representative::center, &one);
  stream::Progress progress{Options{}};
  for (int run = 0; run < 2; ++run) {
    SCOPED_TRACE("run " + std::to_string(run));
    const std::string prefix = dir.file("shares-" + std::to_string(run)) + "/";
    stream::WorkDir work(dir.file("shares-" + std::to_string(run)));
    in.prefix = prefix, in.work = &work;
    if (run == 1) {
      for (double& c : in.sizes) c *= 1.01;
      std::filesystem::create_directories(stream::cluster_shares_dir(prefix));
      std::filesystem::copy(stream::cluster_shares_dir(dir.file("shares-0") + "/") + "centers",
                            stream::cluster_shares_dir(prefix) + "centers");
    }
    in.key = {{"run", run}};
    const stream::ClusterShares plan = stream::plan_cluster_shares(in, 3, progress);
    ASSERT_EQ(plan.by_records.back(), 1) << "the coarsest level is split by records";
    std::vector<nlohmann::ordered_json> figures;
    for (unsigned s = 0; s < 3; ++s) figures.push_back(stream::run_cluster_share(in, plan, s, progress));
    const stream::ClusterSummary cs = stream::merge_cluster_shares(in, plan, figures, progress);
    const std::string whole = dir.file("whole-" + std::to_string(run) + "-");
    const stream::ClusterSummary want =
        stream::cluster_levels(in.index, in.bounds, in.sizes, in.options, in.info, in.memory_bytes, work, progress, whole);
    EXPECT_EQ(cs.cells, want.cells);
    for (size_t l = 0; l < in.sizes.size(); ++l) {
      EXPECT_TRUE(slurp(stream::cells_path(prefix, l)) == slurp(stream::cells_path(whole, l))) << "level " << l;
      EXPECT_TRUE(slurp(stream::cell_info_path(prefix, l)) == slurp(stream::cell_info_path(whole, l))) << "level " << l;
    }
  }
}

// A share over --memory stops with a usage error naming what outgrew it: here the first level split by
// records' centers pass (its covered voxels and cells), at 64 KiB.
TEST(ClusterShares, AShareOverItsBudgetNamesWhatOutgrewIt) {
  TempDir dir;
  SimplifyReport one;
  stream::ClusterShareInput in = room_run_and_share_input(dir, SimplifyOptions().representative, &one);
  stream::WorkDir work(dir.file("shares"));
  in.prefix = dir.file("shares") + "/", in.work = &work;
  stream::Progress progress{Options{}};
  const stream::ClusterShares plan = stream::plan_cluster_shares(in, 3, progress);
  ASSERT_EQ(plan.by_records.back(), 1);
  in.memory_bytes = 64 << 10;
  try {
    stream::run_cluster_share(in, plan, 0, progress);
    ADD_FAILURE() << "a share ran over its budget";
  } catch (const Failure& f) {
    EXPECT_EQ(f.status(), Status::usage);
    EXPECT_NE(std::string(f.what()).find("covered voxels and cells take"), std::string::npos) << f.what();
    EXPECT_NE(std::string(f.what()).find("more than --memory allows (0 MiB): raise --memory, or run more shares"), std::string::npos)
        << f.what();
  }
}

// RankedBits::select, which finds where a sums unit of the clustering merge starts (the center of its first
// cell): the inverse of rank on the set bits, over runs of empty and of full words.
TEST(ClusterShares, CenterBitsSelectIsTheInverseOfRank) {
  stream::RankedBits b(1000);
  for (uint64_t i = 0; i < 1000; ++i)
    if ((i < 200 && i % 7 == 3) || (i >= 448 && i < 640) || i == 999) b.set(i);  // words 4-6 empty, 7-9 full
  b.count();
  uint64_t k = 0;
  for (uint64_t i = 0; i < 1000; ++i)
    if (b.has(i)) {
      EXPECT_EQ(b.rank(i), k);
      EXPECT_EQ(b.select(k), i) << "set bit " << k;
      ++k;
    }
  EXPECT_EQ(k, b.ones());
}

// The split levels' merge as units (stream/cluster_merge.h), taken up by three threads at once as three
// processes would (each starting at its own unit): 1 unit, 7, 37, and one a 64-record word (so that most
// units share both their first and last word of the map with their neighbours), with center and quadric
// representatives (the centers' positions copied from the middle of the shares' files; the quadric infos
// summed by as many units of cells, each a pass over every record). The maps and infos are one machine's
// bytes; a stamped unit is reused; a record decided by no share fails naming it.
TEST(ClusterShares, MergeUnitsTakenByThreadsAtOnceGiveOneMachinesMaps) {
  for (const Representative rep : {Representative::center, Representative::quadric}) {
    SCOPED_TRACE(rep == Representative::center ? "center" : "quadric");
    TempDir dir;
    SimplifyOptions so = room_options(dir.file("one"));
    so.representative = rep;
    SimplifyReport one;
    ASSERT_TRUE(simplify(sample_room(), so, shared_work(dir), &one).ok());
    const std::string work = dir.file("work") + "/";
    stream::ClusterShareInput in = room_share_input(work, one, stream::cell_info_kind(rep));
    const std::string prefix = dir.file("shares") + "/";
    stream::WorkDir shares_work(dir.file("shares"));
    in.prefix = prefix, in.work = &shares_work;
    stream::Progress progress{Options{}};
    const stream::ClusterShares plan = stream::plan_cluster_shares(in, 3, progress);
    ASSERT_EQ(plan.whole_share.at(0), -1) << "the finest level splits";
    std::vector<nlohmann::ordered_json> figures;
    for (unsigned s = 0; s < 3; ++s) figures.push_back(stream::run_cluster_share(in, plan, s, progress));
    const nlohmann::ordered_json key{{"test", 1}};
    const uint64_t words = (in.index.records + 63) / 64;
    ASSERT_GT(words, 300u);
    for (const uint64_t units : {uint64_t{1}, uint64_t{7}, uint64_t{37}, words}) {
      SCOPED_TRACE("units " + std::to_string(units));
      std::filesystem::remove_all(stream::cluster_merge_dir(prefix));
      for (size_t l = 0; l < one.levels.size(); ++l)
        if (plan.whole_share[l] < 0) std::filesystem::remove(stream::cells_path(prefix, l)), std::filesystem::remove(stream::cell_info_path(prefix, l));
      stream::ClusterShareInput unit_in = in;
      unit_in.merge_units = static_cast<unsigned>(units);
      std::vector<std::vector<uint64_t>> cells(3);
      std::vector<std::thread> threads;
      for (unsigned t = 0; t < 3; ++t)
        threads.emplace_back([&, t] {
          stream::Progress p{Options{}};
          cells[t] = stream::merge_split_levels(unit_in, plan, key, t, p).cells;
        });
      for (auto& t : threads) t.join();
      EXPECT_EQ(cells[0], cells[1]);
      EXPECT_EQ(cells[0], cells[2]);
      size_t stamps = 0;
      for (const auto& e : std::filesystem::directory_iterator(stream::cluster_merge_dir(prefix) + "map"))
        stamps += e.path().filename().string().rfind("merge-map-", 0) == 0;
      EXPECT_EQ(stamps, units);
      size_t sums = 0;
      if (rep == Representative::quadric)
        for (const auto& e : std::filesystem::directory_iterator(stream::cluster_merge_dir(prefix) + "sums"))
          sums += e.path().filename().string().rfind("merge-sums-", 0) == 0;
      EXPECT_EQ(sums, rep == Representative::quadric ? units : 0);
      // Again in this thread, the shares' files moved away: every unit is reused (one that ran again would
      // find no decisions to read).
      std::filesystem::rename(stream::cluster_shares_dir(prefix), dir.file("moved"));
      EXPECT_EQ(stream::merge_split_levels(unit_in, plan, key, 0, progress).cells, cells[0]);
      std::filesystem::rename(dir.file("moved"), stream::cluster_shares_dir(prefix));
      const stream::ClusterSummary cs = stream::merge_cluster_shares(unit_in, plan, figures, cells[0], progress);
      for (size_t l = 0; l < one.levels.size(); ++l) {
        EXPECT_EQ(cs.cells[l], one.levels[l].cells) << "level " << l;
        EXPECT_TRUE(slurp(stream::cells_path(prefix, l)) == slurp(stream::cells_path(work, l))) << "level " << l;
        EXPECT_TRUE(slurp(stream::cell_info_path(prefix, l)) == slurp(stream::cell_info_path(work, l))) << "level " << l;
      }
    }
    // A record no share decides (share 0's last decision of level 0 cut off): the merge names it.
    std::filesystem::remove_all(stream::cluster_merge_dir(prefix));
    const std::string dec = stream::cluster_share_decisions_path(prefix, 0, 0);
    ASSERT_GT(std::filesystem::file_size(dec), 0u);
    std::filesystem::resize_file(dec, std::filesystem::file_size(dec) - 8);
    try {
      stream::ClusterShareInput unit_in = in;
      unit_in.merge_units = 7;
      stream::merge_split_levels(unit_in, plan, key, 0, progress);
      ADD_FAILURE() << "the merge took a share cut short";
    } catch (const Failure& f) {
      EXPECT_EQ(f.status(), Status::io_error);
      EXPECT_NE(std::string(f.what()).find("is decided by no share"), std::string::npos) << f.what();
    }
  }
}

// Every vertex of a 150 x 150 x 134 lattice (3.0 M, 1 apart, cells of 0.5) is a center: as 2 shares under
// center representatives, each share's centers (1.5 M, 18 MB of floats) outrun the merge's 1 MiB read
// buffer many times, and the map and info are still the whole pass's.
TEST(ClusterShares, ManyCentersMergeAcrossReadWindows) {
  TempDir dir;
  const int nx = 150, ny = 150, nz = 134;
  const uint32_t n = nx * ny * nz;
  {
    std::ofstream pos(dir.file("positions.f32"), std::ios::binary), order(dir.file("order.u32"), std::ios::binary);
    uint32_t id = 0;
    for (int x = 0; x < nx; ++x)
      for (int y = 0; y < ny; ++y)
        for (int z = 0; z < nz; ++z, ++id) {
          const float p[3] = {float(x), float(y), float(z)};
          pos.write(reinterpret_cast<const char*>(p), sizeof p);
          order.write(reinterpret_cast<const char*>(&id), 4);
        }
  }
  stream::ClusterShareInput in;
  in.index = {dir.file("order.u32"), "", dir.file("positions.f32"), n, n, true};
  in.bounds = {0, 0, 0, nx - 1.0, ny - 1.0, nz - 1.0};
  in.sizes = {0.5};
  in.info = stream::CellInfoKind::center;
  in.memory_bytes = 512 << 20;
  stream::WorkDir work(dir.file("shares"));
  in.prefix = dir.file("shares") + "/", in.work = &work;
  stream::Progress progress{Options{}};
  const stream::ClusterSummary whole = stream::cluster_levels(in.index, in.bounds, in.sizes, in.options, in.info, in.memory_bytes,
                                                              work, progress, dir.file("whole-"));
  ASSERT_EQ(whole.cells.at(0), n);
  const stream::ClusterShares plan = stream::plan_cluster_shares(in, 2, progress);
  ASSERT_EQ(plan.whole_share.at(0), -1) << "the level splits";
  std::vector<nlohmann::ordered_json> figures;
  for (unsigned s = 0; s < 2; ++s) figures.push_back(stream::run_cluster_share(in, plan, s, progress));
  EXPECT_GT(std::filesystem::file_size(stream::cluster_shares_dir(in.prefix) + "share-0-level-0.ctr"), uint64_t{16} << 20);
  const stream::ClusterSummary cs = stream::merge_cluster_shares(in, plan, figures, progress);
  EXPECT_EQ(cs.cells.at(0), n);
  EXPECT_TRUE(slurp(stream::cells_path(in.prefix, 0)) == slurp(stream::cells_path(dir.file("whole-"), 0)));
  EXPECT_TRUE(slurp(stream::cell_info_path(in.prefix, 0)) == slurp(stream::cell_info_path(dir.file("whole-"), 0)));
}

// Materials and colours travel through the tasks' parts and the merge: the KiCad board (a glTF scene of
// instanced components, one material each) as 3 tasks gives one machine's bytes, tiles included.
TEST(Shard, MaterialsGiveOneMachinesBytes) {
  TempDir dir;
  const std::string board = test::source_dir() + "/tests/data/gltf/kicad-board.glb";
  const Options o = shared_work(dir);
  SimplifyOptions so = room_options(dir.file("one"));
  SimplifyReport one;
  ASSERT_TRUE(simplify(board, so, o, &one).ok());
  const auto want = outputs(dir.file("one"));
  ASSERT_NE(slurp(dir.file("one") + "/lod0.ply").find("property uint material_index"), std::string::npos) << "the board has materials";
  SimplifyReport merged;
  const Result r = run_tasks(dir.file("sharded"), dir.file("work"), 3, {0, 1, 2}, 0, true, &merged, board);
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_EQ(outputs(dir.file("sharded")), want);
  // The manifest lists the OBJ's material libraries as one machine's does (the merge's list once lacked them).
  ASSERT_TRUE(std::filesystem::exists(dir.file("one") + "/lod0.mtl"));
  EXPECT_NE(slurp(dir.file("sharded") + "/manifest.json").find("\"lod0.mtl\""), std::string::npos);
  EXPECT_EQ(manifest_without_timings(dir.file("sharded")), manifest_without_timings(dir.file("one")));
}

TEST(Shard, MergeNamesTheMissingTasks) {
  TempDir dir;
  SimplifyReport merged;
  Result r = merge(dir.file("nothing"), Options{}, &merged);
  EXPECT_EQ(r.status, Status::no_input);
  r = run_tasks(dir.file("out"), dir.file("work"), 4, {0, 2}, 0, true, &merged);
  EXPECT_EQ(r.status, Status::no_input);
  EXPECT_NE(r.message.find("tasks 1, 3 of 4 have not finished"), std::string::npos) << r.message;
  EXPECT_FALSE(std::filesystem::exists(dir.file("out/manifest.json")));
  // The missing tasks alone, then the merge: complete.
  r = run_tasks(dir.file("out"), dir.file("work"), 4, {1, 3}, 0, true, &merged);
  EXPECT_TRUE(r.ok()) << r.message;
  EXPECT_TRUE(std::filesystem::exists(dir.file("out/manifest.json")));
}

TEST(Shard, TaskRangesCoverEveryRegionOnce) {
  stream::LevelCut cut;
  for (uint64_t c : {5, 0, 7, 1, 1, 30, 0, 2, 9, 0}) cut.regions.push_back({}), cut.cells.push_back(c);
  for (unsigned n : {1u, 2u, 3u, 7u, 12u}) {
    uint32_t next = 0;
    for (unsigned i = 0; i < n; ++i) {
      const auto [first, end] = stream::shard_regions(cut, i, n);
      EXPECT_EQ(first, next) << n << " tasks, task " << i;
      EXPECT_LE(first, end);
      next = end;
    }
    EXPECT_EQ(next, cut.regions.size()) << n << " tasks";
  }
  // Balanced by cells: a region goes to the task whose share holds the cells before it (55 cells, 2 tasks:
  // the 30-cell region has 14 before it, in the first half).
  EXPECT_EQ(stream::shard_regions(cut, 0, 2), (std::pair<uint32_t, uint32_t>{0, 6}));
}

// Every level's runs follow the finest level's Morton cut (shard_bounds): they cover each level's regions
// once in task order, the finest level's are its own shard_regions, and a coarser region goes to the task
// whose run of codes holds its first code.
TEST(Shard, LevelsShareTheFinestLevelsRunsOfCodes) {
  // The finest level: the 64 depth-2 nodes in region order, all but a few holding cells; a coarser level:
  // the 8 depth-1 nodes.
  auto morton_sorted = [](unsigned depth) {
    std::vector<core::RegionKey> keys;
    const uint32_t side = 1u << depth;
    for (uint32_t z = 0; z < side; ++z)
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) keys.push_back({static_cast<uint8_t>(depth), x, y, z});
    std::sort(keys.begin(), keys.end(), core::region_before);
    return keys;
  };
  stream::LevelCut fine, coarse;
  fine.regions = morton_sorted(2);
  for (size_t i = 0; i < fine.regions.size(); ++i) fine.cells.push_back(i % 5 == 3 ? 0 : 1 + i % 7);
  coarse.regions = morton_sorted(1);
  coarse.cells.assign(coarse.regions.size(), 3);
  for (unsigned n : {1u, 2u, 3u, 8u, 70u}) {
    const std::vector<uint64_t> bounds = stream::shard_bounds(fine, n);
    ASSERT_EQ(bounds.size(), n + 1u);
    EXPECT_TRUE(std::is_sorted(bounds.begin(), bounds.end())) << n;
    for (const stream::LevelCut* cut : {&fine, &coarse}) {
      uint32_t next = 0;
      for (unsigned t = 0; t < n; ++t) {
        const auto [first, end] = stream::shard_regions_in(*cut, bounds, t);
        EXPECT_EQ(first, next) << n << " tasks, task " << t;
        EXPECT_LE(first, end);
        for (uint32_t r = first; r < end; ++r) {
          EXPECT_GE(core::region_code(cut->regions[r]), bounds[t]);
          if (t + 1 < n) {
            EXPECT_LT(core::region_code(cut->regions[r]), bounds[t + 1]);
          }
        }
        if (cut == &fine) {
          EXPECT_EQ(std::make_pair(first, end), stream::shard_regions(fine, t, n)) << n << " tasks, task " << t;
        }
        next = end;
      }
      EXPECT_EQ(next, cut->regions.size()) << n << " tasks";
    }
  }
}

// shard_runs: levels of at least N regions by the runs of codes (as above); a wide level (coarser, of fewer
// regions than tasks) whole to one task, so that a task's wide levels share one pass. With 3 tasks or more
// the wide levels go to tasks 0 to K - 1, one a task while two tasks remain, and those tasks have no run of
// codes; every level's runs cover its regions once.
TEST(Shard, WideLevelsGoWholeToTasksOfTheirOwn) {
  auto morton_sorted = [](unsigned depth) {
    std::vector<core::RegionKey> keys;
    const uint32_t side = 1u << depth;
    for (uint32_t z = 0; z < side; ++z)
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) keys.push_back({static_cast<uint8_t>(depth), x, y, z});
    std::sort(keys.begin(), keys.end(), core::region_before);
    return keys;
  };
  // Finest first: 64 depth-2 nodes, 8 depth-1 nodes, 3 of them alone, then the root.
  std::vector<stream::LevelCut> cuts(4);
  cuts[0].regions = morton_sorted(2), cuts[0].cells.assign(64, 5);
  cuts[1].regions = morton_sorted(1), cuts[1].cells.assign(8, 4);
  cuts[2].regions = {cuts[1].regions[0], cuts[1].regions[3], cuts[1].regions[6]}, cuts[2].cells.assign(3, 2);
  cuts[3].regions = morton_sorted(0), cuts[3].cells.assign(1, 1);
  for (unsigned n : {1u, 2u, 3u, 4u, 8u, 9u}) {
    SCOPED_TRACE(std::to_string(n) + " tasks");
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> runs;
    for (unsigned t = 0; t < n; ++t) runs.push_back(stream::shard_runs(cuts, t, n));
    std::vector<size_t> wide_levels;
    for (size_t l = 1; l < cuts.size(); ++l)
      if (cuts[l].regions.size() < n) wide_levels.push_back(l);
    const unsigned k = n >= 3 ? std::min<unsigned>(static_cast<unsigned>(wide_levels.size()), n - 2) : 0;
    EXPECT_EQ(stream::wide_task_count(cuts, n), k);
    const std::vector<uint64_t> bounds = stream::shard_bounds(cuts[0], n - k);
    for (size_t l = 0; l < cuts.size(); ++l) {
      std::vector<int> owner(cuts[l].regions.size(), -1);
      for (unsigned t = 0; t < n; ++t)
        for (uint32_t r = runs[t][l].first; r < runs[t][l].second; ++r) {
          EXPECT_EQ(owner[r], -1) << "level " << l << " region " << r;
          owner[r] = static_cast<int>(t);
        }
      for (size_t r = 0; r < owner.size(); ++r) EXPECT_GE(owner[r], 0) << "level " << l << " region " << r;
      const auto j = std::find(wide_levels.begin(), wide_levels.end(), l);
      const bool wide = j != wide_levels.end();
      EXPECT_EQ(stream::wide_level(cuts, l, n), wide) << "level " << l;
      const unsigned wide_task = wide ? static_cast<unsigned>((j - wide_levels.begin()) * std::max(k, 1u) / wide_levels.size()) : 0;
      const uint32_t regions = static_cast<uint32_t>(cuts[l].regions.size());
      for (unsigned t = 0; t < n; ++t) {
        if (wide && t == wide_task) {
          EXPECT_EQ(runs[t][l], (std::pair<uint32_t, uint32_t>{0, regions})) << "level " << l;
        } else if (wide || t < k) {
          EXPECT_EQ(runs[t][l].first, runs[t][l].second) << "level " << l << ": task " << t << " has none of it";
        } else {
          EXPECT_EQ(runs[t][l], stream::shard_regions_in(cuts[l], bounds, t - k)) << "level " << l;
        }
      }
    }
    // 4 tasks: levels 2 (3 regions) and 3 (the root) are wide; 9 tasks: level 1 (8 regions) too.
    EXPECT_EQ(stream::wide_level(cuts, 1, n), n == 9);
    EXPECT_EQ(stream::wide_level(cuts, 2, n), n >= 4);
    EXPECT_EQ(stream::wide_level(cuts, 3, n), n >= 2);
  }
  // 9 tasks: the three wide levels one a task, tasks 0 to 2; 4 tasks: levels 2 and 3 one a task, 2 runs of codes.
  EXPECT_EQ(stream::wide_tasks(cuts, 9), (std::vector<int>{-1, 0, 1, 2}));
  EXPECT_EQ(stream::wide_tasks(cuts, 4), (std::vector<int>{-1, -1, 0, 1}));
  EXPECT_EQ(stream::wide_tasks(cuts, 2), (std::vector<int>{-1, -1, -1, 0}));
  EXPECT_EQ(stream::shard_runs(cuts, 2, 4).at(0).first, 0u) << "task 2 of 4 has the first run of codes";
}

TEST(Shard, OptionsAndEnvironment) {
  TempDir dir;
  SimplifyOptions so = room_options(dir.file("out"));
  so.shard_count = 2;
  SimplifyReport r;
  EXPECT_EQ(simplify(sample_room(), so, Options{}, &r).status, Status::usage) << "no work directory";
  Options o;
  o.work_dir = dir.file("work");
  so.max_error_px = 2;
  EXPECT_EQ(simplify(sample_room(), so, o, &r).status, Status::usage) << "--max-error-px";

  unsigned i = 0, n = 0;
  std::string error;
  for (const char* v : {"SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "JOB_COMPLETION_INDEX", "AWS_BATCH_JOB_ARRAY_INDEX",
                        "LODSTREAM_SHARD_COUNT"})
    unsetenv(v);
  EXPECT_FALSE(shard_from_env(&i, &n, &error));
  setenv("SLURM_ARRAY_TASK_ID", "3", 1);
  setenv("SLURM_ARRAY_TASK_COUNT", "8", 1);
  EXPECT_TRUE(shard_from_env(&i, &n, &error)) << error;
  EXPECT_EQ(i, 3u);
  EXPECT_EQ(n, 8u);
  setenv("SLURM_ARRAY_TASK_COUNT", "1", 1);  // a task resubmitted alone: the count comes from LODSTREAM_SHARD_COUNT
  EXPECT_FALSE(shard_from_env(&i, &n, &error));
  setenv("LODSTREAM_SHARD_COUNT", "8", 1);
  EXPECT_TRUE(shard_from_env(&i, &n, &error)) << error;
  EXPECT_EQ(n, 8u);
  unsetenv("SLURM_ARRAY_TASK_ID");
  unsetenv("SLURM_ARRAY_TASK_COUNT");
  setenv("JOB_COMPLETION_INDEX", "7", 1);
  EXPECT_TRUE(shard_from_env(&i, &n, &error)) << error;
  EXPECT_EQ(i, 7u);
  setenv("JOB_COMPLETION_INDEX", "x", 1);
  EXPECT_FALSE(shard_from_env(&i, &n, &error));
  unsetenv("JOB_COMPLETION_INDEX");
  unsetenv("LODSTREAM_SHARD_COUNT");
}

// A CLI command line with the room's tiling options (room_options) and no progress lines.
std::vector<std::string> room_cli_args(std::vector<std::string> a) {
  for (const char* x : {"--tiles", "--tile-triangles", "6000", "--no-space-check", "--progress", "none"}) a.push_back(x);
  return a;
}

// Through the CLI: `count` tasks of the simplify command line `argv` (with --shard I/count added), one after
// another, then `lodstream merge` of `out`: each must succeed.
void run_cli_tasks_and_merge(const std::vector<std::string>& argv, unsigned count, const std::string& out, const TempDir& log) {
  for (unsigned i = 0; i < count; ++i) {
    std::vector<std::string> a = argv;
    a.push_back("--shard"), a.push_back(std::to_string(i) + "/" + std::to_string(count));
    const test::CliRun t = test::run_cli(a, log);
    ASSERT_EQ(t.exit_code, 0) << t.err;
  }
  const test::CliRun m = test::run_cli({"merge", out}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
}

// Through the CLI: three tasks started at once on a fresh work directory (the first to take the lock runs
// the shared stages, the others wait and reuse them), a task killed with SIGKILL just before its summary,
// merge refusing, the task rerun alone, merge: one machine's bytes.
TEST(Shard, ConcurrentTasksAndAKilledTaskThroughTheCli) {
  TempDir dir, one_out;
  const auto args = room_cli_args;
  test::CliRun one = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("one")}), one_out);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  setenv("LODSTREAM_TEST_KILL_AT", "task-1.json", 1);
  std::vector<test::CliRun> runs(3);
  {
    std::vector<std::thread> tasks;
    std::vector<TempDir> logs(3);
    for (unsigned i = 0; i < 3; ++i)
      tasks.emplace_back([&, i] {
        runs[i] = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", dir.file("work"), "--shard",
                                      std::to_string(i) + "/3"}),
                                logs[i]);
      });
    for (auto& t : tasks) t.join();
  }
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(runs[0].exit_code, 0) << runs[0].err;
  EXPECT_EQ(runs[1].exit_code, 128 + SIGKILL);
  EXPECT_EQ(runs[2].exit_code, 0) << runs[2].err;
  TempDir log;
  test::CliRun m = test::run_cli({"merge", dir.file("out")}, log);
  EXPECT_EQ(m.exit_code, 66);
  EXPECT_NE(m.err.find("task 1 of 3 has not finished"), std::string::npos) << m.err;
  test::CliRun again = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", dir.file("work"), "--shard", "1/3"}), log);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("(reused from work directory)"), std::string::npos) << "the shared stages are reused";
  m = test::run_cli({"merge", dir.file("out")}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  EXPECT_EQ(outputs(dir.file("out")), outputs(dir.file("one")));

  for (const char* bad : {"3/3", "1", "x/2", "1/0", "-1/2", "1/2/3"}) {
    const test::CliRun r = test::run_cli({"simplify", sample_room(), "-o", dir.file("bad"), "--work", dir.file("work"), "--shard", bad}, log);
    EXPECT_EQ(r.exit_code, 64) << bad;
  }
}

// Through the CLI: a clustering share killed with SIGKILL while it finds a coarse level's centers (just
// before the unit's stamp): the unit is left unstamped, the next share runs it, and the tasks then give one
// machine's bytes.
TEST(Shard, AKilledCentersUnitIsRunByTheNextShare) {
  TempDir dir, log;
  const auto args = room_cli_args;
  test::CliRun one = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("one")}), log);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string work = dir.file("work"), centers = stream::cluster_shares_dir(work + "/") + "centers/";
  auto share = [&](unsigned i) {
    return test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--shard-cluster",
                               std::to_string(i) + "/3"}),
                         log);
  };
  setenv("LODSTREAM_TEST_KILL_AT", "level-4.json", 1);
  const test::CliRun killed = share(0);
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(killed.exit_code, 128 + SIGKILL) << killed.err;
  const nlohmann::json plan = nlohmann::json::parse(slurp(stream::cluster_shares_dir(work + "/") + "plan.json")).at("plan");
  ASSERT_EQ(plan.at("by_records").size(), 5u);
  ASSERT_EQ(plan.at("by_records").at(4), 1) << "the room's coarsest level is split by records";
  EXPECT_TRUE(std::filesystem::exists(centers + "level-4.ctrs")) << "the killed share had written the centers";
  EXPECT_FALSE(std::filesystem::exists(centers + "level-4.json")) << "but not stamped them";
  const test::CliRun next = share(1);
  ASSERT_EQ(next.exit_code, 0) << next.err;
  EXPECT_TRUE(std::filesystem::exists(centers + "level-4.json")) << "the next share ran the unit";
  EXPECT_FALSE(std::filesystem::exists(stream::cluster_share_stamp(work + "/", 0))) << "share 0 is still to run";
  run_cli_tasks_and_merge(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--cluster-shards", "3"}), 3,
                          dir.file("out"), log);
  EXPECT_EQ(outputs(dir.file("out")), outputs(dir.file("one")));
}

// Through the CLI: the wide levels' pass A as units (stream/wide_units.h). A task killed with SIGKILL just
// before a unit's stamp leaves the unit's files unstamped; the next task runs the unit, and the tasks then
// give one machine's bytes. The task that emits the wide levels reads the units' files: one of them cut
// short, that task stops with exit 74 naming it rather than classifying the input itself.
TEST(Shard, WideLevelsAreClassifiedInUnitsThatAKilledTaskLeavesToTheNext) {
  TempDir dir, log;
  const auto args = room_cli_args;
  test::CliRun one = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("one")}), log);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string work = dir.file("work"), units = stream::wide_units_dir(work + "/");
  auto task = [&](unsigned i) {
    return test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--shard", std::to_string(i) + "/3"}),
                         log);
  };
  setenv("LODSTREAM_TEST_KILL_AT", "wide-unit-1.json", 1);
  const test::CliRun killed = task(1);
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(killed.exit_code, 128 + SIGKILL) << killed.err;
  // Task 1 took its own unit first: written, not stamped.
  const size_t coarsest = 4;  // the room's levels: the coarsest is wide at N = 3 (one region)
  EXPECT_TRUE(std::filesystem::exists(stream::wide_unit_path(work + "/", 1, coarsest)));
  EXPECT_FALSE(std::filesystem::exists(units + "group-0/wide-unit-1.json"));
  const test::CliRun next = task(2);
  ASSERT_EQ(next.exit_code, 0) << next.err;
  EXPECT_TRUE(std::filesystem::exists(units + "group-0/wide-unit-1.json")) << "the next task ran the unit";
  for (unsigned i : {0u, 1u}) {
    const test::CliRun t = task(i);
    ASSERT_EQ(t.exit_code, 0) << t.err;
    EXPECT_NE(t.out.find("wide-units"), std::string::npos) << t.out;
  }
  const test::CliRun m = test::run_cli({"merge", dir.file("out")}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  EXPECT_EQ(outputs(dir.file("out")), outputs(dir.file("one")));
  const nlohmann::json stage = nlohmann::json::parse(slurp(work + "/wide-units.json")).at("value").at("units");
  ASSERT_FALSE(stage.at("levels").empty());
  EXPECT_EQ(stage.at("levels").back(), coarsest);
  EXPECT_EQ(stage.at("units"), 3);
  EXPECT_EQ(stage.at("seconds").size(), 3u) << "one group: every wide level in one pass of each unit";

  // Task 0 emits the wide levels (wide_tasks: K = 1 at N = 3): it reads unit 1's file of the coarsest.
  const std::string cut = stream::wide_unit_path(work + "/", 1, coarsest);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) - 8);
  const test::CliRun rerun = task(0);
  EXPECT_EQ(rerun.exit_code, 74) << rerun.err;
  EXPECT_NE(rerun.err.find(cut), std::string::npos) << rerun.err;
  // Without tiles the room's levels 1-4 are wide at N = 3: a whole unit file of level 1 in the place of
  // level 4's (the same blocks, cells out of level 4's range).
  const std::string plain = dir.file("plain");
  auto plain_task = [&] {
    return test::run_cli({"simplify", sample_room(), "-o", dir.file("plain-out"), "--work", plain, "--shard", "0/3",
                          "--no-space-check", "--progress", "none"},
                         log);
  };
  ASSERT_EQ(plain_task().exit_code, 0);
  const nlohmann::json levels = nlohmann::json::parse(slurp(plain + "/wide-units.json")).at("value").at("units").at("levels");
  ASSERT_EQ(levels, nlohmann::json({1, 2, 3, 4}));
  const std::string swapped = stream::wide_unit_path(plain + "/", 1, 4);
  std::filesystem::copy_file(stream::wide_unit_path(plain + "/", 1, 1), swapped, std::filesystem::copy_options::overwrite_existing);
  const test::CliRun other = plain_task();
  EXPECT_EQ(other.exit_code, 74) << other.err;
  EXPECT_NE(other.err.find(swapped + ": not a unit of pass A of this level"), std::string::npos) << other.err;
}

// Through the CLI: the clustering shares' decisions are spent once the merge's map is written
// (stream/cluster_merge.h): a task killed just before a pairs unit's stamp has emptied them, marked them
// spent, and left the shares' stamps holding. A merge under another key (another build's, half done: here
// its units removed and the mark's key another) could not read them: the next task runs the shares again,
// and the tasks give one machine's bytes. The map units write no plain cells (the sums and pairs units
// enter the map); the records' positions in weight order are spent once the sums are done, before the pairs
// are written: a clustering at other levels then reads the store's positions.
TEST(Shard, SharesDecisionsAreSpentOnceTheMapIsWrittenAndRunAgainForAnotherMerge) {
  TempDir dir, log;
  const auto args = room_cli_args;
  test::CliRun one = test::run_cli(args({"simplify", sample_room(), "-o", dir.file("one")}), log);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string work = dir.file("work"), prefix = work + "/";
  auto task = [&](unsigned i) {
    return test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--shard", std::to_string(i) + "/3",
                               "--cluster-shards", "3"}),
                         log);
  };
  for (unsigned i = 0; i < 3; ++i) {  // graded as shares: their merge writes the records' positions in weight order
    const test::CliRun g = test::run_cli(
        args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--shard-grade", std::to_string(i) + "/3"}), log);
    ASSERT_EQ(g.exit_code, 0) << g.err;
  }
  // Task 1 on one thread takes map units 1, 2, 0 in turn: killed as unit 0 is stamped, units 1 and 2 have
  // freed the shares' decisions of their records (holes, which read as zeros), and the records' positions in
  // weight order are still there (the sums read them). The next task runs unit 0, which must not read past
  // its records into unit 1's freed ones.
  const std::string positions = stream::ordered_positions_path(prefix, true);
  setenv("LODSTREAM_TEST_KILL_AT", "merge-map-0.json", 1);
  const test::CliRun killed_in_map =
      test::run_cli(args({"simplify", sample_room(), "-o", dir.file("out"), "--work", work, "--shard", "1/3", "--cluster-shards", "3",
                          "--threads", "1"}),
                    log);
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(killed_in_map.exit_code, 128 + SIGKILL);
  EXPECT_GT(std::filesystem::file_size(positions), 0u) << "the positions in weight order are spent after the sums";
  uint64_t freed = 0;
  for (unsigned s = 0; s < 3; ++s) {
    const std::string dec = stream::cluster_share_decisions_path(prefix, s, 0);
    struct stat st {};
    ASSERT_EQ(::stat(dec.c_str(), &st), 0) << dec;
    freed += static_cast<uint64_t>(st.st_size) > static_cast<uint64_t>(st.st_blocks) * 512 ? uint64_t(st.st_size) - uint64_t(st.st_blocks) * 512 : 0;
  }
  EXPECT_GT(freed, 0u) << "map units 1 and 2's decisions are freed once stamped (a file system with holes: this machine's ext4)";
  setenv("LODSTREAM_TEST_KILL_AT", "merge-pairs-0.json", 1);
  const test::CliRun killed = task(0);
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(killed.exit_code, 128 + SIGKILL) << killed.err;
  const std::string spent = stream::cluster_shares_dir(prefix) + "spent.json";
  ASSERT_TRUE(std::filesystem::exists(spent));
  for (unsigned s = 0; s < 3; ++s) {
    const std::string dec = stream::cluster_share_decisions_path(prefix, s, 0);
    ASSERT_TRUE(std::filesystem::exists(dec)) << dec;
    EXPECT_EQ(std::filesystem::file_size(dec), 0u) << dec << " is spent";
    EXPECT_TRUE(std::filesystem::exists(stream::cluster_share_stamp(prefix, s))) << "share " << s << "'s stamp holds";
  }
  EXPECT_FALSE(std::filesystem::exists(stream::cluster_merge_dir(prefix) + "map/cells-0.u32")) << "the map units write no plain cells";
  EXPECT_EQ(std::filesystem::file_size(positions), 0u) << "the positions in weight order are spent before the pairs";

  std::filesystem::remove_all(stream::cluster_merge_dir(prefix));
  io::write_file_atomic(spent, "{\"key\": \"another build's merge\"}\n");
  // Killed again just before a cells-by-vertex unit's stamp: the stage is stamped, and the shares are gone
  // (the cells by vertex read the pairs).
  setenv("LODSTREAM_TEST_KILL_AT", "vertex-cells-0.json", 1);
  const test::CliRun killed_again = task(0);
  unsetenv("LODSTREAM_TEST_KILL_AT");
  EXPECT_EQ(killed_again.exit_code, 128 + SIGKILL);
  EXPECT_TRUE(std::filesystem::exists(work + "/cluster.json"));
  EXPECT_FALSE(std::filesystem::exists(stream::cluster_shares_dir(prefix)));
  EXPECT_FALSE(stream::vertex_pairs_paths(prefix, 0).empty()) << "the pairs stay for the cells by vertex";
  // The records' positions in weight order stay spent: emptied, named still by the grading stage's stamp,
  // which holds.
  const std::string grade_stamp = slurp(work + "/grade.json");
  ASSERT_TRUE(std::filesystem::exists(positions));
  EXPECT_EQ(std::filesystem::file_size(positions), 0u) << positions << " is spent";
  for (unsigned i = 0; i < 3; ++i) {
    const test::CliRun t = task(i);
    ASSERT_EQ(t.exit_code, 0) << t.err;
  }
  const test::CliRun m = test::run_cli({"merge", dir.file("out")}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  EXPECT_EQ(outputs(dir.file("out")), outputs(dir.file("one")));
  const nlohmann::json units = nlohmann::json::parse(slurp(work + "/cluster.json")).at("value").at("merge_units");
  EXPECT_EQ(units.at("pairs").at("seconds").size(), 3u) << "three pairs units";

  // Other levels on the same work directory: the grading stage is reused, and the clustering shares and the
  // merge's sums, finding the positions spent, read the store's column by id: one machine's bytes again.
  auto three_levels = [&](std::vector<std::string> a) {
    a.push_back("--levels"), a.push_back("3");
    return args(a);
  };
  const test::CliRun one3 = test::run_cli(three_levels({"simplify", sample_room(), "-o", dir.file("one3")}), log);
  ASSERT_EQ(one3.exit_code, 0) << one3.err;
  run_cli_tasks_and_merge(three_levels({"simplify", sample_room(), "-o", dir.file("out3"), "--work", work, "--cluster-shards", "3"}), 3,
                          dir.file("out3"), log);
  EXPECT_EQ(outputs(dir.file("out3")), outputs(dir.file("one3")));
  EXPECT_EQ(slurp(work + "/grade.json"), grade_stamp) << "the grading stage ran again";
  EXPECT_EQ(std::filesystem::file_size(positions), 0u);
}

// ---- report as N tasks (stream/report_shard.h)

ReportOptions small_report(const std::string& out) {
  ReportOptions ro;
  ro.output_dir = out;
  ro.views = 7;  // not a multiple of 3 or 4: tasks' shares differ in size
  ro.resolution = 48;
  ro.samples = 3001;
  ro.html_views = 2;
  return ro;
}

// Every file of a report directory but report.json, and report.json without its timings, performance
// counters and task list.
std::map<std::string, Bytes> report_files(const std::string& dir) {
  std::map<std::string, Bytes> f = outputs(dir);
  f.erase("report.json");
  nlohmann::json j = nlohmann::json::parse(slurp(dir + "/report.json"));
  for (const char* k : {"stages", "seconds", "peak_rss_bytes", "work_dir", "performance", "shards"}) j.erase(k);
  for (auto& run : j["runs"])
    for (auto& level : run["levels"]) level.erase("seconds");
  f["report.json"] = {j.dump(1)};
  return f;
}

// Runs report tasks `tasks` of `count` on `work` (then merge_report when `merge_after`), each with `base`'s
// options but its work directory.
Result run_report_tasks(ReportOptions ro, const std::string& work, unsigned count, const std::vector<unsigned>& tasks,
                        bool merge_after, Report* merged, const Options& base = {}) {
  for (unsigned i : tasks) {
    ro.shard_index = i, ro.shard_count = count;
    Options o = base;
    o.work_dir = work;
    o.check_disk_space = false;
    Report r;
    const Result res = report(ro, o, &r);
    if (!res.ok()) return res;
  }
  if (!merge_after) return {};
  return merge_report(ro.output_dir, Options{}, merged);
}

// All `count` report tasks into `output_dir`, then the merge.
Result all_report_tasks(ReportOptions ro, const std::string& output_dir, const std::string& work, unsigned count,
                        const Options& base = {}) {
  ro.output_dir = output_dir;
  std::vector<unsigned> all;
  for (unsigned i = 0; i < count; ++i) all.push_back(i);
  Report merged;
  return run_report_tasks(ro, work, count, all, true, &merged, base);
}

// A simplify output directory of the sample room (three levels), for the reports.
std::string room_levels(const TempDir& dir) {
  SimplifyOptions so;
  so.output_dir = dir.file("lods");
  so.levels = 3;
  SimplifyReport r;
  EXPECT_TRUE(simplify(sample_room(), so, shared_work(dir), &r).ok());
  return so.output_dir;
}

TEST(ReportShard, AnyTaskCountGivesOneMachinesReport) {
  TempDir dir;
  const std::string lods = room_levels(dir);
  ReportOptions ro = small_report(dir.file("one"));
  ro.runs = {lods};
  Report one;
  const Result r1 = report(ro, shared_work(dir), &one);
  ASSERT_TRUE(r1.ok()) << r1.message;
  const auto want = report_files(dir.file("one"));
  ASSERT_EQ(want.count("lod2.csv"), 1u);
  for (unsigned n : {1u, 3u, 4u}) {
    SCOPED_TRACE("tasks " + std::to_string(n));
    const std::string out = dir.file("sharded-" + std::to_string(n));
    const Result r = all_report_tasks(ro, out, dir.file("work"), n);
    ASSERT_TRUE(r.ok()) << r.message;
    EXPECT_EQ(report_files(out), want);
    EXPECT_FALSE(std::filesystem::exists(out + "/shards")) << "merge removes the shares";
    const nlohmann::json j = nlohmann::json::parse(slurp(out + "/report.json"));
    EXPECT_EQ(j["shards"]["count"], n);
    EXPECT_EQ(j["shards"]["tasks"].size(), n);
    // The tasks share the work by primitive ranges (every level has its distance): each traces its N-th of
    // the original, none all of it.
    const nlohmann::json one_json = nlohmann::json::parse(slurp(dir.file("one/report.json")));
    EXPECT_EQ(j["performance"]["original_primitives"], one_json["performance"]["original_primitives"])
        << "every primitive of the original is traced by exactly one task";
    const uint64_t whole = one_json["performance"]["original_primitives"];
    ASSERT_GT(whole, 0u);
    for (const auto& t : j["shards"]["tasks"]) {
      const uint64_t mine = t["original_primitives"];
      EXPECT_GE(mine, whole / n);
      EXPECT_LE(mine, whole / n + 1);
    }
  }
}

// An OBJ scene of boxes in two materials, polylines (`l`) and points (`p`) among them: a report's
// original with lines and points of its own, drawn one pixel wide, and with colours.
std::string lines_and_points_scene(const TempDir& dir) {
  std::string mtl = "newmtl red\nKd 0.9 0.1 0.1\nnewmtl blue\nKd 0.1 0.2 0.9\n", obj = "mtllib scene.mtl\n";
  uint64_t v = 0;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      const double x = i * 1.5, y = j * 1.5, h = 0.5 + 0.25 * ((i * 7 + j * 3) % 5);
      obj += fmt::format("o box{}_{}\nusemtl {}\n", i, j, (i + j) % 2 ? "red" : "blue");
      for (int c = 0; c < 8; ++c)
        obj += fmt::format("v {} {} {}\n", x + (c & 1), y + (c >> 1 & 1), c >> 2 ? h : 0.0);
      const int f[6][4] = {{1, 3, 4, 2}, {5, 6, 8, 7}, {1, 2, 6, 5}, {3, 7, 8, 4}, {1, 5, 7, 3}, {2, 4, 8, 6}};
      for (const auto& q : f) obj += fmt::format("f {} {} {} {}\n", v + q[0], v + q[1], v + q[2], v + q[3]);
      v += 8;
    }
  obj += "o wires\nusemtl red\n";
  for (int r = 0; r < 5; ++r) {
    for (int k = 0; k < 12; ++k) obj += fmt::format("v {} {} {}\n", 0.2 + 0.75 * k, 1.25 + 1.5 * r, 0.05 + 0.3 * (k % 3));
    obj += "l";
    for (int k = 1; k <= 12; ++k) obj += fmt::format(" {}", v + k);
    obj += "\n";
    v += 12;
  }
  obj += "o marks\nusemtl blue\n";
  for (int k = 0; k < 9; ++k) obj += fmt::format("v {} {} 1.6\np {}\n", 1.25 + k, 0.6 + 0.9 * k, ++v);
  const std::string path = dir.file("scene.obj");
  std::ofstream(dir.file("scene.mtl")) << mtl;
  std::ofstream(path) << obj;
  return path;
}

// Tasks by primitive ranges where ranges cut chunks of both the original and the finest level (a tiny
// --chunk-bytes), an original with lines, points and materials, 3 × 3 rays a pixel, and more tasks than a
// coarse level has primitives (empty ranges): the tasks' images composited and distances lowered give one
// machine's report, byte for byte, and one machine's own chunked report.
TEST(ReportShard, PrimitiveRangesThroughChunksLinesAndColoursGiveOneMachinesReport) {
  TempDir dir;
  SimplifyOptions so;
  so.output_dir = dir.file("lods");
  so.levels = 3;
  SimplifyReport sr;
  const Result s = simplify(lines_and_points_scene(dir), so, shared_work(dir), &sr);
  ASSERT_TRUE(s.ok()) << s.message;
  ASSERT_GT(sr.levels.size(), 2u);
  ReportOptions ro = small_report(dir.file("one"));
  ro.runs = {so.output_dir};
  ro.resolution = 64;
  Report one;
  Result r = report(ro, shared_work(dir), &one);
  ASSERT_TRUE(r.ok()) << r.message;
  Options chunked = shared_work(dir);
  chunked.chunk_bytes = 8 << 10;
  ReportOptions rc = ro;
  rc.output_dir = dir.file("one-chunked");
  Report one_chunked;
  r = report(rc, chunked, &one_chunked);
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_GE(one_chunked.original_chunks, 3u);
  EXPECT_GE(one_chunked.level_chunks, 2u);
  const auto want = report_files(dir.file("one"));
  EXPECT_EQ(report_files(rc.output_dir), want) << "one machine's chunks change nothing";
  const nlohmann::json levels = nlohmann::json::parse(slurp(dir.file("one/report.json")))["runs"][0]["levels"];
  EXPECT_LT(levels.back()["triangles"].get<uint64_t>() + levels.back()["edges"].get<uint64_t>() + levels.back()["points"].get<uint64_t>(),
            40u) << "a coarse level of fewer primitives than tasks";
  for (unsigned n : {2u, 5u, 40u}) {
    SCOPED_TRACE("tasks " + std::to_string(n));
    const std::string out = dir.file("ranges-" + std::to_string(n));
    r = all_report_tasks(ro, out, dir.file("work"), n, chunked);
    ASSERT_TRUE(r.ok()) << r.message;
    EXPECT_EQ(report_files(out), want);
  }
}

// An original's samples drawn as units by three processes at once (threads: the units' locks are flock
// locks on their own open files, which exclude each other within one process too), as 3 and as 7 units,
// and by one process as 2 units after one process's draw, give one process's samples and view targets bit
// for bit; a second draw on the same directory reuses the units' files. The room has 4 blocks of
// primitives: 7 units are 4 (a unit of at least one block each).
TEST(ReportShard, SamplesDrawnAsUnitsByProcessesAtOnceAreOneProcesssSamples) {
  TempDir dir;
  ReportOptions ro = small_report(dir.file("one"));
  ro.original = sample_room();
  ro.lods = {sample_room()};
  ro.switch_distances = {10};
  Report one;
  ASSERT_TRUE(report(ro, shared_work(dir), &one).ok()) << "ingests the room into work/store";
  stream::StoreMeta meta;
  ASSERT_TRUE(stream::read_store_meta(dir.file("work/store"), &meta));
  ASSERT_GT(meta.primitives(), 3u << 16);
  const stream::SampleOptions so{20011, 7, 9};
  stream::Progress progress(Options{});
  stream::StoreChunks chunks(dir.file("work/store"), meta);
  chunks.plan(stream::kChunkSceneCosts, 1 << 20);
  ASSERT_GT(chunks.chunks().size(), 3u);
  const stream::OriginalSamples want = stream::draw_original_samples(dir.file("work/store"), meta, so, chunks, progress);
  ASSERT_EQ(want.xyz.size(), 3u * (20011 * 2 + std::min<uint64_t>(20011, chunks.used_vertices())));
  ASSERT_EQ(want.faces, 20011u);
  ASSERT_EQ(want.targets.size(), 27u);
  for (unsigned units : {3u, 7u}) {
    SCOPED_TRACE(std::to_string(units) + " units");
    const std::string units_dir = dir.file("units-" + std::to_string(units));
    std::vector<stream::OriginalSamples> got(3);
    std::vector<std::string> errors(3);
    std::vector<std::thread> processes;
    for (unsigned i = 0; i < 3; ++i)
      processes.emplace_back([&, i] {
        try {
          stream::Progress p(Options{});
          got[i] = stream::draw_original_samples_in_units(dir.file("work/store"), meta, so, units_dir, units, i, 256 << 10, p);
        } catch (const std::exception& e) {
          errors[i] = e.what();
        }
      });
    for (std::thread& t : processes) t.join();
    for (unsigned i = 0; i < 3; ++i) {
      EXPECT_EQ(errors[i], "");
      EXPECT_EQ(got[i].xyz, want.xyz) << "process " << i;
      EXPECT_EQ(got[i].faces, want.faces);
      EXPECT_EQ(got[i].targets, want.targets);
    }
    const stream::OriginalSamples again =
        stream::draw_original_samples_in_units(dir.file("work/store"), meta, so, units_dir, units, 0, 256 << 10, progress);
    EXPECT_EQ(again.xyz, want.xyz) << "the units' files reused";
    EXPECT_FALSE(std::filesystem::exists(units_dir + "/measure/measure-0.used")) << "the used vertices' bits go once the vertex samples are drawn";
  }
  const stream::OriginalSamples two =
      stream::draw_original_samples_in_units(dir.file("work/store"), meta, so, dir.file("units-2"), 2, 1, 64 << 10, progress);
  EXPECT_EQ(two.xyz, want.xyz);
  EXPECT_EQ(two.targets, want.targets);
}

// The same on the grid store (1.02 M primitives: 16 blocks; 360 K vertices: the vertex samples' bits
// read in two slices, their positions in two blocks of ids), with segments and points: 5 units by three
// processes at once are one process's samples bit for bit.
TEST(ReportShard, SamplesOfAGridWithSegmentsDrawnAsUnitsAreOneProcesssSamples) {
  TempDir dir;
  const std::string store = dir.file("store");
  const stream::StoreMeta meta = grid_store(store);
  const stream::SampleOptions so{50000, 3, 12};
  stream::Progress progress(Options{});
  stream::StoreChunks chunks(store, meta);
  chunks.plan(stream::kChunkSceneCosts, 8 << 20);
  const stream::OriginalSamples want = stream::draw_original_samples(store, meta, so, chunks, progress);
  ASSERT_EQ(want.xyz.size(), 3u * 150000);
  std::vector<stream::OriginalSamples> got(3);
  std::vector<std::thread> processes;
  for (unsigned i = 0; i < 3; ++i)
    processes.emplace_back([&, i] {
      stream::Progress p(Options{});
      got[i] = stream::draw_original_samples_in_units(store, meta, so, dir.file("units"), 5, i, 4 << 20, p);
    });
  for (std::thread& t : processes) t.join();
  for (unsigned i = 0; i < 3; ++i) {
    EXPECT_EQ(got[i].xyz, want.xyz) << "process " << i;
    EXPECT_EQ(got[i].targets, want.targets) << "process " << i;
  }
  // Vertex positions read by runs of sorted ids match the ones read one id at a time.
  std::vector<uint32_t> ids;
  for (uint32_t v = 3; v < meta.vertices; v += 977) ids.push_back(v);
  EXPECT_EQ(chunks.positions_of_sorted(ids), chunks.positions_of(ids));
}

// Ingest by byte ranges for a report of two runs with different originals (a binary PLY and an OBJ): every
// original's ranges go to their own segments, the first task joins them, and the report is one machine's.
TEST(ReportShard, OriginalsIngestedByByteRangesGiveOneMachinesReport) {
  TempDir dir;
  const std::string room = room_levels(dir);
  SimplifyOptions so;
  so.output_dir = dir.file("table-lods");
  so.levels = 2;
  SimplifyReport sr;
  ASSERT_TRUE(simplify(test::source_dir() + "/tests/data/small/bedsideTable2.obj", so, shared_work(dir), &sr).ok());
  ReportOptions ro = small_report(dir.file("one"));
  ro.runs = {room, so.output_dir};
  Report one;
  const Result r1 = report(ro, shared_work(dir), &one);
  ASSERT_TRUE(r1.ok()) << r1.message;
  // A fresh work directory, so that the tasks' stores come from the ranges.
  const std::string work = dir.file("ranges-work");
  Options o;
  o.work_dir = work;
  o.check_disk_space = false;
  ReportOptions rn = ro;
  rn.output_dir = dir.file("sharded");
  for (unsigned i = 0; i < 3; ++i) {
    rn.ingest_index = i, rn.ingest_count = 3;
    Report rr;
    const Result r = report(rn, o, &rr);
    ASSERT_TRUE(r.ok()) << r.message;
    ASSERT_EQ(rr.stages.size(), 1u);
    EXPECT_EQ(rr.stages[0].name, "ingest-range");
  }
  for (const char* d : {"/ingest-ranges/range-2-of-3.seg", "/ingest-ranges-1/range-2-of-3.seg"})
    EXPECT_TRUE(std::filesystem::exists(work + d)) << d;
  EXPECT_FALSE(std::filesystem::exists(work + "/store/store.json")) << "a range task builds no store";
  rn.ingest_count = 0;
  Report merged;
  const Result r = run_report_tasks(rn, work, 3, {0, 1, 2}, true, &merged);
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_EQ(report_files(rn.output_dir), report_files(dir.file("one")));
  EXPECT_FALSE(std::filesystem::exists(work + "/ingest-ranges/range-2-of-3.seg")) << "the join removes the segments";
  // A range task needs the shared directory and an index below the count.
  rn.ingest_index = 3, rn.ingest_count = 3;
  Report bad;
  EXPECT_EQ(report(rn, o, &bad).status, Status::usage);
  rn.ingest_index = 0;
  EXPECT_EQ(report(rn, Options{}, &bad).status, Status::usage);
}

// Levels given as files without switching distances: their distance comes from the whole Hausdorff max,
// which every task measures (keeping its share); a small budget cuts the original into several chunks.
TEST(ReportShard, LevelsWithoutDistancesAndChunksGiveOneMachinesReport) {
  TempDir dir;
  const std::string lods = room_levels(dir);
  ReportOptions ro = small_report(dir.file("one"));
  ro.original = sample_room();
  ro.lods = {lods + "/lod1.ply", lods + "/lod2.ply"};
  Options o = shared_work(dir);
  o.chunk_bytes = 1 << 20;
  Report one;
  ASSERT_TRUE(report(ro, o, &one).ok());
  ASSERT_GE(one.original_chunks, 2u);
  ReportOptions rn = ro;
  rn.output_dir = dir.file("sharded");
  Report merged;
  const Result r = run_report_tasks(rn, dir.file("work"), 3, {0, 1, 2}, true, &merged);
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_EQ(report_files(rn.output_dir), report_files(dir.file("one")));
}

TEST(ReportShard, MergeNamesTheMissingTasksAndATaskRerunResumes) {
  TempDir dir;
  const std::string lods = room_levels(dir);
  ReportOptions ro = small_report(dir.file("out"));
  ro.runs = {lods};
  Report merged;
  Result r = run_report_tasks(ro, dir.file("work"), 4, {0, 2}, true, &merged);
  EXPECT_EQ(r.status, Status::no_input);
  EXPECT_NE(r.message.find("report tasks 1, 3 of 4 have not finished"), std::string::npos) << r.message;
  EXPECT_FALSE(std::filesystem::exists(dir.file("out/report.json")));
  ro.shard_count = 2;
  EXPECT_EQ(report(ro, Options{}, &merged).status, Status::usage) << "a task needs --work";
  // The missing tasks alone, then the merge: complete, and through the CLI's merge, which tells a report's
  // shares from a simplify's parts.
  r = run_report_tasks(ro, dir.file("work"), 4, {1, 3}, false, &merged);
  ASSERT_TRUE(r.ok()) << r.message;
  TempDir log;
  const test::CliRun m = test::run_cli({"merge", dir.file("out"), "--progress", "none"}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  ro.output_dir = dir.file("one");
  ro.shard_count = 0;
  ASSERT_TRUE(report(ro, Options{}, &merged).ok());
  EXPECT_EQ(report_files(dir.file("out")), report_files(dir.file("one")));
}

// Through the CLI, the task index from the environment as Slurm gives it.
TEST(ReportShard, ShardFromEnvironmentThroughTheCli) {
  TempDir dir, log;
  const std::string lods = room_levels(dir);
  const std::vector<std::string> common{"--views", "5", "--resolution", "40", "--samples", "2000", "--no-space-check", "--progress", "none"};
  auto args = [&](std::vector<std::string> a) {
    a.insert(a.end(), common.begin(), common.end());
    return a;
  };
  ASSERT_EQ(test::run_cli(args({"report", lods, "-o", dir.file("one")}), log).exit_code, 0);
  ASSERT_EQ(test::run_cli(args({"report", lods, "-o", dir.file("out"), "--work", dir.file("work"), "--shard-prepare"}), log).exit_code, 0);
  setenv("SLURM_ARRAY_TASK_COUNT", "2", 1);
  for (const char* i : {"1", "0"}) {
    setenv("SLURM_ARRAY_TASK_ID", i, 1);
    const test::CliRun t = test::run_cli(args({"report", lods, "-o", dir.file("out"), "--work", dir.file("work"), "--shard-from-env"}), log);
    EXPECT_EQ(t.exit_code, 0) << t.err;
    EXPECT_NE(t.out.find("(reused from work directory)"), std::string::npos) << "the prepared store is reused";
  }
  unsetenv("SLURM_ARRAY_TASK_ID");
  unsetenv("SLURM_ARRAY_TASK_COUNT");
  const test::CliRun m = test::run_cli({"merge", dir.file("out"), "--progress", "none"}, log);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  EXPECT_EQ(report_files(dir.file("out")), report_files(dir.file("one")));
  const test::CliRun bad = test::run_cli(args({"report", lods, "-o", dir.file("bad"), "--work", dir.file("work"), "--shard", "2/2"}), log);
  EXPECT_EQ(bad.exit_code, 64);
}

// The grid a task tests block boxes against is conservative: a box near a marked one reaches it, one far
// away does not, and a coordinate outside the cube or NaN widens to the border rather than being lost.
TEST(BlockBounds, ReachGridMarksConservatively) {
  core::SceneCube cube;
  cube.min[0] = cube.min[1] = cube.min[2] = 0, cube.side = stream::ReachGrid::kSide;  // one unit a voxel
  stream::ReachGrid g(cube);
  const double lo[3] = {10.2, 10.2, 10.2}, hi[3] = {11.8, 11.8, 11.8};
  g.mark(lo, hi);
  g.finish();
  auto reaches = [&](double x0, double y0, double z0, double x1, double y1, double z1) {
    const double a[3] = {x0, y0, z0}, b[3] = {x1, y1, z1};
    return g.reaches(a, b);
  };
  EXPECT_TRUE(reaches(11, 11, 11, 11, 11, 11));           // inside
  EXPECT_TRUE(reaches(12.9, 12.9, 12.9, 13, 13, 13));     // in the voxel next to a marked one
  EXPECT_FALSE(reaches(13.1, 11, 11, 13.5, 11, 11));      // one voxel farther
  EXPECT_TRUE(reaches(11.8, 11.8, 11.8, 11.8, 11.8, 11.8)); // the marked box's corner, a point
  EXPECT_TRUE(reaches(0, 0, 0, 63, 63, 63));              // a box around it
  EXPECT_FALSE(reaches(30, 30, 30, 40, 40, 40));          // far away
  EXPECT_FALSE(reaches(10, 30, 10, 11, 31, 11));          // far on one axis
  EXPECT_TRUE(reaches(-100, -100, -100, 10, 10, 10));     // outside the cube: its border voxel on
  EXPECT_FALSE(reaches(1e9, 1e9, 1e9, 2e9, 2e9, 2e9));    // beyond the cube's far corner: its last voxel
  const double nan = std::nan("");
  EXPECT_TRUE(reaches(nan, 11, 11, nan, 11, 11));         // NaN: the whole axis
  stream::ReachGrid empty(cube);
  empty.finish();
  EXPECT_FALSE(empty.reaches(lo, hi));
}

}  // namespace
}  // namespace lodstream

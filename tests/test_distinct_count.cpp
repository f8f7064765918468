#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>

#include "core/status.h"
#include "io/file_writer.h"
#include "stream/distinct_count.h"
#include "stream/weld_file.h"
#include "stream/work_dir.h"
#include "test_util.h"

namespace lodstream {
namespace {

template <class T>
void check(uint64_t n) {
  test::TempDir tmp;
  std::mt19937 rng(11);
  std::vector<T> xyz;
  std::set<std::array<T, 3>> expect;
  for (uint64_t i = 0; i < n; ++i) {
    // Few distinct values per axis, so there are many duplicates; some -0 that must equal +0.
    std::array<T, 3> p{static_cast<T>(rng() % 40) / 4, static_cast<T>(rng() % 30), rng() % 17 == 0 ? T(-0.0) : T(rng() % 5)};
    xyz.insert(xyz.end(), p.begin(), p.end());
    for (T& v : p) v = v == 0 ? T(0) : v;
    expect.insert(p);
  }
  const std::string path = tmp.file("positions");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(xyz.data()), static_cast<std::streamsize>(xyz.size() * sizeof(T)));
  stream::Progress progress{Options{}};
  const bool single = sizeof(T) == 4;
  EXPECT_EQ(stream::count_distinct_positions(path, n, single, 1 << 30, progress), expect.size());
  // A budget that forces several partitions gives the same count.
  EXPECT_EQ(stream::count_distinct_positions(path, n, single, 1 << 20, progress), expect.size());
}

TEST(DistinctCount, FloatKeysInMemoryAndPartitioned) { check<float>(200000); }
TEST(DistinctCount, DoubleKeysInMemoryAndPartitioned) { check<double>(200000); }

// Positions where about half the vertices repeat an earlier one (a few with -0 for +0), for the weld.
template <class T>
std::vector<T> positions_with_repeats(uint64_t n) {
  std::mt19937_64 rng(7);
  std::vector<T> xyz;
  xyz.reserve(3 * n);
  for (uint64_t i = 0; i < n; ++i) {
    if (i > 0 && rng() % 2 == 0) {
      const uint64_t j = rng() % i;
      for (int a = 0; a < 3; ++a) xyz.push_back(xyz[3 * j + a]);
      if (rng() % 9 == 0)
        for (int a = 0; a < 3; ++a) xyz[3 * i + a] = xyz[3 * i + a] == 0 ? T(-0.0) : xyz[3 * i + a];
    } else {
      for (int a = 0; a < 3; ++a) xyz.push_back(rng() % 5 == 0 ? T(0) : static_cast<T>(rng() % (1 << 20)) / 64);
    }
  }
  return xyz;
}

// canonical[v]: the smallest id at v's exact position (-0 = +0), by sorting the ids by position.
template <class T>
std::vector<uint32_t> canonical_by_sorting(const std::vector<T>& xyz) {
  const uint64_t n = xyz.size() / 3;
  struct Entry {
    std::array<T, 3> key;
    uint32_t id;
  };
  std::vector<Entry> order(n);
  for (uint32_t v = 0; v < n; ++v) {
    order[v].id = v;
    for (int a = 0; a < 3; ++a) order[v].key[a] = xyz[3 * v + a] == 0 ? T(0) : xyz[3 * v + a];
  }
  std::sort(order.begin(), order.end(), [](const Entry& a, const Entry& b) { return a.key != b.key ? a.key < b.key : a.id < b.id; });
  std::vector<uint32_t> canonical(n);
  for (uint64_t i = 0; i < n; ++i)
    canonical[order[i].id] = i > 0 && order[i].key == order[i - 1].key ? canonical[order[i - 1].id] : order[i].id;
  return canonical;
}

// The weld (weld_positions) writes the map of the smallest id at each position, the same bytes in one batch
// with no spill as in many batches, sub-buckets and sort runs, and as 1, 3 or 7 units whose runs are
// written into one map (weld_unit, write_weld_map, or the map's own units in place: write_weld_map_unit);
// it refuses a budget below its floor.
template <class T>
void check_weld(const std::vector<T>& xyz) {
  test::TempDir tmp;
  const uint64_t n = xyz.size() / 3;
  const std::vector<uint32_t> expect = canonical_by_sorting(xyz);
  const std::string path = tmp.file("positions");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(xyz.data()), static_cast<std::streamsize>(xyz.size() * sizeof(T)));
  stream::Progress progress{Options{}};
  stream::WorkDir work(tmp.file("work"));
  const bool single = sizeof(T) == 4;
  uint64_t distinct = 0;
  for (uint32_t v = 0; v < n; ++v) distinct += expect[v] == v;
  const uint64_t floor = stream::weld_memory_floor(n, single);
  std::string first_bytes;
  for (uint64_t memory : {uint64_t{1} << 30, floor}) {
    const std::string map = tmp.file("weld-" + std::to_string(memory));
    ASSERT_EQ(stream::weld_positions(path, n, single, memory, work, progress, map), distinct) << memory;
    std::vector<uint32_t> got(n);
    for (uint32_t v = 0; v < n; ++v) got[v] = v;
    stream::WeldFile(map, n).for_each_welded([&](uint64_t v, uint32_t c) { got[v] = c; });
    ASSERT_EQ(got, expect) << memory;
    const std::string bytes = io::read_small_file(map);
    if (first_bytes.empty()) first_bytes = bytes;
    EXPECT_EQ(bytes, first_bytes) << memory;
  }
  // As units (one process each; at twice the floor: a few batches each), their runs written into one map:
  // the same bytes.
  // The first unit counts the bucket sizes and leaves them for the others (a file of another column, or
  // a damaged one, is counted again: the 7 units start from a garbage file).
  for (unsigned units : {1u, 3u, 7u}) {
    std::vector<std::pair<std::string, uint64_t>> runs;
    uint64_t unit_distinct = 0, welded = 0;
    const std::string sizes = tmp.file("sizes-" + std::to_string(units));
    if (units == 7) std::ofstream(sizes) << std::string(24 + 8 * 256 * ((n + (1 << 20) - 1) >> 20), 'x');
    for (unsigned u = 0; u < units; ++u) {
      const std::string run = tmp.file("unit-" + std::to_string(units) + "-" + std::to_string(u));
      const stream::WeldUnitResult r = stream::weld_unit(path, n, single, 2 * floor, work, progress, u, units, run, sizes);
      EXPECT_TRUE(std::filesystem::exists(sizes));
      EXPECT_EQ(std::filesystem::file_size(run), 8 * r.welded);
      runs.emplace_back(run, r.welded);
      unit_distinct += r.distinct, welded += r.welded;
    }
    EXPECT_EQ(unit_distinct, distinct) << units;
    EXPECT_EQ(welded, n - distinct) << units;
    const std::string map = tmp.file("units-" + std::to_string(units));
    stream::write_weld_map(runs, n, 2 * floor, work, map);
    EXPECT_EQ(io::read_small_file(map), first_bytes) << units << " units";
    // The map itself as units (write_weld_map_unit), in reverse order, into one file started beforehand:
    // the same bytes, with 2 and 5 map units (word ranges cut unevenly against the runs' buckets).
    for (unsigned map_units : {2u, 5u}) {
      const std::string in_place = tmp.file("map-units-" + std::to_string(units) + "-" + std::to_string(map_units));
      stream::start_weld_map(in_place, n, welded);
      for (unsigned k = map_units; k-- > 0;) stream::write_weld_map_unit(runs, n, 2 * floor, work, in_place, k, map_units);
      EXPECT_EQ(io::read_small_file(in_place), first_bytes) << units << " units, " << map_units << " map units";
    }
  }
  try {
    stream::weld_positions(path, n, single, floor - 1, work, progress, tmp.file("refused"));
    ADD_FAILURE() << "a budget below the floor was accepted";
  } catch (const Failure& e) {
    EXPECT_EQ(e.status(), Status::usage);
    EXPECT_NE(std::string(e.what()).find("welding " + std::to_string(n) + " stored vertices needs at least"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(tmp.file("refused")));
}

// 3 M floats: buckets of about 12 K keys, so sub-buckets; 1.5 M welded pairs, more than the floor's
// sort buffer holds, so runs spill.
TEST(Weld, FloatPositionsInOneBatchAndInManyGiveTheSameMap) { check_weld(positions_with_repeats<float>(3'000'000)); }
TEST(Weld, DoublePositionsInOneBatchAndInManyGiveTheSameMap) { check_weld(positions_with_repeats<double>(600'000)); }

// Five positions, two of them repeated: most of 3 or 7 units hold no key at all.
TEST(Weld, AFewPositionsLeaveUnitsEmpty) {
  check_weld(std::vector<float>{0, 0, 0, 1, 2, 3, -0.0f, 0, 0, 4, 5, 6, 1, 2, 3});
}

// 5.12 M distinct positions (about 20 K a bucket) and 20 K copies of one more, scattered among them: the
// copies' bucket holds about 40 K keys, so its sub-bucket with the copies holds about 22 K keys of which
// some 2.5 K distinct, more than the 1 K its table starts with, so the table grows twice (its keys placed
// again each time).
TEST(Weld, ManyCopiesOfOnePositionGrowTheirSubBucketsTable) {
  std::mt19937_64 rng(5);
  std::vector<float> xyz;
  constexpr uint64_t kDistinct = 5'120'000, kCopies = 20'000;
  xyz.reserve(3 * (kDistinct + kCopies));
  for (uint64_t i = 0; i < kDistinct + kCopies; ++i) {
    if (rng() % ((kDistinct + kCopies) / kCopies) == 0) {
      xyz.insert(xyz.end(), {1.0f, 2.0f, 3.0f});
    } else {
      for (int a = 0; a < 3; ++a) xyz.push_back(static_cast<float>(rng() % (1 << 22)) / 64 + 100);
    }
  }
  check_weld(xyz);
}

// A store whose positions are all distinct gets no map.
TEST(Weld, DistinctPositionsWriteNoMap) {
  test::TempDir tmp;
  std::vector<float> xyz;
  for (int i = 0; i < 3000; ++i) xyz.insert(xyz.end(), {static_cast<float>(i), 1.0f, 2.0f});
  const std::string path = tmp.file("positions");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(xyz.data()), static_cast<std::streamsize>(xyz.size() * sizeof(float)));
  stream::Progress progress{Options{}};
  stream::WorkDir work(tmp.file("work"));
  EXPECT_EQ(stream::weld_positions(path, 3000, true, 1 << 30, work, progress, tmp.file("map")), 3000u);
  EXPECT_FALSE(std::filesystem::exists(tmp.file("map")));
}

// The compact weld map (stream/weld_file.h) gives back every canonical id, by lookup and in order, for
// vertex counts on and off a word boundary, and refuses a file of another store.
// The map from weld units' runs refuses a run that names a vertex past the store's (a damaged or foreign
// run) with an I/O error and leaves no map, not even a partial one; a sound run gives the map its pairs say.
TEST(Weld, MapFromRunsRefusesAnIdPastTheStore) {
  test::TempDir tmp;
  stream::WorkDir work(tmp.file("work"));
  auto run_of = [&](const std::string& name, std::vector<uint64_t> pairs) {
    const std::string path = tmp.file(name);
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(pairs.data()), static_cast<std::streamsize>(8 * pairs.size()));
    return std::vector<std::pair<std::string, uint64_t>>{{path, pairs.size()}};
  };
  const std::string map = tmp.file("weld.map");
  try {
    stream::write_weld_map(run_of("bad", {uint64_t{5} << 32 | 1, uint64_t{12} << 32 | 2}), 10, 64 << 20, work, map);
    ADD_FAILURE() << "a run with vertex 12 of 10 was accepted";
  } catch (const Failure& e) {
    EXPECT_EQ(e.status(), Status::io_error);
    EXPECT_NE(std::string(e.what()).find("not a weld unit's run"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(map));
  EXPECT_FALSE(std::filesystem::exists(map + ".partial"));
  stream::write_weld_map(run_of("good", {uint64_t{5} << 32 | 1, uint64_t{9} << 32 | 2}), 10, 64 << 20, work, map);
  stream::WeldFile f(map, 10);
  f.acquire();
  for (uint32_t v = 0; v < 10; ++v) EXPECT_EQ(f(v), v == 5 ? 1u : v == 9 ? 2u : v) << v;
}

TEST(WeldFile, LookupsAndTheOrderedVisitGiveEveryCanonicalId) {
  test::TempDir tmp;
  std::mt19937_64 rng(3);
  for (uint32_t n : {0u, 1u, 64u, 65u, 200'003u}) {
    std::vector<uint32_t> canonical(n);
    for (uint32_t v = 0; v < n; ++v) canonical[v] = v > 0 && rng() % 3 == 0 ? static_cast<uint32_t>(rng() % v) : v;
    const std::string path = tmp.file("weld" + std::to_string(n));
    stream::write_weld_file(path, canonical);
    stream::WeldFile weld(path, n);
    weld.acquire();
    for (uint32_t v = 0; v < n; ++v) ASSERT_EQ(weld(v), canonical[v]) << v;
    std::vector<uint32_t> visited(canonical.size());
    for (uint32_t v = 0; v < n; ++v) visited[v] = v;
    uint64_t last = 0, count = 0;
    weld.for_each_welded([&](uint64_t v, uint32_t c) {
      EXPECT_TRUE(count == 0 || v > last);
      last = v, ++count;
      visited[v] = c;
    });
    EXPECT_EQ(visited, canonical);
    EXPECT_THROW(stream::WeldFile(path, n + 1), Failure);
  }
}

}  // namespace
}  // namespace lodstream

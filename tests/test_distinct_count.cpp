#include <gtest/gtest.h>

#include <array>
#include <fstream>
#include <random>
#include <set>

#include "core/status.h"
#include "io/file_writer.h"
#include "stream/distinct_count.h"
#include "stream/weld_file.h"
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

// The compact weld map (stream/weld_file.h) gives back every canonical id, by lookup and in order, for
// vertex counts on and off a word boundary, and refuses a file of another store.
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

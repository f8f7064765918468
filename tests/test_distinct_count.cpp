#include <gtest/gtest.h>

#include <array>
#include <fstream>
#include <random>
#include <set>

#include "stream/distinct_count.h"
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

}  // namespace
}  // namespace lodstream

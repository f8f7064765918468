#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>
#include <vector>

#include "stream/external_sort.h"
#include "test_util.h"

namespace lodstream {
namespace {

struct Rec {
  uint32_t key;
  uint32_t id;
};
struct RecLess {
  bool operator()(const Rec& a, const Rec& b) const { return a.key != b.key ? a.key > b.key : a.id < b.id; }
};

std::vector<Rec> sorted_with_budget(const std::vector<Rec>& in, uint64_t bytes, size_t* runs) {
  test::TempDir tmp;
  stream::WorkDir work(tmp.path().string());
  stream::ExternalSorter<Rec, RecLess> sorter(work, "t", bytes);
  for (const Rec& r : in) sorter.push(r);
  *runs = sorter.runs();
  std::vector<Rec> out;
  sorter.merge([&](const Rec& r) { out.push_back(r); });
  // Every run file is gone once merged.
  for (const auto& e : std::filesystem::directory_iterator(tmp.path())) ADD_FAILURE() << "left behind: " << e.path();
  return out;
}

TEST(ExternalSort, SameOrderInMemoryAndSpilledWithTies) {
  std::mt19937 rng(7);
  std::vector<Rec> in(100000);
  for (uint32_t i = 0; i < in.size(); ++i) in[i] = {static_cast<uint32_t>(rng() % 1000), i};  // many ties
  std::vector<Rec> expect = in;
  std::sort(expect.begin(), expect.end(), RecLess{});

  size_t runs_big = 0, runs_small = 0;
  const auto big = sorted_with_budget(in, 64 << 20, &runs_big);
  const auto small = sorted_with_budget(in, 8192, &runs_small);  // 1024-record minimum -> ~98 runs
  EXPECT_EQ(runs_big, 0u);
  EXPECT_GT(runs_small, 50u);
  ASSERT_EQ(big.size(), expect.size());
  ASSERT_EQ(small.size(), expect.size());
  for (size_t i = 0; i < expect.size(); ++i) {
    ASSERT_EQ(big[i].key, expect[i].key);
    ASSERT_EQ(big[i].id, expect[i].id);
    ASSERT_EQ(small[i].key, expect[i].key);
    ASSERT_EQ(small[i].id, expect[i].id);
  }
}

// expect() cuts the first run short so that the last, merged from memory, is a full buffer: fewer records
// written, the same order. 2500 records with room for 1024: runs of 452 and 1024 written (1476) and 1024
// kept, where without the hint 1024 + 1024 are written and 452 kept. Also with a total that is not exact
// (an upper bound) and with a hint below the total.
TEST(ExternalSort, ExpectKeepsTheLastRunFull) {
  std::mt19937 rng(11);
  std::vector<Rec> in(2500);
  for (uint32_t i = 0; i < in.size(); ++i) in[i] = {static_cast<uint32_t>(rng() % 50), i};
  std::vector<Rec> expect = in;
  std::sort(expect.begin(), expect.end(), RecLess{});
  for (uint64_t hint : {0ull, 2500ull, 2600ull, 1500ull}) {
    test::TempDir tmp;
    stream::WorkDir work(tmp.path().string());
    stream::ExternalSorter<Rec, RecLess> sorter(work, "t", 1024 * sizeof(Rec));
    if (hint) sorter.expect(hint);
    for (const Rec& r : in) sorter.push(r);
    const uint64_t spilled = hint == 0 ? 2048u : hint == 2500 ? 1476u : hint == 2600 ? 552u + 1024u : 476u + 1024u;
    EXPECT_EQ(sorter.spilled_records(), spilled) << hint;  // 2600 % 1024 = 552 first; 1500 % 1024 = 476
    std::vector<Rec> out;
    sorter.merge([&](const Rec& r) { out.push_back(r); });
    ASSERT_EQ(out.size(), expect.size()) << hint;
    for (size_t i = 0; i < expect.size(); ++i) {
      ASSERT_EQ(out[i].key, expect[i].key) << hint;
      ASSERT_EQ(out[i].id, expect[i].id) << hint;
    }
  }
}

TEST(ExternalSort, Empty) {
  size_t runs = 0;
  EXPECT_TRUE(sorted_with_budget({}, 1 << 20, &runs).empty());
}

}  // namespace
}  // namespace lodstream

// The cluster stage (stream/cluster_stage.h): its cell records are the plain sums over each cell's vertices
// in weight order, to the bit, whether the sums pass makes them in one range of cells or in many; and the
// stage stops with a usage error, naming the cells, when its clusterers outgrow the memory it is given.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <tbb/task_arena.h>

#include "core/floating_cell.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "lodstream/lodstream.h"
#include "stream/cluster_stage.h"
#include "stream/grade_stage.h"
#include "stream/progress.h"
#include "stream/work_dir.h"
#include "test_util.h"

namespace lodstream {
namespace {

// A weight index of n float records on a jittered lattice of spacing 1, in decreasing grade.
std::vector<stream::WeightRecord32> make_index(uint32_t n, const std::string& path) {
  std::vector<stream::WeightRecord32> records(n);
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  std::vector<uint32_t> order(n);
  for (uint32_t i = 0; i < n; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);  // weight order is spatially random
  const uint32_t side = 100;
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t v = order[i];
    records[i].grade = 1.0 - i * 1e-7;
    records[i].id = v;
    records[i].position[0] = static_cast<float>(v % side) + jitter(rng);
    records[i].position[1] = static_cast<float>(v / side % side) + jitter(rng);
    records[i].position[2] = static_cast<float>(v / side / side) + jitter(rng);
  }
  io::FileWriter out(path);
  out.write_array(std::span<const stream::WeightRecord32>(records));
  out.commit();
  return records;
}

std::vector<stream::CellInfo> read_infos(const std::string& path) {
  const std::string bytes = io::read_small_file(path);
  std::vector<stream::CellInfo> infos(bytes.size() / sizeof(stream::CellInfo));
  std::memcpy(infos.data(), bytes.data(), infos.size() * sizeof(stream::CellInfo));
  return infos;
}

TEST(ClusterStage, CellRecordsAreTheSumsInWeightOrderInAnyNumberOfRanges) {
  test::TempDir tmp;
  constexpr uint32_t n = 150'000;
  const std::string index = tmp.file("weights.idx");
  const std::vector<stream::WeightRecord32> records = make_index(n, index);
  const std::vector<double> sizes = {0.5, 3};  // level 0: a cell per vertex
  const std::vector<double> bounds = {-1, -1, -1, 101, 101, 41};
  Options options;
  stream::Progress progress(options);
  std::vector<std::vector<std::vector<stream::CellInfo>>> runs;
  // The sums pass makes its records in chunks of at most 16 MiB (here: more than the clusterers' peak)
  // per thread: one thread makes level 0's 150,000 records (13 MB) in one range, two threads in two.
  for (int threads : {1, 2}) {
    stream::WorkDir work(tmp.file("work" + std::to_string(threads)));
    const std::string prefix = work.file("");
    stream::ClusterSummary s;
    tbb::task_arena(threads).execute([&] {
      s = stream::cluster_levels(index, n, true, bounds, sizes, {}, uint64_t{1} << 30, work, progress, prefix);
    });
    ASSERT_EQ(s.cells[0], n);
    std::vector<std::vector<stream::CellInfo>> infos;
    for (size_t l = 0; l < sizes.size(); ++l) infos.push_back(read_infos(stream::cell_info_path(prefix, l)));
    runs.push_back(infos);
    // The plain computation: each record, in order, added to its cell; the first one is the center.
    const std::string maps = io::read_small_file(stream::cells_path(prefix, 1));
    std::vector<stream::CellInfo> expected(s.cells[1], stream::CellInfo{});
    for (uint32_t i = 0; i < n; ++i) {
      uint32_t cell;
      std::memcpy(&cell, maps.data() + 4 * size_t{i}, 4);
      stream::CellInfo& c = expected[cell];
      const double p[3] = {records[i].position[0], records[i].position[1], records[i].position[2]};
      if (c.vertices == 0) {
        std::copy(p, p + 3, c.center);
        c.center_vertex = records[i].id;
      }
      for (int k = 0; k < 3; ++k) c.weighted[k] += records[i].grade * p[k], c.sum[k] += p[k];
      c.weight += records[i].grade;
      ++c.vertices;
    }
    ASSERT_EQ(infos[1].size(), expected.size());
    EXPECT_EQ(std::memcmp(infos[1].data(), expected.data(), expected.size() * sizeof(stream::CellInfo)), 0);
    for (uint32_t c : {0u, 12345u, n - 1}) {
      EXPECT_EQ(infos[0][c].vertices, 1u);
      EXPECT_EQ(infos[0][c].center_vertex, records[c].id);
    }
  }
  for (size_t l = 0; l < sizes.size(); ++l) {
    ASSERT_EQ(runs[0][l].size(), runs[1][l].size());
    EXPECT_EQ(std::memcmp(runs[0][l].data(), runs[1][l].data(), runs[0][l].size() * sizeof(stream::CellInfo)), 0)
        << "level " << l;
  }
}

TEST(ClusterStage, ClusterersBeyondTheBudgetStopWithTheCells) {
  // The estimate before the stage (check_cluster_estimate) sees triangles only; this is the stage's own
  // check, which stops a pass whose cells outgrow the budget, with the counts so far.
  test::TempDir tmp;
  constexpr uint32_t n = 400'000;
  const std::string index = tmp.file("weights.idx");
  make_index(n, index);
  const std::vector<double> sizes = {0.5};
  Options options;
  stream::Progress progress(options);
  stream::WorkDir work(tmp.file("work"));
  Status status = Status::ok;
  std::string message;
  try {
    stream::cluster_levels(index, n, true, {}, sizes, {}, 4 << 20, work, progress, work.file(""));
  } catch (const Failure& e) {
    status = e.status();
    message = e.what();
  }
  EXPECT_EQ(status, Status::usage);
  EXPECT_NE(message.find("clustering needs more memory than --memory allows"), std::string::npos) << message;
  EXPECT_NE(message.find("level 0: "), std::string::npos) << message;
}

}  // namespace
}  // namespace lodstream

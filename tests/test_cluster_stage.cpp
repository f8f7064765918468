// The cluster stage (stream/cluster_stage.h): its bit-packed maps read back as written; its cell records
// give the emit stage the bits of the plain sums over each cell's vertices in weight order, whether the
// sums pass makes them in one range of cells or in many; and the
// stage stops with a usage error, naming the cells, when its clusterers outgrow the memory it is given.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <filesystem>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <fcntl.h>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "core/floating_cell.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/offset_file.h"
#include "lodstream/lodstream.h"
#include "stream/cell_map_file.h"
#include "stream/cluster_stage.h"
#include "stream/grade_stage.h"
#include "stream/position_gather.h"
#include "stream/progress.h"
#include "stream/work_dir.h"
#include "test_util.h"

namespace lodstream {
namespace {

// A weight index of n vertices on a jittered lattice of spacing 1, in decreasing grade, in `dir`: the
// order, the grades and the positions (by vertex id) as the grade stage and the store leave them.
struct TestIndex {
  stream::WeightIndex files;
  std::vector<uint32_t> order;  // vertex id of each record
  std::vector<double> grade;    // of each record
  std::vector<float> position;  // by vertex id
};
TestIndex make_index(uint32_t n, const std::string& dir) {
  TestIndex t;
  t.files = {dir + "/order.u32", dir + "/grades.f64", dir + "/positions.f32", n, n, true};
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  t.order.resize(n);
  for (uint32_t i = 0; i < n; ++i) t.order[i] = i;
  std::shuffle(t.order.begin(), t.order.end(), rng);  // weight order is spatially random
  const uint32_t side = 100;
  t.position.resize(3 * size_t{n});
  for (uint32_t v = 0; v < n; ++v) {
    t.position[3 * v] = static_cast<float>(v % side) + jitter(rng);
    t.position[3 * v + 1] = static_cast<float>(v / side % side) + jitter(rng);
    t.position[3 * v + 2] = static_cast<float>(v / side / side) + jitter(rng);
  }
  for (uint32_t i = 0; i < n; ++i) t.grade.push_back(i % 7 == 3 ? 0.0 : 1.0 - i * 1e-7);
  auto write = [](const std::string& path, const auto& v) {
    io::FileWriter out(path);
    out.write(v.data(), v.size() * sizeof(v[0]));
    out.commit();
  };
  write(t.files.order_path, t.order);
  write(t.files.grades_path, t.grade);
  write(t.files.positions_path, t.position);
  return t;
}

std::vector<uint32_t> read_map(const std::string& path, uint64_t records, uint64_t cells) {
  std::vector<uint32_t> map(records);
  stream::CellMapReader reader(path);
  reader.read(map);
  reader.finish(records, cells);
  return map;
}

TEST(ClusterStage, CellMapsRoundTripAtTheWidthOfTheCellsSoFar) {
  test::TempDir tmp;
  std::mt19937_64 rng(9);
  std::vector<uint32_t> cells;
  uint32_t made = 0;
  for (int i = 0; i < 200'000; ++i) {
    const bool fresh = made == 0 || rng() % 5 == 0;
    cells.push_back(fresh ? made++ : static_cast<uint32_t>(rng() % made));
  }
  stream::CellMapWriter w;
  w.open(tmp.file("m"), 1 << 16);
  for (size_t i = 0; i < cells.size(); i += 777) w.write(std::span<const uint32_t>(cells).subspan(i, std::min<size_t>(777, cells.size() - i)));
  w.commit();
  EXPECT_EQ(w.cells(), made);
  uint64_t bits = 0;
  for (uint32_t c = 0, seen = 0; c < cells.size(); ++c) bits += std::bit_width(seen), seen += cells[c] == seen;
  EXPECT_EQ(std::filesystem::file_size(tmp.file("m")), (bits + 63) / 64 * 8);
  EXPECT_EQ(read_map(tmp.file("m"), cells.size(), made), cells);
  // A cell that skips a number is a bug of the caller; a stream read past its end or with other counts is
  // a damaged file.
  stream::CellMapWriter bad;
  bad.open(tmp.file("bad"), 1 << 16);
  const uint32_t skip[2] = {0, 2};
  EXPECT_THROW(bad.write(skip), Failure);
  EXPECT_THROW(read_map(tmp.file("m"), cells.size() + 100, made), Failure);
  EXPECT_THROW(read_map(tmp.file("m"), cells.size(), made + 1), Failure);
}

TEST(ClusterStage, CellInfoIsWhatTheRepresentativeReadsInAnyNumberOfRanges) {
  test::TempDir tmp;
  constexpr uint32_t n = 150'000;
  const TestIndex t = make_index(n, tmp.path().string());
  const std::vector<double> sizes = {0.5, 3};  // level 0: a cell per vertex
  const std::vector<double> bounds = {-1, -1, -1, 101, 101, 41};
  Options options;
  stream::Progress progress(options);
  for (stream::CellInfoKind kind : {stream::CellInfoKind::center, stream::CellInfoKind::mean, stream::CellInfoKind::quadric}) {
    std::vector<std::string> runs;
    // The sums pass makes its records in chunks of at most 16 MiB (here: more than the clusterers' peak)
    // per thread: one thread makes level 0's 150,000 records (13 MB) in one range, two threads in two.
    for (int threads : {1, 2}) {
      stream::WorkDir work(tmp.file("work" + std::to_string(threads) + "-" + std::to_string(static_cast<int>(kind))));
      const std::string prefix = work.file("");
      stream::ClusterSummary s;
      tbb::task_arena(threads).execute([&] {
        s = stream::cluster_levels(t.files, bounds, sizes, {}, kind, uint64_t{1} << 30, work, progress, prefix);
      });
      ASSERT_EQ(s.cells[0], n);
      // The plain computation: each record, in order, added to its cell; the first one is the center.
      const std::vector<uint32_t> map = read_map(stream::cells_path(prefix, 1), n, s.cells[1]);
      std::vector<stream::CellInfo> expected(s.cells[1], stream::CellInfo{});
      for (uint32_t i = 0; i < n; ++i) {
        stream::CellInfo& c = expected[map[i]];
        const float* f = &t.position[3 * size_t{t.order[i]}];
        const double p[3] = {f[0], f[1], f[2]};
        if (c.vertices == 0) std::copy(p, p + 3, c.center);
        for (int k = 0; k < 3; ++k) c.weighted[k] += t.grade[i] * p[k], c.sum[k] += p[k];
        c.weight += t.grade[i];
        ++c.vertices;
      }
      const stream::CellInfoReader reader(stream::cell_info_path(prefix, 1), s.cells[1], kind, true);
      const io::Window w = reader.map(0, s.cells[1]);
      for (uint64_t c = 0; c < s.cells[1]; ++c) {
        const stream::CellInfo got = reader.get(w, c);
        const stream::CellInfo& e = expected[c];
        for (int k = 0; k < 3; ++k) {
          if (kind != stream::CellInfoKind::mean) {
            ASSERT_EQ(got.center[k], e.center[k]) << c;
          }
          // What the emit stage computes from the record, against what it computed from the full sums.
          const double mean = e.sum[k] / e.vertices;
          const double want = kind == stream::CellInfoKind::mean && e.weight > 0 ? e.weighted[k] / e.weight : mean;
          if (kind == stream::CellInfoKind::mean) {
            ASSERT_EQ(got.weighted[k] / got.weight, want) << c;
          } else if (kind == stream::CellInfoKind::quadric) {
            ASSERT_EQ(got.sum[k] / got.vertices, want) << c;
          }
        }
      }
      for (uint32_t c : {0u, 12345u, n - 1})
        if (kind != stream::CellInfoKind::mean) {
          const stream::CellInfoReader r0(stream::cell_info_path(prefix, 0), n, kind, true);
          const io::Window w0 = r0.map(c, c + 1);
          EXPECT_EQ(r0.get(w0, 0).center[0], t.position[3 * size_t{t.order[c]}]);
        }
      std::string bytes;
      for (size_t l = 0; l < sizes.size(); ++l)
        bytes += io::read_small_file(stream::cells_path(prefix, l)) + io::read_small_file(stream::cell_info_path(prefix, l));
      runs.push_back(bytes);
    }
    EXPECT_EQ(runs[0], runs[1]) << "kind " << static_cast<int>(kind);
  }
}

TEST(PositionGather, ReadByIdGivesTheMappedValuesForSparseAndDenseBatches) {
  // Segments of 1 KiB (85 float or 42 double positions): a batch of 40 ids over 100,000 vertices reads
  // them one by one, a batch of 300,000 (repeats included) reads every segment's span once.
  test::TempDir tmp;
  constexpr uint32_t n = 100'000;
  std::mt19937_64 rng(3);
  std::vector<float> f(3 * size_t{n});
  std::vector<double> d(3 * size_t{n});
  for (size_t i = 0; i < f.size(); ++i) f[i] = static_cast<float>(static_cast<int64_t>(rng() % 2000001) - 1000000) / 7.0f, d[i] = f[i] / 3.0;
  for (bool single : {true, false}) {
    const std::string path = tmp.file(single ? "p.f32" : "p.f64");
    io::FileWriter out(path);
    if (single) out.write(f.data(), f.size() * 4);
    else out.write(d.data(), d.size() * 8);
    out.commit();
    const stream::PositionGather mapped(path, single, n, true), read(path, single, n, false, 1024);
    EXPECT_TRUE(mapped.mapped());
    EXPECT_FALSE(read.mapped());
    for (size_t count : {size_t{1}, size_t{40}, size_t{300'000}}) {
      std::vector<uint32_t> ids(count);
      for (uint32_t& v : ids) v = static_cast<uint32_t>(rng() % n);
      ids[0] = n - 1;
      std::vector<double> a(3 * count, -1), b(3 * count, -2);
      stream::PositionGather::Scratch sa, sb;
      mapped.gather(ids, a.data(), sa);
      read.gather(ids, b.data(), sb);
      for (size_t i = 0; i < count; ++i)
        for (int k = 0; k < 3; ++k) {
          const double want = single ? double(f[3 * size_t{ids[i]} + k]) : d[3 * size_t{ids[i]} + k];
          ASSERT_EQ(a[3 * i + k], want) << count << " " << i;
          ASSERT_EQ(b[3 * i + k], want) << count << " " << i;
        }
    }
    std::vector<double> xyz(3);
    stream::PositionGather::Scratch s;
    const uint32_t past = n;
    EXPECT_THROW(read.gather(std::span<const uint32_t>(&past, 1), xyz.data(), s), Failure);
  }
  EXPECT_THROW(stream::PositionGather(tmp.file("p.f32"), true, n + 1, false), Failure);
}

TEST(ClusterStage, PositionsReadByIdGiveTheMappedBytes) {
  // 150,000 float positions (1.8 MB): mapped under a 1 GiB budget; read by id through the page cache when
  // --chunk-bytes is below the column (batches of one block of 16,384 records here), or when the budget is
  // less than twice the column; or read in weight order from the records' positions
  // (WeightIndex::ordered_positions_path, position_gather.h). The three write the same maps and infos.
  EXPECT_TRUE(stream::map_positions_whole(1'800'000, uint64_t{1} << 30, 0));
  EXPECT_FALSE(stream::map_positions_whole(1'800'000, uint64_t{1} << 30, 64 << 10));
  EXPECT_FALSE(stream::map_positions_whole(1'800'000, 3'000'000, 0));
  test::TempDir tmp;
  constexpr uint32_t n = 150'000;
  const TestIndex t = make_index(n, tmp.path().string());
  std::vector<float> ordered;
  for (uint32_t v : t.order) ordered.insert(ordered.end(), {t.position[3 * v], t.position[3 * v + 1], t.position[3 * v + 2]});
  {
    io::FileWriter out(tmp.file("positions-w.f32"));
    out.write(ordered.data(), ordered.size() * 4);
    out.commit();
  }
  const std::vector<double> sizes = {0.5, 3, 9};
  const std::vector<double> bounds = {-1, -1, -1, 101, 101, 41};
  Options options;
  stream::Progress progress(options);
  for (stream::CellInfoKind kind : {stream::CellInfoKind::center, stream::CellInfoKind::mean, stream::CellInfoKind::quadric}) {
    std::string runs[3];
    for (int r = 0; r < 3; ++r) {
      stream::WeightIndex files = t.files;
      if (r == 2) files.ordered_positions_path = tmp.file("positions-w.f32");
      stream::WorkDir work(tmp.file("work" + std::to_string(r) + "-" + std::to_string(static_cast<int>(kind))));
      const std::string prefix = work.file("");
      tbb::task_arena(2).execute([&] {
        stream::cluster_levels(files, bounds, sizes, {}, kind, uint64_t{1} << 30, work, progress, prefix, nullptr,
                               r == 1 ? 64 << 10 : 0);
      });
      for (size_t l = 0; l < sizes.size(); ++l)
        runs[r] += io::read_small_file(stream::cells_path(prefix, l)) + io::read_small_file(stream::cell_info_path(prefix, l));
    }
    EXPECT_FALSE(runs[0].empty());
    EXPECT_TRUE(runs[0] == runs[1]) << "kind " << static_cast<int>(kind);
    EXPECT_TRUE(runs[0] == runs[2]) << "kind " << static_cast<int>(kind);
  }
  // A file of weight-ordered positions that does not hold the index's records is refused.
  stream::WeightIndex bad = t.files;
  bad.ordered_positions_path = tmp.file("order.u32");
  stream::WorkDir work(tmp.file("bad"));
  EXPECT_THROW(stream::cluster_levels(bad, bounds, sizes, {}, stream::CellInfoKind::quadric, uint64_t{1} << 30, work, progress,
                                      work.file(""), nullptr, 0),
               Failure);
}

TEST(PositionGather, WeightOrderedPositionsAreTheColumnsBytesInAnyRanges) {
  // A weight index of 100,000 records over 130,000 vertices (some never used): written whole, and as 7
  // ranges in reverse order into one file sized beforehand, under a budget that maps the column and one
  // that reads it by id in many batches; every way gives record i the column's bytes for vertex order[i].
  test::TempDir tmp;
  constexpr uint32_t vertices = 130'000, records = 100'000;
  std::mt19937_64 rng(11);
  std::vector<uint32_t> order(vertices);
  for (uint32_t v = 0; v < vertices; ++v) order[v] = v;
  std::shuffle(order.begin(), order.end(), rng);
  order.resize(records);
  {
    io::FileWriter out(tmp.file("order.u32"));
    out.write(order.data(), order.size() * 4);
    out.commit();
  }
  Options options;
  stream::Progress progress(options);
  for (bool single : {true, false}) {
    SCOPED_TRACE(single ? "float store" : "double store");
    stream::StoreMeta meta;
    meta.single_precision = single;
    meta.vertices = vertices;
    const uint64_t stride = single ? 12 : 24;
    std::string column(vertices * stride, '\0');
    for (size_t i = 0; i < 3 * size_t{vertices}; ++i) {
      const double x = static_cast<double>(static_cast<int64_t>(rng() % 2000001) - 1000000) / 7.0;
      if (single) {
        const float f = static_cast<float>(x);
        std::memcpy(column.data() + 4 * i, &f, 4);
      } else {
        std::memcpy(column.data() + 8 * i, &x, 8);
      }
    }
    const std::string column_path = stream::positions_column_path(tmp.path().string(), meta);
    {
      io::FileWriter out(column_path);
      out.write(column.data(), column.size());
      out.commit();
    }
    std::string want(records * stride, '\0');
    for (uint32_t i = 0; i < records; ++i) std::memcpy(want.data() + i * stride, column.data() + order[i] * stride, stride);
    // 1 GiB maps the column; 512 KiB reads it by id, in batches of 8,192 records (7 ranges: more than one
    // batch a range).
    EXPECT_TRUE(stream::map_positions_whole(column.size(), uint64_t{1} << 30, 0));
    EXPECT_FALSE(stream::map_positions_whole(column.size(), 1 << 19, 0));
    EXPECT_LT(stream::ordered_positions_batch(1 << 19), records / 7);
    for (uint64_t memory : {uint64_t{1} << 30, uint64_t{1} << 19}) {
      for (unsigned ranges : {1u, 7u}) {
        SCOPED_TRACE(fmt::format("{} bytes, {} ranges", memory, ranges));
        const std::string path = tmp.file(fmt::format("w-{}-{}-{}", single, memory, ranges));
        {
          io::OffsetFile out(path, O_WRONLY | O_CREAT | O_TRUNC);
          out.resize(records * stride);
          for (unsigned k = ranges; k-- > 0;) {
            const uint64_t first = uint64_t{records} * k / ranges, end = uint64_t{records} * (k + 1) / ranges;
            stream::write_ordered_positions(tmp.path().string(), meta, tmp.file("order.u32"), first, end - first, out, memory, progress);
          }
          out.close();
        }
        ASSERT_TRUE(io::read_small_file(path) == want);
        // Read back widened to double, from any record on.
        const stream::OrderedPositions back(path, single, records);
        std::vector<double> xyz(3 * 1000);
        back.read(records - 1000, 1000, xyz.data());
        for (uint32_t i = 0; i < 1000; ++i)
          for (int a = 0; a < 3; ++a) {
            double expect;
            if (single) {
              float f;
              std::memcpy(&f, want.data() + (records - 1000 + i) * stride + 4 * a, 4);
              expect = f;
            } else {
              std::memcpy(&expect, want.data() + (records - 1000 + i) * stride + 8 * a, 8);
            }
            ASSERT_EQ(xyz[3 * i + a], expect);
          }
        EXPECT_THROW(back.read(records - 10, 11, xyz.data()), Failure);
      }
    }
    EXPECT_THROW(stream::OrderedPositions(tmp.file(fmt::format("w-{}-{}-1", single, 1 << 19)), single, records + 1), Failure);
  }
  // An order past the index's records is refused.
  io::OffsetFile out(tmp.file("short"), O_WRONLY | O_CREAT | O_TRUNC);
  stream::StoreMeta meta;
  meta.single_precision = true, meta.vertices = vertices;
  EXPECT_THROW(stream::write_ordered_positions(tmp.path().string(), meta,
                                               tmp.file("order.u32"), records - 5, 6, out, 1 << 19, progress),
               Failure);
}

TEST(ClusterStage, ClusterersBeyondTheBudgetStopWithTheCells) {
  // The estimate before the stage (check_cluster_estimate) sees triangles only; this is the stage's own
  // check, which stops a pass whose cells outgrow the budget, with the counts so far.
  test::TempDir tmp;
  constexpr uint32_t n = 400'000;
  const TestIndex t = make_index(n, tmp.path().string());
  const std::vector<double> sizes = {0.5};
  Options options;
  stream::Progress progress(options);
  stream::WorkDir work(tmp.file("work"));
  Status status = Status::ok;
  std::string message;
  try {
    stream::cluster_levels(t.files, {}, sizes, {}, stream::CellInfoKind::center, 10 << 20, work, progress, work.file(""));
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

// The grade stage's steps that a sharded run makes as units (stream/grade_shares.h), each in one process
// and as U units one after another (as U machines would run them at once), on a simplify work directory's
// store and weld map: the grading plan's block pass (block_pass_unit; the plan's maker then reads the
// units' files), and the merge of the grading shares' sorted runs (run_grade_merge_unit; the runs made
// first by U grading shares, one after another). Prints every unit's time, the slowest unit plus what
// runs once (the step's wall on U machines) against the one process, the CPU of all units, and checks
// that the units' masks and area sums are the one process's bits and their weight index its bytes.
//
// usage: bench_grade_units [--memory SIZE_BYTES] [--units U] [--scratch DIR] WORK_DIR
// WORK_DIR holds store/ and (when positions repeat) weld.map, as `simplify --work WORK_DIR` leaves them;
// DIR (default: a temporary directory) gets the units' files, the runs and the indexes.

#include <fcntl.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/offset_file.h"
#include "lodstream/lodstream.h"
#include "stream/grade_shares.h"
#include "stream/position_gather.h"
#include "stream/grade_stage.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"
#include "tools/bench_timing.h"

namespace {

using namespace lodstream;

using bench::Timing;
using bench::timed;

// Prints the units' times; returns the slowest unit's wall and adds their CPU to `cpu`.
double print_units(const char* what, const std::vector<Timing>& units, double* cpu) {
  double slowest = 0;
  for (size_t u = 0; u < units.size(); ++u) {
    fmt::print("  {} unit {} of {}: {:6.2f} s wall {:6.2f} s CPU\n", what, u, units.size(), units[u].wall, units[u].cpu);
    slowest = std::max(slowest, units[u].wall);
    *cpu += units[u].cpu;
  }
  return slowest;
}

bool same_plan(const stream::GradePlan& a, const stream::GradePlan& b) {
  for (int kind = 0; kind < 3; ++kind)
    if (a.block_ranges[kind] != b.block_ranges[kind]) return false;
  return a.areas.count == b.areas.count &&
         std::memcmp(a.areas.area.data(), b.areas.area.data(), a.areas.area.size() * sizeof(double)) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t memory = 984ull << 20;  // what --memory 1G leaves a stage
  unsigned units = 8;
  std::string dir, scratch;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--memory" && i + 1 < argc) memory = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--units" && i + 1 < argc) units = static_cast<unsigned>(std::atoi(argv[++i]));
    else if (a == "--scratch" && i + 1 < argc) scratch = argv[++i];
    else dir = a;
  }
  if (dir.empty() || units == 0) {
    std::fprintf(stderr, "usage: bench_grade_units [--memory SIZE_BYTES] [--units U] [--scratch DIR] WORK_DIR\n");
    return 2;
  }
  try {
    const std::string store = dir + "/store";
    stream::StoreMeta meta;
    if (!stream::read_store_meta(store, &meta)) fail(Status::io_error, store + ": no complete scene store");
    Options options;
    stream::Progress progress(options);
    stream::WorkDir work(scratch);
    const std::string prefix = work.file("");
    stream::MemoryPlan plan;
    plan.stage_bytes = memory;
    // The weld is done: its map (if any) stands in for the weld units' runs and map.
    stream::PlanUnits done;
    const std::string map = dir + "/weld.map";
    if (std::filesystem::exists(map)) {
      uint64_t header[2];
      io::OffsetFile(map, O_RDONLY).read(header, sizeof header, 0);
      done.weld_runs = {{map, header[1]}};
      done.weld_map = map;
    }
    fmt::print("store {}: {} vertices, {} triangles; {} units, stage budget {} MiB\n", store, meta.vertices, meta.triangles, units,
               memory >> 20);
    const stream::GradeShareInput in{store, &meta, core::Grading::lowtan, plan, prefix, &work, 0};
    std::filesystem::create_directories(stream::grade_shares_dir(prefix));
    const std::string canonical = stream::grade_shares_weld_path(prefix);

    // 1. The block pass, in one process, then as units.
    stream::GradePlan one;
    const Timing t_one = timed([&] { one = stream::plan_grading(store, meta, plan, work, progress, canonical, 0, units, true, done); });
    fmt::print("block pass, one process: {:.2f} s wall {:.2f} s CPU ({} ranges)\n", t_one.wall, t_one.cpu, one.ranges);
    const std::string block_dir = stream::block_units_dir(prefix);
    std::filesystem::create_directories(block_dir);
    const std::array<uint64_t, 3> blocks = stream::grade_blocks(meta);
    io::OffsetFile(block_dir + "blocks.bin", O_WRONLY | O_CREAT | O_TRUNC)
        .resize((blocks[0] + blocks[1] + blocks[2]) * sizeof(stream::RangeMask));
    std::vector<Timing> block_units;
    for (unsigned u = 0; u < units; ++u)
      block_units.push_back(timed([&] {
        stream::block_pass_unit(store, meta, done.weld_map, one.range, u, units, block_dir + "blocks.bin",
                                block_dir + fmt::format("areas-{}.bin", u), progress);
      }));
    double units_cpu = 0;
    const double slowest_block = print_units("block", block_units, &units_cpu);
    stream::PlanUnits with_blocks = done;
    with_blocks.block_dir = block_dir, with_blocks.block_units = units;
    stream::GradePlan from_units;
    const Timing t_read =
        timed([&] { from_units = stream::plan_grading(store, meta, plan, work, progress, canonical, 0, units, true, with_blocks); });
    fmt::print("block pass as {} units: slowest unit {:.2f} s + the plan's reading {:.2f} s = {:.2f} s wall (one process {:.2f} s); "
               "CPU of all {:.2f} s\n",
               units, slowest_block, t_read.wall, slowest_block + t_read.wall, t_one.wall, units_cpu + t_read.cpu);
    const bool same_blocks = same_plan(one, from_units);
    fmt::print("check: the units' masks and area sums are {} the one process's\n", same_blocks ? "the same bits as" : "NOT the same as");

    // 2. U grading shares' runs (one after another), then their merge in one process and as units.
    std::vector<uint64_t> records;
    double share_slowest = 0;
    for (unsigned s = 0; s < units; ++s) {
      uint64_t r = 0;
      const Timing t = timed([&] { r = stream::run_grade_share(in, one, s, units, progress); });
      share_slowest = std::max(share_slowest, t.wall);
      records.push_back(r);
    }
    fmt::print("{} grading shares: slowest {:.2f} s\n", units, share_slowest);
    auto merge = [&](unsigned merge_units, const std::string& order, const std::string& positions, std::vector<Timing>* unit_times) {
      const nlohmann::ordered_json key{{"bench", merge_units}};
      stream::GradeMergePlan mp;
      const Timing t_plan = timed([&] { mp = stream::shared_grade_merge_plan(in, records, merge_units, false, key); });
      for (unsigned u = 0; u < merge_units; ++u)
        unit_times->push_back(timed([&] { stream::run_grade_merge_unit(in, mp, u, progress); }));
      stream::finish_grade_merge(in, one, mp, order, "", positions, work.file("weld-linked.map"));
      return t_plan;
    };
    std::vector<Timing> single, merge_units;
    const Timing single_plan = merge(1, work.file("order-one.u32"), work.file("positions-one.w"), &single);
    const Timing units_plan = merge(units, work.file("order-units.u32"), work.file("positions-units.w"), &merge_units);
    double merge_cpu = units_plan.cpu;
    const double slowest_merge = print_units("merge", merge_units, &merge_cpu);
    fmt::print("merge, one process: {:.2f} s wall {:.2f} s CPU; as {} units: plan {:.2f} s + slowest unit {:.2f} s = {:.2f} s wall; "
               "CPU of all {:.2f} s\n",
               single_plan.wall + single[0].wall, single_plan.cpu + single[0].cpu, units, units_plan.wall, slowest_merge,
               units_plan.wall + slowest_merge, merge_cpu);
    const std::string a = io::read_small_file(work.file("order-one.u32")), b = io::read_small_file(work.file("order-units.u32"));
    const bool same_index = a == b;
    fmt::print("check: the units' weight index is {} the one process's ({} records)\n", same_index ? "the same bytes as" : "NOT the same as",
               a.size() / 4);
    if (std::filesystem::exists(dir + "/order.u32"))
      fmt::print("check: and {} {}/order.u32\n", io::read_small_file(dir + "/order.u32") == a ? "the same bytes as" : "differs from", dir);
    const std::string pa = io::read_small_file(work.file("positions-one.w")), pb = io::read_small_file(work.file("positions-units.w"));
    const bool same_positions = pa == pb;
    fmt::print("check: the units' positions in weight order are {} the one process's ({} bytes)\n",
               same_positions ? "the same bytes as" : "NOT the same as", pa.size());
    const std::string ordered = stream::ordered_positions_path(dir + "/", meta.single_precision);
    if (std::filesystem::exists(ordered))
      fmt::print("check: and {} {}\n", io::read_small_file(ordered) == pa ? "the same bytes as" : "differs from", ordered);
    return same_blocks && same_index && same_positions ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_grade_units: %s\n", e.what());
    return 1;
  }
}

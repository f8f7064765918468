// Grade and sort as N shares: the plan kept in grade-shares/, a share's sorted run, the merge of the runs.
// See grade_shares.h for the contract.
#include "stream/grade_shares.h"

#include <algorithm>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

namespace {

using nlohmann::ordered_json;

std::string plan_path(const std::string& prefix) { return grade_shares_dir(prefix) + "plan.json"; }
std::string blocks_path(const std::string& prefix) { return grade_shares_dir(prefix) + "blocks.bin"; }

// plan.json for `key`, or null when absent, unreadable or made for another key.
ordered_json read_plan(const std::string& prefix, const ordered_json& key) {
  std::error_code ec;
  if (!std::filesystem::exists(plan_path(prefix), ec)) return nullptr;
  try {
    ordered_json j = ordered_json::parse(io::read_small_file(plan_path(prefix)));
    if (j.at("key") == key) return j;
  } catch (const std::exception&) {
    // unreadable: made again
  }
  return nullptr;
}

// The plan from plan.json and blocks.bin; false when they do not agree.
bool parse_plan(const std::string& prefix, const ordered_json& j, GradePlan* gp) {
  try {
    const ordered_json& p = j.at("plan");
    gp->distinct_positions = p.at("distinct_positions");
    gp->welded = p.at("welded");
    gp->range = p.at("range");
    gp->ranges = p.at("ranges");
    gp->areas_summed = true;
    gp->areas.count = p.at("area_counts").get<std::vector<uint64_t>>();
    gp->areas.area = p.at("area_sums").get<std::vector<double>>();
    const std::vector<uint64_t> blocks = p.at("blocks").get<std::vector<uint64_t>>();
    const std::string bytes = io::read_small_file(blocks_path(prefix));
    uint64_t total = 0;
    for (uint64_t b : blocks) total += b;
    if (blocks.size() != 3 || bytes.size() != total * sizeof(RangeMask)) return false;
    if (gp->welded && !std::filesystem::exists(grade_shares_weld_path(prefix))) return false;
    const char* at = bytes.data();
    for (int kind = 0; kind < 3; ++kind) {
      gp->block_ranges[kind].resize(blocks[kind]);
      std::memcpy(gp->block_ranges[kind].data(), at, blocks[kind] * sizeof(RangeMask));
      at += blocks[kind] * sizeof(RangeMask);
    }
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

std::string grade_shares_dir(const std::string& prefix) { return prefix + "grade-shares/"; }
std::string grade_share_stamp(const std::string& prefix, unsigned index) {
  return grade_shares_dir(prefix) + fmt::format("share-{}.json", index);
}
std::string grade_share_run(const std::string& prefix, unsigned index) {
  return grade_shares_dir(prefix) + fmt::format("share-{}.run", index);
}
std::string grade_shares_weld_path(const std::string& prefix) { return grade_shares_dir(prefix) + "weld.map"; }
std::string weld_units_dir(const std::string& prefix) { return prefix + "weld-units/"; }
std::string weld_unit_stamp(const std::string& prefix, unsigned unit) { return weld_units_dir(prefix) + fmt::format("unit-{}.json", unit); }
std::string weld_unit_run(const std::string& prefix, unsigned unit) { return weld_units_dir(prefix) + fmt::format("unit-{}.pairs", unit); }

bool store_needs_weld(const StoreMeta& meta) { return meta.vertices > 0 && meta.format.rfind("stl", 0) != 0; }

WeldUnitResult run_weld_unit(const GradeShareInput& in, unsigned unit, unsigned units, Progress& progress) {
  const StoreMeta& meta = *in.meta;
  return weld_unit(in.store_dir + (meta.single_precision ? "/positions.f32" : "/positions.f64"), meta.vertices,
                   meta.single_precision, in.plan.stage_bytes, *in.work, progress, unit, units, weld_unit_run(in.prefix, unit),
                   weld_units_dir(in.prefix) + "sizes.bin");
}

unsigned grade_shares_planned(const std::string& prefix, const ordered_json& key) {
  const ordered_json j = read_plan(prefix, key);
  return j.is_null() ? 0 : j.value("count", 0u);
}

GradePlan shared_grade_plan(const GradeShareInput& in, unsigned count, const ordered_json& key, Progress& progress,
                            const std::vector<std::pair<std::string, uint64_t>>& weld_runs) {
  GradePlan gp;
  const ordered_json j = read_plan(in.prefix, key);
  if (!j.is_null() && j.value("count", 0u) == count && parse_plan(in.prefix, j, &gp)) return gp;
  // Made afresh: the shares of an older plan are void.
  std::filesystem::remove_all(grade_shares_dir(in.prefix));
  std::filesystem::create_directories(grade_shares_dir(in.prefix));
  gp = plan_grading(in.store_dir, *in.meta, in.plan, *in.work, progress, grade_shares_weld_path(in.prefix), in.max_range_vertices, count,
                    true, weld_runs);
  io::FileWriter blocks(blocks_path(in.prefix));
  ordered_json counts = ordered_json::array();
  for (int kind = 0; kind < 3; ++kind) {
    blocks.write(gp.block_ranges[kind].data(), gp.block_ranges[kind].size() * sizeof(RangeMask));
    counts.push_back(gp.block_ranges[kind].size());
  }
  blocks.commit();
  const ordered_json p{{"distinct_positions", gp.distinct_positions}, {"welded", gp.welded}, {"range", gp.range},
                       {"ranges", gp.ranges}, {"blocks", counts}, {"area_counts", gp.areas.count}, {"area_sums", gp.areas.area}};
  io::write_file_atomic(plan_path(in.prefix), ordered_json{{"key", key}, {"count", count}, {"plan", p}}.dump(1) + "\n");
  return gp;
}

std::pair<uint64_t, uint64_t> grade_share_ranges(const GradePlan& plan, unsigned index, unsigned count) {
  return {plan.ranges * index / count, plan.ranges * (index + 1) / count};
}

uint64_t run_grade_share(const GradeShareInput& in, GradePlan plan, unsigned index, unsigned count, Progress& progress) {
  const auto [first, end] = grade_share_ranges(plan, index, count);
  GradeSorter sorter(*in.work, fmt::format("grade-share-{}", index), std::max<uint64_t>(in.plan.stage_bytes / 3, 4 << 20));
  const uint64_t records =
      grade_ranges(in.store_dir, *in.meta, in.mode, plan, grade_shares_weld_path(in.prefix), first, end, sorter, progress);
  io::FileWriter run(grade_share_run(in.prefix, index), 4 << 20);
  uint64_t written = 0;
  sorter.merge([&](const GradeRecord& r) { run.write(&r, sizeof r), ++written; });
  if (written != records) fail(Status::internal, "grade share: the sort lost records");
  run.commit();
  return records;
}

GradeSummary merge_grade_shares(const GradeShareInput& in, const GradePlan& plan, const std::vector<uint64_t>& records,
                                const std::string& order_path, const std::string& grades_path,
                                const std::string& canonical_path, Progress& progress) {
  GradeSorter sorter(*in.work, "grade-merge", std::max<uint64_t>(in.plan.stage_bytes / 3, 4 << 20));
  uint64_t total = 0;
  for (unsigned s = 0; s < records.size(); ++s) {
    const std::string run = grade_share_run(in.prefix, s);
    std::error_code ec;
    const uint64_t bytes = std::filesystem::file_size(run, ec);
    if (ec || bytes != records[s] * sizeof(GradeRecord)) {
      // The stamp goes with it, so that the next step (or the share's task) runs the share again.
      std::filesystem::remove(grade_share_stamp(in.prefix, s), ec);
      fail(Status::io_error, fmt::format("{}: {} bytes, not the {} records of its stamp: the stamp is removed, the next step "
                                         "runs share {} again",
                                         run, ec ? 0 : bytes, records[s], s));
    }
    if (records[s]) sorter.add_sorted_run(run, records[s]);
    total += records[s];
  }
  write_weight_index(sorter, total, order_path, grades_path, progress);
  if (plan.welded) link_file(grade_shares_weld_path(in.prefix), canonical_path);
  return summary_of(plan, total);
}

}  // namespace lodstream::stream

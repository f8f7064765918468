// Grade and sort as N shares: the plan kept in grade-shares/, a share's sorted run, the merge of the runs.
// See grade_shares.h for the contract.
#include "stream/grade_shares.h"

#include <fcntl.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <memory>

#include <fmt/format.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/offset_file.h"
#include "stream/position_gather.h"
#include "stream/shard.h"
#include "stream/units.h"
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
  return weld_unit(positions_column_path(in.store_dir, meta), meta.vertices,
                   meta.single_precision, in.plan.stage_bytes, *in.work, progress, unit, units, weld_unit_run(in.prefix, unit),
                   weld_units_dir(in.prefix) + "sizes.bin");
}

std::string weld_map_units_dir(const std::string& prefix) { return weld_units_dir(prefix) + "map/"; }
std::string weld_map_unit_stamp(const std::string& prefix, unsigned unit) {
  return weld_map_units_dir(prefix) + fmt::format("map-{}.json", unit);
}

std::string start_weld_map_once(const GradeShareInput& in, uint64_t welded, const ordered_json& key) {
  const std::string path = weld_map_units_dir(in.prefix) + "weld.map";
  start_once(weld_map_units_dir(in.prefix), path, key, {"map-"}, [&] { start_weld_map(path, in.meta->vertices, welded); });
  return path;
}

void run_weld_map_unit(const GradeShareInput& in, const std::vector<std::pair<std::string, uint64_t>>& weld_runs, unsigned unit,
                       unsigned units) {
  write_weld_map_unit(weld_runs, in.meta->vertices, in.plan.stage_bytes, *in.work, weld_map_units_dir(in.prefix) + "weld.map",
                      unit, units);
}

std::string block_units_dir(const std::string& prefix) { return prefix + "block-units/"; }
std::string block_unit_stamp(const std::string& prefix, unsigned unit) {
  return block_units_dir(prefix) + fmt::format("block-{}.json", unit);
}

void start_block_units_once(const GradeShareInput& in, const ordered_json& key) {
  const std::string path = block_units_dir(in.prefix) + "blocks.bin";
  start_once(block_units_dir(in.prefix), path, key, {"block-", "areas-"}, [&] {
    const std::array<uint64_t, 3> blocks = grade_blocks(*in.meta);
    io::OffsetFile(path, O_WRONLY | O_CREAT | O_TRUNC).resize((blocks[0] + blocks[1] + blocks[2]) * sizeof(RangeMask));
  });
}

std::string run_block_unit(const GradeShareInput& in, const std::string& weld_map, unsigned count, unsigned unit, unsigned units,
                           Progress& progress) {
  const std::string dir = block_units_dir(in.prefix), areas = dir + fmt::format("areas-{}.bin", unit);
  block_pass_unit(in.store_dir, *in.meta, weld_map, grade_range_size(*in.meta, in.plan, in.max_range_vertices, count), unit, units,
                  dir + "blocks.bin", areas, progress);
  return areas;
}

unsigned grade_shares_planned(const std::string& prefix, const ordered_json& key) {
  const ordered_json j = read_plan(prefix, key);
  return j.is_null() ? 0 : j.value("count", 0u);
}

GradePlan shared_grade_plan(const GradeShareInput& in, unsigned count, const ordered_json& key, Progress& progress,
                            const PlanUnits& units) {
  GradePlan gp;
  const ordered_json j = read_plan(in.prefix, key);
  if (!j.is_null() && j.value("count", 0u) == count && parse_plan(in.prefix, j, &gp)) return gp;
  // Made afresh: the shares of an older plan are void.
  std::filesystem::remove_all(grade_shares_dir(in.prefix));
  std::filesystem::create_directories(grade_shares_dir(in.prefix));
  gp = plan_grading(in.store_dir, *in.meta, in.plan, *in.work, progress, grade_shares_weld_path(in.prefix), in.max_range_vertices, count,
                    true, units);
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

uint64_t GradeMergePlan::first(unsigned u) const {
  uint64_t n = 0;
  for (uint64_t c : cut.at(u)) n += c;
  return n;
}

std::string grade_merge_dir(const std::string& prefix) { return prefix + "grade-merge/"; }
std::string grade_merge_stamp(const std::string& prefix, unsigned unit) {
  return grade_merge_dir(prefix) + fmt::format("merge-{}.json", unit);
}

namespace {

std::string merged_order_path(const std::string& prefix) { return grade_merge_dir(prefix) + "order.u32"; }
std::string merged_grades_path(const std::string& prefix) { return grade_merge_dir(prefix) + "grades.f64"; }
std::string merged_positions_path(const std::string& prefix, const StoreMeta& meta) {
  return ordered_positions_path(grade_merge_dir(prefix), meta.single_precision);
}

using io::OffsetFile;

nlohmann::ordered_json merge_plan_key(const nlohmann::ordered_json& key, const std::vector<uint64_t>& records, unsigned units,
                                      bool grades) {
  return {{"shares", key}, {"records", records}, {"units", units}, {"grades", grades}};
}

// The cuts of the plan in grade-merge/plan.json made for `key` (which holds mp's units, grades and records),
// with its files at their full size; false when there is none.
bool read_merge_cuts(const std::string& prefix, const StoreMeta& meta, const nlohmann::ordered_json& key, GradeMergePlan* mp) {
  const std::string path = grade_merge_dir(prefix) + "plan.json";
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return false;
  try {
    const ordered_json j = ordered_json::parse(io::read_small_file(path));
    if (j.at("key") != key) return false;
    mp->cut = j.at("cut").get<std::vector<std::vector<uint64_t>>>();
    if (mp->cut.size() != mp->units + 1) return false;
    for (const auto& row : mp->cut)
      if (row.size() != mp->records.size()) return false;
    if (std::filesystem::file_size(merged_order_path(prefix), ec) != mp->total() * 4 || ec) return false;
    if (mp->grades && (std::filesystem::file_size(merged_grades_path(prefix), ec) != mp->total() * 8 || ec)) return false;
    if (std::filesystem::file_size(merged_positions_path(prefix, meta), ec) != mp->total() * position_bytes(meta.single_precision) || ec)
      return false;
    return true;
  } catch (const std::exception&) {
    return false;  // unreadable: made again
  }
}

}  // namespace

GradeMergePlan shared_grade_merge_plan(const GradeShareInput& in, const std::vector<uint64_t>& records, unsigned units,
                                       bool grades, const ordered_json& key) {
  const ordered_json plan_key = merge_plan_key(key, records, units, grades);
  GradeMergePlan mp{units, grades, records, {}};
  if (read_merge_cuts(in.prefix, *in.meta, plan_key, &mp)) return mp;
  // Made afresh: the units of an older plan are void.
  std::filesystem::remove_all(grade_merge_dir(in.prefix));
  std::filesystem::create_directories(grade_merge_dir(in.prefix));
  std::vector<std::unique_ptr<OffsetFile>> runs;
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
    runs.push_back(std::make_unique<OffsetFile>(run, O_RDONLY));
  }
  // The splitters: about 512 records a unit in all, drawn evenly from every run in proportion to its
  // records (so that the samples' quantiles are the records'; their number grows with U, not with N·U),
  // sorted; the u-th U-quantile cuts unit u-1 from unit u in every run at the same key.
  uint64_t total = 0;
  for (uint64_t r : records) total += r;
  std::vector<GradeRecord> samples;
  for (unsigned s = 0; s < records.size() && total; ++s) {
    const uint64_t k = std::min<uint64_t>(records[s], (uint64_t{512} * units * records[s] + total - 1) / total);
    for (uint64_t i = 0; i < k; ++i) samples.push_back(runs[s]->record<GradeRecord>(i * records[s] / k));
  }
  std::sort(samples.begin(), samples.end(), WeightLess());
  mp.cut.assign(units + 1, std::vector<uint64_t>(records.size(), 0));
  mp.cut[units] = records;
  for (unsigned u = 1; u < units && !samples.empty(); ++u) {
    const GradeRecord& splitter = samples[samples.size() * u / units];  // unit u starts at the first record not below it
    auto below = [&](const GradeRecord& r) { return WeightLess()(r, splitter); };
    for (unsigned s = 0; s < records.size(); ++s) mp.cut[u][s] = runs[s]->partition_point<GradeRecord>(records[s], below);
  }
  // The index's files at their full size; the units write their parts in place.
  OffsetFile(merged_order_path(in.prefix), O_WRONLY | O_CREAT | O_TRUNC).resize(mp.total() * 4);
  if (grades) OffsetFile(merged_grades_path(in.prefix), O_WRONLY | O_CREAT | O_TRUNC).resize(mp.total() * 8);
  OffsetFile(merged_positions_path(in.prefix, *in.meta), O_WRONLY | O_CREAT | O_TRUNC).resize(mp.total() * position_bytes(in.meta->single_precision));
  io::write_file_atomic(grade_merge_dir(in.prefix) + "plan.json", ordered_json{{"key", plan_key}, {"cut", mp.cut}}.dump() + "\n");
  return mp;
}

uint64_t run_grade_merge_unit(const GradeShareInput& in, const GradeMergePlan& mp, unsigned unit, Progress& progress) {
  auto sorter = std::make_unique<GradeSorter>(*in.work, fmt::format("grade-merge-{}", unit), std::max<uint64_t>(in.plan.stage_bytes / 3, 4 << 20));
  uint64_t records = 0;
  for (unsigned s = 0; s < mp.records.size(); ++s) {
    const uint64_t n = mp.cut[unit + 1][s] - mp.cut[unit][s];
    if (n) sorter->add_sorted_run(grade_share_run(in.prefix, s), n, mp.cut[unit][s]);
    records += n;
  }
  OffsetFile order(merged_order_path(in.prefix), O_WRONLY);
  std::unique_ptr<OffsetFile> grades;
  if (mp.grades) grades = std::make_unique<OffsetFile>(merged_grades_path(in.prefix), O_WRONLY);
  constexpr size_t kBatch = 1 << 20;  // records a write
  std::vector<uint32_t> ids;
  std::vector<double> values;
  ids.reserve(kBatch);
  if (grades) values.reserve(kBatch);
  uint64_t at = mp.first(unit), written = 0;
  auto flush = [&] {
    order.write(ids.data(), ids.size() * 4, at * 4);
    if (grades) grades->write(values.data(), values.size() * 8, at * 8);
    at += ids.size(), written += ids.size();
    ids.clear(), values.clear();
    progress.report("sort", static_cast<double>(written) / static_cast<double>(std::max<uint64_t>(records, 1)));
  };
  sorter->merge([&](const GradeRecord& r) {
    ids.push_back(r.id);
    if (grades) values.push_back(r.grade);
    if (ids.size() == kBatch) flush();
  });
  flush();
  if (written != records) fail(Status::internal, "grade merge: unit " + std::to_string(unit) + " lost records");
  order.close();
  if (grades) grades->close();
  // The unit's records' positions in weight order (position_gather.h), in place too, once its sorter's
  // buffers are gone: a gather by id of a U-th of the records, which a whole level's cluster share and
  // the prepare job's sums then read in order.
  sorter.reset();
  OffsetFile positions(merged_positions_path(in.prefix, *in.meta), O_WRONLY);
  write_ordered_positions(in.store_dir, *in.meta, merged_order_path(in.prefix), mp.first(unit), records, positions,
                          in.plan.stage_bytes, progress);
  positions.close();
  return records;
}

GradeSummary finish_grade_merge(const GradeShareInput& in, const GradePlan& plan, const GradeMergePlan& mp,
                                const std::string& order_path, const std::string& grades_path,
                                const std::string& positions_path, const std::string& canonical_path) {
  std::filesystem::rename(merged_order_path(in.prefix), order_path);
  if (mp.grades) std::filesystem::rename(merged_grades_path(in.prefix), grades_path);
  std::filesystem::rename(merged_positions_path(in.prefix, *in.meta), positions_path);
  if (plan.welded) link_file(grade_shares_weld_path(in.prefix), canonical_path);
  GradeSummary summary = summary_of(plan, mp.total());
  summary.ordered_positions = true;
  return summary;
}

}  // namespace lodstream::stream

// Grade and the weight index's sort as N shares (issue 19): share I of N grades its part of the canonical
// vertex ids and sorts its records; a merge of the N sorted runs then writes the weight index, the same
// bytes as one machine's grade stage (stream/grade_stage.h).
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.1: a vertex's grade depends on
// its position and its neighbours' (one ring), never on the order they are visited in; the weight order is
// non-increasing grade, ties by id (WeightLess), a total order, so any partition of the records sorted
// apart and merged gives the one order.
//
// The plan (shared_grade_plan; made once a run, by the first process that needs it, under the work
// directory's lock, and read by the others from grade-shares/plan.json): plan_grading's weld (its map in
// grade-shares/weld.map), the range size (at least N ranges, where the vertices allow), and the block
// pass over the store (each block's ranges in grade-shares/blocks.bin, 32 bytes a block of 2^18
// primitives; the area histogram in plan.json). When grading shares run as their own processes, the
// weld, its map and the block pass are made by units they all take part in (below), and the plan's
// maker only reads what the units wrote.
// The share (run_grade_share): ranges [I·R/N, (I+1)·R/N) of the R ranges, each graded from the blocks that
// touch it (grade_ranges), its records sorted under the budget (stream/external_sort.h) into one run,
// grade-shares/share-I.run (12 bytes a record).
// The merge (shared_grade_merge_plan, run_grade_merge_unit, finish_grade_merge): U = min(N, 256) units, each a
// k-way merge of a key range of the N runs written at its place in order.u32 (and the grades), then its
// records' positions gathered into the weight-ordered positions (stream/position_gather.h) in place; the
// processes that need the index (a sharded run's clustering shares or tasks) take the units up as they do
// the weld's (its lock released; its own index first, then waiting for the units others hold), and the
// first back under the lock moves the files into place and links the weld map into the work directory.
// Invariant: the splitters cut every run at the same keys, and the weight order is total, so unit u's
// records all precede unit u+1's, and the units' outputs end to end are the one k-way merge of the runs.
// Invariant: the ranges partition the ids, so every used canonical vertex is graded by exactly one share,
// from all of its primitives (the block pass found every block that touches its range).
// Memory of a share: grade_ranges' (the range's incidence lists, sized from the budget) and the sort's
// buffer (a third of the stage's budget); of a merge unit, one read buffer a run within a third of it, and
// a 4 MiB write buffer.
//
// The weld as units (run_weld_unit; stream/distinct_count.h): when grading shares run as their own
// processes, the weld is not made by the plan's maker alone. Unit u of U = min(N, 256) welds the hash
// buckets of weld_unit_buckets(u, U) into weld-units/unit-u.pairs (the bucket sizes counted by the first
// unit shared in weld-units/sizes.bin); every grading share, once the store is
// ingested, runs the units no other process holds (claimed by a lock each, its own index first), then
// waits for the others' (a unit whose holder died is run by the waiting process); then the map's units
// (run_weld_map_unit, write_weld_map_unit), claimed and waited for likewise, write its words in place into
// weld-units/map/weld.map, which the first of them started (start_weld_map_once); the plan's maker links
// it (the same bytes as one process's weld). The block pass likewise (run_block_unit, block_pass_unit):
// block unit u of U writes the ranges of the u-th U-th of each kind's blocks in place into
// block-units/blocks.bin (sized by start_block_units_once) and its blocks' area sums by bin to
// block-units/areas-u.bin, which the plan's maker adds in store order (the one-process pass's bits). The
// units go when the stage is stamped.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "stream/distinct_count.h"
#include "stream/grade_stage.h"

namespace lodstream::stream {

struct GradeShareInput {
  std::string store_dir;
  const StoreMeta* meta = nullptr;
  core::Grading mode = core::Grading::lowtan;
  MemoryPlan plan;
  std::string prefix;  // the work directory's (grade-shares/ is made there)
  const WorkDir* work = nullptr;
  uint64_t max_range_vertices = 0;  // tests force small ranges
};

std::string grade_shares_dir(const std::string& prefix);
std::string grade_share_stamp(const std::string& prefix, unsigned index);
std::string grade_share_run(const std::string& prefix, unsigned index);
std::string grade_shares_weld_path(const std::string& prefix);  // the plan's weld map, until the merge moves it

std::string weld_units_dir(const std::string& prefix);                       // WORK/weld-units/
std::string weld_unit_stamp(const std::string& prefix, unsigned unit);       // unit-U.json
std::string weld_unit_run(const std::string& prefix, unsigned unit);         // unit-U.pairs
// Whether grading welds the store (not an STL store, welded at ingest, nor an empty one).
bool store_needs_weld(const StoreMeta& meta);
// Runs weld unit `unit` of `units` into weld_unit_run.
WeldUnitResult run_weld_unit(const GradeShareInput& in, unsigned unit, unsigned units, Progress& progress);
// The weld map's units (stream/distinct_count.h, write_weld_map_unit), once every weld unit has run:
// weld-units/map/weld.map, started once (start_weld_map_once, under a lock of its own, for `key`), then
// filled by units stamped weld-units/map/map-U.json.
std::string weld_map_units_dir(const std::string& prefix);
std::string weld_map_unit_stamp(const std::string& prefix, unsigned unit);
// Starts the map for `welded` welded vertices unless started for `key`; returns its path.
std::string start_weld_map_once(const GradeShareInput& in, uint64_t welded, const nlohmann::ordered_json& key);
void run_weld_map_unit(const GradeShareInput& in, const std::vector<std::pair<std::string, uint64_t>>& weld_runs, unsigned unit,
                       unsigned units);
// The block pass's units (stream/grade_stage.h, block_pass_unit), once the weld map is whole (`weld_map`,
// empty: none): block-units/blocks.bin sized once (start_block_units_once, under a lock of its own, for
// `key`), then filled by units stamped block-units/block-U.json, each also writing areas-U.bin.
inline constexpr unsigned kMaxBlockUnits = 256;
std::string block_units_dir(const std::string& prefix);  // WORK/block-units/
std::string block_unit_stamp(const std::string& prefix, unsigned unit);
void start_block_units_once(const GradeShareInput& in, const nlohmann::ordered_json& key);
// Runs block unit `unit` of `units` for `count` grading shares; returns its areas file.
std::string run_block_unit(const GradeShareInput& in, const std::string& weld_map, unsigned count, unsigned unit, unsigned units,
                           Progress& progress);

// The count of the shares' plan written for `key`, or 0 when there is none (no grading share has run).
unsigned grade_shares_planned(const std::string& prefix, const nlohmann::ordered_json& key);
// The plan as every process of a run sees it, made once: read from grade-shares/ when written there for
// `key` and `count`, else made by plan_grading (the weld and a pass over the store) and written there.
// The caller holds the work directory's lock.
// With `units` (what the grading shares' units made: stream/grade_stage.h, PlanUnits), the weld map is
// written from the weld units' runs or linked from the map's units' file, and the block pass is read
// from the block units' files.
GradePlan shared_grade_plan(const GradeShareInput& in, unsigned count, const nlohmann::ordered_json& key, Progress& progress,
                            const PlanUnits& units = {});

// The ranges [first, end) of share `index` of `count`.
std::pair<uint64_t, uint64_t> grade_share_ranges(const GradePlan& plan, unsigned index, unsigned count);

// Runs share `index`: grades its ranges and writes its sorted run; returns its records.
uint64_t run_grade_share(const GradeShareInput& in, GradePlan plan, unsigned index, unsigned count, Progress& progress);

// The merge as units (the shares' runs cut by key): unit u of U merges the records of every run that
// fall in [splitter u-1, splitter u) of the weight order and writes them at their place in the weight
// index, which it finds without the other units (the records before its first: the sum of its cuts).
inline constexpr unsigned kMaxGradeMergeUnits = 256;
struct GradeMergePlan {
  unsigned units = 0;
  bool grades = false;                    // the grades are written beside the order
  std::vector<uint64_t> records;          // per share's run
  std::vector<std::vector<uint64_t>> cut;  // units + 1 rows: unit u merges records [cut[u][s], cut[u + 1][s]) of run s
  uint64_t first(unsigned u) const;       // the index's records before unit u's
  uint64_t total() const { return first(units); }
};
std::string grade_merge_dir(const std::string& prefix);                  // WORK/grade-merge/
std::string grade_merge_stamp(const std::string& prefix, unsigned unit);  // merge-U.json
// The merge's plan for shares holding `records` each, as every process of a run sees it: read from
// grade-merge/plan.json when written there for `key`, else made (`units` units; the runs sampled, about
// 512 records a unit in all, from each run in proportion to its records, and the splitters found in
// every run by binary search) with the index's files, at their full size, in grade-merge/, which the
// units fill. The caller holds the work directory's lock.
// Failure(io_error) when a run does not hold its records (its share's stamp is then removed, so that the
// next step runs the share again).
GradeMergePlan shared_grade_merge_plan(const GradeShareInput& in, const std::vector<uint64_t>& records, unsigned units,
                                       bool grades, const nlohmann::ordered_json& key);
// Runs merge unit `unit`: its records, in weight order, at their place in grade-merge/'s files (their ids,
// grades when kept, then their positions); returns them. Memory: the merge's (a third of the stage's budget),
// then the positions' gather (write_ordered_positions within the stage's budget).
uint64_t run_grade_merge_unit(const GradeShareInput& in, const GradeMergePlan& mp, unsigned unit, Progress& progress);
// Once every unit has run: moves the index's files to `order_path`, `positions_path` and (when kept) `grades_path`, and links the weld
// map (if any) to `canonical_path`; returns the stage's summary.
GradeSummary finish_grade_merge(const GradeShareInput& in, const GradePlan& plan, const GradeMergePlan& mp,
                                const std::string& order_path, const std::string& grades_path,
                                const std::string& positions_path, const std::string& canonical_path);

}  // namespace lodstream::stream

// Past one machine (../shared/DESIGN.md): `simplify --shard I/N` runs task I's share of the emit stage
// over a shared work directory, and `merge` (stream/merge.cpp) welds the tasks' parts into the output
// directory, the same bytes as one machine's. The contract any engine can drive (Slurm job arrays,
// Kubernetes Indexed Jobs, AWS Batch arrays): a task is given only I and N.
//
// - Shared stages (ingest, grade, labels, cluster (with --cluster-shards N: the merge of N shares run
//   before, stream/cluster_shares.h), the store's block boxes (block_bounds.h), and every level's cells by
//   vertex (vertex_cells.h)): whichever task comes first runs them, holding an exclusive lock on
//   WORK/shard.lock (flock; taken before the work directory is opened, so that no task takes another's
//   live scratch files for a dead process's); the others wait, then find their stamps and reuse them.
//   `--shard-prepare` runs them alone (a scheduler's first job). They do not scale with N: they are what
//   one machine runs before its emit stage, plus the block boxes and the cells by vertex. (The stages run
//   as units, stream/units.h, let the lock go while every task takes part in them; the last of them, the
//   wide levels' pass A, stream/wide_units.h, runs in the tasks only, not in --shard-prepare.)
// - A task's share: one run of the Morton codes (shard_bounds), the codes of the finest level's regions
//   that hold an N-th of its cells (shard_regions); in every level, the regions whose code falls in it, a
//   contiguous run (region order is octree Morton order, so whole subtrees but at its two ends). So a
//   task's levels cover about the same place, and its passes read about the same blocks. The levels of
//   fewer regions than tasks go whole to one task (shard_runs), which emits them in one pass; their
//   classification (the emit's pass A) runs first as units that every task takes part in
//   (stream/wide_units.h), and that task reads the units' outputs.
//   It emits them as the batched emit does, each batch with its halo, forming the representatives of its
//   own cells, its halo's and the ring beyond it from their quadrics (EmitOptions::own_representatives;
//   no stage writes them ahead, so none is run once for all tasks), which gives every part the bytes it has
//   in one machine's run
//   (stream/emit_stage.h), and writes the parts, in region order, to OUTDIR/shards/task-I-lodL.parts;
//   then OUTDIR/shards/task-I.json (last: its presence means the task is complete) with the manifest as
//   the task saw it (its own counts), its stages, and the key of what it was made from.
// - A task run again (resubmitted, or killed and rerun) removes its task-I.json and redoes its emit from
//   the start, reusing the shared stages; its parts files are written under .partial names and renamed.
//   Its passes read only the store's blocks whose boxes (written by the shared stages, block_bounds.h) come
//   near its cells, their halos and rings; its packed maps hold only the pages of 64 vertices that those
//   blocks reference, read from the cells by vertex (vertex_cells.h) as each group of blocks needs them
//   (paged_vertex_map.h), so a task's memory does not grow with the scene's vertices.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/mesh.h"
#include "io/file_writer.h"
#include "lodstream/lodstream.h"
#include "stream/block_bounds.h"
#include "stream/emit_regions.h"
#include "stream/emit_stage.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/task_file.h"
#include "stream/tiles.h"

namespace lodstream::stream {

// The exclusive lock on WORK/shard.lock, held while a task runs the shared stages; released by release()
// or the destructor. A default-constructed lock holds nothing. With `wait` false it is taken only if no
// other process holds it (held() tells).
class ShardLock {
 public:
  ShardLock() = default;
  explicit ShardLock(const std::string& work_dir, const std::string& name = "shard.lock", bool wait = true);
  bool held() const { return fd_ >= 0; }
  ShardLock(const ShardLock&) = delete;
  ShardLock& operator=(const ShardLock&) = delete;
  ~ShardLock() { release(); }
  void release();

 private:
  int fd_ = -1;
};

// The regions [first, end) of task `index` of `count` in a level's cut: the regions whose cells before
// them (in region order) are in [index, index + 1) · total / count. Tasks' runs are disjoint and cover
// the cut; a run may be empty.
std::pair<uint32_t, uint32_t> shard_regions(const LevelCut& cut, unsigned index, unsigned count);

// The tasks' runs of Morton codes: task t's is [bounds[t], bounds[t + 1]) (count + 1 bounds, from 0 to
// UINT64_MAX), cut at the first region of each task's run of `finest` (shard_regions). Why one cut for
// every level: a task's passes read only the blocks near its regions (block_bounds.h), so its cost is the
// place its regions cover; with one run per level cut independently (or, as before the block bounds, run
// k of level l given to task (k + l) mod N to spread the coarse levels) a task's levels lay all over the
// scene and each of its passes read most of the input.
std::vector<uint64_t> shard_bounds(const LevelCut& finest, unsigned count);
// The regions [first, end) of a level's cut whose region_code lies in task `index`'s run of `bounds`: the
// tasks' runs are disjoint and cover the cut, in task order (the merge reads them so: region order).
std::pair<uint32_t, uint32_t> shard_regions_in(const LevelCut& cut, const std::vector<uint64_t>& bounds, unsigned index);

// The regions [first, end) of every level's cut (finest first) that task `index` of `count` emits. The
// finest level, and every level of at least `count` regions: its run of codes (shard_regions_in). A wide
// level (wide_level: coarser, of fewer regions than tasks): all its regions to one task (wide_tasks). A
// wide region costs a pass over the place it covers (every input primitive there maps to its cells)
// however few its cells, and the wide levels' regions together cover about the whole scene; a task's wide
// levels share one pass over the input (emit_shard groups them apart from its runs of codes).
// - N <= 2: the wide levels go to task 0, beside its run of codes.
// - N >= 3: the wide levels go to tasks 0 to K - 1 (wide_task_count), which have no run of codes, in even
//   runs of levels, one a task while two tasks remain for the runs of codes; tasks K to N - 1 split the
//   runs of codes (shard_bounds for N - K runs, in task order). On the 193 M-triangle city at N = 8 the
//   three wide levels in one pass took about 40 s of task 0's 54 s, where the tasks of codes took 12-21 s.
// Tasks 0 to K - 1 are the first a scheduler's array starts, so the longest tasks do not run alone at the
// end. For each level the tasks' runs are disjoint and cover the cut; the merge orders them by their first
// region.
std::vector<std::pair<uint32_t, uint32_t>> shard_runs(const std::vector<LevelCut>& cuts, unsigned index, unsigned count);
// K: the tasks that have wide levels and no run of codes (0 when N <= 2 or no level is wide).
unsigned wide_task_count(const std::vector<LevelCut>& cuts, unsigned count);
// Per level: the task that emits it whole, or -1 (not wide).
std::vector<int> wide_tasks(const std::vector<LevelCut>& cuts, unsigned count);
bool wide_level(const std::vector<LevelCut>& cuts, size_t level, unsigned count);

std::string shards_dir(const std::string& output_dir);
std::string shard_parts_path(const std::string& output_dir, unsigned index, size_t level);
std::string shard_task_path(const std::string& output_dir, unsigned index);

// A region's part as the task writes it and the merge reads it back: what the region sink and the level
// files (stream/level_files.h) are given.
struct StoredPart {
  RegionInfo info;
  RegionPart part;
};
// Appends parts to a parts file (written under a .partial name, renamed by commit()).
class PartsWriter {
 public:
  explicit PartsWriter(const std::string& path);
  void add(const RegionInfo& info, const RegionPart& part);
  void commit();
  uint64_t parts() const { return parts_; }

 private:
  io::FileWriter out_;
  uint64_t parts_ = 0;
};
// Reads a parts file part by part; next() returns false after the last.
class PartsReader : TaskFileReader {
 public:
  explicit PartsReader(const std::string& path);
  bool next(StoredPart* out);
};

// What a task's emit needs from simplify (the shared stages' results).
struct ShardEmitInput {
  std::string store_dir, canonical, prefix;
  const StoreMeta* meta = nullptr;
  uint64_t records = 0;
  core::ClusterOptions cluster;
  EmitOptions options;
  uint64_t budget = 0;  // the stage's memory budget
  uint64_t tile_triangles = 0;
  std::vector<double> sizes;
  std::vector<uint64_t> cells;
  bool tiles = false;  // the run writes 3D Tiles: regions are cut with the tiles' side bounds, as one machine cuts them
  // The wide levels' pass A ran as units (stream/wide_units.h): a task emitting a wide level whole reads
  // its units' outputs instead of classifying the input.
  bool wide_units = false;
  // Every level's cut (shard_cuts), when the caller made them already; else made where needed.
  std::vector<LevelCut> cuts{};
};

// Every level's cut, as one machine's emit cuts them (with the tiles' side bounds when the run writes tiles).
std::vector<LevelCut> shard_cuts(const ShardEmitInput& in);

// Emits task `index` of `count`'s regions of every level and writes their parts (see above). Returns the
// task's counts per level; `primitives_read`, when given, gets the input primitives its passes read added;
// `runs`, when given, to its run of each level {first, end, regions in the level} (shard_runs).
std::vector<EmitCounts> emit_shard(const ShardEmitInput& in, unsigned index, unsigned count, const std::string& output_dir,
                                   Progress& progress, EmitScratch& scratch, uint64_t* primitives_read = nullptr,
                                   std::vector<std::array<uint32_t, 3>>* runs = nullptr);

// TilesOptions (stream/tiles.h) as the task hands them to the merge, and back.
nlohmann::ordered_json tiles_options_json(const TilesOptions& o);
TilesOptions tiles_options_from_json(const nlohmann::ordered_json& j);

// Writes OUTDIR/shards/task-I.json: {"index", "key", "manifest"} (durably, last).
void write_shard_task(const std::string& output_dir, unsigned index, const nlohmann::ordered_json& key,
                      const nlohmann::ordered_json& manifest);

// What a merge calls a sharded job's pieces in its messages: its parts ("task parts"), a task ("task"),
// the job ("run"), what makes a task another job's, and the command that runs a task ("simplify").
struct TaskNames {
  const char *parts, *task, *job, *other, *command;
};
// The summaries task-I.json of a sharded job's tasks in `dir`, checked to be one job's: N tasks of count N
// with the same key, in task order. Fails with Status::no_input naming the missing and stale tasks.
std::vector<nlohmann::ordered_json> read_task_summaries(const std::string& dir, const TaskNames& names);

}  // namespace lodstream::stream

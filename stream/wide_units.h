// A sharded run's wide levels (stream/shard.h: the coarse levels of fewer regions than tasks, each emitted
// whole by one task) have their pass A (Low & Tan 1997 §3.3–3.4 as stream/emit_stage.h does it: each
// primitive classified through the level's cluster map, the outputs deduplicated within fixed blocks of
// the input, the cells' quadrics summed per block) run as units that every task takes part in
// (stream/units.h take_units), before any task emits. The task that emits a wide level then reads its
// units' outputs in block order instead of classifying the whole input itself, so it reads the input once
// (its thickness pass) instead of twice, and the pass that grows with the scene is split N ways.
//
// Why the bytes are one machine's: emit_stage.h merges a block's outputs in block order whichever process
// formed them; a unit forms a block's outputs exactly as the task would (the same blocks of kEmitBlock
// primitives, the same level state: a batch of every region, so every primitive is visited), and the task
// merges the units' blocks in the whole input's block order (read_classified checks that order).
//
// Units: U = N (the tasks), unit u the blocks [u·B/U, (u+1)·B/U) of the B blocks (emit_block_count), for
// every wide level at once in one pass sharing one packed map, paged (stream/paged_vertex_map.h: the pages
// of the unit's blocks' vertices), in groups of levels when the map and the levels' working memory do not
// fit the stage's budget together: a pass a group. Unit u writes one file a
// wide level, WORK/wide-units/unit-u-level-L.bin (about the level's deduplicated outputs of each block, its
// touched cells' quadrics, and a bit per input triangle and segment), stamped group-g/wide-unit-u.json; a unit
// whose holder died is run by the process waiting for it.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "stream/emit_regions.h"
#include "stream/emit_stage.h"
#include "stream/progress.h"
#include "stream/shard.h"

namespace lodstream::stream {

struct WideUnitsPlan {
  unsigned units = 0;                        // U
  std::vector<std::vector<size_t>> groups;   // the wide levels, a group a pass of each unit
};
// The plan for `count` tasks from the levels' cuts (shard_cuts); no group when no level is wide. A wide
// level whose paged map and working memory alone do not fit in.budget is left out: its task classifies it.
WideUnitsPlan plan_wide_units(const ShardEmitInput& in, const std::vector<LevelCut>& cuts, unsigned count);

std::string wide_units_dir(const std::string& prefix);
std::string wide_unit_path(const std::string& prefix, unsigned unit, size_t level);

// Takes part in the units (this process's own index first), then waits for every unit. `key`: the stage's
// (the units' stamps hold it). The input primitives the units run here read are added to `read`. Returns
// the units' figures (unit_figures) and the plan: {"levels": [...], "units": U, "seconds": [...], "by": [...]}.
nlohmann::ordered_json run_wide_units(const ShardEmitInput& in, unsigned index, unsigned count, const nlohmann::ordered_json& key,
                                      Progress& progress, EmitScratch& scratch, std::atomic<uint64_t>& read);

}  // namespace lodstream::stream

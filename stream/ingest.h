// Stage 1 of the pipeline: input file -> scene store (see ../shared/DESIGN.md, "ingest").
#pragma once

#include <string>

#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// Builds (or, when work/store holds a complete store of the same source, reuses) the scene store in
// `store_dir`. Sets *reused accordingly. Throws Failure.
StoreMeta ingest(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                 const WorkDir& work, Progress& progress, bool* reused);

// Number of distinct positions among the store's vertices (exact comparison; -0 equals +0), by an
// external sort under plan.sort_bytes.
uint64_t count_distinct_positions(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan,
                                  const WorkDir& work, Progress& progress);

}  // namespace lodstream::stream

// Stage 1 of the pipeline: input file -> scene store (see ../shared/DESIGN.md, "ingest").
#pragma once

#include <string>
#include <vector>

#include "lodstream/lodstream.h"

#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// Builds (or, when work/store holds a complete store of the same source, reuses) the scene store in
// `store_dir`. Sets *reused accordingly. Throws Failure. With `ranges_dir` (a sharded run's
// WORK/ingest-ranges) holding range ingest segments of this input, the store is joined from them
// (stream/ingest_range.h), the same bytes, and they are removed once it is complete; a set of them that
// is incomplete fails with Status::no_input naming the missing ranges.
StoreMeta ingest(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                 const WorkDir& work, Progress& progress, bool* reused, const std::string& ranges_dir = {});

// The ingest stage as every entry point runs it: ingest() timed as the stage "ingest" into `stages`, and
// the ingest fields of *scene filled from the store (path, format, counts, bbox; the census fields are
// left alone). Sets *reused. `ranges_dir`: as ingest()'s.
StoreMeta run_ingest_stage(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                           const WorkDir& work, Progress& progress, std::vector<StageStats>* stages,
                           SceneInfo* scene, bool* reused, const std::string& ranges_dir = {});

// Statistics of a store that only `info` needs: distinct positions among the vertices (exact comparison,
// -0 equals +0; see distinct_count.h) and vertices no primitive uses.
struct Census {
  uint64_t vertices_welded = 0;
  uint64_t unused_vertices = 0;
};
Census census(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan, const WorkDir& work,
              Progress& progress);

}  // namespace lodstream::stream

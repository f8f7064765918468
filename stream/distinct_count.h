// Exact count of distinct positions in a store's position column, under a memory budget.
//
// Positions become fixed-width bit keys (-0 normalised to +0, so exact equality of coordinates is
// equality of keys), counted in open-addressing hash tables. When the tables would not fit in
// `memory_bytes`, keys are split by the top bits of their hash into P partitions, each counted in its own
// read-only pass over the column (in parallel, in the calling task arena): equal keys always fall in the
// same partition, so the sum is exact and does not depend on the budget. Nothing is written to disk.
#pragma once

#include <cstdint>
#include <string>

#include "stream/progress.h"

namespace lodstream::stream {

// `path` holds `count` positions as 3 floats (single_precision) or 3 doubles each.
uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress);

}  // namespace lodstream::stream

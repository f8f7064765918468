// Exact count of distinct positions in a store's position column, under a memory budget.
//
// Positions become fixed-width bit keys (-0 normalised to +0, so exact equality of coordinates is
// equality of keys). One pass counts the keys of each of 256 buckets (top bits of the key's hash); then,
// as many consecutive buckets as `memory_bytes` holds at a time are scattered into one array and each
// bucket's distinct keys are counted in its own small, cache-friendly hash table, buckets in parallel (in
// the calling task arena). Equal keys always share a bucket, so the sum is exact and does not depend on
// the budget, which only decides how many read-only passes over the column are made. Nothing is written.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "stream/progress.h"

namespace lodstream::stream {

// `path` holds `count` positions as 3 floats (single_precision) or 3 doubles each.
uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress);

// The same pass, welding: writes canonical[v] = the smallest vertex id whose position equals v's (so
// canonical[v] <= v, and canonical[v] == v for the first vertex at each position). `canonical` has `count`
// entries and is held in memory by the caller (4 bytes per vertex). Returns the distinct count.
uint64_t weld_positions(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                        Progress& progress, std::span<uint32_t> canonical);

}  // namespace lodstream::stream

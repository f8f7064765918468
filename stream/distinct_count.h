// Exact count of distinct positions in a store's position column, and the weld, under a memory budget.
//
// Positions become fixed-width bit keys (-0 normalised to +0, so exact equality of coordinates is
// equality of keys). One pass counts the keys of each of 256 buckets (top bits of the key's hash); then,
// as many consecutive buckets as `memory_bytes` holds at a time are scattered into one array and each
// bucket's distinct keys are counted, buckets in parallel (in the calling task arena). A bucket is first
// split by its next hash bits (a stable counting sort) into sub-buckets of about 8 K keys, each counted in
// its own hash table, small enough to stay in a core's cache: one table for the whole bucket missed the
// cache at nearly every probe. Equal keys always share a sub-bucket, so the sum is exact and does not
// depend on the budget, which only decides how many read-only passes over the column are made.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "stream/progress.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

// `path` holds `count` positions as 3 floats (single_precision) or 3 doubles each. Nothing is written.
uint64_t count_distinct_positions(const std::string& path, uint64_t count, bool single_precision,
                                  uint64_t memory_bytes, Progress& progress);

// The same passes, welding: every vertex's canonical id is the smallest vertex id whose position equals
// its own. Each sub-bucket's keys come in file order, so a key's first id is its canonical id; the welded
// vertices' canonical ids go, in id order, into the weld map at `weld_path` (stream/weld_file.h), which is
// written only when some positions repeat: through an array of a u32 a vertex where that takes at most
// half the budget, else as (id, canonical id) pairs through an external sort (scratch files in `work`, an
// eighth of the budget), so that nothing is held per vertex but the map's bits (1/8 byte a vertex). The
// map's bytes do not depend on the way. Returns the distinct count. Throws Failure(usage) when
// `memory_bytes` is below weld_memory_floor.
uint64_t weld_positions(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                        const WorkDir& work, Progress& progress, const std::string& weld_path);

// The weld shared out among processes (stream/grade_shares.h): unit `unit` of `units` (at most
// kMaxWeldUnits) welds the positions of its hash buckets alone, each position's canonical id being
// settled in the one unit that holds its bucket, and writes its welded vertices' pairs (id << 32 |
// canonical id, u64) in id order to `run_path`; write_weld_map then writes the map from every unit's run
// (path, pairs), the same bytes as weld_positions. A unit's distinct positions and welded vertices add up
// over the units to the store's.
inline constexpr unsigned kMaxWeldUnits = 256;
struct WeldUnitResult {
  uint64_t distinct = 0, welded = 0;
};
// `sizes_path` (empty: none) is where the units share their first pass, the bucket sizes of every slice
// of the column: a unit reads them from there when another unit of the same column wrote them (checked
// against the column's size and time, and the slices' counts), else counts them and writes them there,
// so that most units read the column once, not twice.
WeldUnitResult weld_unit(const std::string& path, uint64_t count, bool single_precision, uint64_t memory_bytes,
                         const WorkDir& work, Progress& progress, unsigned unit, unsigned units, const std::string& run_path,
                         const std::string& sizes_path = {});
void write_weld_map(const std::vector<std::pair<std::string, uint64_t>>& runs, uint64_t count, uint64_t memory_bytes,
                    const WorkDir& work, const std::string& weld_path);
// write_weld_map as units, which different processes may run: start_weld_map writes the map's header at
// `path` and sizes the file for `welded` welded vertices; unit `unit` of `units` (write_weld_map_unit)
// then writes the map's words weld_map_unit_words(count, unit, units) (64 vertices a word) in place: their
// bits, their ranks and their welded vertices' canonical ids, read from the stretch of every run that holds
// them (binary search: a run is sorted by id) at the offset that the runs' pairs before them give. The
// units write disjoint bytes; once all have run the file is write_weld_map's bytes. Memory: a unit's bits
// and ranks (12 bytes a word of its own) and the pairs' merge (pair_sort_bytes).
void start_weld_map(const std::string& path, uint64_t count, uint64_t welded);
std::pair<uint64_t, uint64_t> weld_map_unit_words(uint64_t count, unsigned unit, unsigned units);
void write_weld_map_unit(const std::vector<std::pair<std::string, uint64_t>>& runs, uint64_t count, uint64_t memory_bytes,
                         const WorkDir& work, const std::string& path, unsigned unit, unsigned units);
// The hash buckets [first, end) of 256 that unit `unit` of `units` welds.
std::pair<unsigned, unsigned> weld_unit_buckets(unsigned unit, unsigned units);

// The least budget weld_positions works in for `count` positions: the map's bits and ranks, the sort's
// smallest buffer, and one bucket's keys with each thread's scratch for it (buckets twice the mean size).
uint64_t weld_memory_floor(uint64_t count, bool single_precision);

}  // namespace lodstream::stream

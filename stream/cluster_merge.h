// The clustering shares' merge of the split levels (stream/cluster_shares.h) as units that every process
// of a sharded run that reaches it, and every thread of each, takes part in (take_units, stream/units.h).
// Kok-Lim Low and Tiow-Seng Tan. Model Simplification Using Vertex-Clustering. I3D 1997, §3.2: the
// one-machine pass creates a cell at its center, in weight order, so a split level's cell id is the rank
// of its center among the level's centers in weight order.
//
// The records are cut into U units of whole 64-record words (U = the shares, at most 256); phases of U
// units each, in WORK/cluster-merge/:
// 1. centers (unit u, centers/merge-centers-u.json): each share's decisions of u's records in turn (each
//    share's .dec file is in record order; its first record of the unit is found by binary search) set the
//    centers' bits, written in place into centers/centers.bits (each split level's bits a run of words);
//    the stamp counts u's centers per share.
// 2. map (unit u, map/merge-map-u.json), once every centers unit is stamped: merges the shares' decisions
//    of its records by record, checking that they decide each record exactly once, reads the level's bits whole (a bit
//    and a half a record with their ranks) and writes its records' cells into cells-L.map in place. The map
//    is self-delimiting (stream/cell_map_file.h: record i's cell in bit_width(rank(i)) bits), so unit u's
//    first bit is the sum of those widths before its first record, which the bits give word by word. The
//    words it fills alone it writes; the one or two it shares with its neighbours go into its stamp, and
//    every process that has seen every stamp writes them (the OR of their parts: the same value each time).
//    For center representatives it copies its centers' positions from the shares' .ctr files (its first
//    center in share s's file: the centers of s in the units before it) into cells-L.info at its first cell.
//    With ClusterShareInput::spend_decisions (a sharded simplify), the shares' decisions are spent as the
//    phase goes: the units' key is first written to cluster-shares/spent.json (a merge under another key
//    finds them spent there, forget_shares_spent_elsewhere, and the shares run again); once unit u is
//    stamped, the process that ran it frees the bytes of u's decisions (and centers) in every share's file
//    (fallocate's PUNCH_HOLE where the file system can: a hole reads as zeros, so a unit reads each share's
//    file from its first decision, which phase 1's stamp holds, to the next unit's, never past it); and once
//    every map unit is stamped, the split levels' decision (and center) files are emptied (their names
//    stay, for the shares' stamps, which a process that comes late still reads). On the 193 M-triangle city
//    at N = 8 the decisions (3.91 GB) were the largest item of the shared directory at the phase's end.
// 3. sums (mean and quadric representatives; unit u, sums/merge-sums-u.json), once every map unit is stamped
//    and the maps' shared words written: the u-th U-th of the split levels' cells (taken one level after
//    another) summed by one pass over the records in weight order (sum_cell_info_range, stream/cluster_stage.h)
//    into cells-L.info in place, from the center of its first cell on (a cell's id is its center's rank, so
//    no record before that center is in one of its cells; the centers' bits give where it is). It enters
//    each map there (MapEntry, stream/cell_map_file.h: the bits before the record, map_bits_before, and its
//    rank, both from the centers' bits) rather than decode it from its start, a serial chain through every
//    record before the unit's (a record's width is that of the cells made before it), which made the 8 units
//    of the 193 M-triangle city cost 27 thread-seconds. (From 2026-11 to 2026-12-05 the map units wrote each
//    record's cell as a uint32 beside the map for this, the plain cells: 4 bytes a record a split level on the
//    shared disk, 1.96 GB on that city, beside the shares' decisions at the merge's peak.) A cell adds its
//    vertices in weight order, whichever cells are summed beside it, so a unit's records are one machine's
//    bytes; the cells, not the records, are cut, because partial sums of record ranges added up would not be.
//    Once every sums unit is stamped, the records' positions in weight order (their last reader) are spent
//    (position_gather.h).
// 4. pairs (unit u, pairs/merge-pairs-u.json): its records' cells, from the map entered at its first record,
//    as (vertex, cell) pairs by vertex range into map/pairs-L-u.bin (vertex_pairs_path), its own file, the
//    order's ids read alongside. A phase of its own so that the pairs and the shares' decisions are never on
//    disk together: on the 193 M-triangle city at N = 8 they were (8 bytes a record a split level each), with
//    the plain cells, the shared directory's peak (16.9 GB for a 4.15 GB input).
// The centers' bits and the units' stamps stay after the stage: a process that saw the cluster stage
// unstamped and comes late to the units must find them done, where start_once, missing the bits, would start
// them afresh from the shares' decision files, which the stage's stamp removes.
// Invariant: the map and the center info are the bytes of one pass over the records in weight order (the
// merge before the units, and the whole-scene clustering): every record's cell is the rank of its center,
// written at the map bits of the records before it.
// Disk: the shares' decisions, 8 bytes a record a split level, until the map units are done; then the
// pairs (the vertex's low bits and the cell, packed: 32 to 45 bits a record on the 193 M-triangle city's
// levels) until the cells by vertex are written (packed to each level's bits, vertex_cells.h). On that city
// at N = 8, five split levels, the decisions took 3.91 GB; before 2026-12-05 the plain cells 1.96 GB, the
// pairs 3.91 GB and the cells by vertex 2.75 GB.
// Memory: a process runs as many units at once as it has threads and `memory_bytes` holds, each a bit and
// a half a record of its level, a 1 MiB read buffer of each share's files and 8 MiB of buffers (ids and
// cells read, pairs written); a sums unit takes its
// thread's share of `memory_bytes` (at least kMinSumsUnitBytes) and, when its cells' sums (88 bytes a cell)
// do not fit, sums them in several passes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "stream/cluster_shares.h"
#include "stream/progress.h"

namespace lodstream::stream {

inline constexpr unsigned kMaxClusterMergeUnits = 256;
inline constexpr uint64_t kMinSumsUnitBytes = uint64_t{256} << 20;

std::string cluster_merge_dir(const std::string& prefix);  // WORK/cluster-merge/
// Removes every split level's pairs (once the cells by vertex are written).
void remove_vertex_pairs(const std::string& prefix);
// Pairs unit u's cells of split level `level` as (vertex, cell) pairs by vertex range (stream/vertex_pairs.h),
// for the cells by vertex. vertex_pairs_paths: every unit's that is
// there, in unit order (empty: none).
std::string vertex_pairs_path(const std::string& prefix, size_t level, unsigned unit);
std::vector<std::string> vertex_pairs_paths(const std::string& prefix, size_t level);

struct SplitMerge {
  std::vector<uint64_t> cells;  // per level (0 for the whole levels)
  nlohmann::ordered_json units;  // the units' count, and each phase's units' wall seconds and runners (host:pid)
};

// Writes every split level's cells-L.map and cells-L.info from the shares' files as units (above), this process's threads starting at unit `index`; units stamped for `key` (the
// shares' plan and figures) are reused. Every share must have run. Failure(io_error) when the shares'
// files do not add up to the weight index.
SplitMerge merge_split_levels(const ClusterShareInput& in, const ClusterShares& plan, const nlohmann::ordered_json& key,
                              unsigned index, Progress& progress);
// When the shares' decision files were spent (ClusterShareInput::spend_decisions) by a merge under another
// key than merge_split_levels(in, plan, key) would use (a merge of another build, say, left half done), that
// merge cannot read them: removes the shares' stamps (and the mark), so that the shares run again, and
// returns true. The caller holds the work directory's lock.
bool forget_shares_spent_elsewhere(const ClusterShareInput& in, const ClusterShares& plan, const nlohmann::ordered_json& key);

}  // namespace lodstream::stream

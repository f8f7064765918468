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
//    It also writes its records' cells one uint32 a record into map/cells-L.u32 (plain_cells_path), in place.
//    Once every map unit is stamped, the shares' decision (and center) files of the split levels are spent
//    (ClusterShareInput::spend_decisions): emptied, so that they take no disk while the pairs are written
//    (their names stay, for the shares' stamps, which a process that comes late still reads), the units' key
//    written first to cluster-shares/spent.json; a merge under another key finds them spent there
//    (forget_shares_spent_elsewhere), and the shares run again.
// 3. pairs (unit u, pairs/merge-pairs-u.json): its records' cells, from the plain cells, as (vertex, cell)
//    pairs by vertex range into map/pairs-L-u.bin (vertex_pairs_path), its own file, the order's ids read
//    alongside. A phase of its own so that the pairs (8 bytes a record a split level until 2026-12-05, about
//    5 now that they are packed: vertex_pairs.h) and the shares'
//    decisions (8 too) are never on disk together: on the 193 M-triangle city at N = 8 they were, with the
//    plain cells, the shared directory's peak (16.9 GB for a 4.15 GB input).
// 4. sums (mean and quadric representatives; unit u, sums/merge-sums-u.json), once every map unit is stamped
//    and the maps' shared words written: the u-th U-th of the split levels' cells (taken one level after
//    another) summed by one pass over the records in weight order (sum_cell_info_range, stream/cluster_stage.h)
//    into cells-L.info in place, from the center of its first cell on (a cell's id is its center's rank, so
//    no record before that center is in one of its cells; the centers' bits give where it is). It reads the
//    records' cells from the plain cells, not the map: decoding a map is a serial chain through every
//    record before the unit's start (a record's width is that of the cells made before it), which made
//    the 8 units of the 193 M-triangle city cost 27 thread-seconds where, reading the plain cells, they
//    cost 7–8. A cell adds its vertices in weight order, whichever cells are summed beside it, so a unit's
//    records are one machine's bytes; the cells, not the records, are cut, because partial sums of record
//    ranges added up would not be.
// The centers' bits and the units' stamps stay after the stage: a process that saw the cluster stage
// unstamped and comes late to the units must find them done, where start_once, missing the bits, would start
// them afresh from the shares' decision files, which the stage's stamp removes.
// Invariant: the map and the center info are the bytes of one pass over the records in weight order (the
// merge before the units, and the whole-scene clustering): every record's cell is the rank of its center,
// written at the map bits of the records before it.
// Disk: the plain cells, 4 bytes a record a split level, and the shares' decisions, 8 bytes a record a split
// level, until the map units are done; then the plain cells and the pairs (the vertex's low bits and the
// cell, packed: 43 bits or fewer a record on the 193 M-triangle city's levels), the plain cells until the
// stage's stamp, the pairs until the cells by vertex are written (packed to each level's bits,
// vertex_cells.h; on that city at N = 8, five split levels, the decisions, plain cells and pairs took 3.91,
// 1.96 and 3.91 GB and the cells by vertex 2.75 GB before the pairs and the cells by vertex were packed).
// Memory: a process runs as many units at once as it has threads and `memory_bytes` holds, each a bit and
// a half a record of its level, a 1 MiB read buffer of each share's files and 10 MiB of write buffers
// (plain cells, ids, pairs); a sums unit takes its
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
// Split level `level`'s cells one uint32 a record in weight order (PlainCellReader, stream/cell_map_file.h),
// which the map units write beside the packed map: the pairs and sums units (phases 3 and 4) read them rather than decode the
// map from its start, each of them (the split levels' cells by vertex read the pairs below). They outlive
// the stage's units; remove_plain_cells removes them with the stage's stamp.
std::string plain_cells_path(const std::string& prefix, size_t level);
// Removes the plain cells of every split level (once the stage is stamped: the sums units are done, and the
// cells by vertex read the pairs), or the plain cells and the pairs (below).
void remove_plain_cells(const std::string& prefix);
void remove_plain_cells_and_pairs(const std::string& prefix);
// Map unit u's cells of split level `level` as (vertex, cell) pairs by vertex range (stream/vertex_pairs.h),
// which it writes beside the plain cells for the cells by vertex. vertex_pairs_paths: every unit's that is
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

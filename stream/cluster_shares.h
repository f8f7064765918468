// The clustering pass as N shares (issue 19, "clustering by region"): share I of N clusters the vertices of
// its region of the scene, with a halo, in every level fine enough to split, and the levels too coarse to
// split whole, one share each; a merge then writes the cluster maps and cell infos, the same bytes as the
// one-machine pass (stream/cluster_stage.h).
//
// Low & Tan, "Model Simplification Using Vertex-Clustering", I3D 1997, §3.2: the floating-cell pass, which
// is sequential in weight order. core/floating_cell_region.h proves which decisions a share can settle
// from the vertices it holds; this file is the stage around it.
//
// The plan (plan_cluster_shares; made once a run, by the first process that needs it, under the work
// directory's lock, and read by the others from cluster-shares/plan.json: shared_cluster_plan):
// - Regions: slabs across the longest axis of the scene's bounds, cut where the store's vertices divide
//   into equal parts, one a slab (a histogram of 4096 bins over the axis), so that share I owns the vertices with
//   cuts[I-1] <= p[axis] < cuts[I] (no lower bound for share 0, no upper for share N-1).
// - A level is split by region when its cells are floating, it has no fine grid (silhouette labels: two
//   grids, not handled here), and every slab is at least kSplitCells cells wide; then each share clusters
//   its own vertices. The other levels are clustered whole (exact by construction), a share's whole levels
//   in one cluster_levels pass, which reads the records' positions in weight order (position_gather.h;
//   fetching them by id had been a third of such a share's CPU). With N >= 3 and such
//   levels, shares 1 to K cluster the whole levels only, in even runs of levels (K as many as there are
//   whole levels, while two slabs remain), and have empty slabs (repeated cuts: their split levels'
//   decision files are empty); the other N - K shares own the slabs. With N <= 2, share 1 (share 0 if
//   N = 1) clusters every whole level beside its slab.
// - A level too coarse to split by region whose cells float and which has no fine grid is split by
//   ranges of records instead (with N >= 2 and the scene's bounds, unless ClusterShareInput says not):
//   share I decides records [I·R/N, (I+1)·R/N) of the R records in weight order. Its centers come first,
//   from one pass over every record (core/floating_cell_centers.h: the covered voxels skip most of them),
//   run as a unit of its own that the first share to reach it takes (cluster-shares/centers/level-L.ctrs:
//   each center's record and position, in weight order; stamped level-L.json; a unit whose holder died is
//   run by a share waiting for it); then each share clusters its range with a Clusterer given first the
//   centers before its range (core/floating_cell_centers.h says why that is the whole pass's decision).
//   Its files are a split level's (.dec, .ctr), which the merge reads as it reads a slab's. Before, such a
//   level was clustered whole by one share, which on N nodes the array waited for (the whole pass over the
//   records, the sums and the cells by vertex, in one process).
// The share (run_cluster_share): first it takes the centers units no other share holds, then its slab's
// levels, then it waits for every centers unit, then it decides its range of each level split by records.
// Per split level (by region):
// 1. Select: the vertex ids within the largest halo of the slab (one sequential read of the positions),
//    then the records of the weight index that hold them (one sequential read of order.u32) and their
//    positions, in weight order: the whole-scene order restricted to what the share holds.
// 2. Cluster and widen: a core::RegionClusterer over the records within the level's halo H (first
//    kFirstHaloCells cells). When one of the share's own records stays unsettled (its status or its cell),
//    H doubles and the level runs again; a halo that reaches past the scene's bounds holds everything, where
//    every decision settles, so the loop ends.
// 3. Write, per level L, cluster-shares/share-I-level-L.dec: (record, record of its center) for every
//    own record, in weight order; and, for center representatives, .ctr: the own centers' positions at
//    the store's precision.
// The merge (merge_cluster_shares), per split level: a cell's id is the number of centers before its
// center in weight order (the one-machine pass numbers cells in creation order, and a cell is created by
// its center). The shares' .dec files merged by record make them, as units by record range that every
// process reaching the merge takes part in (stream/cluster_merge.h): first each unit's centers' bits, then
// each unit's records' cells, the rank of their center's bit. The ids go to cells-L.map
// (stream/cell_map_file.h), and the .ctr files to a center-kind info. Mean and quadric infos are summed
// afterwards, as cluster_levels sums them, as units by ranges of cells (sum_cell_info_range). Whole levels' files are linked from the share that made them:
// their map and info, and for a sharded run (ClusterShareInput::vertex_cells) their cells by vertex, which
// the share writes after clustering them (stream/vertex_cells.h), so that the prepare job decodes only the
// split levels' maps (193 M-triangle city: about 2.5 s a level).
// Invariant: each record is owned by exactly one share (the slabs partition the axis), and every owned
// decision written is settled, hence the whole-scene pass's (core/floating_cell_region.h); the merge checks
// that the shares' records are each record exactly once.
// Memory of a share: 28 bytes per record held (its record number and position, gathered in weight order
// from a by-id copy of the selected positions, 24 bytes per vertex selected (12 for a float store; sized
// exactly: the ids are selected in one read of the column, their positions copied in a second), freed
// after the gather), a bit and a half per store vertex while selecting, and the RegionClusterers' entries and slots
// (core/floating_cell_region.h; the split levels run at once, one thread each); of the merge, a bit and
// a half per record and a 1 MiB read buffer of each share's files, per split level (merged at once when the
// budget holds them all, else one after another).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/floating_cell.h"
#include "stream/cluster_stage.h"
#include "stream/progress.h"

namespace lodstream::stream {

inline constexpr double kSplitCells = 32;      // a level splits when every slab is this many cells wide
inline constexpr double kFirstHaloCells = 16;  // the first halo, in cells (README: 17 to 23 at most measured)

struct ClusterShares {
  unsigned count = 0;
  int axis = 0;
  std::vector<double> cuts;       // count - 1 planes across `axis`, non-decreasing
  std::vector<int> whole_share;   // per level: the share that clusters the level whole, or -1 (split);
                                  // non-decreasing over the whole levels
  std::vector<char> by_records;   // per level: 1 when a split level is split by ranges of records, not by slabs
  // Share s's slab on the axis: [lo, hi), infinite at the ends.
  double lo(unsigned s) const;
  double hi(unsigned s) const;
  // Share s's records of a level split by records: [records·s/count, records·(s+1)/count).
  uint64_t first_record(unsigned s, uint64_t records) const;
  nlohmann::ordered_json json() const;
};

// What a share and the merge are given: the weight index, the scene's bounds (6 values, or empty), the
// levels' cell sizes, the clustering, the info kind, the fine grids (or null), the memory budget, and the
// work directory's prefix (cells-L.map etc. are written there; the shares' files in cluster-shares/).
struct ClusterShareInput {
  WeightIndex index;
  std::vector<double> bounds, sizes;
  core::ClusterOptions options;
  CellInfoKind info = CellInfoKind::center;
  const FineCells* fine = nullptr;
  uint64_t memory_bytes = 0, chunk_cap = 0;
  std::string prefix;
  const WorkDir* work = nullptr;
  double first_halo_cells = kFirstHaloCells;  // the tests start lower, to make shares widen
  unsigned merge_units = 0;  // the merge's units (stream/cluster_merge.h); 0: one a share, at most 256 (tests set more)
  // When set, a share also writes its whole levels' cells by vertex (stream/vertex_cells.h; the weld map at
  // canonical_path, empty when none), which the merge links into the work directory: the sharded tasks
  // read them, and the shares write them at once where the prepare job would decode the levels one by one.
  bool vertex_cells = false;
  std::string canonical_path{};
  // false: the levels too coarse for the slabs are clustered whole, one share each where N allows, as a
  // level with a fine grid is (the tests use it to run that route on plain levels).
  bool split_by_records = true;
  // The key the centers units' stamps hold (the caller's share key; empty: the plan's).
  nlohmann::ordered_json key{};
  // The merge frees the shares' decisions as its map units finish and empties the files once they are all
  // done, and empties the records' positions in weight order after its sums (stream/cluster_merge.h), so
  // that they take no disk while it writes the pairs. A sharded run sets it; the tests that merge one set of
  // shares several times do not.
  bool spend_decisions = false;
};

ClusterShares plan_cluster_shares(const ClusterShareInput& in, unsigned count, Progress& progress);
// The plan as every process of a run sees it, made once: read from cluster-shares/plan.json when that was
// written for `key` (the cluster stage's) and `count`, else made by plan_cluster_shares (a pass over the
// store's positions) and written there. The caller holds the work directory's lock, so that the N shares
// and the merge make it once between them.
ClusterShares shared_cluster_plan(const ClusterShareInput& in, unsigned count, const nlohmann::ordered_json& key,
                                  Progress& progress);

std::string cluster_shares_dir(const std::string& prefix);
std::string cluster_share_stamp(const std::string& prefix, unsigned index);
// Share `share`'s files of split level `level`: its decisions, (record, record of its center) for each own
// record in weight order, and, for center representatives, its centers' positions in the same order.
std::string cluster_share_decisions_path(const std::string& prefix, unsigned share, size_t level);
std::string cluster_share_centers_path(const std::string& prefix, unsigned share, size_t level);
// The files share `index` writes (for its stamp).
std::vector<std::string> cluster_share_files(const ClusterShareInput& in, const ClusterShares& plan, unsigned index);

// Runs share `index`; returns its figures for the stamp and the manifest: per level {"level", "cells"
// (whole levels), "halo_cells", "tries", "held", "own"} (slabs) or {"level", "first_record", "own",
// "own_centers", "centers_before"} (split by records).
// The centers units of the levels split by records: their directory, a level's centers file and its stamp.
std::string cluster_centers_dir(const std::string& prefix);
std::string cluster_centers_path(const std::string& prefix, size_t level);
std::string cluster_centers_stamp(const std::string& prefix, size_t level);
// The centers passes' figures of the levels split by records (their stamps' values: {"level", "centers",
// "skipped", "voxel", "seconds", "runner"}), for the cluster stage's stamp; empty when none is stamped.
nlohmann::ordered_json cluster_centers_figures(const ClusterShareInput& in, const ClusterShares& plan);
nlohmann::ordered_json run_cluster_share(const ClusterShareInput& in, const ClusterShares& plan, unsigned index,
                                         Progress& progress);

// Writes cells-L.map and cells-L.info for every level from the shares' files (every share must have run;
// figures[s]: what run_cluster_share returned for share s), and with `vertex_cells` the whole levels'
// vertex-cells-L.bits; returns cells per level and the levels whose cells by vertex it wrote. Failure(io_error) when
// the shares' files do not add up to the weight index.
// The split levels' maps are made by merge_split_levels (stream/cluster_merge.h), in this process alone.
ClusterSummary merge_cluster_shares(const ClusterShareInput& in, const ClusterShares& plan,
                                    const std::vector<nlohmann::ordered_json>& figures, Progress& progress);
// The same once merge_split_levels has made the split levels' maps and infos (`split_cells`: what it
// returned): the whole levels' files linked.
ClusterSummary merge_cluster_shares(const ClusterShareInput& in, const ClusterShares& plan,
                                    const std::vector<nlohmann::ordered_json>& figures, const std::vector<uint64_t>& split_cells,
                                    Progress& progress);

}  // namespace lodstream::stream

// Stage 5 of the pipeline (../shared/DESIGN.md "emit"; Low & Tan 1997 §3.3–3.5): map every input
// primitive through one level's cluster map and build that level's mesh.
//
// - Classification: a triangle whose corners fall in three distinct cells stays a triangle (input
//   winding kept); in two, it collapses to an edge between them; in one, to a point. An input segment
//   likewise gives an edge or a point, an input point a point.
// - Elimination: no two triangles on the same three cells (the first in store order is kept, with its
//   winding), no two edges on the same two cells, no edge that is a side of an output triangle, no point
//   on a cell an output triangle or edge uses.
// - Thickness (§3.3.1): for an edge between cells A and B, over the corners (in A or B) of every input
//   triangle and segment that collapsed to it: P_A, P_B the mean corner positions in A and in B, D_A, D_B
//   the mean distances of those corners to the line P_A P_B; thickness = D_A + D_B. (A vertex shared by k
//   collapsing triangles counts k times.)
// - Representatives: center (the cell's center vertex), mean (grade-weighted mean of the cell's vertices;
//   the plain mean when every grade is 0), quadric (Lindstrom 2000: area-weighted plane quadrics of every
//   input triangle touching the cell, minimised around the cell's mean and clamped into the cell's box).
// - Normals: per vertex with a crease angle (core/normals.h).
//
// Determinism: primitives are processed in fixed blocks of the store (not of the parse or memory plan),
// each block's sums are formed in store order and merged in block order; output primitives and vertices
// are numbered in order of first appearance. So the bytes depend on the input and options only.
// Memory: 4 bytes per stored vertex (the level's cluster map, kept in EmitScratch between levels) and one bit
// per input triangle and segment (collapsed to an edge or not), plus what grows with the output: at the
// peak (classification), the triangle and edge dedupe tables. Elimination runs before the thickness passes
// (corner sums, then distances), which visit only the primitives that collapsed to an edge and keep sums
// for the kept edges only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/floating_cell.h"
#include "core/mesh.h"
#include "lodstream/lodstream.h"
#include "stream/memory.h"
#include "stream/progress.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

struct EmitOptions {
  Representative representative = Representative::center;
  double crease_degrees = 30;
  bool normals = true;
  bool count_only = false;  // stop after classification and triangle dedupe (target search)
};

struct EmitCounts {
  uint64_t triangles = 0, edges = 0, points = 0;
  uint64_t edges_on_triangles = 0, points_covered = 0;  // eliminated
};

// What one level leaves to the next: the buffer of the cluster map (4 bytes per stored vertex), so that
// every level does not fault in and zero fresh pages for it (measured at a tenth of the stage's time on a
// 48M-triangle scene). Holds no result: any scratch, fresh or used, gives the same output.
struct EmitScratch {
  std::vector<uint32_t> map;
};

// `canonical_path` empty: every stored vertex is canonical. `prefix`, `level`: the cluster stage's files.
EmitCounts emit_level(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                      const std::string& prefix, size_t level, uint64_t records, uint64_t cells, double cell_size,
                      const core::ClusterOptions& cluster, const EmitOptions& options, Progress& progress,
                      EmitScratch& scratch, core::LodMesh* out);

}  // namespace lodstream::stream

// Simplify's silhouette labels stage (between grade and cluster): every record of the weight index gets
// its vertex's silhouette label (core/silhouette_labels.h: the distance to the outline, minimum over K
// views, in scene units), written in weight order so that the cluster stage reads it beside the index.
//
// Out of core: the original is traced from the scene store chunk by chunk (stream/chunk_scene.h, the
// report's machinery), the views of a group accumulating their coverage images; each view's exact
// distance image is then made and the index is read in blocks, lowering each block's labels. When the
// views do not fit in memory at once, they are taken in groups, and each later group reads the labels
// file back in blocks and lowers it. Memory: a view costs 21 bytes a pixel while its group is traced (the
// cast image, 17, and its distance image, 4), the chunk scene takes what is left; labels are never held
// whole. The labels are the same bytes for any --threads, --memory and chunking: coverage is exact per
// pixel whatever the chunk (a pixel is covered when any chunk's primitive is hit), and a label is a
// minimum over views.
//
// Output: `out_path`, one float per weight-index record (4 bytes each), core::kNoLabel where no view sees
// the vertex.
#pragma once

#include <cstdint>
#include <string>

#include "stream/progress.h"
#include "stream/scene_store.h"

namespace lodstream::stream {

struct LabelOptions {
  unsigned views = 16;        // K, on a Fibonacci sphere
  unsigned resolution = 512;  // of each view, square
  double fov_degrees = 60;
};

struct LabelSummary {
  uint64_t chunks = 0;      // chunk scenes built (over all groups)
  uint64_t view_groups = 0;
  uint64_t labelled = 0;    // records with a label (seen by some view)
};

// chunk_cap: at most this many bytes a chunk of the original (0 = from memory_bytes alone), as report's
// --chunk-bytes, for tests that cut a small original into many chunks. ordered_positions_path: the
// records' positions in weight order (stream/position_gather.h), read in order, or empty: read by id.
LabelSummary compute_labels(const std::string& store_dir, const StoreMeta& meta, const std::string& order_path,
                            uint64_t records, const LabelOptions& options, uint64_t memory_bytes,
                            uint64_t chunk_cap, Progress& progress, const std::string& out_path,
                            const std::string& ordered_positions_path);

}  // namespace lodstream::stream

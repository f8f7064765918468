// The Metro samples and view targets of a report's meshes (core/surface_sampling.h, README "report"): a
// level's, drawn in memory, and an original's, drawn from its scene store in two passes over its chunks
// (measure, then sample) and a pass over its used vertices, either in one process or as units that the
// tasks of a report by ranges take up (stream/units.h). The weights are summed in fixed blocks of 65,536
// primitives by global id, so units of whole blocks draw one process's samples bit for bit.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "stream/progress.h"
#include "stream/scene_store.h"
#include "stream/store_chunks.h"

namespace lodstream::stream {

// Random streams of the seed (core/surface_sampling.h): one per use, so that changing one use never
// moves the numbers of another.
enum : uint64_t { kStreamTargets = 101, kStreamOriginalSamples = 102, kStreamLodSamples = 103 };

// Metro-style samples of a mesh (faces, edges, vertices): face samples first, then edge and vertex samples.
struct MeshSamples {
  std::vector<float> xyz;
  size_t faces = 0;  // the first `faces` samples are uniform by area
};

// Samples of a mesh held in memory (a level).
MeshSamples sample_mesh(const core::LodMesh& m, uint64_t n, uint64_t seed, uint64_t stream);

// An original's Metro samples and view targets.
struct OriginalSamples {
  std::vector<float> xyz;       // face samples first, then edge and vertex samples
  uint64_t faces = 0;
  std::vector<float> targets;   // view targets, xyz
};

// How many, from which seed: `samples` of each kind, and `views` view targets.
struct SampleOptions {
  uint64_t samples = 0, seed = 0;
  unsigned views = 0;
};

// An original's samples and view targets, in one process, from `chunks` (planned over the whole store).
OriginalSamples draw_original_samples(const std::string& store_dir, const StoreMeta& meta, const SampleOptions& o,
                                      StoreChunks& chunks, Progress& progress);

// The same samples as `units` units (at most one a block) in `dir` (a directory of the shared work
// directory), which every process that needs them takes part in, `index` first (take_units): measure units
// in dir/measure/ (unit u the u-th units-th of the store's blocks: their weights' sums, and which vertices
// their primitives use), then, once, the vertex samples (Algorithm S over the used vertices in store
// order: dir/vertices.bin), then sample units in dir/sample/ (each draws the samples that fall in its
// blocks, from every block's sums); every process then joins the units' samples in unit order.
// `chunk_bytes`: the size of the chunks a unit reads. Resumable: a unit killed before its stamp is run
// again by the next process that needs it.
OriginalSamples draw_original_samples_in_units(const std::string& store_dir, const StoreMeta& meta, const SampleOptions& o,
                                               const std::string& dir, unsigned units, unsigned index, uint64_t chunk_bytes,
                                               Progress& progress);

}  // namespace lodstream::stream

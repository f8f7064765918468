// Silhouette labels stage; see labels_stage.h.
#include "stream/labels_stage.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/silhouette_labels.h"
#include "core/status.h"
#include "core/view_cast.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "stream/chunk_scene.h"
#include "stream/grade_stage.h"
#include "stream/position_gather.h"
#include "stream/store_chunks.h"

namespace lodstream::stream {

namespace {

constexpr uint64_t kBlock = 1 << 16;           // index records per block of the vertex pass (at least)
constexpr uint64_t kViewPixelBytes = 17 + 4;   // cast image (depth, normal, kind) and distance image
constexpr uint64_t kMinSceneBytes = 16 << 20;  // the chunk scene's share is at least this

}  // namespace

LabelSummary compute_labels(const std::string& store_dir, const StoreMeta& meta, const std::string& order_path,
                            uint64_t records, const LabelOptions& options, uint64_t memory_bytes,
                            uint64_t chunk_cap, Progress& progress, const std::string& out_path,
                            const std::string& ordered_positions_path) {
  if (options.views == 0 || options.resolution < 8 || options.resolution > 8192)
    fail(Status::usage, "silhouette labels: views must be at least 1 and the resolution within 8 .. 8192");
  LabelSummary summary;
  io::MappedFile order(order_path);
  if (order.size() != records * 4) fail(Status::io_error, order_path + ": size does not match");

  const double center[3] = {(meta.bbox.min[0] + meta.bbox.max[0]) / 2, (meta.bbox.min[1] + meta.bbox.max[1]) / 2,
                            (meta.bbox.min[2] + meta.bbox.max[2]) / 2};
  double radius = 0;
  for (int k = 0; k < 3; ++k) radius += (meta.bbox.max[k] - meta.bbox.min[k]) * (meta.bbox.max[k] - meta.bbox.min[k]);
  radius = meta.bbox.empty ? 1 : std::max(std::sqrt(radius) / 2, 1e-30);

  // Half the budget for the views of a group, the rest for a chunk's scene (three quarters of it, as the
  // report sizes its chunks against Embree's guard).
  const uint64_t pixels = uint64_t{options.resolution} * options.resolution;
  const uint64_t per_group = std::clamp<uint64_t>(memory_bytes / 2 / (pixels * kViewPixelBytes), 1, options.views);
  const uint64_t scene_bytes =
      std::max(kMinSceneBytes, memory_bytes - std::min(memory_bytes, per_group * pixels * kViewPixelBytes));
  StoreChunks chunks(store_dir, meta);
  chunks.plan(kChunkSceneCosts, chunk_cap ? std::min(chunk_cap, scene_bytes / 4 * 3) : scene_bytes / 4 * 3);
  const size_t n_chunks = chunks.chunks().size();
  const uint64_t groups = (options.views + per_group - 1) / per_group;
  summary.view_groups = groups;

  std::unique_ptr<ChunkScene> cache;  // one chunk: built once for every group
  for (uint64_t g = 0; g < groups; ++g) {
    const unsigned first = static_cast<unsigned>(g * per_group);
    const unsigned end = static_cast<unsigned>(std::min<uint64_t>(options.views, first + per_group));
    std::vector<core::Camera> cameras;
    for (unsigned k = first; k < end; ++k)
      cameras.push_back(core::label_camera(k, options.views, center, radius, options.fov_degrees, options.resolution));
    std::vector<core::ViewImage> images(cameras.size());
    for (size_t c = 0; c < n_chunks; ++c) {
      progress.check();
      std::unique_ptr<ChunkScene> chunk = std::move(cache);
      if (!chunk) {
        chunk = load_chunk_scene(chunks, c, scene_bytes);
        ++summary.chunks;
      }
      // The chunk's lines and points, built again only for a view whose radius differs: the views all
      // stand at one distance, so this is mostly one build a chunk, not one a view.
      std::unique_ptr<core::RayScene> wire;
      float wire_radius = 0;
      for (size_t v = 0; v < cameras.size(); ++v) {
        const core::Camera& cam = cameras[v];
        // Lines and points one pixel wide at the object's center.
        const double eye_to_center = std::sqrt((cam.eye[0] - center[0]) * (cam.eye[0] - center[0]) +
                                               (cam.eye[1] - center[1]) * (cam.eye[1] - center[1]) +
                                               (cam.eye[2] - center[2]) * (cam.eye[2] - center[2]));
        const float line_radius = static_cast<float>(cam.pixel_size(eye_to_center) / 2);
        if (chunk->has_wire() && (!wire || line_radius != wire_radius)) {
          wire.reset();  // one wire scene at a time
          wire = build_wire(chunk->geometry, line_radius, line_radius, scene_bytes);
          wire_radius = line_radius;
        }
        const core::RayScene* scenes[] = {chunk->triangles.get(), wire.get()};
        core::cast_view(std::span<const core::RayScene* const>(scenes, wire ? 2 : 1), cam, &images[v], true);
      }
      progress.report("labels", (double(g) + 0.8 * double(c + 1) / double(n_chunks)) / double(groups));
      if (n_chunks == 1) cache = std::move(chunk);
    }
    std::vector<std::vector<uint32_t>> squared(cameras.size());
    tbb::parallel_for(size_t{0}, cameras.size(), [&](size_t v) {
      squared[v].resize(pixels);
      core::outline_distances(images[v].kind, options.resolution, squared[v]);
      images[v] = {};
    });

    // The vertex pass: this group's views lower every record's label; the first group starts from
    // kNoLabel, later ones from the file the group before wrote.
    std::unique_ptr<io::MappedFile> previous;
    if (g > 0) previous = std::make_unique<io::MappedFile>(out_path);
    io::FileWriter out(out_path + (g > 0 ? ".next" : ""));
    std::vector<float> labels;
    std::vector<double> xyz;
    // Records come in weight order, spread over the column: mapped whole where it takes at most an eighth
    // of the budget (a chunk's scene, kept for the next group, may hold three quarters of what the views
    // leave), else read by id through the page cache (position_gather.h), a block taking a sixteenth of the
    // budget (its labels, positions, slots and index window: 36 bytes a record), since each block costs a
    // pass over the column's segments that hold its ids.
    // With the records' positions in weight order (a sharded run's), they are read in order, block by block.
    const uint64_t column = meta.vertices * position_bytes(meta.single_precision);
    const RecordPositions positions(positions_column_path(store_dir, meta), meta.single_precision, meta.vertices,
                                    ordered_positions_path, records, map_positions_whole(column, memory_bytes / 4, chunk_cap));
    PositionGather::Scratch scratch;
    const uint64_t block = positions.per_block() ? kBlock : std::max<uint64_t>(std::min(memory_bytes / 16, chunk_cap ? chunk_cap : UINT64_MAX) / 36 / kBlock, 1) * kBlock;
    for (uint64_t b = 0; b < records; b += block) {
      progress.check();
      const uint64_t n = std::min(block, records - b);
      labels.assign(n, core::kNoLabel);
      if (previous) {
        const io::Window w = previous->map(b * 4, (b + n) * 4);
        std::copy_n(reinterpret_cast<const float*>(w.data()), n, labels.data());
      }
      xyz.resize(3 * n);
      {
        const io::Window w = order.map(b * 4, (b + n) * 4);
        positions.load(b, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), n), xyz.data(), scratch);
      }
      tbb::parallel_for(tbb::blocked_range<uint64_t>(0, n, 4096), [&](const tbb::blocked_range<uint64_t>& r) {
        const std::span<const double> part(xyz.data() + 3 * r.begin(), 3 * (r.end() - r.begin()));
        const std::span<float> part_labels(labels.data() + r.begin(), r.end() - r.begin());
        for (size_t v = 0; v < cameras.size(); ++v) core::lower_labels(cameras[v], squared[v], part, part_labels);
      });
      if (g + 1 == groups)
        for (float l : labels) summary.labelled += l < core::kNoLabel;
      out.write_array(std::span<const float>(labels));
    }
    out.commit();
    previous.reset();
    if (g > 0) std::filesystem::rename(out_path + ".next", out_path);
    progress.report("labels", double(g + 1) / double(groups));
  }
  return summary;
}

}  // namespace lodstream::stream

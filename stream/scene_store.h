// The scene store: what ingest writes and every later stage reads.
//
// One directory of flat little-endian columns, each cut into fixed-size chunks of `chunk_elements`
// elements (the last one shorter), plus store.json with counts, bounding box, object names, the chunk
// table (per vertex chunk its bounding box) and the identity of the source file. The chunk size is a constant of the store format, not of the
// job: the store's bytes are the same for any thread count, memory budget or parse chunk size.
//
//   positions.f32|.f64     x y z per vertex: float when the input's coordinates are all 32-bit floats
//                          (PLY float, STL), else double, so every input value is kept exactly
//   colors.rgba8           RGBA per vertex (0..255), only when the input has vertex colours
//   triangles.u32          3 vertex ids per triangle, input order, degenerate triangles removed
//   triangle_objects.runs  object and material ids as runs: ObjectRun records, one per change of either
//   lines.u32 / line_objects.runs, points.u32 / point_objects.runs   likewise
//   store.json             written last: its presence means the store is complete
#pragma once

#include <array>
#include <optional>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/mesh.h"
#include "io/file_writer.h"

namespace lodstream::stream {

inline constexpr uint64_t store_chunk_elements = 1 << 20;
// 3: n-gons triangulated in their plane, faces naming two vertices kept as segments (was: fan).
// 4: material ids in the object runs, the material table in store.json.
inline constexpr int store_version = 4;

// Elements first, first + 1, ... up to the next run's `first` belong to `object`.
// `material` indexes StoreMeta::materials; it is 0 when the store has no materials, so that a store
// without them has the bytes it had before materials existed.
struct ObjectRun {
  uint64_t first;
  uint32_t object;
  uint32_t material;
};

// A run of objects within a batch of primitives: `first` counts from the batch's first primitive.
struct LocalRun {
  uint64_t first;
  uint32_t object;
  uint32_t material = 0;
};

struct Bbox {
  std::array<double, 3> min{0, 0, 0}, max{0, 0, 0};
  bool empty = true;
  void add(const Bbox& b) {
    if (b.empty) return;
    add(b.min.data());
    add(b.max.data());
  }
  void add(const float* p) {
    const double d[3] = {p[0], p[1], p[2]};
    add(d);
  }
  void add(const double* p) {
    if (empty) {
      min = max = {p[0], p[1], p[2]};
      empty = false;
      return;
    }
    for (int k = 0; k < 3; ++k) {
      if (p[k] < min[k]) min[k] = p[k];
      if (p[k] > max[k]) max[k] = p[k];
    }
  }
};

// Identity of the input a store was made from; a store is reused only when it matches.
struct SourceId {
  std::string path;  // absolute
  uint64_t bytes = 0;
  int64_t mtime_ns = 0;
  bool operator==(const SourceId&) const = default;
};

struct StoreMeta {
  SourceId source;
  std::string format;
  bool single_precision = false;  // positions.f32 rather than positions.f64
  uint64_t vertices = 0, triangles = 0, lines = 0, points = 0;
  uint64_t primitives() const { return triangles + lines + points; }
  uint64_t vertex_records = 0;  // vertex records in the file (STL: triangle corners before welding)
  uint64_t polygons = 0, degenerate = 0, degenerate_segments = 0, skipped = 0;
  uint64_t face_segments = 0;  // line segments made from faces (io::add_face), counted in `lines`
  uint64_t polygons_concave = 0;   // faces whose fan left them: cut along the other diagonal or by ear clipping
  uint64_t polygons_fallback = 0;  // faces with no plane or not simple: the fan of the file's order kept
  std::vector<std::string> object_names;
  uint64_t objects_used = 0;
  std::vector<core::Material> materials;  // empty: the input has none
  bool colors = false;                    // colors.rgba8 holds a colour per vertex
  Bbox bbox;
  // Chunk table: the bounding box of each vertex chunk.
  std::vector<Bbox> vertex_chunk_bbox;
};

// The store's source as stage keys record it: path, bytes, mtime_ns, format (a stage redone when it changes).
nlohmann::ordered_json source_json(const StoreMeta& m);

// A material as store.json (and a sharded run's task summary, stream/shard.h) records it.
nlohmann::ordered_json material_json(const core::Material& m);
core::Material material_from_json(const nlohmann::ordered_json& j);

class StoreWriter {
 public:
  StoreWriter(const std::string& dir, bool single_precision);
  // Appends vertices. `chunk_boxes` holds the bounding boxes of their parts that fall in each store
  // chunk, as {store chunk index, box}, computed by the caller (in parallel). `xyz32` is the same
  // coordinates as float, given (by the caller, in parallel) when the store is single precision.
  void add_vertices(std::span<const double> xyz, std::span<const float> xyz32,
                    std::span<const std::pair<uint64_t, Bbox>> chunk_boxes);
  void add_vertices(std::span<const double> xyz);
  // Appends vertices given as floats (single-precision stores only).
  void add_vertices32(std::span<const float> xyz32, std::span<const std::pair<uint64_t, Bbox>> chunk_boxes);
  // Appends primitives with their object runs (run `first` relative to ids' first primitive).
  void add_triangles(std::span<const uint32_t> ids, std::span<const LocalRun> runs);
  void add_lines(std::span<const uint32_t> ids, std::span<const LocalRun> runs);
  void add_points(std::span<const uint32_t> ids, std::span<const LocalRun> runs);
  // Appends RGBA colours, one per vertex, in vertex order (stores with colours only: the first call creates
  // colors.rgba8).
  void add_colors(std::span<const uint8_t> rgba);
  // Renames every column into place without writing store.json, so that a pass may still rewrite a column
  // in place (ingest's triangulation of planar faces); commit() then only writes store.json.
  void commit_columns();
  // Renames every column into place, then writes store.json. `meta`'s counts, bbox and chunk table are
  // filled in from what was written; returns the completed metadata (what store.json now holds).
  StoreMeta commit(StoreMeta meta);
  uint64_t vertices() const { return vertices_; }
  const Bbox& bbox() const { return bbox_; }

 private:
  void add_boxes(std::span<const std::pair<uint64_t, Bbox>> chunk_boxes);
  struct Column {
    io::FileWriter ids, runs;
    uint64_t count = 0;
    uint32_t last_object = UINT32_MAX, last_material = UINT32_MAX;
    void add(std::span<const uint32_t> values, int arity, std::span<const LocalRun> local_runs);
  };
  std::string dir_;
  bool single_;
  io::FileWriter positions_;
  std::optional<io::FileWriter> colors_;
  Column triangles_, lines_, points_;
  uint64_t vertices_ = 0;
  std::vector<float> scratch32_;
  Bbox bbox_;
  std::vector<Bbox> vertex_chunk_bbox_;
  bool columns_committed_ = false;
};

// Bounding boxes of the parts of `xyz` (vertices first_vertex, first_vertex + 1, ...) in each store chunk.
std::vector<std::pair<uint64_t, Bbox>> vertex_chunk_boxes(std::span<const double> xyz, uint64_t first_vertex);
std::vector<std::pair<uint64_t, Bbox>> vertex_chunk_boxes(std::span<const float> xyz, uint64_t first_vertex);

// The object runs of a primitive column ("triangle", "line" or "point"), whole (they are few: one per
// change of object or material).
std::vector<ObjectRun> read_object_runs(const std::string& dir, const std::string& kind);

// Reads store.json of a complete store; returns false when there is none (or it is unreadable or of
// another format version), so that the caller rebuilds it.
bool read_store_meta(const std::string& dir, StoreMeta* meta);

std::string store_meta_json(const StoreMeta& meta);

// The store's position column: DIR/positions.f32, or .f64 for a double store; a position's bytes there.
inline std::string positions_column_path(const std::string& dir, const StoreMeta& meta) {
  return dir + (meta.single_precision ? "/positions.f32" : "/positions.f64");
}
inline uint64_t position_bytes(bool single_precision) { return single_precision ? 12 : 24; }

}  // namespace lodstream::stream

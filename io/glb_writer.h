// Binary glTF 2.0 (GLB) writer holding every level of detail of a scene in one file, following the glTF 2.0
// specification (Khronos, "glTF 2.0 Specification", sections 3 and 4.4 GLB File Format) and the vendor
// extension MSFT_lod (KhronosGroup/glTF, extensions/2.0/Vendor/MSFT_lod) with its MSFT_screencoverage extras.
//
// Layout of the file:
// - one node per level, in the order given (node i = levels[i]); a level with something to draw also has
//   a mesh, a level with nothing gets a node without mesh;
// - with two levels or more, node 0 (the finest level) carries extensions.MSFT_lod.ids = [1, 2, ..., n-1]
//   (each id a lower level than the previous one) and extras.MSFT_screencoverage = one value per level,
//   node 0 first: level i is shown while the screen coverage is at least its value, and nothing is drawn
//   below the last value; extensionsUsed lists MSFT_lod. One level alone has neither;
// - one scene whose nodes are [0] (the lower levels are reached through MSFT_lod only);
// - per mesh up to three primitives, each with its own compacted vertex arrays (only the vertices it uses):
//   TRIANGLES (mode 4) with POSITION, NORMAL (when the mesh has normals) and uint32 indices;
//   LINES (mode 1) with POSITION and _THICKNESS (SCALAR float), two vertices per edge, both carrying the
//   edge's thickness (a vertex shared by edges of different thickness is thus repeated), no indices;
//   POINTS (mode 0) with POSITION and, when the level has point sizes, _SIZE (SCALAR float: the diameter
//   in scene units of what collapsed into the point, core/mesh.h; 0 = one pixel), one vertex per point, no
//   indices. An empty kind is left out;
// - without a material table: one material, {doubleSided: true}, used by every primitive;
// - with one (core/mesh.h; every level must carry the same table): the table as glTF materials (name,
//   baseColorFactor, metallicFactor, roughnessFactor, alphaMode and alphaCutoff when not opaque,
//   doubleSided), and per level one TRIANGLES, one LINES and one POINTS primitive per material used (all
//   triangle primitives first, in material order, then the lines, then the points), each with its own
//   compacted vertex arrays (and its own _SIZE accessor);
// - with vertex colours, COLOR_0 (normalized unsigned byte VEC4) on every primitive;
// - one buffer (the BIN chunk); one bufferView per accessor, 4-byte aligned, with its target.
// The bytes depend only on the arguments (no time stamps, fixed JSON key order).
//
// GlbBuilder writes the same file one level at a time, so that no two levels' meshes need to be held
// together: each level's BIN blocks go to a scratch file as the level is added (its accessors and views
// are planned then, at the running BIN offset), and finish() writes the header and JSON chunk and copies
// the scratch file in behind them. write_glb is a GlbBuilder given every level at once; both give the same
// bytes.
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "io/file_writer.h"

namespace lodstream::io {

struct GlbLevel {
  const core::LodMesh* mesh;
  std::string name;        // node and mesh name
  double screen_coverage;  // lower bound of the screen coverage at which this level is shown (MSFT_lod)
};

// Writes `levels` (finest first, at least one) to `path` (through `<path>.partial`, renamed when complete);
// `generator` goes to asset.generator. Throws Failure(io_error) when the file cannot be written,
// Failure(internal) for no levels, a non-finite screen coverage, or a mesh that breaks the conventions of
// core/mesh.h (array sizes, indices out of range).
// `sync`: Sync::none leaves flushing to the caller (3D Tiles: one syncfs for all tiles before tileset.json).
void write_glb(const std::string& path, std::span<const GlbLevel> levels, const std::string& generator,
               Sync sync = Sync::durable);

// A level given as its blocks rather than as a mesh, so that it need not be held (stream/level_files.h):
// the triangles' own vertex array (positions and, with `normals`, normals; with `colors`, RGBA), their
// indices into it, both ends of every edge with its thickness (and their colours), and the points (and
// theirs). Each block function writes exactly its block's bytes (count · 12 for vec3 blocks, indices 12 per
// triangle, positions 24, thickness 8 and colours 8 per edge, colours 4 per vertex or point, sizes 4 per point) through
// `write`, in one or more calls; the builder checks the lengths. Bounds: the min and max of each kind's
// positions (unused for a kind with none).
// Without a material table, the per-material blocks are asked once, with material 0, for all their
// primitives. With one (core/mesh.h; every level of a file the same), each kind has one primitive per
// material that has primitives of it (material_triangles, material_edges, material_points: counts per
// material; material_edge_bounds, material_point_bounds: min xyz then max xyz per material), and the
// per-material blocks are asked for each such material in material order, one block kind after the other
// (all triangle indices, then all edge positions, all edge thicknesses, all edge colours, all point
// positions, all point sizes, all point colours). The triangle primitives of a level share its triangle vertex array.
struct GlbStreamedLevel {
  using Write = std::function<void(const void*, size_t)>;
  using Block = std::function<void(const Write&)>;
  using MaterialBlock = std::function<void(uint32_t material, const Write&)>;
  std::string name;
  double screen_coverage = 0;
  uint64_t triangle_vertices = 0, triangles = 0, edges = 0, points = 0;
  bool normals = true;
  bool colors = false;
  float triangle_min[3], triangle_max[3], edge_min[3], edge_max[3], point_min[3], point_max[3];
  std::vector<core::Material> materials;
  std::vector<uint64_t> material_triangles, material_edges, material_points;
  std::vector<float> material_edge_bounds, material_point_bounds;
  Block triangle_positions, triangle_normals, triangle_colors;
  MaterialBlock triangle_indices, edge_positions, edge_thickness, edge_colors, point_positions, point_colors;
  MaterialBlock point_size;  // 4 bytes per point; none (empty function): no _SIZE attribute
};

class GlbBuilder {
 public:
  // `scratch`: where the BIN chunk is gathered (a path of its own, not created yet; removed by finish() and
  // by the destructor).
  GlbBuilder(std::string path, std::string scratch, std::string generator, Sync sync = Sync::durable);
  GlbBuilder(const GlbBuilder&) = delete;
  GlbBuilder& operator=(const GlbBuilder&) = delete;
  ~GlbBuilder();
  // Appends the next level (finest first); the mesh is not needed after the call. Failures as write_glb.
  void add(const GlbLevel& level);
  // The same for a level given by its blocks.
  void add(const GlbStreamedLevel& level);
  // Writes `path` (through `<path>.partial`); at least one level must have been added.
  void finish();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace lodstream::io

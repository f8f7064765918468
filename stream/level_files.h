// A level's files (lodN.ply, lodN.obj, its part of lods.glb) welded from its region parts without holding
// the level: each part's owned vertices and its primitives go to scratch files as the part arrives, the
// primitives with their vertices named by (cell, variant) (stream/emit_stage.h, RegionPart); the files are
// written when the last part is in, the names resolved through two tables of 4 bytes per cell.
//
// The welded mesh: every output vertex of the level once, numbered in region order, then cell order, then
// variant; triangles in region order, then in the order the emit stage gives a region's triangles; edges
// and points likewise. The GLB's triangle vertex array is the level's vertices that triangles use (those
// with a normal), in vertex order.
// With a material table, every primitive carries its material id (PLY material_index, OBJ usemtl with the
// MTL file, GLB one primitive per material and kind, io/glb_writer.h); the GLB's per-material blocks are
// gathered from the scratch files material by material, in passes that each hold at most kSweepBytes of
// output (materials grouped into runs that fit; a material larger than that streams straight through).
// With vertex colours, every vertex (and both ends of every edge, every point) carries its RGBA.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "io/file_writer.h"
#include "io/glb_writer.h"
#include "stream/emit_stage.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

class LevelFiles {
 public:
  // scratch: a path prefix for the scratch files (removed by the destructor), each named prefix + what +
  // suffix; cells: the level's cells; materials: the store's table (empty: none); colors: the parts carry
  // vertex colours.
  LevelFiles(std::string scratch, uint64_t cells, std::vector<core::Material> materials = {}, bool colors = false,
             std::string suffix = {});
  LevelFiles(const LevelFiles&) = delete;
  LevelFiles& operator=(const LevelFiles&) = delete;
  ~LevelFiles();
  // The parts, in region order.
  void add(const RegionPart& part);
  // After the last part.
  void close();
  uint64_t vertices() const { return vertices_; }
  bool has_materials() const { return !materials_.empty(); }
  void write_ply(const std::string& path, const std::vector<std::string>& comments) const;
  void write_obj(const std::string& path, const std::vector<std::string>& comments) const;
  // The level for io::GlbBuilder; its blocks read the scratch files (valid while this object lives).
  io::GlbStreamedLevel glb(const std::string& name, double screen_coverage) const;

 private:
  uint32_t vertex_id(uint64_t key) const;
  uint32_t triangle_vertex_id(uint64_t key) const;
  std::string path(const char* what) const { return scratch_ + what + suffix_; }
  std::string scratch_, suffix_;
  std::vector<uint32_t> first_vertex_, first_triangle_vertex_;  // per cell: the id of its variant 0
  std::vector<core::Material> materials_;
  bool colors_ = false;
  size_t vertex_bytes_, triangle_bytes_, edge_bytes_, point_bytes_;  // scratch record sizes
  io::FileWriter vertex_out_, triangle_out_, edge_out_, point_out_;
  uint64_t vertices_ = 0, triangle_vertices_ = 0, triangles_ = 0, edges_ = 0, points_ = 0;
  float bounds_[3][2][3];  // triangles, edges, points: min, max
  // With materials: per material its triangles, edges and points, and its edges' and points' bounds.
  std::vector<uint64_t> material_triangles_, material_edges_, material_points_;
  std::vector<float> material_edge_bounds_, material_point_bounds_;
};

// Writes a closed level's files side by side (tasks of the calling arena): `dir`/`stem`.ply and .obj when
// asked (the OBJ with its .mtl when the level has a material table), and its part of the GLB when `glb` is
// given (shown down to the screen coverage `lower`). Returns the files' names in `dir`, for the manifest.
// One machine's emit and the sharded run's merge write their levels so.
std::vector<std::string> write_level_outputs(const LevelFiles& level, const std::string& dir, const std::string& stem,
                         const std::vector<std::string>& comments, bool ply, bool obj, io::GlbBuilder* glb, double lower);

// The levels being welded while the emit stage hands out their parts (the levels of a group interleave):
// a level's LevelFiles opens with its first part, on scratch files of `work` named after `stem` and the
// level, and is taken, closed, after its last.
// With an output directory instead (OutputScratch), the scratch files of the levels of the output go there:
// STEMN.scratch-vertices.partial and so on (the level's PLY, OBJ and GLB data in the making, as the GLB's
// gathered binary data is; a killed run's are replaced by the rerun's, which removes them when the level
// is written), so that they do not add to the work directory's peak.
class OpenLevels {
 public:
  OpenLevels(const WorkDir& work, std::string stem, std::vector<uint64_t> cells,
             std::vector<core::Material> materials = {}, bool colors = false)
      : work_(&work), stem_(std::move(stem)), cells_(std::move(cells)), materials_(std::move(materials)), colors_(colors) {}
  struct OutputScratch {
    std::string dir;
  };
  OpenLevels(OutputScratch output, std::string stem, std::vector<uint64_t> cells, std::vector<core::Material> materials = {},
             bool colors = false)
      : output_dir_(std::move(output.dir)), stem_(std::move(stem)), cells_(std::move(cells)), materials_(std::move(materials)),
        colors_(colors) {}
  void add(size_t level, const RegionPart& part);
  // Fails (Status::internal) when the level had no part.
  std::unique_ptr<LevelFiles> take(size_t level);

 private:
  const WorkDir* work_ = nullptr;
  std::string output_dir_;  // without work_
  std::string stem_;
  std::vector<uint64_t> cells_;
  std::vector<core::Material> materials_;
  bool colors_ = false;
  std::map<size_t, std::unique_ptr<LevelFiles>> open_;
};

}  // namespace lodstream::stream

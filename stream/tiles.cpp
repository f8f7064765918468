// 3D Tiles 1.1 output from the level regions (see stream/tiles.h for the tree, the crack-free argument and
// the geometric error bound). Each part is written as soon as it arrives; only one small record per region
// is kept for the tree.
#include "stream/tiles.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>

#include <fcntl.h>
#include <unistd.h>

#include <fmt/format.h>

#include "core/status.h"
#include "core/octree_regions.h"
#include "core/thick_primitives.h"
#include "io/tileset_writer.h"

namespace lodstream::stream {

namespace {

struct Record {
  size_t level;
  TileRegion region;
  bool content = false;
  double min[3] = {0, 0, 0}, max[3] = {0, 0, 0};  // content bounds, glTF frame (scene units)
  double error = 0;       // own bound
  uint64_t vertices = 0, triangles = 0, edges = 0, points = 0, bytes = 0;
  std::string uri;
};

core::RegionKey node_of(const TileRegion& g) { return core::RegionKey{g.depth, g.x, g.y, g.z}; }

// How far snapping to the level's grid moves a point (0 for plain tiles, which are not snapped).
double snap_error(const TilesOptions& o, double cell_size) {
  return o.encoding == io::TileEncoding::plain ? 0 : std::sqrt(3.0) / 2 * tile_quantum(cell_size);
}

// A tile's own error bound (tiles.h): the cell diagonal, the thick primitives' radius, the float rounding of
// the scene's magnitude and the snapping (summed in this order, which the tileset's bytes depend on).
double own_error(const TilesOptions& o, double cell_size, double radius) {
  return std::sqrt(3.0) * cell_size + radius + std::ldexp(o.scene_magnitude, -23) + snap_error(o, cell_size);
}

}  // namespace

// c/32: snapping then adds at most sqrt(3)/2·c/32 < 0.03·c to the error bound (sqrt(3)·c), and a tile of
// a level spans at most 65,535 steps (SHORT positions) up to 1,024 cells across, wider than most regions.
double tile_quantum(double cell_size) { return io::power_of_two_below(cell_size / 32); }

std::vector<core::SideBound> tile_side_bounds(std::span<const double> cell_sizes, std::span<const uint64_t> cells,
                                              double cube_side) {
  std::vector<core::SideBound> bounds(cell_sizes.size());
  for (size_t l = 1; l < cell_sizes.size(); ++l) {
    const double side = kTileSideCells * cell_sizes[l];
    unsigned d = 0;
    while (d < core::kMaxRegionDepth && std::ldexp(cube_side, -static_cast<int>(d)) > side) ++d;
    bounds[l].min_depth = d;
    const double per_cell = cells[l] > 0 ? static_cast<double>(cells[l - 1]) / static_cast<double>(cells[l]) : 1;
    bounds[l].min_cells = static_cast<uint64_t>(static_cast<double>(kTileChildCells) / std::max(per_cell, 1.0));
  }
  return bounds;
}

struct TilesetBuilder::State {
  TilesOptions o;
  std::vector<Record> records;
};

TilesetBuilder::TilesetBuilder(TilesOptions options) : state_(std::make_unique<State>()) {
  state_->o = std::move(options);
  std::error_code ec;
  std::filesystem::remove_all(state_->o.dir, ec);
  std::filesystem::create_directories(state_->o.dir, ec);
  if (ec) fail(Status::io_error, state_->o.dir + ": cannot create the tiles directory: " + ec.message());
}

TilesetBuilder::~TilesetBuilder() = default;

void TilesetBuilder::add(size_t level, const TileRegion& region, const core::LodMesh& part) {
  State& s = *state_;
  if (level >= s.o.levels) fail(Status::internal, "tiles: level out of range");
  Record r;
  r.level = level;
  r.region = region;
  r.vertices = part.vertex_count();
  r.triangles = part.triangle_count();
  r.edges = part.edge_count();
  r.points = part.point_count();
  double radius = 0;
  if (part.triangles.empty() && part.edges.empty() && part.points.empty()) {
    s.records.push_back(std::move(r));
    return;
  }
  core::LodMesh expanded;
  const core::LodMesh* content = &part;
  if (s.o.thick && (!part.edges.empty() || !part.points.empty())) {
    const double pixel = region.cell_size / s.o.pixels_per_cell;  // one pixel at the level's switching distance
    expanded = core::expand_thick(part, {pixel, pixel / 2}, &radius);
    content = &expanded;
  }
  r.content = true;
  for (int k = 0; k < 3; ++k) r.min[k] = INFINITY, r.max[k] = -INFINITY;
  // The bounds of what is drawn: the vertices the primitives use (a part holds no other), as snapped.
  const double quantum = tile_quantum(region.cell_size);
  for (uint64_t v = 0; v < content->vertex_count(); ++v)
    for (int k = 0; k < 3; ++k) {
      const float f = content->positions[3 * v + k];
      const double x = s.o.encoding == io::TileEncoding::plain ? f : io::snap_to_grid(f, quantum);
      r.min[k] = std::min(r.min[k], x);
      r.max[k] = std::max(r.max[k], x);
    }
  r.error = own_error(s.o, region.cell_size, radius);
  const std::string dir = fmt::format("lod{}", level);
  r.uri = fmt::format("{}/{}_{}_{}_{}.glb", dir, region.depth, region.x, region.y, region.z);
  std::error_code ec;
  std::filesystem::create_directories(s.o.dir + "/" + dir, ec);
  if (ec) fail(Status::io_error, s.o.dir + "/" + dir + ": cannot create: " + ec.message());
  r.bytes = io::write_tile_glb(s.o.dir + "/" + r.uri, *content, fmt::format("lod{} {}", level, r.uri), s.o.generator, quantum,
                               s.o.encoding);
  r.triangles = content->triangle_count();
  if (s.o.thick) r.edges = r.points = 0;
  s.records.push_back(std::move(r));
}

TilesSummary TilesetBuilder::finish() {
  State& s = *state_;
  std::vector<Record>& recs = s.records;
  const size_t n = recs.size();
  // (level, depth, region code) -> record, to find each region's parent: the coarser level's region that is
  // its ancestor or itself.
  std::map<std::tuple<size_t, int, uint64_t>, uint32_t> index;
  for (uint32_t i = 0; i < n; ++i) {
    const TileRegion& g = recs[i].region;
    if (!index.emplace(std::make_tuple(recs[i].level, int{g.depth}, core::region_code(node_of(g))), i).second)
      fail(Status::internal, "tiles: a region was reported twice");
  }
  const size_t coarsest = s.o.levels - 1;
  constexpr uint32_t kNone = UINT32_MAX;
  std::vector<uint32_t> parent(n, kNone);
  for (uint32_t i = 0; i < n; ++i) {
    if (recs[i].level == coarsest) continue;
    for (core::RegionKey k = node_of(recs[i].region);; k = core::region_parent(k)) {
      const auto it = index.find(std::make_tuple(recs[i].level + 1, int{k.depth}, core::region_code(k)));
      if (it != index.end()) {
        parent[i] = it->second;
        break;
      }
      if (k.depth == 0) break;
    }
    if (parent[i] == kNone) fail(Status::internal, "tiles: a region lies in no region of the coarser level (the cuts do not nest)");
  }
  // Finest first: a tile is kept when it has content or a kept child; its box and error take in its kept
  // children's. Records are grouped by level in any order, so visit by level.
  std::vector<uint32_t> by_level(n);
  for (uint32_t i = 0; i < n; ++i) by_level[i] = i;
  std::stable_sort(by_level.begin(), by_level.end(), [&](uint32_t a, uint32_t b) { return recs[a].level < recs[b].level; });
  std::vector<char> kept(n, 0);
  std::vector<double> error(n, 0);
  std::vector<std::array<double, 6>> box(n);
  for (uint32_t i = 0; i < n; ++i) {
    error[i] = recs[i].error;
    for (int k = 0; k < 3; ++k) box[i][k] = recs[i].content ? recs[i].min[k] : INFINITY, box[i][3 + k] = recs[i].content ? recs[i].max[k] : -INFINITY;
    kept[i] = recs[i].content;
  }
  for (uint32_t i : by_level) {
    if (!kept[i] || parent[i] == kNone) continue;
    const uint32_t p = parent[i];
    kept[p] = 1;
    error[p] = std::max(error[p], error[i]);
    for (int k = 0; k < 3; ++k) box[p][k] = std::min(box[p][k], box[i][k]), box[p][3 + k] = std::max(box[p][3 + k], box[i][3 + k]);
  }
  // A tile without content takes its level's bound (its region's primitives, none, lie within it of the
  // original there as anywhere in the level).
  for (uint32_t i = 0; i < n; ++i)
    if (!recs[i].content) error[i] = std::max(error[i], own_error(s.o, recs[i].region.cell_size, 0));

  io::Tileset ts;
  ts.generator = s.o.generator;
  ts.transform = s.o.transform;
  ts.asset_extras = {{"up_axis", "content glTF Y-up, rotated to the tileset's Z-up by the runtime"},
                     {"units", "scene units (as the input)"}};
  std::vector<uint32_t> tile_of(n, kNone);
  const double min_half = std::max(s.o.cube_side * 1e-9, 1e-30);
  for (uint32_t i = 0; i < n; ++i) {
    if (!kept[i]) continue;
    tile_of[i] = static_cast<uint32_t>(ts.tiles.size());
    io::TilesetTile t;
    const double lo[3] = {box[i][0], box[i][1], box[i][2]}, hi[3] = {box[i][3], box[i][4], box[i][5]};
    t.box = io::to_tileset_frame(lo, hi, min_half);
    t.geometric_error = error[i];
    t.content_uri = recs[i].uri;
    const Record& r = recs[i];
    t.extras = {{"level", static_cast<double>(r.level)},
                {"cell_size", r.region.cell_size},
                {"quantum", s.o.encoding == io::TileEncoding::plain ? 0.0 : tile_quantum(r.region.cell_size)},
                {"depth", r.region.depth},
                {"cells", static_cast<double>(r.region.cells)},
                {"vertices", static_cast<double>(r.vertices)},
                {"triangles", static_cast<double>(r.triangles)},
                {"edges", static_cast<double>(r.edges)},
                {"points", static_cast<double>(r.points)}};
    ts.tiles.push_back(std::move(t));
  }
  // Children in record order (regions in region order within a level).
  std::vector<uint32_t> roots;
  for (uint32_t i = 0; i < n; ++i) {
    if (!kept[i]) continue;
    if (parent[i] == kNone) roots.push_back(tile_of[i]);
    else ts.tiles[tile_of[parent[i]]].children.push_back(tile_of[i]);
  }
  TilesSummary sum;
  double diagonal = std::sqrt(3.0) * s.o.cube_side;
  if (roots.size() == 1 && recs[std::find(tile_of.begin(), tile_of.end(), roots[0]) - tile_of.begin()].region.depth == 0) {
    ts.root = roots[0];
  } else {
    // A root without content over the coarsest regions: refined whenever the scene is seen (its error, the
    // scene cube's diagonal, is what drawing nothing costs).
    io::TilesetTile t;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double e = 0;
    for (uint32_t i = 0; i < n; ++i)
      if (kept[i] && parent[i] == kNone) {
        for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], box[i][k]), hi[k] = std::max(hi[k], box[i][3 + k]);
        e = std::max(e, error[i]);
      }
    if (roots.empty()) {  // nothing drawn at all: an empty scene cube
      for (int k = 0; k < 3; ++k) lo[k] = s.o.cube_min[k], hi[k] = s.o.cube_min[k] + s.o.cube_side;
    }
    t.box = io::to_tileset_frame(lo, hi, min_half);
    t.geometric_error = std::max(diagonal, e);
    t.children = roots;
    ts.root = static_cast<uint32_t>(ts.tiles.size());
    ts.tiles.push_back(std::move(t));
  }
  ts.geometric_error = std::max(diagonal, ts.tiles[ts.root].geometric_error);
  // The tiles were written without a sync each (hundreds of fsyncs took seconds): one syncfs makes them all
  // durable before tileset.json, written durably last, says they are complete.
  const int fd = ::open(s.o.dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0 || ::syncfs(fd) != 0) {
    if (fd >= 0) ::close(fd);
    fail(Status::io_error, s.o.dir + ": cannot flush the tiles to disk");
  }
  ::close(fd);
  const std::string path = s.o.dir + "/tileset.json";
  io::write_tileset(path, ts);
  sum.tiles = ts.tiles.size();
  for (const Record& r : recs)
    if (r.content) {
      ++sum.content_tiles;
      sum.bytes += r.bytes;
      sum.triangles += r.triangles;
      sum.max_triangles = std::max(sum.max_triangles, r.triangles);
    }
  std::error_code ec;
  sum.bytes += std::filesystem::file_size(path, ec);
  return sum;
}

std::vector<double> enu_transform(double lon_degrees, double lat_degrees, double height) {
  constexpr double a = 6378137.0, f = 1 / 298.257223563;  // WGS84
  const double e2 = f * (2 - f);
  const double lon = lon_degrees * M_PI / 180, lat = lat_degrees * M_PI / 180;
  const double sl = std::sin(lat), cl = std::cos(lat), so = std::sin(lon), co = std::cos(lon);
  const double nr = a / std::sqrt(1 - e2 * sl * sl);
  return {-so,      co,       0,  0,   // east
          -sl * co, -sl * so, cl, 0,   // north
          cl * co,  cl * so,  sl, 0,   // up
          (nr + height) * cl * co, (nr + height) * cl * so, (nr * (1 - e2) + height) * sl, 1};
}

std::vector<double> z_up_transform(const std::vector<double>& t) {
  // Content (x, y, z) arrives in the tileset frame as (x, -z, y); R (a, b, c) = (a, c, -b) takes it back to
  // (x, y, z). Column-major: R e_x = e_x, R e_y = -e_z, R e_z = e_y.
  const double r[16] = {1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1};
  if (t.empty()) return std::vector<double>(r, r + 16);
  std::vector<double> m(16, 0);
  for (int col = 0; col < 4; ++col)
    for (int row = 0; row < 4; ++row)
      for (int k = 0; k < 4; ++k) m[4 * col + row] += t[4 * k + row] * r[4 * col + k];
  return m;
}

}  // namespace lodstream::stream

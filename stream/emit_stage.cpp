// Stage 5: emit one level. See emit_stage.h for the rules.
#include "stream/emit_stage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>
#include <tbb/task_arena.h>

#include "core/normals.h"
#include "core/quadric.h"
#include "core/status.h"
#include "io/mapped_file.h"
#include "stream/cluster_stage.h"
#include "stream/flat_map.h"
#include "stream/store_access.h"

namespace lodstream::stream {

namespace {

// Fixed block size: sums are formed per block and merged in block order, so it must not depend on the
// memory plan or the thread count.
constexpr uint64_t kEmitBlock = 1 << 16;

struct EdgeSums {
  double a[3] = {0, 0, 0}, b[3] = {0, 0, 0};  // corner positions in the edge's lower cell (a), higher (b)
  uint64_t na = 0, nb = 0;
};
struct Distances {
  double a = 0, b = 0;
};

struct Block {
  int kind = 0;  // 0 triangles, 1 segments, 2 points
  uint64_t first = 0, count = 0;
};

struct BlockOut {
  std::vector<std::array<uint32_t, 3>> triangles;  // input winding
  std::vector<std::array<uint32_t, 2>> edges;      // lower cell first
  std::vector<uint32_t> points;
  std::vector<uint32_t> quadric_cells;
  std::vector<core::Quadric> quadrics;
  std::vector<uint32_t> kept_edges;  // passes B and C: kept edge ids, and per id its sums (B) or distances (C)
  std::vector<EdgeSums> sums;
  std::vector<Distances> distances;
  void clear() {
    triangles.clear(), edges.clear(), sums.clear(), points.clear();
    quadric_cells.clear(), quadrics.clear(), kept_edges.clear(), distances.clear();
  }
};

struct Scratch {
  FlatMap<3, false> triangles;
  FlatMap<2> edges;
  FlatMap<1, false> points;
  FlatMap<1> cells;  // pass A: a cell's quadric slot; passes B and C: a kept edge's slot
  void clear() { triangles.clear(), edges.clear(), points.clear(), cells.clear(); }
};

void add(double* sum, const double* p) {
  sum[0] += p[0], sum[1] += p[1], sum[2] += p[2];
}

double distance_to_line(const double* x, const double* a, const double* b) {
  const double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double v[3] = {x[0] - a[0], x[1] - a[1], x[2] - a[2]};
  const double len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  if (!(len2 > 0)) return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const double c[3] = {v[1] * d[2] - v[2] * d[1], v[2] * d[0] - v[0] * d[2], v[0] * d[1] - v[1] * d[0]};
  return std::sqrt((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) / len2);
}

}  // namespace

EmitCounts emit_level(const std::string& store_dir, const StoreMeta& meta, const std::string& canonical_path,
                      const std::string& prefix, size_t level, uint64_t records, uint64_t cells, double cell_size,
                      const core::ClusterOptions& cluster, const EmitOptions& options, Progress& progress,
                      EmitScratch& level_scratch, core::LodMesh* out) {
  // The level's cluster map: stored vertex id -> cell.
  std::vector<uint32_t>& map = level_scratch.map;
  map.assign(meta.vertices, core::kNoCell);
  {
    io::MappedFile order(order_path(prefix)), cell_file(cells_path(prefix, level));
    if (order.size() != records * 4 || cell_file.size() != records * 4)
      fail(Status::io_error, cell_file.path() + ": size does not match the weight index");
    for (uint64_t first = 0; first < records; first += 1 << 20) {
      const uint64_t n = std::min<uint64_t>(1 << 20, records - first);
      const io::Window a = order.map(first * 4, (first + n) * 4), b = cell_file.map(first * 4, (first + n) * 4);
      const uint32_t* ids = reinterpret_cast<const uint32_t*>(a.data());
      const uint32_t* cs = reinterpret_cast<const uint32_t*>(b.data());
      for (uint64_t i = 0; i < n; ++i) map[ids[i]] = cs[i];
    }
    if (!canonical_path.empty())
      for_column_blocks(canonical_path, meta.vertices, 1, 1 << 20, [&](uint64_t first, std::span<const uint32_t> canon) {
        for (uint64_t i = 0; i < canon.size(); ++i)
          if (canon[i] != first + i) map[first + i] = map[canon[i]];
      });
  }

  StorePositions positions(store_dir, meta);
  positions.acquire();
  const std::string column_path[3] = {store_dir + "/triangles.u32", store_dir + "/lines.u32", store_dir + "/points.u32"};
  const uint64_t column_count[3] = {meta.triangles, meta.lines, meta.points};
  std::unique_ptr<io::MappedFile> columns[3];
  std::vector<Block> blocks;
  for (int kind = 0; kind < 3; ++kind) {
    if (column_count[kind] == 0) continue;
    columns[kind] = std::make_unique<io::MappedFile>(column_path[kind]);
    if (columns[kind]->size() != column_count[kind] * 4 * static_cast<uint64_t>(3 - kind))
      fail(Status::io_error, column_path[kind] + ": size does not match store.json");
    for (uint64_t first = 0; first < column_count[kind]; first += kEmitBlock)
      blocks.push_back({kind, first, std::min(kEmitBlock, column_count[kind] - first)});
  }
  const bool quadric = options.representative == Representative::quadric && !options.count_only;

  auto cell_of = [&](uint32_t v) {
    const uint32_t c = map[v];
    if (c == core::kNoCell) fail(Status::internal, "emit: vertex " + std::to_string(v) + " has no cell");
    return c;
  };

  // Runs `work(block, out, scratch)` over the blocks in parallel groups, and `merge(out)` in block order:
  // group g's outputs are merged (one thread) while group g + 1 runs (the others), so the two sets of
  // outputs alternate. Merges stay serial and in block order, so this changes no sum.
  tbb::enumerable_thread_specific<Scratch> scratch;
  const size_t group = 4 * static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  std::vector<BlockOut> outs[2] = {std::vector<BlockOut>(group), std::vector<BlockOut>(group)};
  auto run_blocks = [&](const char* stage, bool segments_and_triangles_only, auto&& work, auto&& merge) {
    size_t merged = 0;  // blocks merged so far
    for (size_t g = 0, k = 0; g < blocks.size() || merged < blocks.size(); g += group, ++k) {
      progress.check();
      const size_t n = g < blocks.size() ? std::min(group, blocks.size() - g) : 0;
      std::vector<BlockOut>& current = outs[k % 2];
      std::vector<BlockOut>& previous = outs[(k + 1) % 2];
      const size_t before = std::min(g, blocks.size());  // the blocks of the groups before g
      tbb::task_group merging;
      if (merged < before) merging.run([&] {
        for (size_t i = 0; merged + i < before; ++i) merge(previous[i]);
      });
      tbb::parallel_for(size_t{0}, n, [&](size_t i) {
        const Block& b = blocks[g + i];
        BlockOut& o = current[i];
        o.clear();
        if (segments_and_triangles_only && b.kind == 2) return;
        const uint64_t arity = static_cast<uint64_t>(3 - b.kind);
        const io::Window w = columns[b.kind]->map(b.first * arity * 4, (b.first + b.count) * arity * 4);
        Scratch& s = scratch.local();
        s.clear();
        work(b, std::span<const uint32_t>(reinterpret_cast<const uint32_t*>(w.data()), b.count * arity), o, s);
      });
      merging.wait();
      merged = before;
      // Drop the position pages this group touched from the resident set (they stay in the page cache).
      positions.release();
      positions.acquire();
      if (merged > 0) progress.report(stage, static_cast<double>(merged) / static_cast<double>(blocks.size()));
    }
  };

  // Pass A: classify, dedupe per block, sum quadrics.
  FlatMap<3, false> g_triangles;
  FlatMap<2> g_edges;
  FlatMap<1, false> g_points;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<std::array<uint32_t, 2>> edges;
  std::vector<uint32_t> points;
  std::vector<core::Quadric> quadrics(quadric ? cells : 0);
  // One bit per input triangle and segment that collapsed to an edge, so that passes B and C visit only
  // those. Blocks start at multiples of 64 primitives: each word is written by one block, hence one thread.
  static_assert(kEmitBlock % 64 == 0);
  std::vector<uint64_t> collapsed[2];
  for (int kind = 0; kind < 2; ++kind)
    if (!options.count_only) collapsed[kind].assign((column_count[kind] + 63) / 64, 0);
  auto mark = [&](const Block& b, size_t i) {
    if (options.count_only) return;
    const uint64_t p = b.first + i;
    collapsed[b.kind][p / 64] |= uint64_t{1} << (p % 64);
  };

  auto classify = [&](const Block& b, std::span<const uint32_t> ids, BlockOut& o, Scratch& s) {
    auto edge = [&](uint32_t c0, uint32_t c1) {
      const std::array<uint32_t, 2> key{std::min(c0, c1), std::max(c0, c1)};
      if (s.edges.insert(key, 0).second) o.edges.push_back(key);
    };
    auto point = [&](uint32_t c) {
      if (s.points.insert({c}, 0).second) o.points.push_back(c);
    };
    const size_t arity = static_cast<size_t>(3 - b.kind);
    for (size_t i = 0; i < ids.size(); i += arity) {
      if (arity == 3) {
        const uint32_t v[3] = {ids[i], ids[i + 1], ids[i + 2]};
        const uint32_t c[3] = {cell_of(v[0]), cell_of(v[1]), cell_of(v[2])};
        if (quadric) {
          double p[3][3];
          for (int k = 0; k < 3; ++k) positions.get(v[k], p[k]);
          core::Quadric q;
          q.add_triangle(p[0], p[1], p[2]);
          for (int k = 0; k < 3; ++k) {
            if ((k > 0 && c[k] == c[0]) || (k > 1 && c[k] == c[1])) continue;
            const auto [slot, fresh] = s.cells.insert({c[k]}, static_cast<uint32_t>(o.quadrics.size()));
            if (fresh) o.quadric_cells.push_back(c[k]), o.quadrics.push_back(q);
            else o.quadrics[slot].add(q);
          }
        }
        if (c[0] != c[1] && c[1] != c[2] && c[0] != c[2]) {
          std::array<uint32_t, 3> key{c[0], c[1], c[2]};
          std::sort(key.begin(), key.end());
          if (s.triangles.insert(key, 0).second) o.triangles.push_back({c[0], c[1], c[2]});
        } else if (c[0] == c[1] && c[1] == c[2]) {
          point(c[0]);
        } else {
          edge(c[0], c[0] != c[1] ? c[1] : c[2]);
          mark(b, i / 3);
        }
      } else if (arity == 2) {
        const uint32_t c0 = cell_of(ids[i]), c1 = cell_of(ids[i + 1]);
        if (c0 == c1) {
          point(c0);
        } else {
          edge(c0, c1);
          mark(b, i / 2);
        }
      } else {
        point(cell_of(ids[i]));
      }
    }
  };
  run_blocks("emit", false, classify, [&](BlockOut& o) {
    for (const auto& t : o.triangles) {
      std::array<uint32_t, 3> key = t;
      std::sort(key.begin(), key.end());
      if (g_triangles.insert(key, 0).second) triangles.push_back(t);
    }
    for (const auto& e : o.edges)
      if (g_edges.insert(e, static_cast<uint32_t>(edges.size())).second) edges.push_back(e);
    for (uint32_t c : o.points)
      if (g_points.insert({c}, 0).second) points.push_back(c);
    for (size_t i = 0; i < o.quadric_cells.size(); ++i) quadrics[o.quadric_cells[i]].add(o.quadrics[i]);
  });

  EmitCounts counts;
  if (options.count_only) {
    counts.triangles = triangles.size();
    counts.edges = edges.size();
    counts.points = points.size();
    return counts;
  }

  // Elimination, before the thickness passes, which then measure the kept edges only. Edges are few next to
  // triangle sides: look each side up among the edges.
  g_triangles = FlatMap<3, false>();
  g_points = FlatMap<1, false>();
  std::vector<uint8_t> on_triangle(edges.size(), 0);
  std::vector<uint8_t> used(cells, 0);
  for (const auto& t : triangles)
    for (int k = 0; k < 3; ++k) {
      used[t[k]] = 1;
      if (edges.empty()) continue;
      const uint32_t e = g_edges.find({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
      if (e != FlatMap<2>::empty) on_triangle[e] = 1;
    }
  g_edges = FlatMap<2>();
  // The kept edges, in edge order; k_edges finds them by cells.
  std::vector<std::array<uint32_t, 2>> kept_edges;
  FlatMap<2> k_edges;
  for (size_t i = 0; i < edges.size(); ++i) {
    if (on_triangle[i]) {
      ++counts.edges_on_triangles;
      continue;
    }
    k_edges.insert(edges[i], static_cast<uint32_t>(kept_edges.size()));
    kept_edges.push_back(edges[i]);
    used[edges[i][0]] = used[edges[i][1]] = 1;
  }
  std::vector<std::array<uint32_t, 2>>().swap(edges);
  std::vector<uint8_t>().swap(on_triangle);
  std::vector<uint32_t> kept_points;
  for (uint32_t c : points) {
    if (used[c]) {
      ++counts.points_covered;
      continue;
    }
    kept_points.push_back(c);
  }
  std::vector<uint8_t>().swap(used);

  // Passes B and C visit the input triangles and segments that collapsed to a kept edge (an eliminated
  // edge's thickness would go unused). For each, `visit(corner ids, their cells, arity, lower cell, kept
  // edge, slot, o)` gets the edge's slot in the block's output (o.kept_edges with o.sums or o.distances, in
  // order of first appearance), so that sums are formed per block in primitive order and merged in block
  // order.
  auto for_kept_edges = [&](auto&& visit) {
    return [&, visit](const Block& b, std::span<const uint32_t> ids, BlockOut& o, Scratch& s) {
      const size_t arity = static_cast<size_t>(3 - b.kind);
      const uint64_t* bits = collapsed[b.kind].data();
      for (size_t i = 0; i < ids.size(); i += arity) {
        const uint64_t prim = b.first + i / arity;
        if (!(bits[prim / 64] >> (prim % 64) & 1)) continue;
        uint32_t c[3], lo = UINT32_MAX, hi = 0;
        for (size_t k = 0; k < arity; ++k) c[k] = cell_of(ids[i + k]), lo = std::min(lo, c[k]), hi = std::max(hi, c[k]);
        const uint32_t e = k_edges.find({lo, hi});
        if (e == FlatMap<2>::empty) continue;
        const auto [slot, fresh] = s.cells.insert({e}, static_cast<uint32_t>(o.kept_edges.size()));
        if (fresh) o.kept_edges.push_back(e), o.sums.emplace_back(), o.distances.emplace_back();
        visit(&ids[i], c, arity, lo, e, slot, o);
      }
    };
  };

  // Pass B: the corner sums of the kept edges, for P_A and P_B (a corner in the lower cell goes to A).
  std::vector<EdgeSums> kept_sums(kept_edges.size());
  if (!kept_edges.empty()) {
    run_blocks("emit", true,
               for_kept_edges([&](const uint32_t* v, const uint32_t* c, size_t arity, uint32_t lo, uint32_t, uint32_t slot,
                                  BlockOut& o) {
                 EdgeSums& e = o.sums[slot];
                 for (size_t k = 0; k < arity; ++k) {
                   double p[3];
                   positions.get(v[k], p);
                   if (c[k] == lo) add(e.a, p), ++e.na;
                   else add(e.b, p), ++e.nb;
                 }
               }),
               [&](BlockOut& o) {
                 for (size_t i = 0; i < o.kept_edges.size(); ++i) {
                   EdgeSums& e = kept_sums[o.kept_edges[i]];
                   add(e.a, o.sums[i].a), add(e.b, o.sums[i].b);
                   e.na += o.sums[i].na, e.nb += o.sums[i].nb;
                 }
               });
  }

  // Pass C: mean distances of the collapsed corners to the line through the mean positions.
  std::vector<std::array<double, 3>> pa(kept_edges.size()), pb(kept_edges.size());
  for (size_t i = 0; i < kept_edges.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      pa[i][k] = kept_sums[i].na ? kept_sums[i].a[k] / static_cast<double>(kept_sums[i].na) : 0;
      pb[i][k] = kept_sums[i].nb ? kept_sums[i].b[k] / static_cast<double>(kept_sums[i].nb) : 0;
    }
  std::vector<Distances> distances(kept_edges.size());
  if (!kept_edges.empty()) {
    run_blocks("emit", true,
               for_kept_edges([&](const uint32_t* v, const uint32_t* c, size_t arity, uint32_t lo, uint32_t e, uint32_t slot,
                                  BlockOut& o) {
                 for (size_t k = 0; k < arity; ++k) {
                   double p[3];
                   positions.get(v[k], p);
                   const double d = distance_to_line(p, pa[e].data(), pb[e].data());
                   if (c[k] == lo) o.distances[slot].a += d;
                   else o.distances[slot].b += d;
                 }
               }),
               [&](BlockOut& o) {
                 for (size_t i = 0; i < o.kept_edges.size(); ++i) {
                   distances[o.kept_edges[i]].a += o.distances[i].a;
                   distances[o.kept_edges[i]].b += o.distances[i].b;
                 }
               });
  }
  positions.release();
  for (auto& bits : collapsed) std::vector<uint64_t>().swap(bits);
  k_edges = FlatMap<2>();
  std::vector<float> thickness(kept_edges.size());
  for (size_t i = 0; i < kept_edges.size(); ++i) {
    const double da = kept_sums[i].na ? distances[i].a / static_cast<double>(kept_sums[i].na) : 0;
    const double db = kept_sums[i].nb ? distances[i].b / static_cast<double>(kept_sums[i].nb) : 0;
    thickness[i] = static_cast<float>(da + db);
  }

  // The cells in use, numbered in order of first use: triangle corners, then edge and point ends.
  std::vector<uint32_t> slot_of(cells, UINT32_MAX);
  std::vector<uint32_t> slot_cell;
  auto use = [&](uint32_t c) {
    if (slot_of[c] == UINT32_MAX) slot_of[c] = static_cast<uint32_t>(slot_cell.size()), slot_cell.push_back(c);
    return slot_of[c];
  };
  std::vector<uint32_t> tri_slots;
  tri_slots.reserve(3 * triangles.size());
  for (const auto& t : triangles)
    for (uint32_t c : t) tri_slots.push_back(use(c));
  std::vector<std::array<uint32_t, 3>>().swap(triangles);
  const size_t triangle_slots = slot_cell.size();
  for (const auto& e : kept_edges) use(e[0]), use(e[1]);
  for (uint32_t c : kept_points) use(c);

  // Their representatives, reading the cell table in cell order through windows (only the cells in use).
  std::vector<double> rep(3 * slot_cell.size());
  {
    std::vector<std::pair<uint32_t, uint32_t>> need(slot_cell.size());
    for (size_t i = 0; i < slot_cell.size(); ++i) need[i] = {slot_cell[i], static_cast<uint32_t>(i)};
    std::sort(need.begin(), need.end());
    io::MappedFile f(cell_info_path(prefix, level));
    if (f.size() != cells * sizeof(CellInfo)) fail(Status::io_error, f.path() + ": size does not match");
    constexpr uint64_t window_cells = 1 << 16;
    io::Window w;
    uint64_t window_first = 0;
    for (const auto& [c, slot] : need) {
      if (!w.data() || c >= window_first + window_cells) {
        window_first = c - c % window_cells;
        w = f.map(window_first * sizeof(CellInfo), (window_first + window_cells) * sizeof(CellInfo));
      }
      CellInfo ci;
      std::memcpy(&ci, w.data() + (c - window_first) * sizeof(CellInfo), sizeof ci);
      double* p = &rep[3 * slot];
      double mean[3];
      for (int k = 0; k < 3; ++k) mean[k] = ci.sum[k] / static_cast<double>(ci.vertices);
      if (options.representative == Representative::center) {
        std::copy(ci.center, ci.center + 3, p);
      } else if (options.representative == Representative::mean) {
        for (int k = 0; k < 3; ++k) p[k] = ci.weight > 0 ? ci.weighted[k] / ci.weight : mean[k];
      } else {
        double lo[3], hi[3];
        for (int k = 0; k < 3; ++k) {
          if (cluster.clustering == core::Clustering::uniform) {
            const double sq = static_cast<double>(core::grid_square(ci.center[k], cell_size));
            lo[k] = sq * cell_size, hi[k] = (sq + 1) * cell_size;
          } else {
            lo[k] = ci.center[k] - cell_size / 2, hi[k] = ci.center[k] + cell_size / 2;
          }
        }
        const std::array<double, 3> x = core::quadric_minimizer(quadrics[c], mean, lo, hi);
        std::copy(x.begin(), x.end(), p);
      }
    }
  }
  std::vector<core::Quadric>().swap(quadrics);

  // Output vertices: triangle corners split by normal (core/normals.h), then edge and point ends, which
  // reuse a triangle vertex of their cell when there is one.
  core::LodMesh mesh;
  core::CreaseNormals normals;
  core::crease_normals(std::span<const double>(rep.data(), 3 * triangle_slots), tri_slots,
                       options.normals ? options.crease_degrees : 180.0, normals);
  std::vector<uint32_t>().swap(tri_slots);
  mesh.positions.reserve(3 * (normals.vertex.size() + slot_cell.size() - triangle_slots));
  for (uint32_t v : normals.vertex)
    for (int k = 0; k < 3; ++k) mesh.positions.push_back(static_cast<float>(rep[3 * v + k]));
  mesh.normals = std::move(normals.normals);
  mesh.triangles = std::move(normals.triangles);
  std::vector<uint32_t> out_vertex(slot_cell.size(), UINT32_MAX);
  for (size_t i = 0; i < normals.vertex.size(); ++i)
    if (out_vertex[normals.vertex[i]] == UINT32_MAX) out_vertex[normals.vertex[i]] = static_cast<uint32_t>(i);
  std::vector<uint32_t>().swap(normals.vertex);
  auto end_vertex = [&](uint32_t c) {
    const uint32_t slot = slot_of[c];
    if (out_vertex[slot] == UINT32_MAX) {
      out_vertex[slot] = static_cast<uint32_t>(mesh.positions.size() / 3);
      for (int k = 0; k < 3; ++k) mesh.positions.push_back(static_cast<float>(rep[3 * slot + k])), mesh.normals.push_back(0.0f);
    }
    return out_vertex[slot];
  };
  for (const auto& e : kept_edges) {
    mesh.edges.push_back(end_vertex(e[0]));
    mesh.edges.push_back(end_vertex(e[1]));
  }
  mesh.thickness = std::move(thickness);
  for (uint32_t c : kept_points) mesh.points.push_back(end_vertex(c));

  counts.triangles = mesh.triangle_count();
  counts.edges = mesh.edge_count();
  counts.points = mesh.point_count();
  *out = std::move(mesh);
  return counts;
}

}  // namespace lodstream::stream

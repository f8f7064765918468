// Samples of a report's meshes; see report_samples.h.
#include "stream/report_samples.h"

#include <fcntl.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <functional>
#include <span>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/status.h"
#include "core/surface_sampling.h"
#include "io/file_writer.h"
#include "io/offset_file.h"
#include "stream/chunk_scene.h"
#include "stream/job.h"
#include "stream/store_access.h"
#include "stream/units.h"

namespace lodstream::stream {
namespace {

// Samples of a mesh streamed in parts, in its primitive order (every triangle, then every segment; a
// part's triangles and segments come after the earlier parts'), measured in one pass over the parts and
// sampled in a second; the used vertices are sampled in vertex order. With k > 0, also k view targets
// from the same passes: points uniform by area on the triangles; with no triangles, uniform by length on
// the segments; with neither, the points themselves in turn. The samples depend on the mesh alone, never
// on how it is cut into parts: the primitives' weights are summed in fixed blocks of kSampleBlock
// primitives by global id (core/surface_sampling.h), so that blocks measured and sampled by several
// processes give one process's samples (draw_original_samples_in_units).
constexpr unsigned kSampleBlockBits = 16;
constexpr uint64_t kSampleBlock = uint64_t{1} << kSampleBlockBits;

// A block's weight sums, of the samples' sampler and of the view targets'.
struct BlockSums {
  core::SamplerSums sampler, aim;
};

class MeshSampling {
 public:
  // `triangles`: the mesh's triangle count (its segments' global ids follow them); `primitives`: all of them.
  MeshSampling(uint64_t n, uint64_t seed, uint64_t stream, unsigned k, uint64_t triangles, uint64_t primitives)
      : sampler_(n, seed, stream), aim_(k, seed, kStreamTargets), n_(n), k_(k), triangles_(triangles),
        sums_((primitives + kSampleBlock - 1) / kSampleBlock), before_(sums_.size()) {}

  // Pass 1 over a part whose first primitive has global id `first`.
  void measure(std::span<const float> xyz, std::span<const uint32_t> triangles, std::span<const uint32_t> segments, uint64_t first) {
    const float* p = xyz.data();
    for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
      measure_block(first + t / 3);
      const float *a = p + 3ull * triangles[t], *b = p + 3ull * triangles[t + 1], *c = p + 3ull * triangles[t + 2];
      sampler_.measure_triangle(a, b, c);
      if (k_) aim_.measure_triangle(a, b, c);
    }
    const uint64_t first_segment = std::max(first, triangles_);
    for (size_t e = 0; e + 1 < segments.size(); e += 2) {
      measure_block(first_segment + e / 2);
      const float *a = p + 3ull * segments[e], *b = p + 3ull * segments[e + 1];
      sampler_.measure_segment(a, b);
      if (k_ && triangles_ == 0) aim_.measure_segment(a, b);
    }
  }
  // Pass 1's results, for a process that measured some blocks: every block's sums (zero where it measured
  // none); and a block another process measured.
  const std::vector<BlockSums>& sums() {
    close_block();
    return sums_;
  }
  void set_sums(uint64_t block, const BlockSums& s) { sums_.at(block) = s; }
  // Between the passes: the blocks' sums added in block order, and the positions drawn.
  void begin(uint64_t used_vertices) {
    close_block();
    for (size_t b = 0; b < sums_.size(); ++b) {
      before_[b] = {{sampler_.area(), sampler_.length()}, {aim_.area(), aim_.length()}};
      sampler_.add_block(sums_[b].sampler), aim_.add_block(sums_[b].aim);
    }
    sampler_.add_vertices(used_vertices);
    sampler_.begin_sampling();
    aim_.begin_sampling();
    faces_.reserve(3 * n_), edges_.reserve(3 * n_), vertices_.reserve(3 * std::min(n_, used_vertices));
  }
  // Pass 2 over a part, as pass 1.
  void sample(std::span<const float> xyz, std::span<const uint32_t> triangles, std::span<const uint32_t> segments, uint64_t first) {
    const float* p = xyz.data();
    for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
      sample_block(first + t / 3);
      const float *a = p + 3ull * triangles[t], *b = p + 3ull * triangles[t + 1], *c = p + 3ull * triangles[t + 2];
      sampler_.sample_triangle(a, b, c, faces_, edges_);
      if (k_) aim_.sample_triangle(a, b, c, aim_faces_, aim_unused_);
    }
    const uint64_t first_segment = std::max(first, triangles_);
    for (size_t e = 0; e + 1 < segments.size(); e += 2) {
      sample_block(first_segment + e / 2);
      const float *a = p + 3ull * segments[e], *b = p + 3ull * segments[e + 1];
      sampler_.sample_segment(a, b, edges_);
      // Targets on segments only without any area: then no target lies on a triangle.
      if (k_ && !(aim_.area() > 0)) aim_.sample_segment(a, b, aim_edges_);
    }
  }
  // Consecutive used vertices, in vertex order.
  void sample_vertices(std::span<const float> xyz) {
    for (size_t v = 0; v + 2 < xyz.size(); v += 3) sampler_.sample_vertex(xyz.data() + v, vertices_);
  }
  // Whether the next used vertex is a vertex sample (its position is the caller's to add: add_vertex).
  bool take_vertex() { return sampler_.take_vertex(); }
  void add_vertex(const float* p) { vertices_.insert(vertices_.end(), p, p + 3); }
  // Pass 2's samples so far: face, edge and target samples (targets on triangles or else on segments).
  const std::vector<float>& faces() const { return faces_; }
  const std::vector<float>& edges() const { return edges_; }
  const std::vector<float>& aim() const { return aim_.area() > 0 ? aim_faces_ : aim_edges_; }
  // `point_xyz`: positions of points 0, 1, ... (cyclically, k of them), the targets of a mesh of points.
  MeshSamples finish(std::vector<float>* targets, const std::function<std::vector<float>()>& point_xyz) {
    if (targets) {
      *targets = !aim_faces_.empty() ? std::move(aim_faces_) : std::move(aim_edges_);
      if (targets->empty()) *targets = point_xyz();
    }
    MeshSamples out;
    out.faces = faces_.size() / 3;
    faces_.insert(faces_.end(), edges_.begin(), edges_.end());
    faces_.insert(faces_.end(), vertices_.begin(), vertices_.end());
    out.xyz = std::move(faces_);
    return out;
  }

 private:
  // Pass 1: primitive `g` closes the block being measured when it starts another.
  void measure_block(uint64_t g) {
    const uint64_t b = g >> kSampleBlockBits;
    if (open_ && b != block_) close_block();
    open_ = true, block_ = b;
  }
  void close_block() {
    if (!open_) return;
    sums_.at(block_) = {sampler_.end_block(), aim_.end_block()};
    open_ = false;
  }
  // Pass 2: primitive `g` starts its block from the sums of the blocks before it.
  void sample_block(uint64_t g) {
    const uint64_t b = g >> kSampleBlockBits;
    if (open_ && b == block_) return;
    sampler_.begin_block(before_.at(b).sampler), aim_.begin_block(before_.at(b).aim);
    open_ = true, block_ = b;
  }

  core::SurfaceSampler sampler_, aim_;
  uint64_t n_;
  unsigned k_;
  uint64_t triangles_;
  std::vector<BlockSums> sums_, before_;  // per block: its sums; the sums of the blocks before it
  bool open_ = false;
  uint64_t block_ = 0;
  std::vector<float> faces_, edges_, vertices_, aim_faces_, aim_edges_, aim_unused_;
};

}  // namespace

// Samples of a mesh held in memory (a level).
MeshSamples sample_mesh(const core::LodMesh& m, uint64_t n, uint64_t seed, uint64_t stream) {
  MeshSampling s(n, seed, stream, 0, m.triangle_count(), m.triangle_count() + m.edge_count() + m.point_count());
  s.measure(m.positions, m.triangles, m.edges, 0);
  std::vector<uint8_t> used(m.positions.size() / 3, 0);
  for (auto ids : {std::span<const uint32_t>(m.triangles), std::span<const uint32_t>(m.edges), std::span<const uint32_t>(m.points)})
    for (uint32_t v : ids) used[v] = 1;
  s.begin(static_cast<uint64_t>(std::count(used.begin(), used.end(), 1)));
  s.sample(m.positions, m.triangles, m.edges, 0);
  for (size_t v = 0; v < used.size(); ++v)
    if (used[v]) s.sample_vertices(std::span<const float>(m.positions.data() + 3 * v, 3));
  return s.finish(nullptr, {});
}

namespace {

// The view targets of a mesh of points only: points 0, 1, ... (cyclically, `views` of them).
std::vector<float> point_targets(const std::string& store_dir, const StoreMeta& meta, unsigned views, const StoreChunks& chunks) {
  std::vector<uint32_t> ids;
  for_column_blocks(store_dir + "/points.u32", meta.points, 1, 1 << 20, [&](uint64_t, std::span<const uint32_t> p) {
    for (size_t i = 0; i < p.size() && ids.size() < views; ++i) ids.push_back(p[i]);
  });
  const size_t have = ids.size();
  for (size_t i = have; have > 0 && i < views; ++i) ids.push_back(ids[i % have]);
  return chunks.positions_of(ids);
}

}  // namespace

OriginalSamples draw_original_samples(const std::string& store_dir, const StoreMeta& meta, const SampleOptions& o,
                                      StoreChunks& chunks, Progress& progress) {
  const size_t n = chunks.chunks().size();
  MeshSampling s(o.samples, o.seed, kStreamOriginalSamples, o.views, meta.triangles, meta.primitives());
  ChunkGeometry g;
  for (size_t c = 0; c < n; ++c) {
    chunks.read(c, &g);
    s.measure(g.xyz, g.triangles, g.lines, g.first);
    progress.report("load", 0.1 + 0.4 * double(c + 1) / double(n));
  }
  s.begin(chunks.used_vertices());
  for (size_t c = 0; c < n; ++c) {
    if (n > 1) chunks.read(c, &g);  // one chunk: still there
    s.sample(g.xyz, g.triangles, g.lines, g.first);
    progress.report("load", 0.5 + 0.4 * double(c + 1) / double(n));
  }
  g = {};
  chunks.for_used_vertices([&](std::span<const float> xyz) { s.sample_vertices(xyz); });
  OriginalSamples out;
  const MeshSamples m = s.finish(&out.targets, [&] { return point_targets(store_dir, meta, o.views, chunks); });
  out.xyz = m.xyz, out.faces = m.faces;
  return out;
}

// ------------------------------------------------------------------------------------------- units

namespace {

// A unit's wall and CPU seconds, for its stamp (tools/bench_report_shards.sh reads them).
class UnitClock {
 public:
  nlohmann::ordered_json seconds() const {
    return {{"seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count()},
            {"cpu_seconds", process_cpu_seconds() - cpu0_}};
  }

 private:
  std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
  double cpu0_ = process_cpu_seconds();
};

// A unit's files in `dir`.
std::string unit_file(const std::string& dir, const char* what, unsigned u, const char* ext) {
  return fmt::format("{}{}-{}.{}", dir, what, u, ext);
}

void write_floats(io::FileWriter& out, const std::vector<float>& v) {
  const uint64_t n = v.size();
  out.write(&n, 8);
  out.write(v.data(), n * sizeof(float));
}

// A small binary file of the units, read whole; Failure(io_error) naming it when it is cut short.
class UnitFile {
 public:
  explicit UnitFile(const std::string& path) : path_(path), bytes_(io::read_small_file(path)) {}
  template <class T>
  T value() {
    T v;
    take(&v, sizeof v);
    return v;
  }
  std::vector<float> floats() {
    const uint64_t n = value<uint64_t>();
    if (n > (bytes_.size() - at_) / sizeof(float)) fail(Status::io_error, path_ + ": a sampling unit's file is damaged");
    std::vector<float> v(n);
    take(v.data(), n * sizeof(float));
    return v;
  }

 private:
  void take(void* p, size_t n) {
    if (n > bytes_.size() - at_) fail(Status::io_error, path_ + ": a sampling unit's file is cut short");
    std::memcpy(p, bytes_.data() + at_, n);
    at_ += n;
  }
  std::string path_, bytes_;
  size_t at_ = 0;
};

// One original's sampling units (draw_original_samples_in_units): where they go, and what they share.
struct SampleUnits {
  SampleUnits(const std::string& store_dir_in, const StoreMeta& meta_in, const SampleOptions& o_in, const std::string& dir_in,
              unsigned units, uint64_t chunk_bytes_in)
      : store_dir(store_dir_in), meta(meta_in), o(o_in), dir(dir_in.back() == '/' ? dir_in : dir_in + "/"),
        measure_dir(dir + "measure/"), sample_dir(dir + "sample/"),
        blocks((meta.primitives() + kSampleBlock - 1) / kSampleBlock), words((meta.vertices + 63) / 64),
        count(static_cast<unsigned>(std::max<uint64_t>(1, std::min<uint64_t>(units, blocks)))), chunk_bytes(chunk_bytes_in),
        key{{"source", source_json(meta)}, {"vertices", meta.vertices}, {"triangles", meta.triangles}, {"lines", meta.lines},
            {"points", meta.points}, {"samples", o.samples}, {"seed", o.seed}, {"views", o.views}, {"units", count},
            {"block", kSampleBlock}} {}

  const std::string& store_dir;
  const StoreMeta& meta;
  const SampleOptions& o;
  const std::string dir, measure_dir, sample_dir;  // each phase's units in a directory of their own (their locks apart)
  const uint64_t blocks, words;                    // the store's blocks of primitives; 64-bit words of a bit a vertex
  const unsigned count;                            // units, at most one a block
  const uint64_t chunk_bytes;
  const nlohmann::ordered_json key;

  std::pair<uint64_t, uint64_t> block_range(unsigned u) const { return {blocks * u / count, blocks * (u + 1) / count}; }
  MeshSampling sampling() const {
    return MeshSampling(o.samples, o.seed, kStreamOriginalSamples, o.views, meta.triangles, meta.primitives());
  }
  // visit(chunk) over unit u's primitives (its blocks'), read chunk by chunk; returns the chunks read.
  template <class Visit>
  std::unique_ptr<StoreChunks> for_unit_chunks(unsigned u, const Visit& visit) const {
    const auto [b0, b1] = block_range(u);
    auto chunks = std::make_unique<StoreChunks>(store_dir, meta);
    chunks->plan_range(kChunkSceneCosts, chunk_bytes, b0 * kSampleBlock, std::min(meta.primitives(), b1 * kSampleBlock));
    ChunkGeometry g;
    for (size_t c = 0; c < chunks->chunks().size(); ++c) {
      chunks->read(c, &g);
      visit(g);
    }
    return chunks;
  }
};

// Measure units: each block's sums (4 doubles a block) and the unit's used vertices (a bit a store vertex).
// Returns every block's sums.
std::vector<BlockSums> run_measure_units(const SampleUnits& su, unsigned index, Progress& progress) {
  take_units(su.measure_dir, su.count, index, [&](unsigned u) { return unit_file(su.measure_dir, "measure", u, "json"); }, su.key,
             [&](unsigned u) {
               const UnitClock clock;
               MeshSampling s = su.sampling();
               const auto chunks = su.for_unit_chunks(u, [&](const ChunkGeometry& g) { s.measure(g.xyz, g.triangles, g.lines, g.first); });
               const std::vector<BlockSums>& sums = s.sums();
               const auto [b0, b1] = su.block_range(u);
               io::FileWriter out(unit_file(su.measure_dir, "measure", u, "sums"));
               out.write(sums.data() + b0, (b1 - b0) * sizeof(BlockSums));
               out.commit();
               io::FileWriter used(unit_file(su.measure_dir, "measure", u, "used"));
               used.write(chunks->used_bits().data(), su.words * 8);
               used.commit();
               progress.report("samples", 0.3 * double(u + 1) / double(su.count));
               return std::pair(std::vector<std::string>{unit_file(su.measure_dir, "measure", u, "sums")}, clock.seconds());
             });
  std::vector<BlockSums> sums(su.blocks);
  for (unsigned u = 0; u < su.count; ++u) {
    const auto [b0, b1] = su.block_range(u);
    UnitFile f(unit_file(su.measure_dir, "measure", u, "sums"));
    for (uint64_t b = b0; b < b1; ++b) sums[b] = f.value<BlockSums>();
  }
  return sums;
}

// Once, after the measure units: the vertex samples, Algorithm S over the vertices any unit's primitives
// use, in store order, into dir/vertices.bin (the used count, then the samples); then the units' bits go.
// The bits are read a slice at a time (a pass to count the used vertices, which Algorithm S needs first,
// and a pass to take them): memory a slice of each unit's, and the taken vertices' ids.
std::string draw_vertex_samples(const SampleUnits& su) {
  const std::string path = su.dir + "vertices.bin";
  start_once(su.dir, path, su.key, {"vertices"}, [&] {
    const UnitClock clock;
    std::vector<std::unique_ptr<io::OffsetFile>> used;
    for (unsigned u = 0; u < su.count; ++u) {
      const std::string unit = unit_file(su.measure_dir, "measure", u, "used");
      std::error_code ec;
      if (std::filesystem::file_size(unit, ec) != su.words * 8) fail(Status::io_error, unit + ": a sampling unit's file is missing or cut short");
      used.push_back(std::make_unique<io::OffsetFile>(unit, O_RDONLY));
    }
    constexpr uint64_t kSlice = 1 << 12;  // words: 262,144 vertices, 32 KiB a unit
    std::vector<uint64_t> bits, part;
    // visit(first word), the slice's bits OR-ed over the units in `bits`
    const auto for_slices = [&](const auto& visit) {
      for (uint64_t w0 = 0; w0 < su.words; w0 += kSlice) {
        const uint64_t n = std::min(kSlice, su.words - w0);
        bits.assign(n, 0), part.resize(n);
        for (const auto& f : used) {
          f->read(part.data(), n * 8, w0 * 8);
          for (uint64_t i = 0; i < n; ++i) bits[i] |= part[i];
        }
        visit(w0);
      }
    };
    uint64_t used_count = 0;
    for_slices([&](uint64_t) {
      for (uint64_t w : bits) used_count += static_cast<uint64_t>(std::popcount(w));
    });
    MeshSampling s = su.sampling();
    s.begin(used_count);
    std::vector<uint32_t> taken;
    for_slices([&](uint64_t w0) {
      for (uint64_t i = 0; i < bits.size(); ++i)
        for (uint64_t b = bits[i]; b != 0; b &= b - 1)
          if (s.take_vertex()) taken.push_back(static_cast<uint32_t>((w0 + i) * 64 + static_cast<uint64_t>(std::countr_zero(b))));
    });
    io::FileWriter out(path);
    out.write(&used_count, 8);
    write_floats(out, StoreChunks(su.store_dir, su.meta).positions_of_sorted(taken));
    out.commit();
    io::write_file_atomic(su.dir + "vertices.json", clock.seconds().dump() + "\n");
  });
  for (unsigned u = 0; u < su.count; ++u) std::filesystem::remove(unit_file(su.measure_dir, "measure", u, "used"));
  return path;
}

// Sample units: the face, edge and target samples in their blocks, from every block's sums.
void run_sample_units(const SampleUnits& su, unsigned index, const std::vector<BlockSums>& sums, uint64_t used_count,
                      Progress& progress) {
  take_units(su.sample_dir, su.count, index, [&](unsigned u) { return unit_file(su.sample_dir, "sample", u, "json"); }, su.key,
             [&](unsigned u) {
               const UnitClock clock;
               MeshSampling s = su.sampling();
               for (uint64_t b = 0; b < su.blocks; ++b) s.set_sums(b, sums[b]);
               s.begin(used_count);
               su.for_unit_chunks(u, [&](const ChunkGeometry& g) { s.sample(g.xyz, g.triangles, g.lines, g.first); });
               io::FileWriter out(unit_file(su.sample_dir, "sample", u, "bin"));
               write_floats(out, s.faces()), write_floats(out, s.edges()), write_floats(out, s.aim());
               out.commit();
               progress.report("samples", 0.4 + 0.6 * double(u + 1) / double(su.count));
               return std::pair(std::vector<std::string>{unit_file(su.sample_dir, "sample", u, "bin")}, clock.seconds());
             });
}

// The units' samples in unit order: every face sample, then every edge sample, then the vertex samples;
// the targets likewise (or, for a mesh of points only, the points).
OriginalSamples join_unit_samples(const SampleUnits& su, UnitFile& vertices) {
  OriginalSamples out;
  std::vector<float> edges;
  for (unsigned u = 0; u < su.count; ++u) {
    UnitFile f(unit_file(su.sample_dir, "sample", u, "bin"));
    const std::vector<float> faces = f.floats(), unit_edges = f.floats(), aim = f.floats();
    out.xyz.insert(out.xyz.end(), faces.begin(), faces.end());
    edges.insert(edges.end(), unit_edges.begin(), unit_edges.end());
    out.targets.insert(out.targets.end(), aim.begin(), aim.end());
  }
  out.faces = out.xyz.size() / 3;
  out.xyz.insert(out.xyz.end(), edges.begin(), edges.end());
  const std::vector<float> vertex_samples = vertices.floats();
  out.xyz.insert(out.xyz.end(), vertex_samples.begin(), vertex_samples.end());
  if (out.targets.empty()) out.targets = point_targets(su.store_dir, su.meta, su.o.views, StoreChunks(su.store_dir, su.meta));
  return out;
}

}  // namespace

OriginalSamples draw_original_samples_in_units(const std::string& store_dir, const StoreMeta& meta, const SampleOptions& o,
                                               const std::string& dir, unsigned units, unsigned index, uint64_t chunk_bytes,
                                               Progress& progress) {
  const SampleUnits su(store_dir, meta, o, dir, units, chunk_bytes);
  const std::vector<BlockSums> sums = run_measure_units(su, index, progress);
  UnitFile vertices(draw_vertex_samples(su));
  const uint64_t used_count = vertices.value<uint64_t>();
  progress.report("samples", 0.4);
  run_sample_units(su, index, sums, used_count, progress);
  return join_unit_samples(su, vertices);
}

}  // namespace lodstream::stream

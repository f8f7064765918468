// Ingest: input file -> scene store.
//
// A TBB parallel_pipeline with plan.tokens chunks in flight (so mapped input and parsed buffers are
// bounded by construction): the reader cuts chunks in file order, parses them in parallel, resolves them
// in file order, and this file appends the result to the store. Soups (STL) are then welded by exact
// position with two external sorts, so their memory is bounded too.
//
// Faces of four corners or more are stored first as the fan of their ring (io::add_face), a placeholder
// of the right size: their triangles need positions that a chunk's parse does not have (faces name
// vertices of any earlier or later chunk). Once every vertex is stored, triangulate_planar_faces rewrites
// each such face's triangles in place with core::triangulate_polygon (only those that differ from the
// fan), before store.json marks the store complete; the result depends on the face and its positions
// alone, so it is the same for any chunking, thread count or budget.
//
// Invariant of the store: every reference is a valid vertex id, no triangle names a vertex twice, and the
// bytes depend on the input alone (the order of everything is file order, or position order for welded
// soups), never on threads, budget or chunk size.
#include "stream/ingest.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>

#include "core/polygon_triangulation.h"
#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/reader.h"
#include "stream/distinct_count.h"
#include "stream/external_sort.h"
#include "stream/ingest_range.h"
#include "stream/job.h"

namespace lodstream::stream {

namespace {

// Ids are stored as uint32; UINT32_MAX stays free as a marker for later stages.
constexpr int64_t max_vertices = int64_t{UINT32_MAX};

// A chunk's primitives ready for the store: references checked and narrowed to uint32, degenerate
// primitives dropped and counted. Built in parallel, appended in file order.
struct Prepared {
  std::vector<uint32_t> triangles, lines, points;
  std::vector<LocalRun> triangle_runs, line_runs, point_runs;
  std::vector<float> positions32;  // for single-precision stores
  std::vector<std::pair<uint64_t, Bbox>> vertex_boxes;
  std::vector<uint64_t> planar_faces;  // pairs (index among this chunk's kept triangles, corners)
  std::vector<int64_t> ring;           // scratch
  uint64_t degenerate = 0, degenerate_segments = 0, face_segments = 0;
  int64_t max_ref = -1;
  bool negative_ref = false;

  void clear() {
    for (auto* v : {&triangles, &lines, &points}) v->clear();
    for (auto* v : {&triangle_runs, &line_runs, &point_runs}) v->clear();
    positions32.clear();
    vertex_boxes.clear();
    planar_faces.clear();
    degenerate = degenerate_segments = face_segments = 0;
    max_ref = -1;
    negative_ref = false;
  }
};

// Narrows `n` primitives of `arity` references each, dropping those that name a vertex twice.
// Object ids become runs (one per change of object, `first` counted among the kept primitives).
template <int arity, class Ref>
uint64_t narrow_primitives(const std::vector<Ref>& refs, const std::vector<uint32_t>& objects,
                           const std::vector<uint32_t>& materials, std::vector<uint32_t>* ids,
                           std::vector<LocalRun>* runs, Prepared* p) {
  const size_t n = objects.size();
  ids->resize(arity * n);
  uint32_t* out = ids->data();
  uint64_t dropped = 0, kept = 0;
  int64_t hi = p->max_ref, lo = 0;
  uint32_t last_object = UINT32_MAX, last_material = UINT32_MAX;
  const bool with_materials = !materials.empty();
  for (size_t i = 0; i < n; ++i) {
    const Ref* r = &refs[arity * i];
    bool degenerate = false;
    if constexpr (arity == 3) degenerate = r[0] == r[1] || r[1] == r[2] || r[0] == r[2];
    if constexpr (arity == 2) degenerate = r[0] == r[1];
    if (degenerate) {
      ++dropped;
      continue;
    }
    for (int k = 0; k < arity; ++k) {
      const int64_t id = static_cast<int64_t>(r[k]);
      hi = std::max(hi, id);
      lo = std::min(lo, id);
      *out++ = static_cast<uint32_t>(id);
    }
    const uint32_t object = objects[i], material = with_materials ? materials[i] : 0;
    if (object != last_object || material != last_material)
      runs->push_back({kept, last_object = object, last_material = material});
    ++kept;
  }
  ids->resize(static_cast<size_t>(out - ids->data()));
  p->max_ref = hi;
  if (lo < 0) p->negative_ref = true;
  return dropped;
}

bool distinct(std::vector<int64_t>* ring) {
  const size_t m = ring->size();
  const int64_t* r = ring->data();
  if (m <= 32) {
    for (size_t i = 0; i < m; ++i)
      for (size_t j = i + 1; j < m; ++j)
        if (r[i] == r[j]) return false;
    return true;
  }
  std::sort(ring->begin(), ring->end());
  return std::adjacent_find(ring->begin(), ring->end()) == ring->end();
}

// The chunk's planar faces (io::ParsedChunk::planar_faces) renumbered among the kept triangles. A face
// whose ring repeats a vertex in global ids (OBJ: one vertex named by an absolute and a relative index,
// which parse() cannot compare) is not triangulated in its plane: it keeps its fan, less the triangles
// narrow_primitives dropped.
template <class Ref>
void select_planar_faces(const std::vector<Ref>& refs, const std::vector<uint64_t>& faces, bool any_dropped,
                         Prepared* p) {
  auto repeats = [&](uint64_t t) {
    const Ref* r = &refs[3 * t];
    return r[0] == r[1] || r[1] == r[2] || r[0] == r[2];
  };
  uint64_t scanned = 0, dropped = 0;
  for (size_t k = 0; k < faces.size(); k += 2) {
    const uint64_t first = faces[k], m = faces[k + 1];
    if (any_dropped) {
      for (; scanned < first; ++scanned) dropped += repeats(scanned);
      bool lost = false;
      for (uint64_t t = first; t < first + m - 2; ++t) lost = lost || repeats(t);
      if (lost) continue;
    }
    p->ring.clear();
    p->ring.push_back(static_cast<int64_t>(refs[3 * first]));
    p->ring.push_back(static_cast<int64_t>(refs[3 * first + 1]));
    for (uint64_t t = first; t < first + m - 2; ++t) p->ring.push_back(static_cast<int64_t>(refs[3 * t + 2]));
    if (!distinct(&p->ring)) continue;
    p->planar_faces.push_back(first - dropped);
    p->planar_faces.push_back(m);
  }
}

void prepare(const io::ParsedChunk& c, bool soup, bool single, uint64_t first_vertex, Prepared* p) {
  p->clear();
  if (!soup) {
    if (!c.positions32.empty()) {
      // The reader gave floats already (exact): only the chunk boxes to compute.
      p->vertex_boxes = vertex_chunk_boxes(c.positions32, first_vertex);
    } else {
      p->vertex_boxes = vertex_chunk_boxes(c.positions, first_vertex);
      if (single) {
        p->positions32.resize(c.positions.size());
        for (size_t i = 0; i < c.positions.size(); ++i) p->positions32[i] = static_cast<float>(c.positions[i]);
      }
    }
    p->degenerate = c.triangles32.empty()
                        ? narrow_primitives<3>(c.triangles, c.triangle_objects, c.triangle_materials, &p->triangles, &p->triangle_runs, p)
                        : narrow_primitives<3>(c.triangles32, c.triangle_objects, c.triangle_materials, &p->triangles, &p->triangle_runs, p);
    if (!c.planar_faces.empty()) {
      if (c.triangles32.empty()) select_planar_faces(c.triangles, c.planar_faces, p->degenerate != 0, p);
      else select_planar_faces(c.triangles32, c.planar_faces, p->degenerate != 0, p);
    }
    p->degenerate += c.degenerate;
    p->face_segments = c.face_segments;
  }
  p->degenerate_segments = narrow_primitives<2>(c.lines, c.line_objects, c.line_materials, &p->lines, &p->line_runs, p);
  narrow_primitives<1>(c.points, c.point_objects, c.point_materials, &p->points, &p->point_runs, p);
}

// The chunk's vertex colours to the store, one RGBA per vertex record; a record the reader gave no colour
// (it has none where the others have, e.g. a PLY vertex record of variable size) is white.
void add_colors(StoreWriter& store, const io::ParsedChunk& c) {
  const size_t vertices = (c.positions.size() + c.positions32.size()) / 3;
  if (c.colors.size() == 4 * vertices) return store.add_colors(c.colors);
  std::vector<uint8_t> rgba(4 * vertices, 255);
  std::copy_n(c.colors.begin(), std::min(c.colors.size(), rgba.size()), rgba.begin());
  store.add_colors(rgba);
}

// A face to triangulate in its plane: its first triangle in triangles.u32 and its corner count.
struct PlanarFace {
  uint64_t first_triangle;
  uint64_t corners;
};

// Appends prepared primitives to the store in file order and keeps the totals. Planar faces go to a
// scratch file, in file order, for triangulate_planar_faces.
class Feeder {
 public:
  Feeder(StoreWriter& store, const std::string& planar_path) : store_(store), planar_path_(planar_path) {}

  void add(const Prepared& p) {
    if (p.negative_ref) fail(Status::internal, "a reader let through a negative vertex reference");
    if (p.max_ref >= max_vertices) fail(Status::usage, "more than 4,294,967,295 vertices are not supported");
    max_ref_ = std::max(max_ref_, p.max_ref);
    degenerate_ += p.degenerate;
    degenerate_segments_ += p.degenerate_segments;
    face_segments_ += p.face_segments;
    if (!p.planar_faces.empty()) {
      if (!planar_.has_value()) planar_.emplace(planar_path_, 1 << 20);
      for (size_t k = 0; k < p.planar_faces.size(); k += 2) {
        const PlanarFace f{triangles_ + p.planar_faces[k], p.planar_faces[k + 1]};
        planar_->write(&f, sizeof f);
        ++planar_faces_;
      }
    }
    triangles_ += p.triangles.size() / 3;
    for (const auto* runs : {&p.triangle_runs, &p.line_runs, &p.point_runs})
      for (const LocalRun& r : *runs) {
        if (r.object >= objects_used_.size()) objects_used_.resize(std::max<size_t>(r.object + 1, objects_used_.size() * 2), 0);
        objects_used_[r.object] = 1;
      }
    if (!p.triangles.empty()) store_.add_triangles(p.triangles, p.triangle_runs);
    if (!p.lines.empty()) store_.add_lines(p.lines, p.line_runs);
    if (!p.points.empty()) store_.add_points(p.points, p.point_runs);
  }

  // After the last primitive, with the final vertex count: a reference past it means a reader let one
  // through, which is a bug, not bad data (readers report bad references with their location).
  void finish(StoreMeta* meta) {
    const uint64_t v = store_.vertices();
    if (max_ref_ >= static_cast<int64_t>(v))
      fail(Status::internal, "a reader let through vertex reference " + std::to_string(max_ref_) + " of " +
                                 std::to_string(v));
    meta->degenerate = degenerate_;
    meta->degenerate_segments = degenerate_segments_;
    meta->face_segments = face_segments_;
    meta->objects_used = 0;
    for (uint8_t u : objects_used_) meta->objects_used += u;
  }

  // The planar faces written, committed to their scratch file (none: 0 and no file).
  uint64_t commit_planar_faces() {
    if (planar_.has_value()) planar_->commit();
    return planar_faces_;
  }

 private:
  StoreWriter& store_;
  std::string planar_path_;
  std::optional<io::FileWriter> planar_;
  std::vector<uint8_t> objects_used_;
  int64_t max_ref_ = -1;
  uint64_t degenerate_ = 0, degenerate_segments_ = 0, face_segments_ = 0;
  uint64_t triangles_ = 0, planar_faces_ = 0;
};

// Replaces each planar face's fan in triangles.u32 by core::triangulate_polygon's triangles (see the top
// of this file). Faces go in batches of consecutive records whose triangles span at most kSpanBytes: the
// batch's triangles are read with one pread, and the positions its faces name with one more when they
// span at most kSpanBytes too (faces name nearby vertices in real files), else corner by corner. The
// faces of a batch are triangulated in parallel; only those whose triangles change are written back.
// Memory: two buffers of at most kSpanBytes (plus one face larger than that), nothing mapped.
void triangulate_planar_faces(const std::string& store_dir, bool single, const std::string& faces_path,
                              uint64_t faces, StoreMeta* meta, Progress& progress) {
  constexpr uint64_t kSpanBytes = 8 << 20;
  struct Fd {
    int fd;
    std::string path;
    Fd(const std::string& p, int flags) : fd(::open(p.c_str(), flags | O_CLOEXEC)), path(p) {
      if (fd < 0) fail(Status::io_error, path + ": cannot open: " + std::strerror(errno));
    }
    ~Fd() { ::close(fd); }
    void read(void* data, size_t bytes, uint64_t offset) const {
      if (::pread(fd, data, bytes, static_cast<off_t>(offset)) != static_cast<ssize_t>(bytes))
        fail(Status::io_error, path + ": read failed at byte " + std::to_string(offset));
    }
    void write(const void* data, size_t bytes, uint64_t offset) const {
      if (::pwrite(fd, data, bytes, static_cast<off_t>(offset)) != static_cast<ssize_t>(bytes))
        fail(Status::io_error, path + ": write failed at byte " + std::to_string(offset));
    }
  };
  const Fd tri(store_dir + "/triangles.u32", O_RDWR);
  const Fd pos(store_dir + (single ? "/positions.f32" : "/positions.f64"), O_RDONLY);
  const uint64_t stride = single ? 12 : 24;
  struct Scratch {
    std::vector<uint32_t> local;
    std::vector<double> xyz;
    core::PolygonScratch polygon;
    uint64_t concave = 0, fallback = 0;
  };
  tbb::enumerable_thread_specific<Scratch> scratch;
  io::MappedFile list(faces_path);
  std::vector<uint32_t> fans;       // the batch's triangles, from its first face's first triangle
  std::vector<char> corners;        // positions lo..hi of the vertices the batch names
  std::vector<uint8_t> changed;     // per face of the batch
  constexpr uint64_t kWindow = 1 << 16;  // records mapped at a time
  uint64_t done = 0;
  while (done < faces) {
    progress.check();
    const uint64_t window_end = std::min(faces, done + kWindow);
    const io::Window w = list.map(done * sizeof(PlanarFace), window_end * sizeof(PlanarFace));
    const PlanarFace* records = reinterpret_cast<const PlanarFace*>(w.data());
    const uint64_t in_window = window_end - done;
    for (uint64_t b = 0; b < in_window;) {
      // The batch: records b..e, their triangles first..last.
      const uint64_t first = records[b].first_triangle;
      uint64_t e = b + 1;
      while (e < in_window && (records[e].first_triangle + records[e].corners - 2 - first) * 12 <= kSpanBytes) ++e;
      const uint64_t last = records[e - 1].first_triangle + records[e - 1].corners - 2;
      fans.resize(3 * (last - first));
      tri.read(fans.data(), fans.size() * 4, first * 12);
      uint32_t lo = UINT32_MAX, hi = 0;
      for (uint64_t k = b; k < e; ++k) {
        const uint32_t* f = &fans[3 * (records[k].first_triangle - first)];
        const uint64_t m = records[k].corners;
        auto see = [&](uint32_t id) { lo = std::min(lo, id), hi = std::max(hi, id); };
        see(f[0]), see(f[1]);
        for (uint64_t t = 0; t + 2 < m; ++t) see(f[3 * t + 2]);
      }
      const bool in_memory = (uint64_t{hi} - lo + 1) * stride <= kSpanBytes;
      if (in_memory) {
        corners.resize((uint64_t{hi} - lo + 1) * stride);
        pos.read(corners.data(), corners.size(), uint64_t{lo} * stride);
      }
      changed.assign(e - b, 0);
      tbb::parallel_for(tbb::blocked_range<uint64_t>(b, e, 64), [&](const tbb::blocked_range<uint64_t>& r) {
        Scratch& s = scratch.local();
        for (uint64_t k = r.begin(); k < r.end(); ++k) {
          const uint32_t m = static_cast<uint32_t>(records[k].corners);
          uint32_t* f = &fans[3 * (records[k].first_triangle - first)];
          s.xyz.resize(3 * size_t{m});
          for (uint32_t c = 0; c < m; ++c) {
            const uint32_t id = c < 2 ? f[c] : f[3 * (c - 2) + 2];
            char bytes[24];
            const char* at = bytes;
            if (in_memory) at = &corners[(uint64_t{id} - lo) * stride];
            else pos.read(bytes, stride, uint64_t{id} * stride);
            if (single) {
              float v[3];
              std::memcpy(v, at, 12);
              for (int a = 0; a < 3; ++a) s.xyz[3 * c + a] = v[a];
            } else {
              std::memcpy(&s.xyz[3 * c], at, 24);
            }
          }
          s.local.resize(3 * size_t{m - 2});
          const core::Triangulation how = core::triangulate_polygon(s.xyz.data(), m, s.local.data(), &s.polygon);
          if (how == core::Triangulation::fan) continue;
          if (how == core::Triangulation::fallback) {
            ++s.fallback;
            continue;  // the fallback is the fan the store holds
          }
          ++s.concave;
          // Corner numbers to vertex ids: corner 0, 1 and then the third corner of each fan triangle.
          for (uint32_t& c : s.local) c = c < 2 ? f[c] : f[3 * (c - 2) + 2];
          std::copy(s.local.begin(), s.local.end(), f);
          changed[k - b] = 1;
        }
      });
      for (uint64_t k = b; k < e; ++k)
        if (changed[k - b]) {
          const uint64_t at = records[k].first_triangle;
          tri.write(&fans[3 * (at - first)], (records[k].corners - 2) * 12, at * 12);
        }
      b = e;
    }
    done = window_end;
    progress.report("triangulate", static_cast<double>(done) / static_cast<double>(faces));
  }
  for (const Scratch& s : scratch) {
    meta->polygons_concave += s.concave;
    meta->polygons_fallback += s.fallback;
  }
}

// Soup welding (STL): corners are sorted by (position, corner index); each distinct position becomes a
// vertex, in position order; the (corner, vertex id) pairs are sorted back into corner order to form the
// triangles. Both sorts are total orders, so the result does not depend on the memory budget.
struct CornerRec {
  double x, y, z;
  uint64_t corner;
};
struct CornerLess {
  bool operator()(const CornerRec& a, const CornerRec& b) const {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    if (a.z != b.z) return a.z < b.z;
    return a.corner < b.corner;
  }
};
struct CornerIdRec {
  uint64_t corner;
  uint64_t id;
};
struct CornerIdLess {
  bool operator()(const CornerIdRec& a, const CornerIdRec& b) const { return a.corner < b.corner; }
};

class SoupWelder {
 public:
  SoupWelder(const WorkDir& work, const MemoryPlan& plan)
      : work_(work), plan_(plan), corners_(work, "corners", plan.sort_bytes / 2),
        objects_path_(work.scratch("soup-objects")), objects_(objects_path_, 1 << 20) {}
  ~SoupWelder() {
    std::error_code ec;
    std::filesystem::remove(objects_path_, ec);
  }

  void add(const io::ParsedChunk& c) {
    const size_t n = c.positions.size() / 3;
    for (size_t i = 0; i < n; ++i)
      corners_.push({zero(c.positions[3 * i]), zero(c.positions[3 * i + 1]), zero(c.positions[3 * i + 2]), next_corner_++});
    objects_.write_array(std::span<const uint32_t>(c.triangle_objects));
  }

  void weld(StoreWriter& store, Feeder& feeder, Progress& progress) {
    objects_.commit();
    const uint64_t corners = next_corner_;
    ExternalSorter<CornerIdRec, CornerIdLess> back(work_, "corner-ids", plan_.sort_bytes / 2);
    std::vector<double> batch;
    batch.reserve(3 * 65536);
    uint64_t next_id = 0, seen = 0;
    double last[3] = {0, 0, 0};
    corners_.merge([&](const CornerRec& r) {
      if (next_id == 0 || r.x != last[0] || r.y != last[1] || r.z != last[2]) {
        last[0] = r.x, last[1] = r.y, last[2] = r.z;
        batch.insert(batch.end(), {r.x, r.y, r.z});
        if (batch.size() == batch.capacity()) store.add_vertices(batch), batch.clear();
        ++next_id;
      }
      back.push({r.corner, next_id - 1});
      if ((++seen & 0xFFFFF) == 0) progress.report("weld", 0.5 * static_cast<double>(seen) / static_cast<double>(corners));
    });
    store.add_vertices(batch);
    if (next_id > static_cast<uint64_t>(max_vertices)) fail(Status::usage, "more than 4,294,967,295 vertices are not supported");

    io::MappedFile objects_file(objects_path_);
    std::vector<int64_t> refs;
    std::vector<uint32_t> objs;
    refs.reserve(3 * 65536);
    uint64_t triangle = 0;
    Prepared prepared;
    auto flush = [&] {
      if (objs.empty()) return;
      const io::Window w = objects_file.map((triangle - objs.size()) * 4, triangle * 4);
      std::memcpy(objs.data(), w.data(), objs.size() * 4);
      prepared.clear();
      prepared.degenerate = narrow_primitives<3>(refs, objs, {}, &prepared.triangles, &prepared.triangle_runs, &prepared);
      feeder.add(prepared);
      refs.clear();
      objs.clear();
    };
    seen = 0;
    back.merge([&](const CornerIdRec& r) {
      refs.push_back(static_cast<int64_t>(r.id));
      if (refs.size() % 3 == 0) {
        objs.push_back(0);
        ++triangle;
        if (objs.size() == 65536) flush();
      }
      if ((++seen & 0xFFFFF) == 0) progress.report("weld", 0.5 + 0.5 * static_cast<double>(seen) / static_cast<double>(corners));
    });
    flush();
  }

 private:
  static double zero(double v) { return v == 0 ? 0.0 : v; }  // -0 and +0 are one position
  const WorkDir& work_;
  const MemoryPlan& plan_;
  ExternalSorter<CornerRec, CornerLess> corners_;
  std::string objects_path_;
  io::FileWriter objects_;
  uint64_t next_corner_ = 0;
};

struct Slot {
  io::Chunk chunk;
  io::ParsedChunk parsed;
  uint64_t first_vertex = 0;  // global id of the chunk's first vertex, set when resolved
  uint64_t end_offset = 0;    // file offset where the chunk ends, for progress
  bool loaded = false;        // parsed by a range task: `parsed` came from its segment
  Prepared prepared;
};

}  // namespace

StoreMeta ingest(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                 const WorkDir& work, Progress& progress, bool* reused, const std::string& ranges_dir) {
  io::MappedFile file(input);
  std::error_code ec;
  SourceId source{std::filesystem::absolute(input, ec).lexically_normal().string(), file.size(), file.mtime_ns()};

  StoreMeta meta;
  if (read_store_meta(store_dir, &meta) && meta.source == source) {
    *reused = true;
    return meta;
  }
  *reused = false;
  std::filesystem::remove(store_dir + "/store.json", ec);

  std::unique_ptr<io::Reader> reader = io::open_reader(file);
  reader->open();
  // A join of range tasks' parses (stream/ingest_range.h): the splitter cuts the chunks they cut.
  std::unique_ptr<Segments> segments;
  if (!ranges_dir.empty()) {
    segments = std::make_unique<Segments>();
    if (!segments->open(ranges_dir, source)) segments.reset();
  }
  const uint64_t chunk_bytes = segments ? segments->chunk_bytes() : plan.chunk_bytes;
  const unsigned tokens = segments ? range_tokens(plan, chunk_bytes) : plan.tokens;
  meta = StoreMeta{};
  meta.source = source;
  meta.format = reader->format();

  StoreWriter store(store_dir, reader->single_precision());
  const std::string planar_path = work.scratch("planar-faces");
  struct RemoveFile {
    const std::string& path;
    ~RemoveFile() {
      std::error_code ec;
      std::filesystem::remove(path, ec);
      std::filesystem::remove(path + ".partial", ec);
    }
  } remove_planar{planar_path};
  Feeder feeder(store, planar_path);
  std::unique_ptr<SoupWelder> welder;
  if (reader->soup()) welder = std::make_unique<SoupWelder>(work, plan);

  std::vector<std::unique_ptr<Slot>> slots;
  std::vector<Slot*> free_slots;
  std::mutex free_mutex;
  for (unsigned i = 0; i < tokens; ++i) {
    slots.push_back(std::make_unique<Slot>());
    free_slots.push_back(slots.back().get());
  }
  uint64_t seq = 0, vertex_records = 0;
  const double file_bytes = static_cast<double>(std::max<uint64_t>(file.size(), 1));

  progress.report("ingest", 0);
  const bool soup = reader->soup();
  const bool single = reader->single_precision();
  const bool colors = reader->has_colors() && !soup;
  auto take_slot = [&]() {
    std::lock_guard lock(free_mutex);
    Slot* s = free_slots.back();
    free_slots.pop_back();
    return s;
  };
  auto give_slot = [&](Slot* s) {
    std::lock_guard lock(free_mutex);
    free_slots.push_back(s);
  };
  // Five stages; the serial ones do only what needs file order, so both cores stay busy.
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, Slot*>(tbb::filter_mode::serial_in_order,
                                    [&](tbb::flow_control& fc) -> Slot* {
                                      progress.check();
                                      Slot* s = take_slot();
                                      s->chunk = io::Chunk{};
                                      s->chunk.seq = seq;
                                      if (!reader->next_chunk(chunk_bytes, &s->chunk)) {
                                        give_slot(s);
                                        fc.stop();
                                        return nullptr;
                                      }
                                      ++seq;
                                      s->loaded = segments != nullptr;
                                      if (s->loaded) {
                                        s->parsed.clear();
                                        segments->load(s->chunk, &s->parsed);
                                        s->end_offset = s->chunk.bytes.end();
                                        s->chunk.bytes.reset();
                                      }
                                      return s;
                                    }) &
          tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::parallel,
                                         [&](Slot* s) {
                                           if (s->loaded) return s;
                                           s->parsed.clear();
                                           s->parsed.seq = s->chunk.seq;
                                           reader->parse(s->chunk, &s->parsed);
                                           s->end_offset = s->chunk.bytes.end();
                                           s->chunk.bytes.reset();  // release the mapped input pages
                                           return s;
                                         }) &
          tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::serial_in_order,
                                         [&](Slot* s) {
                                           reader->resolve(&s->parsed);
                                           s->first_vertex = vertex_records;
                                           vertex_records += (s->parsed.positions.size() + s->parsed.positions32.size()) / 3;
                                           return s;
                                         }) &
          tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::parallel,
                                         [&](Slot* s) {
                                           prepare(s->parsed, soup, single, s->first_vertex, &s->prepared);
                                           return s;
                                         }) &
          tbb::make_filter<Slot*, void>(tbb::filter_mode::serial_in_order, [&](Slot* s) {
            const io::ParsedChunk& c = s->parsed;
            meta.polygons += c.polygons;
            meta.skipped += c.skipped;
            if (welder) welder->add(c);
            else if (!c.positions32.empty()) store.add_vertices32(c.positions32, s->prepared.vertex_boxes);
            else store.add_vertices(c.positions, s->prepared.positions32, s->prepared.vertex_boxes);
            if (colors) add_colors(store, c);
            feeder.add(s->prepared);
            const uint64_t done = s->end_offset;
            give_slot(s);
            progress.report("ingest", static_cast<double>(done) / file_bytes);
          }));
  reader->finish(reader->soup() ? 0 : vertex_records);
  progress.report("ingest", 1);
  if (welder) {
    welder->weld(store, feeder, progress);
    welder.reset();
  }
  meta.vertex_records = vertex_records;
  meta.object_names = reader->object_names();
  meta.materials = reader->materials();
  feeder.finish(&meta);
  const uint64_t planar_faces = feeder.commit_planar_faces();
  if (planar_faces) {
    store.commit_columns();
    triangulate_planar_faces(store_dir, single, planar_path, planar_faces, &meta, progress);
  }
  StoreMeta done = store.commit(std::move(meta));
  if (segments) segments->remove();
  return done;
}


namespace {
// Marks the vertices a column of uint32 references uses.
void mark_used(const std::string& path, std::vector<uint64_t>* used, Progress& progress) {
  io::MappedFile column(path);
  const uint64_t step = 4 << 18;  // 1 MiB windows: mapped pages count as resident
  for (uint64_t at = 0; at < column.size(); at += step) {
    progress.check();
    const io::Window w = column.map(at, at + step);
    const uint32_t* ids = reinterpret_cast<const uint32_t*>(w.data());
    for (uint64_t i = 0, n = w.size() / 4; i < n; ++i) (*used)[ids[i] >> 6] |= uint64_t{1} << (ids[i] & 63);
  }
}
}  // namespace

Census census(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan, const WorkDir& work,
              Progress& progress) {
  Census c;
  if (meta.vertices == 0) return c;
  std::vector<uint64_t> used((meta.vertices + 63) / 64, 0);
  for (const char* column : {"triangles.u32", "lines.u32", "points.u32"}) mark_used(store_dir + "/" + column, &used, progress);
  uint64_t n_used = 0;
  for (uint64_t w : used) n_used += static_cast<uint64_t>(std::popcount(w));
  c.unused_vertices = meta.vertices - n_used;
  std::vector<uint64_t>().swap(used);

  if (meta.format.rfind("stl", 0) == 0) {
    c.vertices_welded = meta.vertices;  // welded by exact position during ingest
    return c;
  }
  c.vertices_welded = count_distinct_positions(
      positions_column_path(store_dir, meta), meta.vertices, meta.single_precision,
      plan.stage_bytes, progress);
  progress.report("census", 1);
  return c;
}

StoreMeta run_ingest_stage(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                           const WorkDir& work, Progress& progress, std::vector<StageStats>* stages,
                           SceneInfo* scene, bool* reused, const std::string& ranges_dir) {
  const StoreMeta meta = run_stage(stages, "ingest", [&](StageStats& st) {
    StoreMeta m = ingest(input, store_dir, plan, work, progress, reused, ranges_dir);
    st.reused = *reused;
    return m;
  });
  scene->path = input;
  scene->format = meta.format;
  scene->file_bytes = meta.source.bytes;
  scene->vertex_records = meta.vertex_records;
  scene->vertices = meta.vertices;
  scene->polygons = meta.polygons;
  scene->triangles = meta.triangles;
  scene->degenerate = meta.degenerate;
  scene->degenerate_segments = meta.degenerate_segments;
  scene->face_segments = meta.face_segments;
  scene->polygons_concave = meta.polygons_concave;
  scene->polygons_fallback = meta.polygons_fallback;
  scene->lines = meta.lines;
  scene->points = meta.points;
  scene->objects = meta.objects_used;
  scene->skipped_statements = meta.skipped;
  for (int k = 0; k < 3; ++k) scene->bbox_min[k] = meta.bbox.min[k], scene->bbox_max[k] = meta.bbox.max[k];
  return meta;
}

}  // namespace lodstream::stream

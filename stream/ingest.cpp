// Ingest: input file -> scene store.
//
// A TBB parallel_pipeline with plan.tokens chunks in flight (so mapped input and parsed buffers are
// bounded by construction): the reader cuts chunks in file order, parses them in parallel, resolves them
// in file order, and this file appends the result to the store. Soups (STL) are then welded by exact
// position with two external sorts, so their memory is bounded too.
//
// Invariant of the store: every reference is a valid vertex id, no triangle names a vertex twice, and the
// bytes depend on the input alone (the order of everything is file order, or position order for welded
// soups), never on threads, budget or chunk size.
#include "stream/ingest.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <vector>

#include <tbb/parallel_pipeline.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "io/mapped_file.h"
#include "io/reader.h"
#include "stream/external_sort.h"

namespace lodstream::stream {

namespace {

// Ids are stored as uint32; UINT32_MAX stays free as a marker for later stages.
constexpr int64_t max_vertices = int64_t{UINT32_MAX};

// Checks references, drops degenerate primitives, narrows ids to uint32 and appends to the store.
// Also marks which vertices are used, for the unused-vertex count.
class Feeder {
 public:
  explicit Feeder(StoreWriter& store) : store_(store) {}

  void triangles(const std::vector<int64_t>& refs, const std::vector<uint32_t>& objects) {
    ids_.clear();
    obj_.clear();
    for (size_t t = 0, n = objects.size(); t < n; ++t) {
      const int64_t a = refs[3 * t], b = refs[3 * t + 1], c = refs[3 * t + 2];
      if (a == b || b == c || a == c) {
        ++degenerate_;
        continue;
      }
      ids_.push_back(narrow(a));
      ids_.push_back(narrow(b));
      ids_.push_back(narrow(c));
      obj_.push_back(use_object(objects[t]));
    }
    store_.add_triangles(ids_, obj_);
  }

  void lines(const std::vector<int64_t>& refs, const std::vector<uint32_t>& objects) {
    ids_.clear();
    obj_.clear();
    for (size_t s = 0, n = objects.size(); s < n; ++s) {
      if (refs[2 * s] == refs[2 * s + 1]) {
        ++degenerate_segments_;
        continue;
      }
      ids_.push_back(narrow(refs[2 * s]));
      ids_.push_back(narrow(refs[2 * s + 1]));
      obj_.push_back(use_object(objects[s]));
    }
    store_.add_lines(ids_, obj_);
  }

  void points(const std::vector<int64_t>& refs, const std::vector<uint32_t>& objects) {
    ids_.clear();
    obj_.clear();
    for (size_t p = 0, n = objects.size(); p < n; ++p) {
      ids_.push_back(narrow(refs[p]));
      obj_.push_back(use_object(objects[p]));
    }
    store_.add_points(ids_, obj_);
  }

  // After the last primitive, with the final vertex count: a reference past it means a reader let one
  // through, which is a bug, not bad data (readers report bad references with their location).
  void finish(StoreMeta* meta) {
    const uint64_t v = store_.vertices();
    if (v > 0 && max_ref_ >= static_cast<int64_t>(v))
      fail(Status::internal, "a reader let through vertex reference " + std::to_string(max_ref_) + " of " +
                                 std::to_string(v));
    uint64_t used = 0;
    for (size_t w = 0; w < used_.size(); ++w) used += static_cast<uint64_t>(std::popcount(used_[w]));
    meta->unused_vertices = v - used;
    meta->degenerate = degenerate_;
    meta->degenerate_segments = degenerate_segments_;
    meta->objects_used = 0;
    for (uint8_t u : objects_used_) meta->objects_used += u;
  }

 private:
  uint32_t narrow(int64_t id) {
    if (id < 0) fail(Status::internal, "a reader let through a negative vertex reference");
    if (id >= max_vertices) fail(Status::usage, "more than 4,294,967,295 vertices are not supported");
    if (id > max_ref_) max_ref_ = id;
    const size_t word = static_cast<size_t>(id >> 6);
    if (word >= used_.size()) used_.resize(std::max(word + 1, used_.size() * 2), 0);
    used_[word] |= uint64_t{1} << (id & 63);
    return static_cast<uint32_t>(id);
  }
  uint32_t use_object(uint32_t object) {
    if (object >= objects_used_.size()) objects_used_.resize(std::max<size_t>(object + 1, objects_used_.size() * 2), 0);
    objects_used_[object] = 1;
    return object;
  }

  StoreWriter& store_;
  std::vector<uint32_t> ids_, obj_;
  std::vector<uint64_t> used_;
  std::vector<uint8_t> objects_used_;
  int64_t max_ref_ = -1;
  uint64_t degenerate_ = 0, degenerate_segments_ = 0;
};

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
    auto flush = [&] {
      if (objs.empty()) return;
      const io::Window w = objects_file.map((triangle - objs.size()) * 4, triangle * 4);
      std::memcpy(objs.data(), w.data(), objs.size() * 4);
      feeder.triangles(refs, objs);
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
};

}  // namespace

StoreMeta ingest(const std::string& input, const std::string& store_dir, const MemoryPlan& plan,
                 const WorkDir& work, Progress& progress, bool* reused) {
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
  meta = StoreMeta{};
  meta.source = source;
  meta.format = reader->format();

  StoreWriter store(store_dir);
  Feeder feeder(store);
  std::unique_ptr<SoupWelder> welder;
  if (reader->soup()) welder = std::make_unique<SoupWelder>(work, plan);

  std::vector<std::unique_ptr<Slot>> slots;
  std::vector<Slot*> free_slots;
  std::mutex free_mutex;
  for (unsigned i = 0; i < plan.tokens; ++i) {
    slots.push_back(std::make_unique<Slot>());
    free_slots.push_back(slots.back().get());
  }
  uint64_t seq = 0, vertex_records = 0;
  const double file_bytes = static_cast<double>(std::max<uint64_t>(file.size(), 1));

  progress.report("ingest", 0);
  tbb::parallel_pipeline(
      plan.tokens,
      tbb::make_filter<void, Slot*>(tbb::filter_mode::serial_in_order,
                                    [&](tbb::flow_control& fc) -> Slot* {
                                      progress.check();
                                      Slot* s;
                                      {
                                        std::lock_guard lock(free_mutex);
                                        s = free_slots.back();
                                        free_slots.pop_back();
                                      }
                                      s->chunk = io::Chunk{};
                                      s->chunk.seq = seq;
                                      if (!reader->next_chunk(plan.chunk_bytes, &s->chunk)) {
                                        std::lock_guard lock(free_mutex);
                                        free_slots.push_back(s);
                                        fc.stop();
                                        return nullptr;
                                      }
                                      ++seq;
                                      return s;
                                    }) &
          tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::parallel,
                                         [&](Slot* s) {
                                           s->parsed.clear();
                                           s->parsed.seq = s->chunk.seq;
                                           reader->parse(s->chunk, &s->parsed);
                                           return s;
                                         }) &
          tbb::make_filter<Slot*, void>(tbb::filter_mode::serial_in_order, [&](Slot* s) {
            const uint64_t done = s->chunk.bytes.end();
            s->chunk.bytes.reset();  // release the mapped input pages before resolving
            io::ParsedChunk& c = s->parsed;
            reader->resolve(&c);
            meta.polygons += c.polygons;
            meta.skipped += c.skipped;
            vertex_records += c.positions.size() / 3;
            if (welder) {
              welder->add(c);
            } else {
              store.add_vertices(c.positions);
              feeder.triangles(c.triangles, c.triangle_objects);
            }
            feeder.lines(c.lines, c.line_objects);
            feeder.points(c.points, c.point_objects);
            {
              std::lock_guard lock(free_mutex);
              free_slots.push_back(s);
            }
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
  feeder.finish(&meta);
  store.commit(std::move(meta));
  StoreMeta written;
  if (!read_store_meta(store_dir, &written)) fail(Status::io_error, store_dir + "/store.json: cannot read back");
  return written;
}

namespace {
struct Pos {
  double x, y, z;
};
struct PosLess {
  bool operator()(const Pos& a, const Pos& b) const {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
  }
};
}  // namespace

uint64_t count_distinct_positions(const std::string& store_dir, const StoreMeta& meta, const MemoryPlan& plan,
                                  const WorkDir& work, Progress& progress) {
  if (meta.vertices == 0) return 0;
  io::MappedFile positions(store_dir + "/positions.f64");
  if (positions.size() != meta.vertices * 24) fail(Status::io_error, positions.path() + ": size does not match store.json");
  ExternalSorter<Pos, PosLess> sorter(work, "positions", plan.sort_bytes);
  const uint64_t step = 24 * store_chunk_elements;
  for (uint64_t at = 0; at < positions.size(); at += step) {
    const io::Window w = positions.map(at, at + step);
    const double* p = reinterpret_cast<const double*>(w.data());
    for (uint64_t i = 0, n = w.size() / 24; i < n; ++i) {
      auto z = [](double v) { return v == 0 ? 0.0 : v; };
      sorter.push({z(p[3 * i]), z(p[3 * i + 1]), z(p[3 * i + 2])});
    }
    progress.report("weld-count", 0.5 * static_cast<double>(at + w.size()) / static_cast<double>(positions.size()));
  }
  uint64_t distinct = 0, seen = 0;
  Pos last{};
  sorter.merge([&](const Pos& p) {
    if (distinct == 0 || p.x != last.x || p.y != last.y || p.z != last.z) ++distinct, last = p;
    if ((++seen & 0xFFFFF) == 0)
      progress.report("weld-count", 0.5 + 0.5 * static_cast<double>(seen) / static_cast<double>(meta.vertices));
  });
  progress.report("weld-count", 1);
  return distinct;
}

}  // namespace lodstream::stream

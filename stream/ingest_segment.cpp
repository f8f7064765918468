// The segment file of a range task (stream/ingest_range.h) and the join's reading of a set of them.
//
// range-I-of-N.seg: the magic, a SegmentHeader (the task, the source's bytes and mtime, the splitter's
// chunk size), then per chunk the task parsed, in file order: its sequence number and byte range as the
// splitter cut it, then every field of its io::ParsedChunk as parse() left it (vectors as a count and
// their bytes), and an end record (sequence number UINT64_MAX). Written under a .partial name and renamed
// when complete, so a segment present is a whole one. Little-endian, this machine's layout: segments are
// read by the same build on the same kind of machine (a cluster's nodes).
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <map>
#include <regex>
#include <set>

#include <fmt/format.h>

#include "core/status.h"
#include "stream/ingest_range.h"
#include "stream/shard.h"

namespace lodstream::stream {

namespace {

constexpr char kSegmentMagic[8] = {'L', 'O', 'D', 'I', 'N', 'G', 'R', '1'};
constexpr uint64_t kEnd = UINT64_MAX;

}  // namespace

void write_segment_header(io::FileWriter& out, const SegmentHeader& h) {
  out.write(kSegmentMagic, sizeof kSegmentMagic);
  put(out, h.index);
  put(out, h.count);
  put(out, h.source_bytes);
  put(out, h.source_mtime_ns);
  put(out, h.chunk_bytes);
}

void write_parsed_chunk(io::FileWriter& out, const io::Chunk& chunk, const io::ParsedChunk& c) {
  put(out, chunk.seq);
  put(out, chunk.bytes.begin());
  put(out, chunk.bytes.end());
  put_array(out, c.positions);
  put_array(out, c.triangles);
  put_array(out, c.positions32);
  put_array(out, c.triangles32);
  put_array(out, c.lines);
  put_array(out, c.points);
  for (const auto* v : {&c.triangle_objects, &c.line_objects, &c.point_objects, &c.triangle_materials,
                        &c.line_materials, &c.point_materials})
    put_array(out, *v);
  put_array(out, c.colors);
  put(out, static_cast<uint64_t>(c.object_names.size()));
  for (const std::string& name : c.object_names) put_string(out, name);
  put_array(out, c.planar_faces);
  for (uint64_t v : {c.polygons, c.degenerate, c.face_segments, c.skipped, c.newlines}) put(out, v);
  put(out, c.reader_state);
  put(out, static_cast<uint8_t>(c.error.set));
  put(out, c.error.offset);
  put(out, c.error.line);
  put_string(out, c.error.message);
}

void write_segment_end(io::FileWriter& out) { put(out, kEnd); }

// One segment, read from its start, record by record.
struct Segments::Reader : TaskFileReader {
  explicit Reader(const std::string& path) : TaskFileReader(path, kSegmentMagic, "a range ingest segment") {
    get(&header.index);
    get(&header.count);
    get(&header.source_bytes);
    get(&header.source_mtime_ns);
    get(&header.chunk_bytes);
  }
  template <class T>
  void get(T* v) {
    read(v, sizeof *v);
  }
  template <class T>
  void get_vector(std::vector<T>* v) {
    uint64_t n = 0;
    get(&n);
    if (n > (uint64_t{1} << 40) / sizeof(T)) fail(Status::io_error, path_ + ": " + what_ + " is damaged");
    v->resize(n);
    read(v->data(), n * sizeof(T));
  }
  void get_string(std::string* s) {
    uint64_t n = 0;
    get(&n);
    if (n > (uint64_t{1} << 32)) fail(Status::io_error, path_ + ": " + what_ + " is damaged");
    s->resize(n);
    read(s->data(), n);
  }

  void load(const io::Chunk& chunk, io::ParsedChunk* c) {
    uint64_t seq = 0, begin = 0, end = 0;
    get(&seq);
    if (seq != kEnd) {
      get(&begin);
      get(&end);
    }
    if (seq != chunk.seq || begin != chunk.bytes.begin() || end != chunk.bytes.end())
      fail(Status::io_error, fmt::format("{}: holds no chunk {} (bytes {}..{}): not a segment of this input's cut", path_,
                                         chunk.seq, chunk.bytes.begin(), chunk.bytes.end()));
    c->seq = seq;
    get_vector(&c->positions);
    get_vector(&c->triangles);
    get_vector(&c->positions32);
    get_vector(&c->triangles32);
    get_vector(&c->lines);
    get_vector(&c->points);
    for (auto* v : {&c->triangle_objects, &c->line_objects, &c->point_objects, &c->triangle_materials,
                    &c->line_materials, &c->point_materials})
      get_vector(v);
    get_vector(&c->colors);
    uint64_t names = 0;
    get(&names);
    if (names > (uint64_t{1} << 32)) fail(Status::io_error, path_ + ": " + what_ + " is damaged");
    c->object_names.resize(names);
    for (std::string& name : c->object_names) get_string(&name);
    get_vector(&c->planar_faces);
    for (uint64_t* v : {&c->polygons, &c->degenerate, &c->face_segments, &c->skipped, &c->newlines}) get(v);
    get(&c->reader_state);
    uint8_t set = 0;
    get(&set);
    c->error.set = set != 0;
    get(&c->error.offset);
    get(&c->error.line);
    get_string(&c->error.message);
  }

  SegmentHeader header;
};

Segments::Segments() = default;
Segments::~Segments() = default;

bool Segments::open(const std::string& dir, const SourceId& source) {
  dir_ = dir;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return false;
  // Per count N, the indices of this source's segments.
  std::map<unsigned, std::set<unsigned>> sets;
  const std::regex name(R"(range-(\d+)-of-(\d+)\.seg)");
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    std::smatch m;
    const std::string file = entry.path().filename().string();
    if (!std::regex_match(file, m, name)) continue;
    const unsigned index = static_cast<unsigned>(std::stoul(m[1])), count = static_cast<unsigned>(std::stoul(m[2]));
    if (count == 0 || index >= count) continue;
    Reader r(entry.path().string());
    if (r.header.source_bytes != source.bytes || r.header.source_mtime_ns != source.mtime_ns || r.header.index != index ||
        r.header.count != count)
      continue;  // another input's (or an older version of this one's)
    sets[count].insert(index);
  }
  if (sets.empty()) return false;
  unsigned count = 0;
  for (const auto& [n, indices] : sets)
    if (indices.size() == n) {
      count = n;
      break;
    }
  if (count == 0) {
    // None complete: name what the fullest set lacks.
    auto fullest = std::max_element(sets.begin(), sets.end(), [](const auto& a, const auto& b) {
      return a.second.size() < b.second.size();
    });
    const unsigned n = fullest->first;
    std::vector<unsigned> missing;
    for (unsigned i = 0; i < n; ++i)
      if (!fullest->second.count(i)) missing.push_back(i);
    std::string list;
    for (size_t k = 0; k < missing.size() && k < 20; ++k) list += (k ? ", " : "") + std::to_string(missing[k]);
    if (missing.size() > 20) list += fmt::format(" and {} more", missing.size() - 20);
    fail(Status::no_input, fmt::format("{}: range ingest of {} ranges incomplete: range {} missing (run `simplify "
                                       "--shard-ingest I/{}` for {})",
                                       dir, n, list, n, missing.size() == 1 ? "it" : "them"));
  }
  count_ = count;
  file_bytes_ = source.bytes;
  for (unsigned i = 0; i < count; ++i) {
    readers_.push_back(std::make_unique<Reader>(segment_path(dir, i, count)));
    chunk_bytes_ = readers_.back()->header.chunk_bytes;
  }
  if (chunk_bytes_ != range_chunk_bytes(file_bytes_, count))
    fail(Status::io_error, dir + ": range ingest segments of another version (chunk size)");
  return true;
}

void Segments::load(const io::Chunk& chunk, io::ParsedChunk* out) {
  // The range whose byte range holds the chunk's first byte (ranges are ordered and may be empty).
  const uint64_t begin = chunk.bytes.begin();
  unsigned lo = 0, hi = count_;  // the last range whose first byte is at or before `begin`: in [lo, hi)
  while (hi - lo > 1) {
    const unsigned mid = lo + (hi - lo) / 2;
    if (range_bytes(file_bytes_, mid, count_).first <= begin) lo = mid;
    else hi = mid;
  }
  readers_[lo]->load(chunk, out);
}

void Segments::remove() {
  const unsigned n = count_;
  readers_.clear();
  std::error_code ec;
  for (unsigned i = 0; i < n; ++i) std::filesystem::remove(segment_path(dir_, i, n), ec);
}

}  // namespace lodstream::stream

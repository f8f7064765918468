#include "stream/scene_store.h"

#include <algorithm>
#include <cstring>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "core/status.h"
#include "stream/kill_point.h"

namespace lodstream::stream {

using nlohmann::ordered_json;

StoreWriter::StoreWriter(const std::string& dir, bool single_precision) : dir_(dir), single_(single_precision) {
  // Buffers count against the memory budget (see memory.cpp); chunks larger than a buffer bypass it.
  positions_.open(dir + (single_ ? "/positions.f32" : "/positions.f64"), 1 << 20);
  triangles_.ids.open(dir + "/triangles.u32", 1 << 20);
  triangles_.runs.open(dir + "/triangle_objects.runs", 1 << 16);
  lines_.ids.open(dir + "/lines.u32", 1 << 18);
  lines_.runs.open(dir + "/line_objects.runs", 1 << 16);
  points_.ids.open(dir + "/points.u32", 1 << 18);
  points_.runs.open(dir + "/point_objects.runs", 1 << 16);
}

void StoreWriter::Column::add(std::span<const uint32_t> values, int arity, std::span<const LocalRun> local_runs) {
  ids.write_array(values);
  for (const LocalRun& r : local_runs) {
    if (r.object == last_object && r.material == last_material) continue;  // continues the previous batch's run
    const ObjectRun run{count + r.first, r.object, r.material};
    runs.write(&run, sizeof run);
    last_object = r.object, last_material = r.material;
  }
  count += values.size() / static_cast<size_t>(arity);
}

namespace {
// Min/max per axis in the coordinates' own type (no conversion per vertex), widened once per part.
template <class T>
std::vector<std::pair<uint64_t, Bbox>> chunk_boxes(std::span<const T> xyz, uint64_t first_vertex) {
  std::vector<std::pair<uint64_t, Bbox>> boxes;
  const uint64_t n = xyz.size() / 3;
  for (uint64_t i = 0; i < n;) {
    const uint64_t chunk = (first_vertex + i) / store_chunk_elements;
    const uint64_t end = std::min(n, (chunk + 1) * store_chunk_elements - first_vertex);
    T lo[3] = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}, hi[3] = {lo[0], lo[1], lo[2]};
    for (; i < end; ++i)
      for (int k = 0; k < 3; ++k) {
        const T v = xyz[3 * i + k];
        lo[k] = v < lo[k] ? v : lo[k];
        hi[k] = v > hi[k] ? v : hi[k];
      }
    Bbox b;
    b.add(lo);
    b.add(hi);
    boxes.emplace_back(chunk, b);
  }
  return boxes;
}
}  // namespace

std::vector<std::pair<uint64_t, Bbox>> vertex_chunk_boxes(std::span<const float> xyz, uint64_t first_vertex) {
  return chunk_boxes(xyz, first_vertex);
}

std::vector<std::pair<uint64_t, Bbox>> vertex_chunk_boxes(std::span<const double> xyz, uint64_t first_vertex) {
  return chunk_boxes(xyz, first_vertex);
}

void StoreWriter::add_vertices(std::span<const double> xyz, std::span<const float> xyz32,
                               std::span<const std::pair<uint64_t, Bbox>> chunk_boxes) {
  if (single_) {
    if (xyz32.size() != xyz.size()) fail(Status::internal, "single-precision store given no float coordinates");
    positions_.write_array(xyz32);
  } else {
    positions_.write_array(xyz);
  }
  add_boxes(chunk_boxes);
  vertices_ += xyz.size() / 3;
}

void StoreWriter::add_boxes(std::span<const std::pair<uint64_t, Bbox>> chunk_boxes) {
  for (const auto& [chunk, box] : chunk_boxes) {
    if (chunk >= vertex_chunk_bbox_.size()) vertex_chunk_bbox_.resize(chunk + 1);
    vertex_chunk_bbox_[chunk].add(box);
    bbox_.add(box);
  }
}

void StoreWriter::add_vertices32(std::span<const float> xyz32, std::span<const std::pair<uint64_t, Bbox>> chunk_boxes) {
  if (!single_) fail(Status::internal, "float coordinates given to a double-precision store");
  positions_.write_array(xyz32);
  add_boxes(chunk_boxes);
  vertices_ += xyz32.size() / 3;
}

void StoreWriter::add_vertices(std::span<const double> xyz) {
  scratch32_.clear();
  if (single_)
    for (double v : xyz) scratch32_.push_back(static_cast<float>(v));
  add_vertices(xyz, scratch32_, vertex_chunk_boxes(xyz, vertices_));
}

void StoreWriter::add_triangles(std::span<const uint32_t> ids, std::span<const LocalRun> runs) { triangles_.add(ids, 3, runs); }
void StoreWriter::add_lines(std::span<const uint32_t> ids, std::span<const LocalRun> runs) { lines_.add(ids, 2, runs); }
void StoreWriter::add_points(std::span<const uint32_t> ids, std::span<const LocalRun> runs) { points_.add(ids, 1, runs); }

void StoreWriter::add_colors(std::span<const uint8_t> rgba) {
  if (!colors_) colors_.emplace(dir_ + "/colors.rgba8", 1 << 18);
  colors_->write_array(rgba);
}

void StoreWriter::commit_columns() {
  if (columns_committed_) return;
  for (io::FileWriter* w : {&positions_, &triangles_.ids, &triangles_.runs, &lines_.ids, &lines_.runs, &points_.ids,
                            &points_.runs})
    w->commit();
  if (colors_) colors_->commit();
  columns_committed_ = true;
}

StoreMeta StoreWriter::commit(StoreMeta meta) {
  commit_columns();
  meta.single_precision = single_;
  meta.vertices = vertices_;
  meta.triangles = triangles_.count;
  meta.lines = lines_.count;
  meta.points = points_.count;
  meta.bbox = bbox_;
  meta.colors = colors_.has_value();
  meta.vertex_chunk_bbox = vertex_chunk_bbox_;
  kill_point("store.json");
  io::write_file_atomic(dir_ + "/store.json", store_meta_json(meta));
  return meta;
}

namespace {
const char* const kAlphaModes[] = {"OPAQUE", "MASK", "BLEND"};

ordered_json bbox_json(const Bbox& b) {
  return ordered_json{{"min", b.empty ? std::array<double, 3>{0, 0, 0} : b.min},
                      {"max", b.empty ? std::array<double, 3>{0, 0, 0} : b.max}};
}
}  // namespace

ordered_json source_json(const StoreMeta& m) {
  return {{"path", m.source.path}, {"bytes", m.source.bytes}, {"mtime_ns", m.source.mtime_ns}, {"format", m.format}};
}

ordered_json material_json(const core::Material& m) {
  ordered_json j;
  j["name"] = m.name;
  j["base_color"] = std::vector<float>(m.base_color, m.base_color + 4);
  j["metallic"] = m.metallic;
  j["roughness"] = m.roughness;
  j["alpha_mode"] = kAlphaModes[static_cast<int>(m.alpha)];
  j["alpha_cutoff"] = m.alpha_cutoff;
  j["double_sided"] = m.double_sided;
  return j;
}

core::Material material_from_json(const ordered_json& j) {
  core::Material m;
  m.name = j.at("name").get<std::string>();
  const auto c = j.at("base_color").get<std::array<float, 4>>();
  std::copy(c.begin(), c.end(), m.base_color);
  m.metallic = j.at("metallic").get<float>();
  m.roughness = j.at("roughness").get<float>();
  const std::string mode = j.at("alpha_mode").get<std::string>();
  m.alpha = mode == "MASK" ? core::Material::Alpha::mask : mode == "BLEND" ? core::Material::Alpha::blend : core::Material::Alpha::opaque;
  m.alpha_cutoff = j.at("alpha_cutoff").get<float>();
  m.double_sided = j.at("double_sided").get<bool>();
  return m;
}

std::string store_meta_json(const StoreMeta& m) {
  ordered_json j;
  j["version"] = store_version;
  j["chunk_elements"] = store_chunk_elements;
  j["source"] = {{"path", m.source.path}, {"bytes", m.source.bytes}, {"mtime_ns", m.source.mtime_ns}};
  j["format"] = m.format;
  j["positions"] = m.single_precision ? "f32" : "f64";
  j["vertices"] = m.vertices;
  j["vertex_records"] = m.vertex_records;
  j["triangles"] = m.triangles;
  j["lines"] = m.lines;
  j["points"] = m.points;
  j["polygons"] = m.polygons;
  j["degenerate"] = m.degenerate;
  j["degenerate_segments"] = m.degenerate_segments;
  j["face_segments"] = m.face_segments;
  j["polygons_concave"] = m.polygons_concave;
  j["polygons_fallback"] = m.polygons_fallback;
  j["skipped"] = m.skipped;
  j["objects_used"] = m.objects_used;
  j["bbox"] = bbox_json(m.bbox);
  j["object_names"] = m.object_names;
  if (m.colors) j["colors"] = "rgba8";
  if (!m.materials.empty()) {
    ordered_json mats = ordered_json::array();
    for (const core::Material& x : m.materials) mats.push_back(material_json(x));
    j["materials"] = mats;
  }
  ordered_json vc = ordered_json::array();
  for (const Bbox& b : m.vertex_chunk_bbox) vc.push_back(bbox_json(b));
  j["vertex_chunks"] = vc;
  return j.dump(1) + "\n";
}

std::vector<ObjectRun> read_object_runs(const std::string& dir, const std::string& kind) {
  const std::string path = dir + "/" + kind + "_objects.runs";
  const std::string bytes = io::read_small_file(path);
  if (bytes.size() % sizeof(ObjectRun) != 0) fail(Status::io_error, path + ": not a whole number of runs");
  std::vector<ObjectRun> runs(bytes.size() / sizeof(ObjectRun));
  std::memcpy(runs.data(), bytes.data(), bytes.size());
  return runs;
}

bool read_store_meta(const std::string& dir, StoreMeta* m) {
  const std::string path = dir + "/store.json";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  try {
    const ordered_json j = ordered_json::parse(io::read_small_file(path));
    if (j.at("version").get<int>() != store_version) return false;
    if (j.at("chunk_elements").get<uint64_t>() != store_chunk_elements) return false;
    m->source.path = j.at("source").at("path").get<std::string>();
    m->source.bytes = j.at("source").at("bytes").get<uint64_t>();
    m->source.mtime_ns = j.at("source").at("mtime_ns").get<int64_t>();
    m->format = j.at("format").get<std::string>();
    m->single_precision = j.at("positions").get<std::string>() == "f32";
    m->vertices = j.at("vertices").get<uint64_t>();
    m->vertex_records = j.at("vertex_records").get<uint64_t>();
    m->triangles = j.at("triangles").get<uint64_t>();
    m->lines = j.at("lines").get<uint64_t>();
    m->points = j.at("points").get<uint64_t>();
    m->polygons = j.at("polygons").get<uint64_t>();
    m->degenerate = j.at("degenerate").get<uint64_t>();
    m->degenerate_segments = j.at("degenerate_segments").get<uint64_t>();
    m->face_segments = j.at("face_segments").get<uint64_t>();
    m->polygons_concave = j.at("polygons_concave").get<uint64_t>();
    m->polygons_fallback = j.at("polygons_fallback").get<uint64_t>();
    m->skipped = j.at("skipped").get<uint64_t>();
    m->objects_used = j.at("objects_used").get<uint64_t>();
    m->object_names = j.at("object_names").get<std::vector<std::string>>();
    m->colors = j.contains("colors");
    m->materials.clear();
    if (j.contains("materials"))
      for (const auto& x : j.at("materials")) m->materials.push_back(material_from_json(x));
    auto read_bbox = [](const ordered_json& b) {
      Bbox r;
      r.min = b.at("min").get<std::array<double, 3>>();
      r.max = b.at("max").get<std::array<double, 3>>();
      r.empty = false;
      return r;
    };
    m->bbox = read_bbox(j.at("bbox"));
    m->bbox.empty = m->vertices == 0;
    m->vertex_chunk_bbox.clear();
    for (const auto& b : j.at("vertex_chunks")) m->vertex_chunk_bbox.push_back(read_bbox(b));
  } catch (const std::exception&) {
    return false;
  }
  return true;
}

}  // namespace lodstream::stream
